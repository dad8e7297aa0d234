"""Animated glTF uploads (engine.body.gltf_anim): morph targets and skins sampled at a frame rate."""

from __future__ import annotations

import json
import struct

import numpy as np
import pytest

from engine.errors import InputError


def _glb(doc: dict, blobs: list[np.ndarray]) -> bytes:
    """A GLB with one buffer holding `blobs` (one bufferView and accessor each, in order)."""
    data, views = b"", []
    for b in blobs:
        raw = np.ascontiguousarray(b).tobytes()
        views.append({"buffer": 0, "byteOffset": len(data), "byteLength": len(raw)})
        data += raw + b"\0" * ((-len(raw)) % 4)
    doc = dict(doc, asset={"version": "2.0"}, buffers=[{"byteLength": len(data)}], bufferViews=views)
    js = json.dumps(doc).encode()
    js += b" " * ((-len(js)) % 4)
    out = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(data), 0x004E4942) + data
    return struct.pack("<4sII", b"glTF", 2, 12 + len(out)) + out


def _acc(i, comp, kind, count, **kw):
    return dict(bufferView=i, componentType=comp, type=kind, count=count, **kw)


def _bar():
    """A bar along +x from 0 to 2 (vertices at x = 0, 0.5, ..., 2; 4 around), triangles."""
    xs = np.linspace(0.0, 2.0, 5)
    ring = np.array([[0, -0.1, -0.1], [0, 0.1, -0.1], [0, 0.1, 0.1], [0, -0.1, 0.1]])
    v = np.concatenate([ring + [x, 0, 0] for x in xs]).astype(np.float32)
    f = []
    for k in range(len(xs) - 1):
        for j in range(4):
            a, b, c, d = 4 * k + j, 4 * k + (j + 1) % 4, 4 * (k + 1) + (j + 1) % 4, 4 * (k + 1) + j
            f += [[a, b, c], [a, c, d]]
    return v, np.array(f, np.uint32)


def _skinned_bar(interp="LINEAR"):
    """Two joints: j0 at the origin (translates up 0.5 m over 1 s), j1 at x = 1, its child
    (turns 90 degrees about z over 1 s). Vertices with x < 1 follow j0, x > 1 j1, x = 1 half each."""
    v, f = _bar()
    w1 = np.where(v[:, 0] > 1.01, 1.0, np.where(v[:, 0] > 0.99, 0.5, 0.0)).astype(np.float32)
    joints = np.tile(np.array([0, 1, 0, 0], np.uint8), (len(v), 1))
    weights = np.stack([1 - w1, w1, 0 * w1, 0 * w1], axis=1).astype(np.float32)
    ibm = np.stack([np.eye(4), np.array([[1, 0, 0, -1], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1.0]])])
    ibm = ibm.transpose(0, 2, 1).astype(np.float32)  # column-major
    t = np.array([0.0, 1.0], np.float32)
    tr = np.array([[0, 0, 0], [0, 0.5, 0]], np.float32)
    s45 = np.sin(np.pi / 4)
    rot = np.array([[0, 0, 0, 1], [0, 0, s45, s45]], np.float32)
    blobs = [v, f.reshape(-1), joints, weights, ibm, t, tr, rot]
    doc = {
        "scene": 0, "scenes": [{"nodes": [0, 2]}],
        "nodes": [{"name": "j0", "children": [1]}, {"name": "j1", "translation": [1, 0, 0]},
                  {"name": "bar", "mesh": 0, "skin": 0, "translation": [5, 5, 5]}],  # ignored: skinned
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "JOINTS_0": 2, "WEIGHTS_0": 3}, "indices": 1}]}],
        "skins": [{"joints": [0, 1], "inverseBindMatrices": 4}],
        "accessors": [_acc(0, 5126, "VEC3", len(v)), _acc(1, 5125, "SCALAR", f.size), _acc(2, 5121, "VEC4", len(v)),
                      _acc(3, 5126, "VEC4", len(v)), _acc(4, 5126, "MAT4", 2), _acc(5, 5126, "SCALAR", 2),
                      _acc(6, 5126, "VEC3", 2), _acc(7, 5126, "VEC4", 2)],
        "animations": [{"samplers": [{"input": 5, "output": 6, "interpolation": interp},
                                     {"input": 5, "output": 7, "interpolation": interp}],
                        "channels": [{"sampler": 0, "target": {"node": 0, "path": "translation"}},
                                     {"sampler": 1, "target": {"node": 1, "path": "rotation"}}]}],
    }
    return _glb(doc, blobs), v, w1


def _expected_bar(v, w1, t):
    """The bar at time t, worked out by hand: j0 up 0.5 t, j1 turned 90 t degrees about z at x = 1."""
    a = np.radians(90.0 * t)
    rot = np.array([[np.cos(a), -np.sin(a), 0], [np.sin(a), np.cos(a), 0], [0, 0, 1]])
    up = np.array([0, 0.5 * t, 0])
    by_j0 = v + up
    by_j1 = (v - [1, 0, 0]) @ rot.T + [1, 0, 0] + up
    return (1 - w1)[:, None] * by_j0 + w1[:, None] * by_j1


def test_skinned_glb_matches_hand_worked_skinning(tmp_path):
    from engine.body.gltf_anim import sample_gltf_animation

    data, v, w1 = _skinned_bar()
    p = tmp_path / "bar.glb"
    p.write_bytes(data)
    frames, faces, notes = sample_gltf_animation(p, fps=4)
    assert frames.shape == (5, len(v), 3) and faces.shape == (32, 3)  # 0, .25, .5, .75, 1 s
    for k in range(5):
        assert np.abs(frames[k] - _expected_bar(v.astype(float), w1, k / 4)).max() < 1e-5, k
    # the tip (x = 2) turned: at 1 s it points up from the joint
    tip = v[:, 0] > 1.99
    assert np.allclose(frames[-1][tip, 0], 1.0 + v[tip, 1] * -1, atol=1e-5)


def test_step_interpolation_holds_keys(tmp_path):
    from engine.body.gltf_anim import sample_gltf_animation

    data, v, w1 = _skinned_bar("STEP")
    p = tmp_path / "bar.glb"
    p.write_bytes(data)
    frames, _, _ = sample_gltf_animation(p, fps=4)
    assert np.abs(frames[2] - v).max() < 1e-6  # still the first key at 0.5 s
    assert np.abs(frames[4] - _expected_bar(v.astype(float), w1, 1.0)).max() < 1e-5


def test_morph_target_glb_of_a_walk_loads_as_the_same_motion(tmp_path):
    """Our own anim.glb writer (morph targets, LINEAR weights) read back as an uploaded animation:
    the frames are the walk's frames (up to the loader's re-centring) and it walks a garment."""
    from engine.body.animation import load_animation
    from engine.body.default import default_body
    from engine.body.motion import WalkParams, walk_track
    from engine.io.anim import write_anim_glb

    body = default_body("female")
    tr = walk_track(body, WalkParams(), fps=30)
    frames = np.stack([tr.vertices(i) for i in range(12)]).astype(np.float32)
    p = write_anim_glb(tmp_path / "walk.glb", [("body", body.faces, frames, (200, 160, 140, 255))], fps=30)
    t = load_animation(p, fps=30)
    assert t.frames.shape == (12, len(body.vertices), 3)
    shift = t.frames[0].astype(np.float64) - frames[0]
    assert np.abs(shift - shift.mean(axis=0)).max() < 1e-5
    for k in (4, 11):
        assert np.abs((t.vertices(k) - shift) - frames[k]).max() < 1e-4
    # sampled at twice the rate: in-between frames are the LINEAR blend of the keys
    t2 = load_animation(p, fps=60)
    assert t2.frames.shape[0] == 23
    mid = 0.5 * (frames[3].astype(np.float64) + frames[4])
    assert np.abs((t2.vertices(7) - shift) - mid).max() < 1e-4
    assert t.body.segments is not None


@pytest.mark.parametrize("make, words", [
    (lambda p: p.write_bytes(b"glTF" + struct.pack("<II", 1, 20) + b"\0" * 8), "version 1"),
    (lambda p: p.write_bytes(b"glTF" + struct.pack("<II", 2, 999) + struct.pack("<II", 50, 0x4E4F534A) + b"{}"),
     "truncated"),
    (lambda p: p.write_text("{\"asset\": {\"version\": \"2.0\"}, \"nodes\": []}"), "no animation"),
    (lambda p: p.write_text(json.dumps({"asset": {"version": "2.0"}, "buffers": [{"uri": "walk.bin", "byteLength": 4}],
                                        "animations": [{"samplers": [], "channels": []}]})), "external file"),
])
def test_bad_gltf_animations_are_refused(tmp_path, make, words):
    from engine.body.animation import load_animation

    p = tmp_path / ("a.glb" if words in ("version 1", "truncated") else "a.gltf")
    make(p)
    with pytest.raises(InputError, match=words):
        load_animation(p, fps=30)


def test_corrupt_accessor_is_refused(tmp_path):
    from engine.body.gltf_anim import sample_gltf_animation

    data, v, _ = _skinned_bar()
    doc_len = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + doc_len])
    doc["accessors"][0]["count"] = 10_000  # positions read past the buffer
    blob_at = 20 + doc_len
    bin_len = struct.unpack_from("<I", data, blob_at)[0]
    js = json.dumps(doc).encode()
    js += b" " * ((-len(js)) % 4)
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + data[blob_at:blob_at + 8 + bin_len]
    p = tmp_path / "bad.glb"
    p.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    with pytest.raises(InputError, match="past its buffer"):
        sample_gltf_animation(p, fps=30)


@pytest.mark.integration
def test_walk_cli_with_an_animated_glb(tmp_path):
    """`tryon walk --body walk.glb`: an animated glTF is played as the motion (a static one would
    be a scan); the garment is dressed on its first frame and walks to the animation's end."""
    from typer.testing import CliRunner

    from engine.body.default import default_body
    from engine.body.motion import WalkParams, walk_track
    from engine.cli import app
    from engine.io.anim import write_anim_glb

    body = default_body("female")
    tr = walk_track(body, WalkParams(), fps=30)
    frames = np.stack([tr.vertices(i) for i in range(10)]).astype(np.float32)
    p = write_anim_glb(tmp_path / "walk.glb", [("body", body.faces, frames, (200, 160, 140, 255))], fps=30)
    r = CliRunner().invoke(app, ["walk", "--out", str(tmp_path / "o"), "--body", str(p), "--garment", "skirt",
                                 "--resolution", "3", "--seconds", "2"])
    assert r.exit_code == 0, (r.output, r.stderr)
    rep = json.loads((tmp_path / "o" / "report.json").read_text())
    assert rep["frames"] == 9 and rep["walk"]["map_frames_rendered"] == 10
    assert rep["walk"]["penetration_mm"]["max"] <= 10.0
