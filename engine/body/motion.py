"""Body motion: a procedural walk cycle for a rigged body, sampled into a `BodyTrack`.

    track = walk_track(body, WalkParams(speed=1.2), fps=30)
    v = track.vertices(i)            # (N, 3) world positions of frame i (any i >= 0)
    u = track.velocities(i)          # (N, 3) world velocities (m/s)

The walk (angles in degrees, from the shape of normal gait curves: Perry & Burnfield, "Gait
Analysis", 2nd ed., 2010, ch. 4-6; Winter, "Biomechanics and Motor Control of Human Movement",
4th ed., 2009, appendix A): per leg, with the gait phase p (0 = that leg's heel strike, the right
leg half a cycle after the left)
    hip flexion    10 + 20 cos(2 pi p) + 0.5 cos(4 pi p) + 3 sin(4 pi p)   (+30 at heel strike, -10 at push-off)
    knee flexion   5 + 11 b(p; 0.13, 0.07) + 56 b(p; 0.69, 0.13)           (loading response, swing)
    ankle dorsiflexion 4 + 8 b(p; 0.44, 0.12) - 19 b(p; 0.61, 0.04) - 4.5 b(p; 0.06, 0.04)
(b = a periodic Gaussian bump: centre, width; peaks: knee 16 at loading, 61 in swing; ankle +12
in late stance, -15 at push-off), with the toes bending at the ball of the foot from heel rise to
toe-off (they stay level while the heel rises: the toe roll), the pelvis turns +-4 degrees with
the forward leg, the thorax turns against it, the arms swing +-14 degrees against the legs with
the elbows bending 0 .. 16 degrees less than the rest pose's ~45, and hang 6 degrees closer to
the body than in the rest (A-) pose (more, and the hands press a skirt against the thighs).
Within the published ranges, the centres, widths and heights of the bumps were chosen (a random
search) so that the planted pelvis moves most evenly: forward speed and vertical velocity
jumps where the foot stood on changes (scripts are not kept; the figures are in
tests/test_motion.py). With the older curves (hip 10 + 20 cos, knee 3 + 15 b(.15) + 57 b(.72),
ankle 9 b(.45) - 17 b(.63) - 4 b(.06), no toe roll) the pelvis went 0.61 .. 1.98 m/s forward
within each step at 1.2 m/s and dropped at up to 0.96 m/s before each heel strike.
The hip amplitude is scaled so that one cycle covers the asked stride.

Feet planted, by construction: every pose is lifted so its lowest foot point touches y = 0 (no
floating, no floor penetration; this is the pelvis bob), and the root moves horizontally so that
the lowest foot point not swinging forward -- the one the body stands on -- keeps its place from
one instant to the next (no sliding; computed on a grid 16x finer than the frames). Walking in place is a treadmill:
the root stays put and the stance foot slides back at the walking speed.
Where the point stood on moves to the other foot (heel strike) that planted path has a kink --
the body's vertical velocity jumped by ~0.5 m/s and its forward by ~0.2 m/s from one instant to
the next -- so the pelvis takes the planted path smoothed over PELVIS_SMOOTH of the cycle (a
Gaussian, 34 ms at 1.2 m/s; _pelvis_path) and the legs take up the difference, more of it the
lower down (leg_share: 0 at the hips, 1 from the ankles down, so the feet stay planted): the
legs stretch or shorten by at most ~7 mm (at 1.2 and at 3.6 m/s). Measured on default:female, the pelvis's velocity changed
by up to 0.496 m/s between two frames at 120 fps, now 0.051; at 30 fps the chest's acceleration
peaked at 11.9 m/s^2 (the sample scan's 15.7), now 5.8.
Even pace: the curves are not exactly consistent with feet planted, so the root moves forward
unevenly over the cycle (0.9 .. 1.6 m/s at 1.2 m/s); the gait's clock is retimed (even_pace,
PACE_EVEN) so the cycle's poses -- and so the planted feet -- are the same but the pelvis moves
at 1.0 .. 1.4 m/s, the joints' pace varying +-15 % instead.

The walk starts from the rest pose (the pose the garment was draped on): the joint angles grow
from 0 to full over `ramp` seconds (smoothstep) while the gait's clock speeds up from 0, starting
at the left leg's mid-stance (so the first thing the body does is lift its right foot; the feet's
pitch grows as the weight squared, like the lift bending the leg gives, so that foot's toe does not
dip below the left sole). After the ramp the motion is periodic; the
track stores the ramp frames and one cycle, relative to the root's horizontal offset, and
repeats the cycle shifted by the stride -- so one cycle of collision maps serves the whole walk.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from engine.body.rig import _skin_kernel, joint_matrices
from engine.body.types import SEGMENT_ID, Body, Rig
from engine.errors import InputError
from engine.jit import serial_kernel

FINE = 16  # planting grid: steps per frame
SWING_SPEED = 0.1  # m/s: a foot point moving forward faster than this (relative to the root) is not stood on
START_PHASE = 0.3  # the walk starts at the left leg's mid-stance
TOES = [f"toe{i}-1" for i in range(1, 6)]  # the joints at the ball of the foot (toe roll; optional)
TOE_OFF, TOE_EASE = 0.64, 0.08  # gait phase of toe-off, and how long the toes take to ease back
PELVIS_SMOOTH = 0.03  # the pelvis's path: the planted one smoothed over this x the cycle (Gaussian sigma; _pelvis_path)
PACE_EVEN = 0.5  # how far the gait's clock is retimed toward an even pace (0: not, 1: constant speed)
ARM_IN = 6.0  # degrees the arms hang closer to the body while walking than in the rest (A-) pose ...
ARM_WALK_MIN = 24.0  # ... but no closer than this from the vertical (in the frontal plane): arms
# hanging down (a scan's) are turned out to it as the walk starts, so the hands swing clear of the hips


@dataclass
class WalkParams:
    speed: float = 1.2  # m/s, a comfortable adult walking speed
    stride: float | None = None  # m per cycle (two steps); None: 0.82 x stature (step ~0.41 h)
    in_place: bool = False  # treadmill: the root stays, the stance foot slides back
    ramp: float = 0.5  # s from the rest pose to the full walk

    def validate(self) -> None:
        if not (0.1 <= self.speed <= 5.0):
            raise InputError(f"walking speed {self.speed} m/s is out of range (0.1 .. 5 m/s; 1.2 is a normal walk)")
        if self.stride is not None and not (0.3 <= self.stride <= 2.5):
            raise InputError(f"stride {self.stride} m is out of range (0.3 .. 2.5 m per cycle of two steps)")
        if not (0.0 <= self.ramp <= 5.0):
            raise InputError(f"ramp {self.ramp} s is out of range (0 .. 5 s)")


def frame_velocities(frames: np.ndarray, fps: float) -> np.ndarray:
    """(F, N, 3) float32 vertex velocities of frames (F, N, 3) played at fps: frame differences,
    central inside, one-sided at the two ends."""
    step = np.diff(frames, axis=0).astype(np.float64) * fps
    vel = np.empty(frames.shape, np.float32)
    vel[0], vel[-1] = step[0], step[-1]
    vel[1:-1] = 0.5 * (step[1:] + step[:-1])
    return vel


@dataclass
class BodyTrack:
    """A body moving over time, sampled at `fps`.

    frames: (F, N, 3) float32 positions relative to the root's horizontal offset (distinct frames:
    the ramp, then one cycle when periodic); vel: (F, N, 3) float32 world velocities (m/s);
    offsets: (F, 3) float64 root offsets (horizontal; world = frame + offset);
    cycle_start, cycle_frames: frames >= cycle_start repeat with period cycle_frames (0: not
    periodic; frames past the end hold the last one), each cycle shifted by `shift` (3,).
    """

    body: Body
    fps: float
    frames: np.ndarray
    vel: np.ndarray
    offsets: np.ndarray
    cycle_start: int
    cycle_frames: int
    shift: np.ndarray
    notes: list[str]

    def index(self, i: int) -> tuple[int, int]:
        """frame i -> (distinct frame k, cycles completed)."""
        i = max(int(i), 0)
        if self.cycle_frames and i >= self.cycle_start:
            c, r = divmod(i - self.cycle_start, self.cycle_frames)
            return self.cycle_start + r, c
        return min(i, len(self.frames) - 1), 0

    def offset(self, i: int) -> np.ndarray:
        k, c = self.index(i)
        return self.offsets[k] + c * self.shift

    def offset_at(self, t: float) -> np.ndarray:
        """Root offset at time t (s), linear between frames. The two frames' offsets are kept
        while t stays between them (a collider asks every solver step; looking them up took a
        third of its ~10 us set_time)."""
        f = max(t, 0.0) * self.fps
        i = int(math.floor(f))
        a = f - i
        pair = self.__dict__.get("_offset_pair")
        if pair is None or pair[0] != i:
            pair = self.__dict__["_offset_pair"] = (i, self.offset(i), self.offset(i + 1))
        return (1.0 - a) * pair[1] + a * pair[2]

    def root_velocity(self, i: int) -> np.ndarray:
        """The root's horizontal velocity at frame i (m/s, central difference of the offsets)."""
        if i > 0:
            return (self.offset(i + 1) - self.offset(i - 1)) * self.fps / 2
        return (self.offset(1) - self.offset(0)) * self.fps

    def vertices(self, i: int) -> np.ndarray:
        k, _ = self.index(i)
        return self.frames[k].astype(np.float64) + self.offset(i)

    def velocities(self, i: int) -> np.ndarray:
        return self.vel[self.index(i)[0]].astype(np.float64)

    @property
    def periodic(self) -> bool:
        return self.cycle_frames > 0


# ----------------------------------------------------------------------------------------------
# the walk


def _rot(axis: str, deg: float) -> np.ndarray:
    a = math.radians(deg)
    c, s = math.cos(a), math.sin(a)
    if axis == "x":
        return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])
    if axis == "y":
        return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def _bump(p: float, centre: float, width: float) -> float:
    d = (p - centre + 0.5) % 1.0 - 0.5
    return math.exp(-0.5 * (d / width) ** 2)


def gait_deltas(phase: float, amp: float, weight: float, arm_in: float = ARM_IN) -> dict[str, np.ndarray]:
    """Joint rotations (3x3, about the joint, in the rest pose's world axes) at gait phase
    `phase` (0..1, left heel strike at 0); amp scales the hip swing (stride), weight (0..1) the
    whole pose (the ramp from rest). X is the body's left, Y up, Z forward."""
    out = {}
    for side, p in (("L", phase % 1.0), ("R", (phase + 0.5) % 1.0)):
        c = math.cos(2 * math.pi * p)
        hip = amp * (10.0 + 20.0 * c + 0.5 * math.cos(4 * math.pi * p) + 3.0 * math.sin(4 * math.pi * p))
        knee = 5.0 + 11.0 * _bump(p, 0.13, 0.07) + 56.0 * _bump(p, 0.69, 0.13)
        ankle = 4.0 + 8.0 * _bump(p, 0.44, 0.12) - 19.0 * _bump(p, 0.61, 0.04) - 4.5 * _bump(p, 0.06, 0.04)
        out[f"upperleg01.{side}"] = _rot("x", -weight * hip)  # flexion: the thigh swings forward
        out[f"lowerleg01.{side}"] = _rot("x", weight * knee)  # flexion: the shank swings back
        # the foot's pitch (toes up) from the leg's angles is weight * (hip - knee + ankle):
        # ramping it as weight^2, like the lift that bending the leg gives, keeps a swinging foot's
        # toe from dipping below the sole of the foot stood on at the start of the walk
        ankle += (weight - 1.0) * (hip - knee + ankle)
        out[f"foot.{side}"] = _rot("x", -weight * ankle)  # dorsiflexion: toes up
        # toe roll: from heel strike to toe-off the toes stay level while the heel rises (they bend
        # at the ball of the foot), easing back over early swing; the body then rolls over the
        # ball of the foot rather than over the toe tips
        heel_up = max(0.0, weight * (knee - hip - ankle))  # the foot's pitch, toes down
        hold = 1.0 if p <= TOE_OFF else max(0.0, 1.0 - (p - TOE_OFF) / TOE_EASE)
        toes = _rot("x", -heel_up * hold)
        for toe in TOES:
            out[f"{toe}.{side}"] = toes
        # the arm swings with the opposite leg: forward when that leg is forward
        q = (p + 0.5) % 1.0
        cq = math.cos(2 * math.pi * q)
        toward = -arm_in if side == "L" else arm_in  # closer to the body than the rest pose (about Z)
        out[f"upperarm01.{side}"] = _rot("x", -weight * 14.0 * amp * cq) @ _rot("z", weight * toward)
        out[f"lowerarm01.{side}"] = _rot("x", -weight * (-8.0 + 8.0 * cq))  # the rest pose bends it ~45
    c = math.cos(2 * math.pi * phase)
    out["root"] = _rot("y", -weight * 4.0 * amp * c)  # the pelvis turns with the forward (left) leg
    out["spine01"] = _rot("y", weight * 6.0 * amp * c)  # the thorax turns against it
    return out


def pose_joints(rig: Rig, deltas: dict[str, np.ndarray]) -> np.ndarray:
    """(J, 4, 4) posed world transforms: each named joint rotated about itself by its delta
    (in the rest pose's world axes), children following (a walk poses the skeleton thousands
    of times: the chain's products run compiled, _chain_product)."""
    rest = rig.rest_transforms
    local, parent, index = _chain(rig)
    link = local.copy()  # each joint's transform from its parent's frame (the world's for a root)
    for name, r in deltas.items():
        j = index[name]
        rr = rest[j, :3, :3]
        link[j, :, :3] = link[j, :, :3] @ (rr.T @ r @ rr)  # link @ [[rr^T r rr, 0], [0, 1]]
    g = np.empty_like(rest)
    _chain_product(link, parent, g)
    return g


@serial_kernel
def _chain_product(link, parent, g):
    """g[j] = g[parent[j]] @ link[j] down the chain (a root's g is its link); parents first."""
    for j in range(link.shape[0]):
        p = parent[j]
        if p < 0:
            for r in range(4):
                for c in range(4):
                    g[j, r, c] = link[j, r, c]
            continue
        for r in range(4):
            for c in range(4):
                s = 0.0
                for k in range(4):
                    s += g[p, r, k] * link[j, k, c]
                g[j, r, c] = s


def _chain(rig: Rig):
    """(local (J, 4, 4): each joint's rest transform relative to its parent -- the rest
    transform itself for a root --, parents, name -> index), kept on the rig (computed once)."""
    cached = rig.__dict__.get("_chain")
    if cached is None or cached[0] is not rig.rest_transforms:
        rest = rig.rest_transforms
        parent = np.asarray(rig.parents, dtype=np.int64)
        local = np.empty_like(rest)
        for j in range(len(rest)):
            p = parent[j]
            if p >= j:
                raise InputError(f"the skeleton lists joint {rig.joint_names[j]} before its parent")
            local[j] = rest[j] if p < 0 else np.linalg.inv(rest[p]) @ rest[j]
        cached = (rest, (local, parent, {n: i for i, n in enumerate(rig.joint_names)}))
        rig.__dict__["_chain"] = cached
    return cached[1]


def arm_in(rig: Rig) -> float:
    """Degrees the walk turns the arms in from the rest pose (ARM_IN; negative: out), so that
    they hang no closer to the vertical than ARM_WALK_MIN: the smaller over the two upper arms
    of (rest angle in the frontal plane - ARM_WALK_MIN), at most ARM_IN."""
    idx = {n: i for i, n in enumerate(rig.joint_names)}
    angles = []
    for side in ("L", "R"):
        if f"upperarm01.{side}" not in idx or f"lowerarm01.{side}" not in idx:
            return ARM_IN
        d = rig.rest_transforms[idx[f"lowerarm01.{side}"], :3, 3] - rig.rest_transforms[idx[f"upperarm01.{side}"], :3, 3]
        angles.append(math.degrees(math.atan2(abs(d[0]), -d[1])))
    return float(min(ARM_IN, min(angles) - ARM_WALK_MIN))


class _Walker:
    """Poses and plants the walk for one body."""

    def __init__(self, body: Body, params: WalkParams):
        if body.rig is None:
            raise InputError("this body has no skeleton, so it cannot walk: use default:female / default:male, "
                             "or a scan (its skeleton is fitted from the default body)")
        self.body, self.rig, self.p = body, body.rig, params
        names = set(body.rig.joint_names)
        missing = [n for n in gait_deltas(0.0, 1.0, 1.0) if n not in names and n.split(".")[0] not in TOES]
        self.toes = all(f"{t}.{s}" in names for t in TOES for s in "LR")  # a rig without toe joints walks flat-footed
        if missing:
            raise InputError(f"the body's skeleton lacks the joints {', '.join(missing)} the walk moves")
        rv = body.vertices
        legs = np.zeros(len(rv), bool) if body.segments is None else np.isin(
            body.segments, [SEGMENT_ID["left_leg"], SEGMENT_ID["right_leg"]])
        feet = np.flatnonzero(legs & (rv[:, 1] < 0.12 * body.height))
        if len(feet) < 10:
            feet = np.flatnonzero(rv[:, 1] < 0.06 * body.height)
        self.feet = feet
        self.left_foot = rv[feet, 0] > 0  # the body's left is +x
        self.feet_rest = np.ascontiguousarray(rv[feet])
        self.feet_idx = np.ascontiguousarray(self.rig.skin_indices[feet], dtype=np.int32)
        self.feet_w = np.ascontiguousarray(self.rig.skin_weights[feet], dtype=np.float64)
        self.amp = 1.0
        self.period = 1.0
        self.pace = None  # (clock, phase) tables of the retiming (even_pace); None: phase = clock
        self.arm_in = arm_in(body.rig)

    def deltas(self, t: float) -> dict[str, np.ndarray]:
        """The pose at time t: during the ramp the pose weight w = smoothstep(t / ramp) grows
        from 0 (rest) to 1 while the gait's clock runs at w times its speed, from mid-stance of
        the left leg (its foot under the body, the right foot lifting); after it, the cycle.
        The clock (in cycles) becomes the gait's phase through the retiming of even_pace."""
        r = self.p.ramp
        if r > 0 and t < r:
            x = t / r
            w = x * x * (3.0 - 2.0 * x)
            run = r * (x ** 3 - 0.5 * x ** 4)  # integral of smoothstep from 0 to t
        else:
            w, run = 1.0, 0.5 * r + (t - r)
        u = run / self.period
        if self.pace is not None:
            whole = math.floor(u)
            u = whole + float(np.interp(u - whole, *self.pace))
        d = gait_deltas((START_PHASE + u) % 1.0, self.amp, w, self.arm_in)
        if not self.toes:
            for name in [n for n in d if n.split(".")[0] in TOES]:
                del d[name]
        return d

    def even_pace(self, samples: int, strength: float) -> None:
        """Retime the gait so the body's forward speed varies less: planted as it is, the root
        moves forward D(phase), unevenly (the joint curves are not exactly consistent with
        planted feet -- measured on the default bodies at 1.2 m/s, 0.9 .. 1.6 m/s within each
        step); the clock spends time on each part of the cycle in
        proportion to D'(phase)^strength, so the root moves at a speed that goes as
        D'^(1 - strength) -- the poses, and so the planted feet, are the same, only reached at
        other times (the joints' pace then varies instead, as D'^-strength)."""
        self.pace = None
        keep = self.p
        self.p = replace(keep, ramp=0.0)  # the clock from 0 at START_PHASE: one cycle
        _, offs = self.plant(0.0, self.period, samples, np.zeros(3))
        self.p = keep
        d = np.maximum(np.diff(offs[:, 2]), 1e-9) ** strength
        clock = np.concatenate([[0.0], np.cumsum(d)]) / d.sum()
        self.pace = (clock, np.linspace(0.0, 1.0, samples + 1))

    def feet_at(self, t: float) -> np.ndarray:
        m = joint_matrices(self.rig, pose_joints(self.rig, self.deltas(t)))
        out = np.empty_like(self.feet_rest)
        _skin_kernel(self.feet_rest, self.feet_idx, self.feet_w, m, out)
        return out

    def plant(self, t0: float, t1: float, steps: int, off0: np.ndarray):
        """Root offsets (steps+1, 3) (x, z planted; y the lift) from t0 to t1."""
        ts = np.linspace(t0, t1, steps + 1)
        step = (t1 - t0) / max(steps, 1)
        offs = np.zeros((steps + 1, 3))
        offs[0] = off0
        prev = self.feet_at(ts[0])
        offs[0, 1] = -prev[:, 1].min()
        for k in range(1, steps + 1):
            cur = self.feet_at(ts[k])
            # the point the body stands on: the lowest of those not swinging forward (faster
            # than SWING_SPEED relative to the root). (Taking the lowest of all, at the start of
            # the walk the foot swinging forward, its toe not yet lifted, was stood on: the body
            # slid back 5 cm over 3 frames, 0.9 m/s, then lurched forward.)
            y = np.where(cur[:, 2] - prev[:, 2] <= SWING_SPEED * step, prev[:, 1], np.inf)
            c = int(np.argmin(y)) if np.isfinite(y).any() else int(np.argmin(prev[:, 1]))
            offs[k, 0] = offs[k - 1, 0] - (cur[c, 0] - prev[c, 0])
            offs[k, 2] = offs[k - 1, 2] - (cur[c, 2] - prev[c, 2])
            offs[k, 1] = -cur[:, 1].min()
            prev = cur
        return ts, offs


def _pelvis_path(offs: np.ndarray, start: int, period: int, shift: np.ndarray, sigma: float) -> np.ndarray:
    """The planted root offsets (K, 3) at the fine steps (the ramp, then one cycle from `start`,
    `period` steps, repeating shifted by `shift`) smoothed by a Gaussian of `sigma` steps: the
    path the pelvis takes (walk_track). Planting has a kink wherever the point stood on moves
    to the other foot -- at heel strike the pelvis's vertical velocity jumped by ~0.5 m/s and
    its forward by ~0.2 m/s from one instant to the next (15.7 m/s^2 at the sample scan's chest,
    frame to frame at 30 fps), and the collision maps, which move each frame's surface along its
    velocity, were off by up to ~2 mm around it. The cycle is smoothed as the periodic signal it
    is, so it repeats exactly; the ramp with its own neighbours (at rest before it), its
    difference from the planted path faded in from 0 (the walk starts from the drape's pose)
    and, over its last 4 sigma, over to the cycle's (the ramp ends near the first heel strike,
    where the two differ by ~2 mm)."""
    if sigma <= 0:
        return offs.copy()
    from scipy.ndimage import gaussian_filter1d

    pad = int(math.ceil(4 * sigma))
    c = max(1, -(-pad // period))  # cycles the window spans
    cyc = offs[start:start + period]
    ext = np.concatenate([np.repeat(offs[:1], pad, axis=0), offs[:start]]  # at rest before the walk
                         + [cyc + r * shift for r in range(2 * c + 2)])  # the cycle repeated on
    sm = gaussian_filter1d(ext, sigma, axis=0, mode="nearest")
    dev = np.empty_like(offs)  # smoothed - planted
    # the cycle: from a repetition whose window reaches neither the ramp nor the end
    dev[start:start + period] = sm[pad + start + c * period:pad + start + (c + 1) * period] - c * shift - cyc
    dev[start + period:] = dev[start:start + len(offs) - start - period]
    if start > 0:
        k = np.arange(start)
        ramp = sm[pad:pad + start] - offs[:start]
        x = k / start
        ramp *= (x * x * (3.0 - 2.0 * x))[:, None]
        lead = np.clip((k - (start - pad)) / pad, 0.0, 1.0)
        beta = (lead * lead * (3.0 - 2.0 * lead))[:, None]
        tail = dev[start + (k - start) % period]  # the cycle's, run back before it
        dev[:start] = (1.0 - beta) * ramp + beta * tail
    return offs + dev


def leg_share(body: Body) -> np.ndarray:
    """(N,) how much of the planted path (against the pelvis's smoothed one, _pelvis_path) each
    vertex follows: 0 at and above the hips, growing down each leg to 1 at the ankle and below
    (the feet stay planted), by its skinning weights on the leg joints (the joints from
    upperleg01 down, each by its rest height between the hip and the ankle). The legs stretch or
    shorten by the few millimetres between the two paths (measured: at most ~7 mm at heel
    strike, over the whole leg)."""
    rig = body.rig
    names = list(rig.joint_names)
    share = np.zeros(len(names))
    for side in ("L", "R"):
        hip, ankle = f"upperleg01.{side}", f"foot.{side}"
        if hip not in names or ankle not in names:
            continue
        y_hip = rig.rest_transforms[names.index(hip)][1, 3]
        y_ankle = rig.rest_transforms[names.index(ankle)][1, 3]
        below = np.zeros(len(names), bool)
        below[names.index(hip)] = True
        for j in range(len(names)):  # the hip's descendants (parents come first: _chain_product)
            if rig.parents[j] >= 0 and below[rig.parents[j]]:
                below[j] = True
        y = rig.rest_transforms[below, 1, 3]
        share[below] = np.clip((y_hip - y) / max(y_hip - y_ankle, 1e-6), 0.0, 1.0)
    return np.einsum("nk,nk->n", rig.skin_weights, share[rig.skin_indices])


def walk_track(body: Body, params: WalkParams | None = None, fps: float = 30.0) -> BodyTrack:
    """Sample the walk of `body` (rigged) at `fps`: the ramp from rest, then one cycle."""
    p = params or WalkParams()
    p.validate()
    if not (5.0 <= fps <= 240.0):
        raise InputError(f"frame rate {fps} is out of range (5 .. 240 frames per second)")
    w = _Walker(body, p)
    stride = p.stride if p.stride is not None else 0.82 * body.height
    # the cycle lasts a whole number of frames (so its maps repeat exactly)
    n_cycle = max(4, int(round(stride / p.speed * fps)))
    w.period = n_cycle / fps
    n_ramp = int(math.ceil(p.ramp * fps))
    ramp_t = n_ramp / fps
    w.p = WalkParams(speed=p.speed, stride=stride, in_place=p.in_place, ramp=ramp_t)
    # scale the hip swing until one cycle covers the stride (it is nearly linear in the amplitude)
    for _ in range(4):
        _, offs = w.plant(ramp_t, ramp_t + w.period, n_cycle * FINE, np.zeros(3))
        got = float(offs[-1, 2] - offs[0, 2])
        if got <= 1e-3:
            raise InputError("the walk cycle does not move the body forward (the skeleton's legs may not face +Z)")
        w.amp = float(np.clip(w.amp * stride / got, 0.2, 2.0))
        if abs(got - stride) < 0.005 * stride:
            break
    w.even_pace(n_cycle * FINE, PACE_EVEN)
    # plant over the ramp and one cycle
    n = n_ramp + n_cycle
    ts, offs = w.plant(0.0, n / fps, n * FINE, np.zeros(3))
    shift = offs[-1] - offs[n_ramp * FINE]
    shift[1] = 0.0
    if p.in_place:
        offs[:, [0, 2]] = 0.0
        shift[:] = 0.0
    # the pelvis on a smoothed path, the legs taking up the difference (_pelvis_path, leg_share)
    smooth = _pelvis_path(offs, n_ramp * FINE, n_cycle * FINE, shift, PELVIS_SMOOTH * n_cycle * FINE)
    share = leg_share(body)[:, None]
    frame_offs = smooth[::FINE][:n].copy()
    rig, rv = body.rig, body.vertices
    idx = np.ascontiguousarray(rig.skin_indices, dtype=np.int32)
    wts = np.ascontiguousarray(rig.skin_weights, dtype=np.float64)
    frames = np.empty((n, len(rv), 3), np.float32)
    vel = np.empty_like(frames)
    h = 1.0 / (fps * FINE)
    buf = np.empty_like(rv)

    def placed(k):
        """(N, 3) each vertex's offset at fine step k (before the walk: as at 0): the pelvis's,
        and the legs' toward the planted one."""
        k = max(k, 0)
        return smooth[k] + share * (offs[k] - smooth[k])

    for i in range(n):
        t = i / fps
        m = joint_matrices(rig, pose_joints(rig, w.deltas(t)))
        _skin_kernel(rv, idx, wts, m, buf)
        frames[i] = buf + placed(i * FINE) - (frame_offs[i, 0], 0.0, frame_offs[i, 2])
        # world velocity: central difference over one fine step, the root's motion included
        pos = []
        for s in (-1, 1):
            k = i * FINE + s
            m = joint_matrices(rig, pose_joints(rig, w.deltas(t + s * h)))
            _skin_kernel(rv, idx, wts, m, buf)
            o = placed(k) if k < len(offs) else 2 * placed(len(offs) - 1) - placed(len(offs) - 2)
            pos.append(buf + o)
        vel[i] = (pos[1] - pos[0]) / (2 * h)
    frame_offs[:, 1] = 0.0  # the lift is in the frames
    speed = float(np.linalg.norm(shift)) / w.period if not p.in_place else stride / w.period
    notes = [f"walk: {speed:.2f} m/s, stride {stride:.2f} m, cycle {w.period:.3f} s = {n_cycle} frames at "
             f"{fps:g} fps, ramp from rest {ramp_t:.2f} s" + (", in place (treadmill)" if p.in_place else "")]
    return BodyTrack(body=body, fps=float(fps), frames=frames, vel=vel, offsets=frame_offs,
                     cycle_start=n_ramp, cycle_frames=n_cycle, shift=shift, notes=notes)
