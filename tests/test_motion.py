"""The walk cycle (engine.body.motion) and the numba skinning kernel."""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from engine.body.default import default_body
from engine.body.motion import WalkParams, gait_deltas, pose_joints, walk_track
from engine.body.rig import skin, skin_fast
from engine.body.types import SEGMENT_ID
from engine.errors import InputError


@pytest.fixture(scope="module")
def female():
    return default_body("female")


@pytest.fixture(scope="module")
def track(female):
    return walk_track(female, WalkParams(speed=1.2), fps=30)


def test_skin_fast_matches_reference(female):
    g = pose_joints(female.rig, gait_deltas(0.37, 1.0, 1.0))
    ref = skin(female.vertices, female.rig, g)
    fast = skin_fast(female.vertices, female.rig, g)
    assert np.abs(fast - ref).max() < 1e-9
    # and the pose really moved the body (the test is not comparing two rest poses)
    assert np.abs(ref - female.vertices).max() > 0.1


def test_pose_joints_composes_the_chain(female):
    """Each joint: its parent's posed transform, times its rest offset from the parent, times
    its delta (a rotation about itself in the rest pose's world axes) -- composed here one joint
    at a time, as the reference for the compiled chain."""
    rig = female.rig
    deltas = gait_deltas(0.61, 1.3, 0.7)
    rest = rig.rest_transforms
    names = {n: i for i, n in enumerate(rig.joint_names)}
    ref = np.empty_like(rest)
    for j in range(len(rest)):
        p = rig.parents[j]
        m = rest[j] if p < 0 else ref[p] @ np.linalg.inv(rest[p]) @ rest[j]
        name = rig.joint_names[j]
        if name in deltas:
            d = np.eye(4)
            rr = rest[j, :3, :3]
            d[:3, :3] = rr.T @ deltas[name] @ rr
            m = m @ d
        ref[j] = m
    assert set(deltas) <= set(names)
    np.testing.assert_allclose(pose_joints(rig, deltas), ref, atol=1e-12)
    # a skeleton that lists a child before its parent is refused
    bad = replace(rig, parents=np.where(np.arange(len(rig.parents)) == 1, 5, rig.parents).astype(np.int32))
    with pytest.raises(InputError, match="before its parent"):
        pose_joints(bad, deltas)


def test_rest_pose_is_identity(female):
    g = pose_joints(female.rig, gait_deltas(0.0, 1.0, 0.0))
    # (float32 weights sum to 1 within ~1e-7: a micrometre)
    assert np.abs(skin_fast(female.vertices, female.rig, g) - female.vertices).max() < 1e-5


def test_walk_starts_at_rest(female, track):
    assert np.abs(track.vertices(0) - female.vertices).max() < 1e-5
    assert np.abs(track.velocities(0)).max() < 0.05


def test_feet_on_the_floor_every_frame(track):
    for i in range(0, 100):
        y = track.vertices(i)[:, 1]
        assert abs(y.min()) < 1e-3, (i, y.min())  # no floating, no floor penetration


def test_feet_do_not_slide(track):
    """Body points touching the floor move (horizontally) no faster than 10 cm/s, while the
    body walks at 1.2 m/s; measured as displacement between frames, not from the velocities."""
    fps = track.fps
    worst = 0.0
    for i in range(track.cycle_start, track.cycle_start + track.cycle_frames):
        a, b = track.vertices(i), track.vertices(i + 1)
        on = (a[:, 1] < 0.002) & (b[:, 1] < 0.002)
        if on.any():
            worst = max(worst, float(np.linalg.norm((b - a)[on][:, [0, 2]], axis=1).max() * fps))
    assert worst < 0.1, worst


def test_the_walk_starts_without_lurching_back(female, track):
    """From rest, the pelvis does not move backward (under 2 cm/s: as the pose grows, the foot
    stood on first moves forward under a millimetre a frame) and its speed changes smoothly;
    the foot stood on in the ramp (the left: the walk starts at its mid-stance) does not slide,
    and the swinging foot lifts rather than scuffs. Before, the right foot, swinging forward
    with its toe pitched down below the left foot's sole, was the lowest and taken as the one
    stood on: the body slid back 5 cm over 3 frames (0.9 m/s) and lurched forward, and the
    trousers' seat went 10 mm into the body in that frame; standing on the left foot alone,
    that toe scuffed forward over the floor at up to 1.4 m/s."""
    pelvis = female.segments == 1
    z = np.array([track.vertices(i)[pelvis, 2].mean() for i in range(track.cycle_start + track.cycle_frames)])
    v = np.diff(z) * track.fps  # m/s
    assert v.min() >= -0.02, np.round(v, 2)  # before: -0.88 m/s
    assert np.abs(np.diff(v)).max() * track.fps < 20.0, np.round(v, 2)  # m/s^2 (before: 45)
    left = female.vertices[:, 0] > 0
    for i in range(track.cycle_start):
        a, b = track.vertices(i), track.vertices(i + 1)
        on = (a[:, 1] < 0.002) & (b[:, 1] < 0.002)
        slide = np.linalg.norm((b - a)[:, [0, 2]], axis=1) * track.fps
        assert slide[on & left].max(initial=0.0) < 0.1, (i, slide[on & left].max())
        assert slide[on].max(initial=0.0) < 0.2, (i, slide[on].max())  # the right foot lifting off


def test_walk_speed_stride_and_period(female, track):
    period = track.cycle_frames / track.fps
    assert abs(track.shift[2] / period - 1.2) < 0.03  # the asked speed (cycle rounded to frames)
    assert abs(track.shift[2] - 0.82 * female.height) < 0.01  # the default stride
    assert abs(track.shift[0]) < 0.01  # straight ahead (+Z, the way the body faces)


def test_cycle_repeats_shifted_by_the_stride(track):
    a = track.cycle_start + 3
    b = a + track.cycle_frames
    assert np.abs(track.vertices(b) - (track.vertices(a) + track.shift)).max() < 1e-5
    assert np.abs(track.velocities(b) - track.velocities(a)).max() < 1e-5


@pytest.mark.integration  # (walk tracks of the default body, several seconds)
def test_velocities_match_the_motion(female):
    """The stored world velocities agree with central differences of the frames (at 120 fps:
    at 30 fps the difference quotient itself is 0.09 m/s off where the pelvis speeds up), in
    every frame of the cycle. Planting keeps the lowest foot point still, and where that point
    jumps -- from one foot to the other at each heel strike, and from heel to ball as the heel
    rises -- the planted path has a kink (at heel strike about 0.2 m/s forward and 0.5 m/s
    up); the pelvis takes that path smoothed and the legs the rest (engine.body.motion.
    _pelvis_path, leg_share), so a difference quotient across it is off only at the legs: 2
    frames of the cycle with a median error over 0.01 m/s (0.015 at most; 8 before the
    smoothing, up to 0.27)."""
    track = walk_track(female, WalkParams(), fps=120)
    medians, kinks = [], 0
    for i in range(track.cycle_start + 1, track.cycle_start + track.cycle_frames + 1):
        fd = (track.vertices(i + 1) - track.vertices(i - 1)) * track.fps / 2
        err = np.linalg.norm(fd - track.velocities(i), axis=1)
        medians.append(np.median(err))
        kink = medians[-1] > 0.01
        kinks += kink
        # feet swing at 4-5 m/s
        assert np.percentile(err, 99) < (0.5 if kink else 0.3), (i, np.percentile(err, 99))
        assert medians[-1] < 0.3, (i, medians[-1])
    assert kinks <= 4 and max(medians) < 0.05, (kinks, np.round(medians, 3))
    assert np.median(medians) < 0.01, np.median(medians)


@pytest.mark.integration  # (walk tracks of the default body, several seconds)
def test_the_pelvis_does_not_jolt_at_heel_strike(female):
    """Planted, the body's vertical velocity jumped by ~0.5 m/s from one instant to the next
    at each heel strike (the lowest foot point moves to the other foot), its forward by ~0.2:
    0.496 m/s between two frames at 120 fps (60 m/s^2). The pelvis now takes the planted path
    smoothed (engine.body.motion._pelvis_path; the legs stretch or shorten by the difference,
    leg_share): 0.051 m/s. The feet stay planted (test_feet_on_the_floor_every_frame,
    test_feet_do_not_slide); the torso follows the pelvis, the soles the planted path."""
    from engine.body.motion import leg_share

    track = walk_track(female, WalkParams(), fps=120)
    pelvis = female.segments == 1
    v = np.array([track.velocities(i)[pelvis].mean(0)
                  for i in range(track.cycle_start, track.cycle_start + track.cycle_frames + 1)])
    assert np.abs(np.diff(v, axis=0)).max() < 0.1, np.abs(np.diff(v, axis=0)).max()
    share = leg_share(female)
    upper = np.isin(female.segments, [SEGMENT_ID[n] for n in ("head", "left_arm", "right_arm")])
    torso = female.segments == SEGMENT_ID["torso"]
    soles = female.vertices[:, 1] < 0.01
    assert np.all(share[upper] == 0.0) and share[torso].max() < 0.05 and share[soles].min() > 0.99
    assert np.all((share >= 0.0) & (share <= 1.0 + 1e-6))  # (float32 weights)


def test_the_pelvis_keeps_an_even_pace(female, track):
    """Over a cycle the pelvis moves forward at the walking speed +-20 % and up or down at under
    0.45 m/s (frame to frame at 30 fps). Before the toe roll and the retiming of the gait's
    clock (engine.body.motion.even_pace), 0.61 .. 1.98 m/s forward and down at up to 0.96 m/s
    before each heel strike: the body surged and dropped twice a cycle."""
    pelvis = female.segments == 1
    c = np.array([track.vertices(i)[pelvis].mean(0)
                  for i in range(track.cycle_start, track.cycle_start + track.cycle_frames + 1)])
    v = np.diff(c, axis=0) * track.fps
    assert 0.8 * 1.2 < v[:, 2].min() and v[:, 2].max() < 1.2 * 1.2, np.round(v[:, 2], 2)
    assert np.abs(v[:, 1]).max() < 0.45, np.round(v[:, 1], 2)
    # the cycle still covers the stride in the same time, and both feet share it evenly: the
    # pelvis moves half a stride forward in each half of the cycle (+-10 %)
    half = track.cycle_frames // 2
    d1, d2 = c[half, 2] - c[0, 2], c[-1, 2] - c[half, 2]
    assert abs(d1 - d2) < 0.1 * (d1 + d2) / 2, (d1, d2)


def test_in_place_is_a_treadmill(female):
    t = walk_track(female, WalkParams(in_place=True), fps=30)
    assert np.abs(t.offsets).max() == 0.0 and np.abs(t.shift).max() == 0.0
    # the pelvis stays within a few cm of where it started
    pelvis = t.vertices(40)[female.segments == 1].mean(axis=0) - female.vertices[female.segments == 1].mean(axis=0)
    assert np.hypot(pelvis[0], pelvis[2]) < 0.1


@pytest.mark.parametrize("params, fps, words", [
    (WalkParams(speed=0.0), 30, "speed"),
    (WalkParams(speed=50.0), 30, "speed"),
    (WalkParams(stride=10.0), 30, "stride"),
    (WalkParams(), 1000, "frame rate"),
])
def test_bad_walk_parameters(female, params, fps, words):
    with pytest.raises(InputError, match=words):
        walk_track(female, params, fps=fps)


def test_body_without_skeleton_cannot_walk(female):
    from engine.body.types import Body

    with pytest.raises(InputError, match="no skeleton"):
        walk_track(Body(female.vertices, female.faces), WalkParams(), fps=30)
