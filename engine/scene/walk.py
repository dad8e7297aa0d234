"""Walk a dressed body (seed 000 end to end): dress it standing (engine.scene.tryon), then play a
BodyTrack and let the cloth follow.

Per body frame (1/fps s): the solver takes whole steps of at most the eq. 4 bound; before each
step that checks collisions (ClothSolver.checks_next; the steps between do not ask the collider)
the collider is put at the step's end time (maps of the nearest frame, surface moved along
its velocity, root offset interpolated: engine.collide.moving). The collision response is
relative to the body's velocity (seed 000 eq. 15), the reaction force (eq. 16) holds cloth
pressed on the body, and the strain limit is eq. 5's average by default; the directional vector
v_dir = g dt + v_object (eq. 6 and §3.2's two rules) can be chosen, but is not yet stable here
(WalkOptions.velocity_mode). Damping is the fabric's own
(the drape's extra settling damping is off: walking is dynamic).

Softer springs while walking (WalkOptions.stiffness, default 0.25 x the drape's stretch and shear
springs): the eq. 4 step grows as 1 / sqrt of it (0.147 -> 0.295 ms on the dress), and the strain
limit (velocity modification, the strain guard) holds the fit, as in seed 003 §4. Where it cannot
-- a band the moving body wedges -- a frame whose strain max passes the fabric's threshold +
WalkOptions.stiffen_at doubles the stiffness (up to the drape's) for the rest of the walk and the
report says so. Measured on default:female, M, 4 s (max strain over all frames, the median of the
frames' maxima, penetration max; realtime factors of one process each on this noisy machine):
  dress     x1: 7.5 % / 6.6 %, 2.0 mm, 0.137 | x0.25: 12.9 % / 7.0 %, 1.2 mm, 0.201 | x0.0625: 35.2 % / 8.3 %
  trousers  x1: 7.2 % / 7.0 %, 1.5 mm, 0.140 | x0.25: 21.8 % / 11.5 %, 4.2 mm, 0.181 | x0.0625: torn (52 %)
  skirt     x1: 7.4 % / 5.8 %, 1.3 mm, 0.189 | x0.25: 11.9 % / 7.0 %, 1.1 mm, 0.335 | x0.0625: 24.1 % / 12.9 %
  shirt     x1: 7.2 % / 6.5 %, 3.5 mm, 0.216 | x0.25: 13.5 % / 7.0 %, 1.4 mm, 0.275 | x0.0625: 33.3 % / 7.5 %
The strain peaks are a few springs for a few frames (the dress's armholes as an arm swings back,
the trousers' hips); with stiffening at threshold + 10 % the trousers went to x0.5 at frame 11
(18.2 %) and then stayed at 7.3 % (median); the others never stiffened. Since the pelvis no
longer jolts at heel strike (engine.body.motion._pelvis_path) none stiffens: strain max 7.7 %
(dress), 14.9 % (trousers; median 8.1), 7.4 % (skirt), 7.7 % (shirt).

A periodic walk's maps (the ramp and one cycle) are rendered before the walking stage
(WalkOptions.prerender; `map_prerender_seconds`), and the walk expands their float16 copies.
Otherwise the maps of each frame are rendered one frame ahead in a helper thread with its own
GL context (WalkOptions.render_ahead; engine.collide.moving): the body's motion does not depend
on the cloth, and the numba kernels release the GIL, so the render runs on the second core while
the solver works; the solver waits only when a render is late (`ms_per_frame.maps` counts that
wait, `map_render_seconds` the renders). The maps are the same bit for bit (tests/test_walk.py).

Each frame is checked: non-finite positions, runaway strain or cloth far from the body end the run
with SimulationError (never an exploded garment written as a result).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field

import numpy as np

from engine.body.motion import BodyTrack, WalkParams, walk_track
from engine.body.types import SEGMENTS, Body
from engine.cloth.model import ClothState, with_stiffness
from engine.cloth.solver import ClothSolver
from engine.errors import InputError, SimulationError
from engine.scene.drape import DrapeResult, Progress

RUNAWAY_STRAIN = 0.5  # a spring stretched 50 % past its rest length: the cloth is exploding
FLY_OFF = 0.5  # m: a cloth vertex this far outside the body's bounding box has left it
CHECK_TRAVEL = 0.00175  # m: the body's bulk travel between two collision checks (WalkOptions.collide_every)
MAX_CHECK_EVERY = 8  # steps: collisions are checked at least this often


@dataclass
class WalkOptions:
    seconds: float = 4.0
    fps: float = 30.0
    walk: WalkParams = field(default_factory=WalkParams)
    reuse_maps: bool = True  # a periodic walk renders one cycle of maps and reuses it
    # None: keep the drape's rule (eq. 5). The directional rule (eq. 6) is available but runs away
    # on a walking skirt within ~0.25 s (see engine.cloth.kernels.DIR_MIN_OBJECT_SPEED; measured
    # at 0.3 m/s: strain 5 % -> 30 % in 1000 steps, where eq. 5 holds 5.2-5.6 % for 3000).
    velocity_mode: str | None = None
    # Gauss-Seidel passes of the strain limit per call while walking (as the drape). Measured on
    # the dress, 1.5 s of walking:
    # 12 passes 517 ms a frame, strain max 7.6 %, penetration max 1.5 mm; 6 passes 418 ms,
    # 7.7 %, 0.6 mm; 3 passes 388 ms, 8.4 %.
    vm_passes: int = 6
    # Steps between collision checks (the points predicted that many steps ahead; in between the
    # reaction force holds contacts' forces and cloth.kernels.hold_contacts their velocities). The
    # eq. 4 step is set by the stiffest spring, not by contact: a point moving 1 m/s travels
    # 0.9 mm in 8 steps of 0.115 ms, a fifth of the band. Measured before hold_contacts on the
    # dress (4374 vertices, 2 s): every step 503 ms a frame, penetration max 0.6 mm, strain 7.7 %;
    # every 4 steps 311 ms, 1.7 mm, 6.4 %; every 8 steps (2 contact rounds, 4 s) 221 ms, 5.3 mm
    # -- and at every 4, the strain limit pulled the tight front of the dress (default:female, M)
    # 4.15 mm into the bust, showing through (every 2nd step: 1.0 mm, still showing). With
    # hold_contacts, 4 s on default:female, M, every 4 -> every 8 steps: dress 0.72 -> 1.20 mm,
    # trousers 2.32 -> 3.08, skirt 0.89 -> 0.85, shirt 1.80 -> 1.78 (p99 0 throughout), strain
    # max 7.1-7.8 % either way; the dress 277 -> 212 ms a frame (one process, same machine). At
    # 3.6 m/s every 8 steps left p99 at 3.4 mm: None (the default) checks as often as the body's
    # bulk travel covers CHECK_TRAVEL, on average (check_every; at the drape's stiffness every 8
    # steps at 1.2 m/s, ~3 at 3.6; at the walking default, twice the step, ~4 at 1.2 m/s). Measured at the
    # walking default: every 6 steps instead of 4 saved 12-18 ms a frame but let the trousers
    # reach 6.8 mm (4.2) and 30 % strain (21.8), the shirt 4.1 mm (1.4): left at CHECK_TRAVEL
    collide_every: int | None = None
    # Alternations of strain limit and collision response per check (the drape also uses 2:
    # ClothParams.contact_rounds).
    # Measured on the dress, 4 s: 4 rounds 195 ms a frame, penetration max 3.0 mm, strain
    # 7.3 %; 2 rounds 152 ms, 3.4 mm, 7.3 %; 1 round 140 ms, 3.8 mm, 7.7 %.
    contact_rounds: int = 2
    # Positions keep springs within the fabric's threshold + this (Provot; never pulling cloth
    # into the body), as in the drape. Measured on the shirt, 4 s, 2 contact rounds: without it
    # strain max 11.9 %, penetration max 3.4 mm, 134 ms a frame; with 0.02: 7.1 %, 2.2 mm, 137 ms.
    strain_guard: float | None = 0.02
    # The stretch and shear springs while walking, as a fraction of the drape's (the eq. 4 step
    # grows as 1 / sqrt of it; the strain limit and the guard hold the fit). See module doc:
    # 0.0625 tore the trousers and let the dress's armholes reach 35 %.
    stiffness: float = 0.25
    # A frame whose strain max passes the fabric's threshold + this doubles the springs' stiffness
    # (at most the drape's) for the rest of the walk: the strain limit alone does not hold a band
    # the body wedges (measured, see module doc). None: never.
    stiffen_at: float | None = 0.10
    # Render each frame's maps one frame ahead in a helper thread while the solver works on this
    # frame (the body's motion does not depend on the cloth); the solver waits only when they
    # are late. False: render when the frame comes up, in this thread.
    render_ahead: bool = True
    # Maps kept for reuse (a periodic walk: the ramp and one cycle) are all rendered before the
    # walking stage (TrackCollider.prerender; "walk maps" in progress, the report's
    # map_prerender_seconds), with both cores free: the walking stage then only expands kept
    # float16 copies, and each of its frames costs what a reused frame costs. Measured on the
    # dress, 4 s (default:female, M): rendered one frame ahead, the first 49 frames took 50-62 ms
    # each and the reused ones after them 35-51 ms (same runs); the 49 renders took 1.08 s up
    # front against 1.54 s of the helper thread's time during the walk. False: render each
    # frame's maps when it comes up (ahead, as render_ahead says).
    prerender: bool = True
    # Spring forces in single precision (ClothSolver.single_precision_forces; velocities and
    # positions stay double). False: double, as the drape.
    single_precision_forces: bool = True
    # The shear springs' forces evaluated with the flexion springs', every flexion_every steps
    # (ClothSolver.hold_shear; they are still listed for the strain limit every step). False:
    # every step, as the drape.
    hold_shear: bool = True
    # Steps between evaluations of the flexion springs' forces (and, with hold_shear, the shear
    # springs'), held in between (ClothParams.flexion_every; the drape's: 4). At the walk's
    # stiffness a shear spring's period is ~56 ms on the dress (cotton, 0.38 N/m, ~30 mg a
    # point); 8 steps are 2.5 ms of it.
    flexion_every: int = 8
    # The cap on each spring's damping (engine.cloth.model.with_stiffness; the drape's 0.25 x
    # m / (dt degree)). At the walk's quarter stiffness the drape's cap holds every stretch
    # spring's damping at 2 % of critical instead of the 30 % asked for, and the cloth rang:
    # ~230 Hz in-plane, velocities off their mean by ~0.6 m/s (measured on the dress: a point's
    # x + 4 dt v missed where it was 4 steps later by 0.81 mm, median; 2.34 mm at the 90th
    # percentile). At 0.5: 0.02 mm.
    damping_cap: float = 0.5
    # The strain guard run at the start of each step, from its force pass's list of long springs,
    # instead of by a pass of its own over every spring at the end of the step before
    # (ClothSolver.late_guard; the frames are guarded before they are written). False: as the
    # drape.
    late_guard: bool = True
    # s: a checked point in the inner half of the collision band is moved out over about this
    # long (ClothParams.push_time; the drape's 0.02 s). At 0.02 the walking springs' tension
    # pressed tight cloth to within 0.2-0.5 mm of the skin (the dress over default:female's bust:
    # 1.35 mm after the drape, 0.17 mm after 1.7 s of walking), and a sharp part of the body --
    # the bust's apex -- came through between the cloth's vertices by up to 1 mm, skin spots in
    # the pictures (the sample scan in its XL dress: a spot ~1 cm wide on the bust in 3 of the
    # strip's 8 frames), though no cloth vertex was inside. Measured, 3 s on default:female in M
    # at 1.5 cm, every 2nd frame, body vertices through the cloth's triangles by more than
    # 0.3 mm, 0.02 -> 0.005: dress 30 -> 20 frames of 45, shirt 29 -> 14, trousers 35 -> 22,
    # skirt 7 -> 3 (deepest 1.29 -> 1.09, 2.39 -> 1.53, 3.31 -> 3.15, 0.65 -> 0.60 mm); 4 s,
    # cloth vertices inside (max; p99 0 in all): dress 1.50 -> 0.96 mm, shirt 1.03 -> 1.03,
    # skirt 1.05 -> 0.98, trousers 1.56 -> 4.16 (one frame; its strain limit fought the
    # stronger push, stiffened once more at frame 105). 0.01 left the scan's spots as at 0.02.
    push_time: float = 0.005
    collision: str = "image"  # or "object": the BVH baseline (engine.collide.moving.TrackObjectCollider)
    friction: float = 1.0  # x the fabric's cloth-body friction (engine.scene.arms lowers arms without it)

    def validate(self) -> None:
        if not (0.1 <= self.seconds <= 60.0):
            raise InputError(f"--seconds {self.seconds}: walk between 0.1 and 60 s")
        if self.collision not in ("image", "object"):
            raise InputError(f"collision '{self.collision}': use image or object")
        if not (1 <= self.vm_passes <= 100):
            raise InputError(f"vm_passes {self.vm_passes}: use 1 .. 100")
        if self.strain_guard is not None and not (0.0 <= self.strain_guard <= 0.5):
            raise InputError(f"strain_guard {self.strain_guard}: use 0 .. 0.5 (or None: off)")
        if not (1 <= self.flexion_every <= 16):
            raise InputError(f"flexion_every {self.flexion_every}: evaluate flexion springs every 1 .. 16 steps")
        if not (1 <= self.contact_rounds <= 16):
            raise InputError(f"contact_rounds {self.contact_rounds}: use 1 .. 16")
        if self.collide_every is not None and not (1 <= self.collide_every <= 16):
            raise InputError(f"collide_every {self.collide_every}: check collisions every 1 .. 16 steps")
        if not (0.01 <= self.stiffness <= 1.0):
            raise InputError(f"walking stiffness {self.stiffness} (--walk-stiffness): use 0.01 .. 1 "
                             "(a fraction of the drape's springs)")
        if self.stiffen_at is not None and not (0.0 < self.stiffen_at <= 0.4):
            raise InputError(f"stiffen_at {self.stiffen_at}: use 0 .. 0.4 (strain past the fabric's threshold), or None")
        if not (0.0 < self.damping_cap <= 1.0):
            raise InputError(f"damping_cap {self.damping_cap}: use 0 .. 1 (x m / (dt degree))")
        if not (0.001 <= self.push_time <= 0.2):
            raise InputError(f"push_time {self.push_time}: use 0.001 .. 0.2 s")
        if not (0.0 <= self.friction <= 2.0):
            raise InputError(f"friction scale {self.friction}: use 0 .. 2")
        if not (5.0 <= self.fps <= 120.0):
            raise InputError(f"--fps {self.fps}: use 5 .. 120 frames per second")
        self.walk.validate()
        from engine.cloth.kernels import VM_MODES

        if self.velocity_mode is not None and self.velocity_mode not in VM_MODES:
            raise InputError(f"unknown velocity modification '{self.velocity_mode}'; "
                             f"choose one of: {', '.join(VM_MODES)}")


def check_every(track: BodyTrack, dt: float) -> float:
    """Solver steps between collision checks while walking, on average (ClothSolver._check_now):
    as many as the body's bulk travel (its vertices' mean velocity, fastest frame) takes to cover
    CHECK_TRAVEL, 1 .. MAX_CHECK_EVERY, to 0.01 of a step. Not rounded down to whole steps: a
    step 6 % longer (the ~4,000-vertex dress, 0.314 ms against 0.295) took the dress from a
    check every 4 steps to every 3 -- 35 instead of 28 checks a frame."""
    bulk = float(np.linalg.norm(track.vel.mean(axis=1, dtype=np.float64), axis=1).max())
    return float(np.clip(math.floor(100.0 * CHECK_TRAVEL / max(bulk * dt, 1e-12)) / 100.0, 1, MAX_CHECK_EVERY))


@dataclass
class WalkResult:
    garment_frames: np.ndarray  # (F, M, 3) float32 cloth positions per frame (frame 0: the drape)
    triangles: np.ndarray  # (T, 3) int32
    track: BodyTrack
    report: dict


def walking_body(body: Body) -> Body:
    """The body to walk: a scan (no rig) gets the default body's skeleton and weights fitted to it
    (engine.body.fit); a rigged body walks as it is. The scan is dressed as loaded (dressed with
    the fitted segment maps, the sample skirt on the sample scan was left at 17 % strain)."""
    if body.rig is not None:
        return body
    from engine.body.fit import fit_rig

    return fit_rig(body)


def walk_segments(body: Body, track: BodyTrack, garment_top: float) -> tuple[list[str] | None, list[str]]:
    """Segment maps for a walk: every limb the garment can meet while walking (the arms swing
    down past the hips, so unlike a standing skirt a walking one needs them), the head only when
    the garment reaches the neck. Returns (segments or None for one whole-body map, left out)."""
    if body.segments is None:
        return None, ["segment maps, because this body has no segment labels (one whole-body map pair)"]
    present = set(int(s) for s in np.unique(body.segments))
    segs = [s for s in ("torso", "left_arm", "right_arm", "left_leg", "right_leg") if SEGMENTS.index(s) in present]
    left = []
    head = body.segments == SEGMENTS.index("head")
    if head.any() and garment_top + 0.05 > float(body.vertices[head, 1].min()):
        segs = ["head"] + segs
    else:
        left.append("head maps, because the garment stays below the neck")
    arm = np.isin(body.segments, [SEGMENTS.index("left_arm"), SEGMENTS.index("right_arm")])
    lowest = min(float(track.frames[k][arm, 1].min()) for k in range(len(track.frames))) if arm.any() else np.inf
    if lowest > garment_top + 0.05:
        segs = [s for s in segs if "arm" not in s]
        left.append(f"arm maps, because the arms never come down to the garment (lowest {lowest:.2f} m, "
                    f"garment top {garment_top:.2f} m)")
    return segs, left


def walk_cloth(body: Body, drape: DrapeResult, options: WalkOptions, *, texel: float, tol: float,
               progress: Progress | None = None, track: BodyTrack | None = None, observer=None) -> WalkResult:
    """Walk `body` wearing the draped garment `drape` for options.seconds. observer: called
    every frame (engine.scene.drape.Observer, with the body's vertices of the frame; both
    meshes relative to the root's horizontal travel, so that a viewer keeps the walker in view)."""
    from engine.collide.bvh import MeshBVH, penetration_depth
    from engine.collide.maps import MapRenderer
    from engine.collide.moving import TrackCollider

    progress = progress or (lambda *a: None)
    o = options
    o.validate()
    t_all = time.perf_counter()
    progress("motion", 0.0, "posing the walk")
    if track is None:
        track = walk_track(body, o.walk, o.fps)
    left = list(track.notes)
    n_frames = int(round(o.seconds * track.fps))
    if not track.periodic and n_frames > len(track.frames) - 1:
        n_frames = len(track.frames) - 1
        left.append(f"walking past {n_frames / track.fps:.2f} s, because the animation ends there")
    renderer = None
    if o.collision == "object":
        from engine.collide.moving import TrackObjectCollider

        left.append("collision maps, because object-space collision (a BVH refitted every frame) was chosen")
        collider = TrackObjectCollider(track, tol=tol)
    else:
        top = float(drape.positions[:, 1].max())
        segs, seg_left = walk_segments(body, track, top)
        left += seg_left
        window = (0.0, min(float(track.frames[:, :, 1].max()), top + 0.15))
        def make_renderer(own_context: bool = False) -> MapRenderer:
            return MapRenderer(body.faces, segments=body.segments, segment_names=segs, texel=texel, tol=tol,
                               window=window, with_velocity=True, own_context=own_context)

        # rendered ahead: the helper thread makes the renderer; else it is made here
        renderer = None if o.render_ahead else make_renderer()
        if track.periodic and o.reuse_maps:
            distinct = min(n_frames + 1, len(track.frames))
            left.append(f"maps of frames after the first cycle, because the walk is periodic: {distinct} frames "
                        f"of maps rendered once (ramp {track.cycle_start} + cycle {track.cycle_frames}) and "
                        f"reused for all {n_frames + 1} frames (float16 copies)")
        else:
            left.append("nothing: the motion is not periodic, so maps are rendered for every frame")
        if o.render_ahead:
            collider = TrackCollider(track, lambda: make_renderer(own_context=True), tol=tol,
                                     keep=track.periodic and o.reuse_maps, ahead=True)
            collider.last_frame = n_frames
        else:
            collider = TrackCollider(track, renderer, tol=tol, keep=track.periodic and o.reuse_maps)
    frame_time = 1.0 / track.fps
    t_prerender = 0.0
    if o.collision == "image" and o.prerender and collider.keep:
        progress("walk maps", 0.0, "rendering the walk's collision maps")
        t_prerender = collider.prerender(n_frames, lambda k, n: progress(
            "walk maps", k / n, f"collision maps of frame {k}/{n} of the ramp and one cycle"))

    def walking_model(stiffness: float):
        """The drape's model at `stiffness` x its springs with the walk's solver settings; the
        step: the drape's (the eq. 4 bound, or what was chosen) scaled as the bound is."""
        from dataclasses import replace

        m = with_stiffness(drape.model, stiffness, damping_cap=o.damping_cap)
        dt_max = drape.dt * m.dt_bound / drape.model.dt_bound
        n_sub = max(1, math.ceil(frame_time / dt_max - 1e-9))
        ev = o.collide_every if o.collide_every is not None else check_every(track, frame_time / n_sub)
        m = replace(m, params=replace(m.params, vm_passes=o.vm_passes, collide_every=ev,
                                      contact_rounds=o.contact_rounds, strain_guard=o.strain_guard,
                                      flexion_every=o.flexion_every, push_time=o.push_time,
                                      velocity_mode=o.velocity_mode or m.params.velocity_mode))
        return m, n_sub, frame_time / n_sub, ev

    stiffness = o.stiffness
    model, sub, dt, every = walking_model(stiffness)
    stiffened = []
    stiffen_strain = model.fabric.strain_threshold + o.stiffen_at if o.stiffen_at is not None else np.inf
    solver = ClothSolver(model, collider, dt=dt)
    if o.single_precision_forces:
        solver.single_precision_forces()
    if o.hold_shear:
        solver.hold_shear()
    if o.late_guard:
        solver.late_guard()
    solver.drop_forces()  # (only FIRE and diagnostics read them)
    state = ClothState(drape.state.x.copy(), drape.state.v.copy())
    frames = np.empty((n_frames + 1, model.n, 3), np.float32)
    frames[0] = state.x
    per_frame, depths, strains = [], [], []
    lo, hi = body.vertices.min(axis=0), body.vertices.max(axis=0)
    t_maps = t_cloth = t_coll = 0.0
    t_walk0 = time.perf_counter()
    try:
        for i in range(1, n_frames + 1):
            m0, c0, k0 = collider.stats["map_seconds"], solver.timing["cloth"], solver.timing["collision"]
            for s in range(sub):
                if solver.checks_next():  # (the steps between checks do not ask the collider)
                    collider.set_time((i - 1 + (s + 1) / sub) * frame_time)
                solver.step(state, friction_scale=o.friction)
            solver.finish_guard(state)  # (late_guard: the frame's last step's guard)
            t_maps += collider.stats["map_seconds"] - m0
            t_cloth += solver.timing["cloth"] - c0
            t_coll += solver.timing["collision"] - k0
            x = state.x
            if not (np.all(np.isfinite(x)) and np.all(np.isfinite(state.v))):
                raise SimulationError(f"the cloth became unstable at frame {i} ({i / track.fps:.2f} s; non-finite "
                                      "positions); walk slower or use a softer fabric")
            strain = solver.max_strain(state)
            off = track.offset(i)
            far = float(np.max(np.maximum(lo + off - x, x - hi - off)))
            if strain > RUNAWAY_STRAIN or far > FLY_OFF:
                what = (f"a spring is stretched {100 * strain:.0f} %" if strain > RUNAWAY_STRAIN
                        else f"cloth is {far:.2f} m outside the body's box")
                raise SimulationError(f"the garment came apart at frame {i} ({i / track.fps:.2f} s: {what}); "
                                      "walk slower, or use a smaller size or a softer fabric")
            frames[i] = x
            if strain > stiffen_strain and stiffness < 1.0:  # the strain limit is losing: stiffer springs
                stiffness = min(1.0, 2.0 * stiffness)
                model, sub, dt, every = walking_model(stiffness)
                solver.restiffen(model, dt)
                stiffened.append({"frame": i, "strain": strain, "stiffness": stiffness})
                left.append(f"the softer walking springs from frame {i} on ({stiffness:g} x the drape's now), "
                            f"because a spring reached {100 * strain:.1f} % strain")
            strains.append(strain)
            progress("walking", i / n_frames, f"frame {i}/{n_frames}, strain {100 * strain:.1f} %")
            if observer is not None:  # a viewer follows the walker: both relative to the root
                observer("walking", x - off, drape.triangles, track.vertices(i) - off)
        wall_walk = time.perf_counter() - t_walk0
    finally:
        if o.collision == "image":
            collider.release()  # (its query server's thread; rendered ahead: the helper thread's renderer)
        if renderer is not None:
            renderer.release()
    # The exact penetration check of every frame (against that frame's body mesh), after the
    # walking stage: its BVH queries run on both cores (numba's OpenMP pool), whose threads spin
    # for milliseconds after each query -- in the walk's frames they took cores from the solver
    # and its query server (measured on the dress, 3,883 vertices, 4 s, scripts/bench_ab.py
    # --walk, three interleaved rounds: the same walk bit for bit, 0.87 x the ms per frame of
    # checking each frame in the loop; realtime 0.729 against 0.652, medians -- three rounds on
    # this machine overstate: six rounds of it with the held shear springs gave 0.94 x).
    tp = time.perf_counter()
    progress("penetration", 0.0, "checking every frame against the body")
    exact = None
    for i in range(1, n_frames + 1):
        bv = track.vertices(i)
        if exact is None:
            exact = MeshBVH(bv, body.faces)
        else:
            exact.update(bv)  # same topology: refit
        depth, _ = penetration_depth(exact, frames[i])
        depths.append(depth.astype(np.float32))
        per_frame.append({"frame": i, "t": round(i / track.fps, 4),
                          "penetration_mm": {"max": float(depth.max()) * 1000,
                                             "p99": float(np.percentile(depth, 99)) * 1000},
                          "strain_max": strains[i - 1]})
        progress("penetration", i / n_frames, f"frame {i}/{n_frames}")
    t_pen = time.perf_counter() - tp
    sim_seconds = n_frames * frame_time
    pooled = np.concatenate(depths)  # every cloth vertex of every frame
    pmax, p99 = float(pooled.max()) * 1000, float(np.percentile(pooled, 99)) * 1000
    report = {
        "frames": n_frames, "fps": track.fps, "seconds": sim_seconds, "substeps_per_frame": sub, "dt_ms": dt * 1000,
        "collision_every_steps": every,
        "stiffness": {"start": o.stiffness, "end": stiffness, "stiffened": stiffened},
        "damping_cap": o.damping_cap,  # x m / (dt degree): the cap on each spring's damping
        "late_guard": o.late_guard,  # the strain guard from the next force pass's list
        "flexion_every": o.flexion_every,  # steps between the flexion (and held shear) springs' forces
        "contact_rounds": o.contact_rounds,
        "push_time_ms": o.push_time * 1000,
        "strain_guard": o.strain_guard,
        "velocity_mode": model.params.velocity_mode,
        "realtime_factor": sim_seconds / max(wall_walk, 1e-9),
        "ms_per_frame": {"maps": 1000 * t_maps / n_frames, "cloth": 1000 * t_cloth / n_frames,
                         "collision": 1000 * t_coll / n_frames, "total": 1000 * wall_walk / n_frames},
        "map_frames_rendered": collider.stats["renders"], "map_frames_reused": collider.stats["reuses"],
        # the renders' own time (ms_per_frame.maps counts what the walk waited for: rendered ahead,
        # in a helper thread, only their lateness)
        "map_render_seconds": collider.stats.get("render_seconds", collider.stats["map_seconds"]),
        # ... of them, those rendered before the walking stage (WalkOptions.prerender; not in its wall time)
        "map_prerender_seconds": t_prerender,
        "maps_rendered_ahead": o.render_ahead and o.collision == "image",
        "map_memory_mb": collider.stats["map_bytes"] / 2 ** 20,
        # the collision queries' chunks answered by the query server's thread (the rest: the solver's)
        "query_server_share": _server_share(collider.stats.get("query_chunks")),
        # ... let go at this time (s) when it kept making the solver wait (engine.collide.server.StallWatch)
        "query_helper_let_go_at": collider.stats.get("helper_let_go_at"),
        "penetration_mm": {"max": pmax, "p99": p99},  # over all vertices of all frames
        "strain_max": max(f["strain_max"] for f in per_frame),
        "wall_seconds": {"walking": wall_walk, "penetration_check": t_pen, "maps_before": t_prerender,
                         "total": time.perf_counter() - t_all},
        "left_out": left,
        "per_frame": per_frame,
    }
    return WalkResult(garment_frames=frames, triangles=drape.triangles, track=track, report=report)


def _server_share(chunks: dict | None) -> float | None:
    """The query server's share of the queries' chunks (None: no server, object-space collision)."""
    if not chunks or not (chunks["server"] + chunks["solver"]):
        return None
    return chunks["server"] / (chunks["server"] + chunks["solver"])


def walk_report(drape_report: dict, walk: dict) -> dict:
    """The walk's report: the drape's fields (dressing the standing body), then the walk's
    headline fields at the top level (frames, fps, realtime_factor, ms_per_frame, per_frame),
    the rest under "walk"; left_out holds both stages' choices."""
    top = ("frames", "fps", "realtime_factor", "ms_per_frame", "per_frame")
    out = dict(drape_report)
    out.update({k: walk[k] for k in top})
    out["walk"] = {k: v for k, v in walk.items() if k not in top and k != "left_out"}
    out["left_out"] = list(drape_report.get("left_out", [])) + list(walk.get("left_out", []))
    return out


def write_walk_outputs(out, body: Body, walk: WalkResult, report: dict, panels: int = 8,
                       size: int = 420) -> list:
    """anim.glb (body + garment moving), strip.png (a row of side views across the walk) and
    report.json in `out`; returns the paths."""
    import json
    from pathlib import Path

    from PIL import Image

    from engine.io.anim import write_anim_glb
    from engine.io.export import BODY_RGBA, GARMENT_RGBA
    from engine.io.render import BODY_RGB, render_meshes

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    tr, gf = walk.track, walk.garment_frames
    n = len(gf)
    body_frames = np.stack([tr.vertices(i).astype(np.float32) for i in range(n)])
    paths = [write_anim_glb(out / "anim.glb", [("body", body.faces, body_frames, BODY_RGBA),
                                              ("garment", walk.triangles, gf, GARMENT_RGBA)], fps=tr.fps)]
    picks = np.unique(np.linspace(0, n - 1, panels).round().astype(int))
    imgs = []
    for i in picks:
        off = np.array([0.0, 0.0, tr.offset(int(i))[2]])  # each panel centred on the walker
        imgs.append(render_meshes([(body_frames[i] - off, body.faces, BODY_RGB),
                                   (gf[i] - off, walk.triangles, (0.27, 0.43, 0.75))], size=size, view="side"))
    h = min(im.shape[0] for im in imgs)
    p = out / "strip.png"
    Image.fromarray(np.concatenate([im[:h] for im in imgs], axis=1)).save(p)
    paths.append(p)
    p = out / "report.json"
    p.write_text(json.dumps(report, indent=2))
    paths.append(p)
    return paths
