"""The default parametric body (ANNY): presets, frame, segments, height control, cache, rig.

One ANNY model is constructed for the whole session (about 1.5 s; ~23 s on a machine where
body-models has not yet written its preprocessed cache), and bodies are built into a
session-private TRYON_CACHE.
"""

from __future__ import annotations

import os
import time

import numpy as np
import pytest
import trimesh

from engine.body import default as default_mod
from engine.body import resolve_body
from engine.body.default import PRESETS, default_body
from engine.body.rig import skin
from engine.body.types import SEGMENT_ID, SEGMENTS
from engine.errors import InputError
from tests.samples import set_engine_env


@pytest.fixture(scope="session", autouse=True)
def _session_cache(tmp_path_factory):
    with pytest.MonkeyPatch.context() as mp:
        set_engine_env(mp, TRYON_CACHE=str(tmp_path_factory.mktemp("tryon_cache")))
        yield


@pytest.fixture(scope="session")
def female():
    return default_body("female")


@pytest.fixture(scope="session")
def male():
    return default_body("male")


@pytest.fixture(scope="session")
def anny():
    return default_mod._anny_model()


def _joint(body, name):
    return body.rig.rest_transforms[body.rig.joint_names.index(name), :3, 3]


# ---------------------------------------------------------------------------------------------
# Presets, mesh, frame


@pytest.mark.parametrize("preset", ["female", "male"])
def test_preset_mesh_is_clean_and_watertight(preset, request):
    body = request.getfixturevalue(preset)
    assert body.name == f"default:{preset}"
    assert body.vertices.dtype == np.float64 and body.vertices.shape[1] == 3
    assert body.faces.dtype == np.int32 and body.faces.shape[1] == 3
    assert body.faces.min() == 0 and body.faces.max() == len(body.vertices) - 1
    mesh = trimesh.Trimesh(body.vertices, body.faces, process=False)
    assert mesh.is_watertight and mesh.is_winding_consistent
    assert len(mesh.split(only_watertight=False)) == 1  # eyes and tongue dropped
    # Counter-clockwise seen from outside: positive signed volume; 40..110 litres for an adult.
    assert 0.04 < mesh.volume < 0.11
    assert any("ANNY" in n for n in body.notes)


def test_preset_heights_plausible(female, male):
    assert 1.60 <= female.height <= 1.72
    assert 1.72 <= male.height <= 1.85
    assert abs(female.height - PRESETS["female"]["height"]) < 0.005
    assert abs(male.height - PRESETS["male"]["height"]) < 0.005


@pytest.mark.parametrize("preset", ["female", "male"])
def test_world_frame_feet_on_floor_centred_facing_plus_z(preset, request):
    body = request.getfixturevalue(preset)
    v = body.vertices
    assert abs(v[:, 1].min()) < 1e-9  # feet on y = 0
    assert v[:, 1].max() == pytest.approx(body.height)
    torso = v[body.segments == SEGMENT_ID["torso"]]
    centre = (torso.min(axis=0) + torso.max(axis=0)) / 2
    assert abs(centre[0]) < 1e-6 and abs(centre[2]) < 1e-6  # torso centred on x = z = 0
    assert abs(v[:, 0].max() + v[:, 0].min()) < 0.01  # left-right symmetric about x = 0
    for side in ("L", "R"):
        # Toes in front of the ankle (+z), and the foot reaches further forward than back.
        assert _joint(body, f"toe1-1.{side}")[2] > _joint(body, f"foot.{side}")[2] + 0.05
        # Eyes in front of the head joint.
        assert _joint(body, f"eye.{side}")[2] > _joint(body, "head")[2] + 0.03
    sole = v[v[:, 1] < 0.03]
    ankle_z = _joint(body, "foot.L")[2]
    assert sole[:, 2].max() - ankle_z > 2 * (ankle_z - sole[:, 2].min())
    # Nose: the frontmost vertex of the face (between mouth and brows) is on the midline.
    head = v[(body.segments == SEGMENT_ID["head"]) & (v[:, 1] > 0.9 * body.height)
             & (v[:, 1] < 0.96 * body.height)]
    nose = head[head[:, 2].argmax()]
    assert abs(nose[0]) < 0.005 and nose[2] > _joint(body, "head")[2] + 0.08


def test_to_world_maps_anny_output(female, anny):
    raw = np.asarray(anny.forward_vertices(**_anny_params(anny, female)), dtype=np.float64)[0]
    world = raw @ female.to_world[:3, :3].T + female.to_world[:3, 3]
    keep = default_mod._body_component(np.asarray(anny._assets.triangles), anny.num_vertices)
    np.testing.assert_allclose(world[keep], female.vertices, atol=2e-5)  # h printed to 1e-7
    r = female.to_world[:3, :3]
    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-12)
    assert np.linalg.det(r) == pytest.approx(1.0)


# ---------------------------------------------------------------------------------------------
# Segments


@pytest.mark.parametrize("preset", ["female", "male"])
def test_segments_present_and_left_is_plus_x(preset, request):
    body = request.getfixturevalue(preset)
    seg = body.segments
    assert seg.dtype == np.uint8 and seg.shape == (len(body.vertices),)
    counts = np.bincount(seg, minlength=len(SEGMENTS))
    assert len(counts) == len(SEGMENTS) and (counts > 300).all(), dict(zip(SEGMENTS, counts))
    x = body.vertices[:, 0]
    for part in ("arm", "leg"):
        left, right = seg == SEGMENT_ID[f"left_{part}"], seg == SEGMENT_ID[f"right_{part}"]
        assert (x[left] > 0).all() and (x[right] < 0).all()
        assert counts[SEGMENT_ID[f"left_{part}"]] == counts[SEGMENT_ID[f"right_{part}"]]
    # The hands are arm, the head top is head, the soles are legs.
    y = body.vertices[:, 1]
    assert seg[x.argmax()] == SEGMENT_ID["left_arm"] and seg[x.argmin()] == SEGMENT_ID["right_arm"]
    assert seg[y.argmax()] == SEGMENT_ID["head"]
    assert set(np.unique(seg[y < 0.03])) == {SEGMENT_ID["left_leg"], SEGMENT_ID["right_leg"]}
    # Rest pose: the lower arms hang clear of torso and legs (matters for dressing).
    other = body.vertices[(seg == SEGMENT_ID["torso"]) | (seg == SEGMENT_ID["left_leg"])]
    forearm = body.vertices[(seg == SEGMENT_ID["left_arm"]) & (y < _joint(body, "lowerarm01.L")[1])]
    gap = np.min(np.linalg.norm(forearm[::7, None, :] - other[None, ::3, :], axis=-1))
    assert gap > 0.08


# ---------------------------------------------------------------------------------------------
# Shape parameters


@pytest.mark.parametrize(
    "preset, params",
    [
        ("female", dict(height=1.52)),
        ("female", dict(height=1.80, weight=0.85, muscle=0.2)),
        ("male", dict(height=1.95, proportions=0.8)),
        ("male", dict(height=1.68, gender=0.3, age=0.95)),
    ],
)
def test_height_parameter_honoured(preset, params):
    body = default_body(preset, **params)
    assert abs(body.height - params["height"]) < 0.005
    mesh = trimesh.Trimesh(body.vertices, body.faces, process=False)
    assert mesh.is_watertight and mesh.volume > 0


def test_shape_parameters_change_the_body(female):
    heavy = default_body("female", weight=1.0)
    assert heavy.height == pytest.approx(female.height, abs=0.005)
    vol = lambda b: trimesh.Trimesh(b.vertices, b.faces, process=False).volume  # noqa: E731
    assert vol(heavy) > 1.1 * vol(female)  # ANNY's range is narrow: ~46..60 litres at 1.65 m
    as_male = default_body("female", gender=0.0)
    assert as_male.name == "default:female" and not np.allclose(as_male.vertices, female.vertices)


@pytest.mark.parametrize(
    "kwargs, words",
    [
        (dict(preset="robot"), ["female", "male"]),
        (dict(height=165), ["metres", "centimetres"]),
        (dict(height=1.0), ["1.4", "2.1"]),
        (dict(height=2.6), ["1.4", "2.1"]),
        (dict(height=float("nan")), ["height"]),
        (dict(weight=-0.1), ["weight", "[0, 1]"]),
        (dict(muscle=1.5), ["muscle", "[0, 1]"]),
        (dict(proportions=2), ["proportions"]),
        (dict(gender=float("inf")), ["gender"]),
        (dict(age=0.5), ["age", "child"]),
        (dict(age=30), ["age", "not years"]),
        (dict(weight="heavy"), ["weight", "number"]),
        (dict(shoe_size=42), ["shoe_size", "allowed"]),
    ],
)
def test_bad_parameters_raise_input_error(kwargs, words):
    preset = kwargs.pop("preset", "female")
    with pytest.raises(InputError) as err:
        default_body(preset, **kwargs)
    message = str(err.value)
    assert "\n" not in message
    for w in words:
        assert w in message, message


def test_resolve_body_spec():
    body = resolve_body("default:male,height=1.8")
    assert body.name == "default:male" and abs(body.height - 1.8) < 0.005
    with pytest.raises(InputError):
        resolve_body("default:male,wingspan=2")


# ---------------------------------------------------------------------------------------------
# Cache


def test_cache_used_without_anny(monkeypatch, tmp_path):
    set_engine_env(monkeypatch, TRYON_CACHE=str(tmp_path))
    first = default_body("male", weight=0.6)
    files = list((tmp_path / "default_body").iterdir())
    assert [f.suffix for f in files] == [".npz"]  # no temporary files left behind

    def refuse(*a, **k):
        raise AssertionError("ANNY must not be constructed or used for a cached body")

    monkeypatch.setattr(default_mod, "_make_anny", refuse)
    monkeypatch.setattr(default_mod, "_anny_model", refuse)
    t0 = time.perf_counter()
    second = default_body("male", weight=0.6)
    elapsed = time.perf_counter() - t0
    assert elapsed < 0.5, f"cached load took {elapsed:.3f} s"
    np.testing.assert_array_equal(first.vertices, second.vertices)
    np.testing.assert_array_equal(first.faces, second.faces)
    np.testing.assert_array_equal(first.segments, second.segments)
    np.testing.assert_array_equal(first.rig.rest_transforms, second.rig.rest_transforms)
    np.testing.assert_array_equal(first.rig.skin_weights, second.rig.skin_weights)
    assert first.rig.joint_names == second.rig.joint_names
    assert second.name == "default:male" and first.notes == second.notes[: len(first.notes)]
    with pytest.raises(AssertionError):  # a body not in the cache needs ANNY
        default_body("male", weight=0.61)


def test_damaged_cache_file_is_rebuilt(monkeypatch, tmp_path):
    set_engine_env(monkeypatch, TRYON_CACHE=str(tmp_path))
    good = default_body("female", muscle=0.4)
    (path,) = (tmp_path / "default_body").glob("*.npz")
    path.write_bytes(b"not a zip file")
    again = default_body("female", muscle=0.4)
    np.testing.assert_allclose(again.vertices, good.vertices)
    assert os.path.getsize(path) > 100_000


# ---------------------------------------------------------------------------------------------
# Rig


def _anny_params(anny, body, body_pose=None):
    params = anny.get_rest_pose(batch_dims=(1,))
    params["shape"] = _shape_of(body)
    if body_pose is not None:
        params["body_pose"] = body_pose
    return params


def _shape_of(body):
    """The ANNY shape vector of a default body, from its notes (the build records it)."""
    p = dict(PRESETS["female"] if body.name.endswith("female") else PRESETS["male"])
    line = next(n for n in body.notes if n.startswith("ANNY controls"))
    h = float(line.split("height control ")[1].split()[0])
    return default_mod._shape(p, h)


def test_rig_fields(female):
    rig = female.rig
    n, j = len(female.vertices), len(rig.joint_names)
    assert rig.parents.dtype == np.int32 and rig.parents.shape == (j,)
    assert rig.parents[0] == -1 and (rig.parents[1:] >= 0).all()
    assert rig.rest_transforms.shape == (j, 4, 4) and rig.rest_transforms.dtype == np.float64
    rot = rig.rest_transforms[:, :3, :3]
    np.testing.assert_allclose(rot @ rot.transpose(0, 2, 1), np.broadcast_to(np.eye(3), rot.shape), atol=1e-5)
    assert rig.skin_indices.dtype == np.int32 and rig.skin_indices.shape[0] == n
    assert rig.skin_weights.dtype == np.float32 and rig.skin_weights.shape == rig.skin_indices.shape
    assert rig.skin_indices.min() >= 0 and rig.skin_indices.max() < j
    np.testing.assert_allclose(rig.skin_weights.sum(axis=1), 1.0, atol=1e-6)
    # Joints sit inside the body's extent, in the world frame.
    heads = rig.rest_transforms[:, :3, 3]
    assert heads[:, 1].min() > -0.01 and heads[:, 1].max() < female.height + 0.02


def test_lbs_rest_pose_is_identity(female, male):
    for body in (female, male):
        posed = skin(body.vertices, body.rig, body.rig.rest_transforms)
        np.testing.assert_allclose(posed, body.vertices, atol=1e-6)


def test_lbs_matches_body_models_when_posed(female, anny):
    """Bend the left knee 60 degrees (and a few other joints) with body-models, then with our
    LBS from the stored rest transforms: same vertices within 1 mm."""
    keep = default_mod._body_component(np.asarray(anny._assets.triangles), anny.num_vertices)
    names = anny.joint_names
    body_pose = np.zeros((1, 64, 3), dtype=np.float32)  # body_pose[k] drives joint k + 1 here
    assert names.index("lowerleg01.L") == 4 and names.index("upperleg01.R") == 22
    cases = {
        "knee": {"lowerleg01.L": [np.radians(60), 0, 0]},
        "several": {
            "lowerleg01.L": [np.radians(60), 0, 0],
            "upperleg01.R": [np.radians(-30), 0, np.radians(10)],
            "spine03": [0, np.radians(15), 0],
            "upperarm01.L": [0, 0, np.radians(-40)],
        },
    }
    to_world = female.to_world
    for joints in cases.values():
        bp = body_pose.copy()
        for name, aa in joints.items():
            bp[0, names.index(name) - 1] = aa
        params = _anny_params(anny, female, bp)
        expected = np.asarray(anny.forward_vertices(**params), dtype=np.float64)[0, keep]
        expected = expected @ to_world[:3, :3].T + to_world[:3, 3]
        skeleton = np.asarray(anny.forward_skeleton(**params), dtype=np.float64)[0]
        ours = skin(female.vertices, female.rig, to_world @ skeleton)
        moved = np.linalg.norm(expected - female.vertices, axis=1).max()
        assert moved > 0.2  # the pose really moves the leg
        err = np.linalg.norm(ours - expected, axis=1).max()
        assert err < 1e-3, f"LBS differs from body-models by {err * 1000:.2f} mm"
