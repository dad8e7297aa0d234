"""Measurements of the GarmentCode reference body against its published values."""

from __future__ import annotations


import numpy as np
import pytest
import yaml

from tests.samples import SAMPLE_BODY, SAMPLE_YAML  # noqa: F401
from engine.body.load import load_body_file
from engine.body.measure import Measurements, measure, slice_pieces, slice_stack

SAMPLE = SAMPLE_BODY
REF = yaml.safe_load(SAMPLE_YAML.read_text())["body"]


@pytest.fixture(scope="module")
def body():
    return load_body_file(SAMPLE)


@pytest.fixture(scope="module")
def meas(body):
    return measure(body)


def test_reference_values(meas):
    d = meas.to_dict()
    assert d["units"] == "cm"
    assert abs(d["height"] - REF["height"]) <= 1.0
    for key in ("bust", "waist", "hips"):
        assert abs(d[key] - REF[key]) <= 3.0, (key, d[key], REF[key])
    # Looser checks on the secondary values (reported, not required).
    assert abs(d["underbust"] - REF["underbust"]) <= 3.0
    assert abs(d["shoulder_width"] - REF["shoulder_w"]) <= 4.0
    assert abs(d["arm_length"] - REF["arm_length"]) <= 5.0


def test_landmarks_ordered(meas):
    m = meas
    assert 0 < m.knee_height < m.crotch_height < m.hip_height < m.waist_height < m.bust_height
    assert m.bust_height < m.shoulder_height < m.height
    assert m.inseam == m.crotch_height
    assert m.underbust < m.bust and m.waist < m.hips


def test_text_and_dict(meas):
    d = meas.to_dict()
    for key in ("height", "bust", "underbust", "waist", "hips", "shoulder_width", "arm_length", "inseam",
                "shoulder_height", "bust_height", "waist_height", "hip_height", "crotch_height", "knee_height"):
        assert isinstance(d[key], float) and d[key] == round(d[key], 1)
    text = meas.to_text()
    assert "Waist" in text and f"{d['waist']:.1f}" in text
    assert Measurements().to_dict()["bust"] is None  # NaN -> None, not a crash


def test_slice_stack_matches_single_cuts(body):
    ys = np.array([0.3, 0.9, 1.1, 1.3])
    for y, pieces in zip(ys, slice_stack(body.vertices, body.faces, ys)):
        single = slice_pieces(body.vertices, body.faces, float(y))
        assert sorted(round(p.length, 9) for p in pieces) == sorted(round(p.length, 9) for p in single)
    legs = slice_pieces(body.vertices, body.faces, 0.3)
    assert len(legs) == 2 and all(p.closed for p in legs)


def test_rotated_scan_measures_the_same(tmp_path, body, meas):
    import trimesh

    v = body.vertices @ np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], float).T * 100.0
    p = tmp_path / "cm.ply"
    trimesh.Trimesh(v, body.faces, process=False).export(p)
    d2 = measure(load_body_file(p)).to_dict()
    d = meas.to_dict()
    for key in ("height", "bust", "waist", "hips", "crotch_height"):
        assert abs(d2[key] - d[key]) <= 0.2, key


def test_arms_held_closer_still_measure(body, meas):
    """The sample scan with its arms lowered 30 degrees towards the body (the fitted default
    skeleton, linear blend skinning): the arms join the torso one after the other, a cut apart,
    and the armpits were not found (every upper-body measure skipped). Now it measures as the
    A-pose does."""
    from engine.body.fit import fit_rig
    from engine.body.motion import _rot, pose_joints
    from engine.body.rig import skin
    from engine.body.types import Body

    rigged = fit_rig(body)
    posed = skin(rigged.vertices, rigged.rig, pose_joints(rigged.rig, {"upperarm01.L": _rot("z", -30.0),
                                                                      "upperarm01.R": _rot("z", 30.0)}))
    assert np.ptp(posed[:, 0]) < np.ptp(body.vertices[:, 0]) - 0.4  # the hands came 20+ cm closer each
    m = measure(Body(vertices=posed, faces=body.faces, name="arms-down"))
    assert m.arm_gap < 0.02 and m.notes == [  # the arms nearly touch the torso there: said once
        f"the arms hang {100 * m.arm_gap:.1f} cm from the torso 10 cm below the armpits: dresses and "
        "tops are sewn reliably from 10 cm (an A-pose, arms about 45 degrees from the body), so the arms are "
        "turned out that far for dressing and walking (where they cannot be, tops are sewn with friction, and "
        "where the seams beside the arms do not close, sewn again with the arms raised and then lowered)"]
    assert abs(meas.arm_gap - 0.112) < 0.005 and not meas.notes
    for k in ("bust", "underbust", "waist", "hips"):
        assert abs(getattr(m, k) - getattr(meas, k)) < 0.01, (k, getattr(m, k), getattr(meas, k))
    assert abs(m.shoulder_height - meas.shoulder_height) < 0.03
    assert abs(m.shoulder_width - meas.shoulder_width) < 0.03
    assert abs(m.arm_length - meas.arm_length) < 0.03


def test_measurements_are_cached_by_the_mesh_content(body, meas):
    """measure() keeps the last bodies' results by a digest of the mesh: the same mesh again (a
    try-on measures its body 3-6 times) gives equal values in its own copy; a moved mesh is
    measured anew."""
    import time

    from engine.body.types import Body

    again_body = Body(vertices=body.vertices.copy(), faces=body.faces.copy(), name="copy")
    t = time.perf_counter()
    again = measure(again_body)
    assert time.perf_counter() - t < 0.2  # from the cache (a measurement takes ~1 s)
    assert again == meas and again is not meas
    again.notes.append("mine")
    again.bust = 0.0
    assert measure(body).bust == meas.bust and "mine" not in measure(body).notes
    taller = measure(Body(vertices=body.vertices * np.array([1.0, 1.1, 1.0]), faces=body.faces))
    assert abs(taller.height - 1.1 * meas.height) < 1e-6


def test_a_belly_in_front_of_the_chest_is_not_the_bust():
    """default:male at weight 1 (the page's sliders): his belly stands further forward than his
    chest, at the lower edge of the region searched for the bust point; the bust point was put
    there (at the waist) and bust, underbust and --size auto came out n/a. The bust point is now
    the front profile's peak; the default bodies' figures are unchanged."""
    from engine.body import resolve_body
    from engine.pattern.catalogue import recommend_size

    for spec, size in (("default:male,weight=1", "L"), ("default:male,height=1.45,weight=1", "S")):
        b = resolve_body(spec)
        m = measure(b)
        assert np.isfinite(m.bust) and np.isfinite(m.underbust), (spec, m.notes)
        assert m.bust_height > m.waist_height + 0.05 and m.armpit_height - m.bust_height < 0.06 * m.height
        assert m.underbust < m.bust and m.waist < m.bust
        assert recommend_size("shirt", b) == size  # men's chart: 102.7/90.3/105.4 cm, 92.3/81.5/93.6 cm
    for spec, bust, height in (("default:female", 0.850, 1.195), ("default:male", 1.005, 1.285)):
        m = measure(resolve_body(spec))
        assert abs(m.bust - bust) < 0.002 and abs(m.bust_height - height) < 0.003, (spec, m.bust, m.bust_height)
