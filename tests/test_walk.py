"""Dynamic cloth on a walking body: the moving collider, the walk stage, the animated GLB and
the `tryon walk` command."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest
import trimesh
from typer.testing import CliRunner

from engine.body.motion import BodyTrack
from engine.body.types import Body
from engine.cli import app
from engine.cloth.config import StepConfig
from engine.cloth.model import ClothParams
from engine.scene.request import TryOnOptions
from engine.scene.tuning import Tuning, WalkTuning
from tests.samples import write_anim_zip


def _box_body(size=0.4):
    m = trimesh.creation.box(extents=(size, size, size))
    v = np.asarray(m.vertices, np.float64) + (0.0, size / 2, 0.0)
    return Body(v, np.asarray(m.faces, np.int32))


def _sliding_box_track(speed, fps=10.0, frames=6, in_offsets=False):
    """A box moving +z at `speed`: in its frames (in_offsets False) or as root offset."""
    body = _box_body()
    n = len(body.vertices)
    fr = np.empty((frames, n, 3), np.float32)
    offs = np.zeros((frames, 3))
    for k in range(frames):
        d = np.array([0.0, 0.0, speed * k / fps])
        if in_offsets:
            fr[k] = body.vertices
            offs[k] = d
        else:
            fr[k] = body.vertices + d
    vel = np.zeros_like(fr)
    vel[:, :, 2] = speed
    return BodyTrack(body=body, fps=fps, frames=fr, vel=vel, offsets=offs, cycle_start=0, cycle_frames=0,
                     shift=np.zeros(3), notes=[])


def _collider(track):
    from engine.collide.maps import MapRenderer
    from engine.collide.moving import TrackCollider

    r = MapRenderer(track.body.faces, texel=0.005, tol=0.005, window=(0.0, 0.5), with_velocity=True)
    return TrackCollider(track, r, tol=0.005), r


@pytest.mark.parametrize("in_offsets", [False, True])
def test_track_collider_moves_the_surface_between_frames(in_offsets):
    """Frame 2 of a box sliding +z at 1 m/s has its front face at z = 0.2 + 0.2 = 0.4. A point
    at z = 0.43 is clear at t = 0.2 s, but 0.04 s later (frame 2 is still the nearest frame) the
    face is at 0.44 and the point is inside -- whether the motion is in the frames (the surface
    is moved along its velocity) or in the root offset (applied exactly)."""
    track = _sliding_box_track(1.0, in_offsets=in_offsets)
    col, r = _collider(track)
    try:
        p = np.array([[0.0, 0.2, 0.43], [0.0, 0.2, 0.5]])
        col.set_time(0.2)
        st, n, v, d = col.query(p)
        assert list(st) == [0, 0]
        col.set_time(0.24)
        st, n, v, d = col.query(p)
        assert st[0] == 2 and st[1] == 0, st
        assert abs(d[0] - (0.44 - 0.43 + 0.005)) < 0.003  # penetration = depth + tol
        assert n[0, 2] > 0.9 and abs(v[0, 2] - 1.0) < 1e-3  # outward normal, body velocity
        assert col.stats["renders"] == 1  # one frame's maps served both times
    finally:
        r.release()


def test_track_collider_carries_a_contact_as_the_maps_measure_it():
    """A contact answer carried between map queries changes as a fresh query's would: the maps
    measure penetration along z, so on a face whose normal has n_z = 0.6 a point moved 1 mm out
    along the normal is 1 / 0.6 mm less deep (carried as a distance, it was off by 0.67 mm)."""
    m = trimesh.creation.box(extents=(0.4, 0.15, 0.4))
    for _ in range(4):  # fine triangles: the smooth normals are the face's away from its edges
        m = m.subdivide()
    v = np.asarray(m.vertices, np.float64) + (0.0, 0.075, 0.0)
    v[:, 2] -= (v[:, 2] + 0.2) / 0.4 * v[:, 1] / 0.15 * 0.2  # the front slopes back: normal (0, 0.8, 0.6)
    body = Body(v, np.asarray(m.faces, np.int32))
    fr = np.repeat(body.vertices[None].astype(np.float32), 3, axis=0)
    track = BodyTrack(body=body, fps=10.0, frames=fr, vel=np.zeros_like(fr), offsets=np.zeros((3, 3)), cycle_start=0,
                      cycle_frames=0, shift=np.zeros(3), notes=[])
    n = np.array([0.0, 0.8, 0.6])
    p0 = np.array([[0.05, 0.075, 0.1]]) + 0.002 * n  # 2 mm off the face: in the 5 mm band
    p1 = p0 + 0.001 * n
    col, r = _collider(track)
    fresh, r2 = _collider(track)
    try:
        col.set_time(0.1)
        st, nn, _, d0 = col.query(p0)
        assert st[0] == 1 and abs(nn[0] @ n - 1.0) < 0.02
        d0 = float(d0[0])
        col.set_time(0.1005)
        st, _, _, d1 = col.query(p1)
        d1 = float(d1[0])
        assert col.stats["asked"] == 1  # the second answer was carried, not asked
        fresh.set_time(0.1005)
        _, _, _, df = fresh.query(p1)
        assert abs((d0 - float(df[0])) - 0.001 / 0.6) < 0.0004  # the maps' own answer ...
        assert abs(d1 - float(df[0])) < 0.0003, (d0, d1, float(df[0]))  # ... and the carried one
    finally:
        r.release()
        r2.release()


def test_track_collider_reuses_maps_of_a_periodic_track():
    track = _sliding_box_track(0.0, frames=4)
    track.cycle_start, track.cycle_frames = 1, 3
    col, r = _collider(track)
    try:
        for i in range(12):
            col.set_time(i / track.fps)
            col.query(np.zeros((1, 3)))
        assert col.stats["renders"] == 4 and col.stats["reuses"] == 8
        # a reused frame answers from its float16 copy, expanded exactly
        maps, surf16, vel16 = col._kept[col._k]
        assert col.maps is maps and np.array_equal(maps.surf, surf16.astype(np.float32), equal_nan=True)
        assert np.array_equal(maps.vel, vel16.astype(np.float32), equal_nan=True)
    finally:
        r.release()


def test_prerendered_maps_are_each_frames_kept_maps():
    """prerender(last) renders every distinct frame up to `last` once, in the helper thread,
    keeping float16 copies only; the walk's frames then render nothing and use the frame's own
    maps (as float16 expanded), whether in order or after a jump."""
    from engine.collide.maps import MapRenderer
    from engine.collide.moving import TrackCollider

    track = _sliding_box_track(0.5, frames=4)
    track.cycle_start, track.cycle_frames = 1, 3
    col = TrackCollider(track, lambda: MapRenderer(track.body.faces, texel=0.005, tol=0.005, window=(0.0, 0.5),
                                                   with_velocity=True, own_context=True), tol=0.005, ahead=True)
    ref, r = _collider(track)
    seen = []
    try:
        took = col.prerender(11, lambda k, n: seen.append((k, n)))
        assert took > 0 and seen == [(1, 4), (2, 4), (3, 4), (4, 4)] and col.stats["renders"] == 4
        assert all(kept[0].surf is None for kept in col._kept.values())  # float16 copies only
        for i in list(range(12)) + [3, 9]:
            col.set_time(i / track.fps)
            ref.set_time(i / track.fps)
            col.query(np.zeros((1, 3)))
            for a, b in ((col.maps.surf, ref.maps.surf), (col.maps.vel, ref.maps.vel),
                         (col.maps.depth_pairs, ref.maps.depth_pairs)):
                assert np.array_equal(a, b.astype(np.float16).astype(np.float32), equal_nan=True), i
        assert col.stats["renders"] == 4 and col.stats["reuses"] == 13  # every switch (a revisit of the frame in use is none)
    finally:
        col.release()
        r.release()
    unkept = TrackCollider(track, None, tol=0.005, keep=False)
    with pytest.raises(ValueError, match="not kept"):
        unkept.prerender(3)


def test_kept_maps_expanded_ahead_are_the_frames_maps():
    """Rendered ahead in a helper thread, a periodic track's kept frames are expanded (float32
    maps and depth pairs) into the spare buffers while the present frame is in use: at every
    switch -- in order, and after jumps the expansion ahead did not foresee -- the maps in use
    are the frame's own, and each frame's maps are the frame's whether expanded ahead or now."""
    from engine.collide.maps import MapRenderer
    from engine.collide.moving import TrackCollider

    track = _sliding_box_track(0.5, frames=4)
    track.cycle_start, track.cycle_frames = 1, 3
    col = TrackCollider(track, lambda: MapRenderer(track.body.faces, texel=0.005, tol=0.005, window=(0.0, 0.5),
                                                   with_velocity=True, own_context=True), tol=0.005, ahead=True)
    ref, r = _collider(track)  # renders every frame in this thread, keeps nothing expanded
    try:
        order = list(range(12)) + [2, 9, 9, 4, 1, 7]
        reused = 0
        for i in order:
            before = col.stats["renders"]
            col.set_time(i / track.fps)
            ref.set_time(i / track.fps)
            col.query(np.zeros((1, 3)))
            k = col._k
            assert k == ref._k and col.maps is col._kept[k][0]
            # a frame just rendered is used as rendered; a reused one from its float16 copy
            fresh = col.stats["renders"] > before
            reused += not fresh
            for a, b in ((col.maps.surf, ref.maps.surf), (col.maps.vel, ref.maps.vel),
                         (col.maps.depth_pairs, ref.maps.depth_pairs)):
                want = b if fresh else b.astype(np.float16).astype(np.float32)
                assert np.array_equal(a, want, equal_nan=True), (i, k)
        assert col.stats["renders"] == 4 and reused == 14
        assert col._prepared is not None  # (the next frame's expansion was on its way)
    finally:
        col.release()
        r.release()
    assert col._prepared is None


def test_half_conversions_match_numpy():
    """The kept maps' float16 copies (moving._compacted) and their expansion (moving._expanded)
    give numpy's astype bit for bit: random values over the half's whole range (subnormals,
    overflow, ties), every float32 bit pattern class, and the special values."""
    from engine.collide.moving import _compacted, _expanded

    rng = np.random.default_rng(3)
    scaled = (rng.standard_normal(200_000) * 10.0 ** rng.integers(-9, 6, 200_000)).astype(np.float32)
    bits = rng.integers(0, 2 ** 32, 200_000, dtype=np.uint64).astype(np.uint32).view(np.float32)
    special = np.array([np.inf, -np.inf, np.nan, 0.0, -0.0, 65504, 65519.99, 65520, 6e-8, 3e-8, 2.98e-8,
                        5.96e-8, 1e-45, -1e-45, 1 + 2 ** -11, 1 + 3 * 2 ** -11], np.float32)
    for a in (scaled, bits, special):
        with np.errstate(all="ignore"):
            want = a.astype(np.float16)
        got = _compacted(a.reshape(-1, 4) if len(a) % 4 == 0 else a).reshape(-1)
        num = ~np.isnan(want)
        assert np.array_equal(got.view(np.uint16)[num], want.view(np.uint16)[num])
        assert np.array_equal(np.isnan(got), ~num)
    every_half = np.arange(2 ** 16, dtype=np.uint16).view(np.float16)
    out = _expanded(every_half, None)
    assert np.array_equal(out.view(np.uint32), every_half.astype(np.float32).view(np.uint32))
    assert _expanded(every_half, out) is out  # the buffer is reused
    with np.errstate(over="ignore"):  # (numpy's own cast of the values past float16's range)
        want = special.astype(np.float16)
    assert np.array_equal(_compacted(special.astype(np.float64)), want, equal_nan=True)


def test_anim_glb_round_trip(tmp_path):
    from engine.io.anim import write_anim_glb

    tri = np.array([[0, 1, 2]])
    base = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    frames = np.stack([base + (0, 0, 0.1 * k) for k in range(5)])
    p = write_anim_glb(tmp_path / "a.glb", [("garment", tri, frames, (70, 110, 190, 255))], fps=10)
    data = p.read_bytes()
    magic, version, total = struct.unpack("<4sII", data[:12])
    assert magic == b"glTF" and version == 2 and total == len(data)
    jlen = struct.unpack("<I", data[12:16])[0]
    doc = json.loads(data[20:20 + jlen])
    prim = doc["meshes"][0]["primitives"][0]
    assert len(prim["targets"]) == 4
    anim = doc["animations"][0]
    times = doc["accessors"][anim["samplers"][0]["input"]]
    assert times["count"] == 5 and abs(times["max"][0] - 0.4) < 1e-6
    # the last target moves every vertex by +0.4 in z
    acc = doc["accessors"][prim["targets"][-1]["POSITION"]]
    view = doc["bufferViews"][acc["bufferView"]]
    bin0 = 20 + jlen + 8
    disp = np.frombuffer(data[bin0 + view["byteOffset"]: bin0 + view["byteOffset"] + view["byteLength"]],
                         np.float32).reshape(-1, 3)
    assert np.allclose(disp, [0, 0, 0.4])
    # and a general glTF reader accepts the file
    scene = trimesh.load(p)
    assert len(scene.geometry) == 1


def test_anim_glb_refuses_nan(tmp_path):
    from engine.errors import InputError
    from engine.io.anim import write_anim_glb

    frames = np.zeros((2, 3, 3), np.float32)
    frames[1, 0, 0] = np.nan
    with pytest.raises(InputError, match="non-finite"):
        write_anim_glb(tmp_path / "a.glb", [("g", np.array([[0, 1, 2]]), frames, (1, 1, 1, 255))], fps=10)
    assert not (tmp_path / "a.glb").exists()


@pytest.fixture(scope="module")
def walked():
    """A coarse skirt (3 cm cloth edge) dressed on the default woman, then 0.8 s of walking
    (the 0.5 s ramp from rest and 0.3 s of the full walk)."""
    from engine.body.default import default_body
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon
    from engine.scene.walk import walk_cloth, walk_report

    body = default_body("female")
    spec, place, name = resolve_garment("skirt", body, "M")
    res, rep = run_tryon(body, spec, TryOnOptions(resolution_cm=3.0), place=place, source=name)
    w = walk_cloth(body, res, TryOnOptions(seconds=0.8))
    return body, res, w, walk_report(rep, w.report)


@pytest.mark.integration
def test_walking_skirt_stays_on_and_out_of_the_body(walked):
    body, res, w, report = walked
    assert np.all(np.isfinite(w.garment_frames))
    r = w.report
    assert r["frames"] == 24 and len(r["per_frame"]) == 24
    assert r["penetration_mm"]["p99"] <= 2.0 and r["penetration_mm"]["max"] <= 10.0, r["penetration_mm"]
    assert r["strain_max"] < 0.15
    # the garment follows the body: its centre moves forward with the pelvis, within 5 cm
    tr = w.track
    pelvis = body.segments == 1
    for i in (8, 16, 24):
        body_c = tr.vertices(i)[pelvis].mean(axis=0) - body.vertices[pelvis].mean(axis=0)
        cloth_c = w.garment_frames[i].mean(axis=0) - w.garment_frames[0].mean(axis=0)
        assert abs(cloth_c[2] - body_c[2]) < 0.05, (i, cloth_c, body_c)
    assert body_c[2] > 0.2  # and the body did walk (0.5 s of ramp, then 0.3 s at 1.2 m/s)
    # the skirt is still at the waist: its top within 5 cm of where the drape left it (relative)
    top0 = res.positions[:, 1].max()
    assert abs(w.garment_frames[-1][:, 1].max() - top0) < 0.05


@pytest.mark.integration
def test_walk_springs_are_softer_and_stiffen_when_the_strain_limit_loses(walked):
    """The walk runs at TryOnOptions.walk_stiffness x the drape's springs, at the eq. 4 step of those
    (a quarter: twice the drape's step, in whole substeps a frame); a frame whose strain passes
    the threshold + stiffen_at doubles the stiffness, up to the drape's, and says so."""
    from engine.scene.walk import walk_cloth

    body, res, w, _ = walked
    r = w.report
    assert r["stiffness"] == {"start": 0.25, "end": 0.25, "stiffened": []}
    frame_time = 1.0 / r["fps"]
    assert r["substeps_per_frame"] in {int(np.ceil(frame_time / (2.0 * res.dt) * (1 + e))) for e in (-1e-3, 1e-3)}
    assert r["dt_ms"] / 1000 <= 2.0 * res.dt * (1 + 1e-3)
    threshold = res.model.fabric.strain_threshold
    w2 = walk_cloth(body, res, TryOnOptions(seconds=0.2), Tuning(walk=WalkTuning(stiffen_at=0.001)))
    st = w2.report["stiffness"]
    # the first frames past 5.1 % (frames 1 and 2 at the drape's push time, 2 and 3 at the walk's
    # shorter one, WalkTuning.step) double it, then double it again, and it stays at the drape's
    (f1, k1), (f2, k2) = [(s["frame"], s["stiffness"]) for s in st["stiffened"]]
    assert (k1, k2) == (0.5, 1.0) and f1 <= 3 and f2 == f1 + 1, st
    assert all(s["strain"] > threshold + 0.001 for s in st["stiffened"]) and st["end"] == 1.0
    # at the drape's stiffness, the drape's step again
    assert w2.report["substeps_per_frame"] == int(np.ceil(frame_time / res.dt - 1e-9))
    assert sum("softer walking springs" in line for line in w2.report["left_out"]) == 2
    assert np.all(np.isfinite(w2.garment_frames))


@pytest.mark.integration
def test_maps_rendered_ahead_give_the_same_walk(walked):
    """Maps rendered one frame ahead in a helper thread (its own GL context) are the maps the
    walk renders when the frame comes up: the same cloth bit for bit; the thread ends with the
    walk and the main thread's GL context still renders."""
    import threading

    from engine.collide.maps import render_body_maps
    from engine.scene.walk import walk_cloth

    body, res, _, _ = walked
    runs = [walk_cloth(body, res, TryOnOptions(seconds=0.3, reuse_maps=False),
                       Tuning(walk=WalkTuning(render_ahead=ahead))) for ahead in (False, True)]
    assert np.array_equal(runs[0].garment_frames, runs[1].garment_frames)
    assert runs[0].report["map_frames_rendered"] == runs[1].report["map_frames_rendered"] >= 9
    assert not any(t.name.startswith("maps") for t in threading.enumerate())
    maps = render_body_maps(body, texel=0.01)
    assert (maps.kind == 1).any()


@pytest.mark.integration
def test_walk_report_fields(walked):
    _, _, w, report = walked
    for key in ("cloth_vertices", "iterations", "penetration_mm", "strain", "settled", "frames", "fps",
                "realtime_factor", "ms_per_frame", "per_frame", "walk", "left_out"):
        assert key in report, key
    assert set(report["ms_per_frame"]) == {"maps", "cloth", "collision", "total"}
    assert report["realtime_factor"] > 0
    assert any("periodic" in line for line in report["left_out"])
    assert report["walk"]["map_frames_rendered"] <= 15 + 40  # the ramp and at most a cycle
    # ... all rendered before the walking stage (WalkTuning.prerender), not in its wall time
    assert report["walk"]["map_prerender_seconds"] > 0
    assert report["walk"]["wall_seconds"]["maps_before"] == report["walk"]["map_prerender_seconds"]
    assert report["walk"]["push_time_ms"] == 1000 * WalkTuning().step.push_time
    # the walk keeps its own, wider collision band (a swinging leg carries cloth further between checks)
    assert report["walk"]["band_mm"] == pytest.approx({"cloth": 1000 * WalkTuning().tolerance,
                                                      "body": 1000 * WalkTuning().tolerance})
    assert WalkTuning().tolerance > ClothParams().tolerance  # (wider than the drape's)


@pytest.mark.integration
def test_walk_outputs(walked, tmp_path):
    from PIL import Image

    from engine.scene.walk import write_walk_outputs

    body, _, w, report = walked
    paths = write_walk_outputs(tmp_path, body, w, report, panels=4, size=200)
    names = sorted(p.name for p in paths)
    assert names == ["anim.glb", "report.json", "strip.png"]
    im = Image.open(tmp_path / "strip.png")
    assert im.size[0] > 1.5 * im.size[1]  # a row of 4 frames (each a side view, narrower than tall)
    assert json.loads((tmp_path / "report.json").read_text())["frames"] == 24


def _walk_cli(tmp_path, *args):
    return CliRunner().invoke(app, ["walk", "--out", str(tmp_path / "o"), *map(str, args)])


@pytest.mark.integration
@pytest.mark.parametrize("args, words", [
    (["--body", "default:female", "--garment", "skirt", "--seconds", "0"], "--seconds"),
    (["--body", "default:female", "--garment", "skirt", "--speed", "40"], "speed"),
    (["--body", "default:female", "--garment", "skirt", "--fps", "1000"], "--fps"),
    (["--body", "default:female", "--garment", "skirt", "--velocity-mode", "wobble"], "wobble"),
    (["--body", "default:female", "--garment", "skirt", "--walk-stiffness", "0"], "--walk-stiffness"),
    (["--body", "{pillar}", "--garment", "skirt"], "arm"),
])
def test_walk_cli_refuses_bad_input(tmp_path, monkeypatch, args, words):
    from engine.cloth.solver import ClothSolver

    pillar = tmp_path / "pillar.obj"  # a 1.7 m "scan" without arms: no skeleton can be fitted
    trimesh.creation.cylinder(radius=0.15, height=1.7, sections=32).export(pillar)
    args = [a.replace("{pillar}", str(pillar)) for a in args]
    monkeypatch.setattr(ClothSolver, "step", lambda *a, **k: (_ for _ in ()).throw(AssertionError("simulated")))
    r = _walk_cli(tmp_path, *args)
    assert r.exit_code == 2, (r.exit_code, r.output)
    err = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and words in err[0], r.stderr
    assert not (tmp_path / "o" / "anim.glb").exists()


@pytest.fixture(scope="module")
def anim_zip(tmp_path_factory):
    from engine.body.default import default_body
    from engine.body.motion import WalkParams, walk_track

    body = default_body("female")
    tr = walk_track(body, WalkParams(), fps=30)
    frames = [tr.vertices(i) for i in range(20)]
    return write_anim_zip(tmp_path_factory.mktemp("anim") / "walk.zip", frames, body.faces), frames


@pytest.mark.integration  # (walk tracks of the default body, several seconds)
def test_load_animation(anim_zip):
    from engine.body.animation import load_animation

    path, frames = anim_zip
    t = load_animation(path, fps=30)
    assert t.frames.shape == (20, len(frames[0]), 3) and not t.periodic
    # the same motion (the loader only re-centres the first frame's box)
    shift = t.frames[0].astype(np.float64) - frames[0]
    assert np.abs(shift - shift.mean(axis=0)).max() < 1e-5
    for k in (5, 13, 19):
        assert np.abs((t.vertices(k) - shift) - frames[k]).max() < 1e-5
    fd = (frames[11] - frames[9]) * 15
    assert np.abs(t.velocities(10) - fd).max() < 1e-3
    assert t.body.segments is not None  # the first frame (rest pose) was fitted


def _two_topologies(p):
    import zipfile

    write_anim_zip(p, [np.eye(3), np.eye(3)], np.array([[0, 1, 2]]))
    with zipfile.ZipFile(p, "a") as z:  # a third frame with another mesh
        z.writestr("frames/f_002.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\n")


@pytest.mark.parametrize("make, words", [
    (lambda p: p.write_text("not a zip"), "not a zip"),
    (lambda p: write_anim_zip(p, [np.eye(3)], np.array([[0, 1, 2]])), "at least 2"),
    (lambda p: _two_topologies(p), "topology"),
])
def test_load_animation_refuses_bad_files(tmp_path, make, words):
    from engine.body.animation import load_animation
    from engine.errors import InputError

    p = tmp_path / "a.zip"
    make(p)
    with pytest.raises(InputError, match=words):
        load_animation(p, fps=30)


@pytest.mark.integration
def test_walk_cli_with_an_uploaded_animation(anim_zip, tmp_path):
    path, frames = anim_zip
    r = _walk_cli(tmp_path, "--body", path, "--garment", "skirt", "--resolution", "3", "--seconds", "2")
    assert r.exit_code == 0, (r.output, r.stderr)
    rep = json.loads((tmp_path / "o" / "report.json").read_text())
    assert rep["frames"] == 19  # clipped to the animation (20 frames = 19 steps)
    assert rep["walk"]["map_frames_rendered"] == 20  # every frame, none kept (0 .. 19)
    assert any("animation ends" in line for line in rep["left_out"])
    assert rep["walk"]["penetration_mm"]["max"] <= 10.0
    assert (tmp_path / "o" / "anim.glb").stat().st_size > 1000


@pytest.mark.integration
@pytest.mark.parametrize("args", [["--speed", "2.4"], ["--speed", "3.6"], ["--fabric", "denim"], ["--fabric", "silk"]])
def test_walk_stability(tmp_path, args):
    """Twice and three times the walking speed, a stiff and a very light fabric (all at the eq. 4
    time step): the run ends either with a sane result or with a clear error -- never NaN,
    never an exploded garment written as a result."""
    r = _walk_cli(tmp_path, "--body", "default:female", "--garment", "skirt", "--resolution", "3",
                  "--seconds", "1.2", *args)
    if r.exit_code == 0:
        rep = json.loads((tmp_path / "o" / "report.json").read_text())
        assert rep["walk"]["strain_max"] < 0.25, rep["walk"]["strain_max"]
        assert rep["walk"]["penetration_mm"]["max"] < 20.0 and rep["walk"]["penetration_mm"]["p99"] <= 2.0
        assert all(np.isfinite(f["strain_max"]) for f in rep["per_frame"])
    else:
        assert r.exit_code == 2, (r.exit_code, r.output)
        err = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
        assert len(err) == 1 and "internal" not in err[0], r.stderr
        assert not (tmp_path / "o" / "anim.glb").exists()


@pytest.mark.integration
def test_walk_refuses_a_garment_far_too_small(tmp_path):
    """XS on a heavy body: the seams close, but the skirt would be stretched ~50 % (measured
    before the check existed): refused before walking, nothing written."""
    r = _walk_cli(tmp_path, "--body", "default:female,weight=1.0", "--garment", "skirt", "--size", "XS",
                  "--resolution", "3", "--seconds", "1")
    assert r.exit_code == 2, (r.exit_code, r.output)
    assert "too small" in r.stderr and "larger size" in r.stderr
    assert "--size auto picks L" in r.stderr  # the size that covers this body's girths
    assert not (tmp_path / "o").exists() or not any((tmp_path / "o").iterdir())


@pytest.mark.slow
@pytest.mark.parametrize("garment", ["dress", "trousers", "skirt", "shirt"])
def test_walking_quality(tmp_path, garment):
    """Issue 4's quality bar: each garment (size M, 1.5 cm cloth) on the default woman walking
    4 s: no NaN; over all frames penetration p99 <= 2 mm and max <= 10 mm; the garment follows
    the body (its centre keeps within 10 cm of the pelvis's travel)."""
    from engine.body.default import default_body
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon
    from engine.scene.walk import walk_cloth

    body = default_body("female")
    spec, place, name = resolve_garment(garment, body, "M")
    res, _ = run_tryon(body, spec, place=place, source=name)
    w = walk_cloth(body, res, TryOnOptions(seconds=4.0))
    r = w.report
    assert np.all(np.isfinite(w.garment_frames))
    assert r["penetration_mm"]["p99"] <= 2.0 and r["penetration_mm"]["max"] <= 10.0, r["penetration_mm"]
    pelvis = body.segments == 1
    for i in range(0, r["frames"] + 1, 10):
        body_c = w.track.vertices(i)[pelvis].mean(axis=0) - body.vertices[pelvis].mean(axis=0)
        cloth_c = w.garment_frames[i].mean(axis=0) - w.garment_frames[0].mean(axis=0)
        assert np.linalg.norm((cloth_c - body_c)[[0, 2]]) < 0.10, (i, cloth_c, body_c)


@pytest.mark.integration
def test_object_space_walk(walked):
    """The BVH baseline on the moving body (refitted per frame): same checks as image space."""
    from engine.scene.walk import walk_cloth

    body, res, _, _ = walked
    w = walk_cloth(body, res, TryOnOptions(seconds=0.6, collision="object"))
    r = w.report
    assert np.all(np.isfinite(w.garment_frames))
    assert r["penetration_mm"]["p99"] <= 2.0 and r["penetration_mm"]["max"] <= 10.0, r["penetration_mm"]
    assert r["strain_max"] < 0.15
    assert any("object-space" in line for line in r["left_out"])
    assert r["map_frames_rendered"] >= 15  # one refit per frame


def test_stiffening_looks_at_a_region_not_at_one_spring(walked):
    """spread_strain: the n-th most stretched spring. One vertex pulled out stretches the few
    springs round it (a seam's end: the trousers' waistband at the side seam reached 16-23 % at
    one spring, the next most stretched under 11 %, and stiffened every walk of them); the walk
    stiffens when WalkTuning.stiffen_springs springs pass the bar (or one passes it three times over)."""
    from engine.scene.walk import spread_strain

    _, res, _, _ = walked
    m = res.model
    x = res.positions.copy()
    base = spread_strain(m, x, 8)
    s = m.springs[m.strain_limited]
    v = s[0, 0]
    away = x[v] - x[s[0, 1]]
    x[v] += 0.5 * away  # its springs 50 % longer and more, the rest as draped
    near = int(np.sum(np.any(s == v, axis=1)))
    assert 1 <= near < 8 and spread_strain(m, x, 1) > 0.3
    assert abs(spread_strain(m, x, 8) - base) < 0.02
    x[:, 0] *= 1.2  # the whole garment 20 % wider: every horizontal spring past the bar
    assert spread_strain(m, x, 8) > 0.15


@pytest.mark.parametrize("make,words", [
    (lambda: StepConfig(contact_rounds=0), "contact_rounds"),
    (lambda: TryOnOptions.of(walk_stiffness=0.0), "walk_stiffness"),
    (lambda: TryOnOptions.of(walk_stiffness=1.5), "walk_stiffness"),
    (lambda: Tuning(walk=WalkTuning(stiffen_at=0.0)).validate(), "stiffen_at"),
    (lambda: Tuning(walk=WalkTuning(stiffen_springs=0)).validate(), "stiffen_springs"),
    (lambda: Tuning(walk=WalkTuning(tolerance=0.5)).validate(), "walk tolerance"),
    (lambda: Tuning(collide_every=17).validate(), "collide_every"),
    (lambda: StepConfig(vm_passes=0), "vm_passes"), (lambda: StepConfig(strain_guard=-0.1), "strain_guard"),
    (lambda: StepConfig(flexion_every=0), "flexion_every"), (lambda: StepConfig(flexion_every=17), "flexion_every"),
    (lambda: StepConfig(push_time=0.0), "push_time"), (lambda: StepConfig(push_time=5.0), "push_time"),
    (lambda: TryOnOptions.of(seconds=100.0), "seconds"), (lambda: TryOnOptions.of(fps=1.0), "fps")])
def test_walk_options_refuse_absurd_solver_settings(make, words):
    from engine.errors import InputError

    Tuning().validate()  # the defaults are valid
    with pytest.raises(InputError, match=words):
        make()


@pytest.mark.integration  # (walk tracks of the default body, several seconds)
def test_collision_checks_keep_pace_with_the_body():
    """By default the walk checks collisions as often as keeps the body's bulk travel between two
    checks within check_travel: every 8th step at a normal walk, more often when faster."""
    from engine.body.default import default_body
    from engine.body.motion import WalkParams, walk_track
    from engine.scene.walk import check_every

    CHECK_TRAVEL, MAX_CHECK_EVERY = WalkTuning().check_travel, WalkTuning().max_check_every

    body = default_body("female")
    dt = 0.000115
    got = {}
    for speed in (1.2, 2.4, 3.6):
        tr = walk_track(body, WalkParams(speed=speed), 30)
        got[speed] = check_every(tr, dt)
        bulk = float(np.linalg.norm(tr.vel.astype(np.float64).mean(axis=1), axis=1).max())
        assert got[speed] * bulk * dt <= CHECK_TRAVEL or got[speed] == 1
    assert got[1.2] == MAX_CHECK_EVERY and got[1.2] > got[2.4] > got[3.6] >= 1, got


def test_track_collider_prefetch_answers_as_a_query_would():
    """Points prefetched by the query server (a helper thread) for the next check's time are
    answered there as the query at that time would answer them -- bit for bit -- and the server
    only takes times within the frame in use; release() ends its thread."""
    import threading

    track = _sliding_box_track(1.0)
    col, r = _collider(track)
    ref, r2 = _collider(track)
    # around the box's front face (z = 0.42 at t = 0.22 s, moving +z at 1 m/s): inside, in the
    # band, just clear, clear, and beside the box
    p0 = np.array([[0.0, 0.2, 0.4147], [0.0, 0.2, 0.4217], [0.05, 0.3, 0.4262], [0.0, 0.2, 0.45], [0.3, 0.2, 0.3]])
    p1 = p0 + (0.0, 0.0, 0.0003)
    try:
        for c in (col, ref):
            c.set_time(0.2)
            c.query(p0)
        assert col.prefetch(p1, 0.02)
        assert any(t.name == "query-server" for t in threading.enumerate())
        assert not col.prefetch(p1, 0.1)  # frame 3's time: not this frame's maps
        col.set_time(0.22)
        ref.set_time(0.22)
        got = [a.copy() for a in col.query(p1)]
        want = ref.query(p1)
        # the prefetch asked the maps; the query itself only for the point hovering at the
        # band's edge (a clear point that close is always asked again)
        assert col.last_asked == 1 and ref.last_asked == 5
        assert list(want[0]) == [2, 1, 0, 0, 0], want[0]
        for g, w in zip(got, want):
            assert np.array_equal(g, w)
    finally:
        col.release()
        ref.release()
        r.release()
        r2.release()
    assert col.server._thread is None and not any(t.name == "query-server" for t in threading.enumerate())


def test_an_idle_query_server_returns_and_starts_again():
    """A query server left without requests for a while returns from its kernel (a collider its
    owner forgot does not keep a core spinning); the next prefetch starts it again and is
    answered as before."""
    import time

    from engine.collide.server import RUNNING

    track = _sliding_box_track(1.0)
    col, r = _collider(track)
    ref, r2 = _collider(track)
    p0 = np.array([[0.0, 0.2, 0.4147], [0.0, 0.2, 0.4217], [0.05, 0.3, 0.4262], [0.0, 0.2, 0.45]])
    try:
        for c in (col, ref):
            c.set_time(0.2)
            c.query(p0)
        assert col.prefetch(p0, 0.01)
        col.server.wait()
        time.sleep(0.5)
        assert col.server.ctl[RUNNING] == 0
        p1 = p0 + (0.0, 0.0, 0.0003)
        assert col.prefetch(p1, 0.02)
        col.set_time(0.22)
        ref.set_time(0.22)
        for g, w in zip([a.copy() for a in col.query(p1)], ref.query(p1)):
            assert np.array_equal(g, w)
    finally:
        col.release()
        ref.release()
        r.release()
        r2.release()


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")
def test_chunks_are_claimed_once_from_either_end():
    """A request's chunks claimed from the start (the server) and from the end (the walk's
    solver thread) meet in the middle, each chunk once; a thread holding another request's
    number claims nothing."""
    from numba import njit

    from engine.collide.server import REQ, SpinServer, claim

    @njit
    def claims(ctl, r, ends):
        out = np.empty(ends.shape[0], np.int64)
        for i in range(ends.shape[0]):
            out[i] = claim(ctl, r, ends[i])
        return out

    def take(ctl, r, ends):
        return claims(ctl, r, np.array(ends)).tolist()

    sv = SpinServer("test")
    sv.post_chunks(5, launch=False)
    r = int(sv.ctl[REQ])
    assert take(sv.ctl, r - 1, [False, True]) == [-1, -1]
    assert take(sv.ctl, r, [False, True, False, True, False, True, False]) == [0, 4, 1, 3, 2, -1, -1]
    sv.post_chunks(3, launch=False)
    assert take(sv.ctl, r, [False]) == [-1]  # (the old request)
    assert take(sv.ctl, r + 1, [True, True, True, True]) == [2, 1, 0, -1]


@pytest.mark.filterwarnings("ignore::pytest.PytestUnhandledThreadExceptionWarning")  # (its server dies on purpose)
def test_a_dead_query_server_is_an_error_not_a_hang(monkeypatch):
    """A query server whose thread died before taking part answers nothing: the solver's thread
    answers every chunk itself, the same answers. One that died holding a chunk of a query is
    an error once the wait for it ends -- not a hang, not a half answer."""
    import engine.collide.server as server
    from engine.collide.server import NEXT, REQ, claim_word
    from engine.errors import SimulationError

    def broken(*args):
        raise RuntimeError("broken server")

    monkeypatch.setattr(server, "serve", broken)
    track = _sliding_box_track(1.0)
    col, r = _collider(track)
    ref, r2 = _collider(track)
    p = np.array([[0.0, 0.2, 0.402], [0.0, 0.2, 0.43]])
    try:
        for c in (col, ref):
            c.set_time(0.2)
            c.query(p)
        assert col.prefetch(p, 0.02)
        col.set_time(0.22)
        ref.set_time(0.22)
        for g, w in zip([a.copy() for a in col.query(p)], ref.query(p)):
            assert np.array_equal(g, w)
        # a request with its only chunk claimed (by a thread that then died) and not finished
        col._post(1, col._t, col._shift_t, col._offset)
        ctl = col.server.ctl
        ctl[NEXT] = claim_word(int(ctl[REQ]), 1, 1)
        col.help_wait = 3 * 10 ** 8  # ~0.1 s
        with pytest.raises(SimulationError, match="query server stopped answering"):
            col._finish()
    finally:
        col._posted = False
        col.release()  # (the thread is gone: nothing to stop)
        ref.release()
        r.release()
        r2.release()


def test_queries_shared_with_the_server_answer_as_one_thread_does():
    """The query server's thread and the solver's take chunks of each query (and of each
    prefetch) as they come: whichever thread answers a chunk, the answers and the carried
    answers are the ones a collider answering alone gives, bit for bit -- over several chunks
    of points round a moving box, queried and prefetched over a few frames."""
    import engine.collide.moving as mv
    from engine.collide.maps import MapRenderer
    from engine.collide.moving import TrackCollider

    track = _sliding_box_track(1.0)
    rng = np.random.default_rng(3)
    n = 5 * mv.CHUNK + 17
    p = np.array([0.0, 0.25, 0.42]) + rng.uniform(-1.0, 1.0, (n, 3)) * (0.25, 0.25, 0.03)
    cols, rens = [], []
    for helper in (True, False):
        rens.append(MapRenderer(track.body.faces, texel=0.005, tol=0.005, window=(0.0, 0.5), with_velocity=True))
        cols.append(TrackCollider(track, rens[-1], tol=0.005, helper=helper))
    try:
        for step in range(40):
            t = 0.2 + step * 0.002
            x = p + (0.0, 0.0, 0.9 * (t - 0.2)) + rng.normal(0.0, 0.0002, p.shape)
            answers = []
            for c in cols:
                c.set_time(t)
                answers.append([a.copy() for a in c.query(x)] + [c.last_asked])
            for g, w in zip(*answers):
                assert np.array_equal(g, w)
            for name in ("c_local", "c_time", "c_frame", "c_pen", "c_un", "c_surf"):
                assert np.array_equal(getattr(cols[0], name), getattr(cols[1], name)), name
            if step % 2 == 0:
                for c in cols:
                    c.prefetch(x + (0.0, 0.0, 0.0018), 0.002)
        # both threads answered chunks; with helper False no thread was started
        assert cols[0].server.ctl[mv.SERVER_CHUNKS] > 0 and cols[0].server.ctl[mv.SOLVER_CHUNKS] > 0
        assert cols[1].server._thread is None and cols[1].server.ctl[mv.SERVER_CHUNKS] == 0
        assert cols[0].stats["asked"] == cols[1].stats["asked"] > 0
        assert np.any(answers[0][0] == 2) and np.any(answers[0][0] == 0)
    finally:
        for c in cols:
            c.release()
        for r in rens:
            r.release()


def test_a_collider_that_fills_faces_answers_as_for_points_made_whole():
    """With fill_faces the solver writes only the vertex rows of the points it asks for; the
    collider's query chunks (either thread's) make the face rows -- the same rows, bit for bit,
    as KC.collision_points makes -- and answer them as they answer points made whole, queried and
    prefetched over a few steps round a moving box."""
    import engine.cloth.kernels_contact as KC
    import engine.collide.moving as mv
    from engine.collide.maps import MapRenderer
    from engine.collide.moving import TrackCollider

    track = _sliding_box_track(1.0)
    rng = np.random.default_rng(5)
    side = 40  # a 40 x 40 grid of vertices over the box's front face: quads, and a row of triangles
    u, w = np.meshgrid(np.linspace(-0.25, 0.25, side), np.linspace(0.05, 0.45, side))
    x0 = np.stack([u.ravel(), w.ravel(), np.full(side * side, 0.401)], axis=1)
    ids = np.arange(side * side).reshape(side, side)
    quads = np.stack([ids[:-2, :-1].ravel(), ids[:-2, 1:].ravel(), ids[1:-1, 1:].ravel(), ids[1:-1, :-1].ravel()],
                     axis=1).astype(np.int32)
    tris = np.stack([ids[-2, :-1], ids[-2, 1:], ids[-1, 1:]], axis=1).astype(np.int32)
    n = len(x0)
    m = n + len(quads) + len(tris)
    assert m > 3 * mv.CHUNK
    rens = [MapRenderer(track.body.faces, texel=0.005, tol=0.005, window=(0.0, 0.5), with_velocity=True)
            for _ in range(2)]
    filled, whole = (TrackCollider(track, r, tol=0.005) for r in rens)
    filled.fill_faces(n, quads, tris)
    pf, pw, qf, qw = (np.zeros((m, 3)) for _ in range(4))
    try:
        for step in range(12):
            t = 0.2 + step * 0.002
            x = x0 + (0.0, 0.0, t - 0.2) + rng.normal(0.0, 0.004, x0.shape)
            v = rng.normal(0.0, 0.05, x0.shape)
            KC.collision_points(x, v, 0.001, quads[:0], tris[:0], pf)  # the vertex rows only
            KC.collision_points(x, v, 0.001, quads, tris, pw)
            assert not np.array_equal(pf, pw)
            answers = []
            for c, pts in ((filled, pf), (whole, pw)):
                c.set_time(t)
                answers.append([a.copy() for a in c.query(pts)] + [c.last_asked])
            assert np.array_equal(pf, pw)  # the face rows made by the query
            for g, want in zip(*answers):
                assert np.array_equal(g, want)
            if step % 2 == 0:  # (into arrays of their own, as the solver's: read while it steps on)
                KC.collision_points(x, v, 0.004, quads[:0], tris[:0], qf)
                KC.collision_points(x, v, 0.004, quads, tris, qw)
                for c, pts in ((filled, qf), (whole, qw)):
                    assert c.prefetch(pts, 0.002)
        assert np.any(answers[0][0] == 2) and np.any(answers[0][0] == 0)
    finally:
        for c in (filled, whole):
            c.release()
        for r in rens:
            r.release()


def test_stall_watch_lets_a_helper_go_when_the_solver_gets_too_little_of_a_core():
    """A solver's thread that gets less than CPU_SHARE of a core (here: it sleeps between
    requests, as a thread crowded off the cores waits) for CPU_WINDOWS windows lets its helper
    go; one that computes between requests keeps it."""
    import time

    from engine.collide.server import CPU_WINDOW, CPU_WINDOWS, StallWatch

    busy = StallWatch()
    end = time.perf_counter() + (CPU_WINDOWS + 1) * CPU_WINDOW
    while time.perf_counter() < end:
        x = 0.0
        for i in range(20000):
            x += i * 0.5
        busy.saw(0)
    assert not busy.lost
    idle = StallWatch()
    end = time.perf_counter() + (CPU_WINDOWS + 1.5) * CPU_WINDOW
    while time.perf_counter() < end and not idle.lost:
        time.sleep(0.02)
        idle.saw(0)
    assert idle.lost and idle.stalls == 0
