"""Dressing end to end (seed 003): the sample GarmentCode skirt on the sample body, and the
catalogue on the default bodies. The fast test runs a coarse cloth; the quality tests (slow)
run the default resolution and check the issue's criteria: every seam welded, penetration
measured exactly against the body mesh max <= 3 mm and p99 <= 1 mm, strain max <= threshold +
1 %, settled, and the garment still hanging where it was placed."""

from __future__ import annotations

import json
from dataclasses import replace
import re

import numpy as np
import pytest
from typer.testing import CliRunner

from engine.cli import app
from engine.scene.request import TryOnOptions
from engine.scene.tuning import DrapeTuning, SewTuning, Tuning
from tests.samples import GC_SHIRT, ROOT, SAMPLE_BODY, SAMPLE_SKIRT, SMPL_BODY, write_arms_lowered_scan

pytestmark = pytest.mark.integration  # (dresses, walks, or runs the service)

REPORT_KEYS = {"cloth_vertices", "iterations", "ms_per_iteration", "wall_seconds", "penetration_mm", "strain",
               "seam_gap_mm", "settled", "left_out", "shift_mm", "warnings"}


def _check_quality(rep: dict) -> None:
    assert rep["penetration_mm"]["max"] <= 3.0, rep["penetration_mm"]
    assert rep["penetration_mm"]["p99"] <= 1.0, rep["penetration_mm"]
    assert rep["strain"]["max"] <= rep["strain"]["threshold"] + 0.01, rep["strain"]
    assert rep["settled"], "the drape did not settle within its budget"
    # welded: the sewn garment has fewer vertices than the flat panels, seams closed
    assert rep["cloth_vertices"] < rep["cloth_vertices_unsewn"]
    assert rep["seam_gap_mm"]["max"] <= 10.0
    # hanging where it was placed: not slid down the body, not bunched up (a dress blown into a
    # heap on one shoulder passed every check above: its hem had risen 60 cm)
    assert rep["shift_mm"]["top"] >= -100.0 and rep["shift_mm"]["hem"] <= 150.0, rep["shift_mm"]


def test_drape_command_writes_everything(tmp_path):
    """The sample skirt on its own body through the CLI, at a coarse 4 cm cloth (fast)."""
    out = tmp_path / "skirt"
    r = CliRunner().invoke(app, ["drape", "--body", str(SAMPLE_BODY), "--garment", str(SAMPLE_SKIRT),
                                 "--resolution", "4", "--out", str(out)])
    assert r.exit_code == 0, r.output
    for name in ("scene.glb", "garment.obj", "front.png", "side.png", "back.png", "report.json", "pattern.svg"):
        assert (out / name).stat().st_size > 0, name
    # the pattern dressed, written back out: the same GarmentCode spec
    from engine.pattern.io import load_pattern, pattern_to_dict

    assert pattern_to_dict(load_pattern(out / "pattern.json")) == pattern_to_dict(load_pattern(SAMPLE_SKIRT))
    assert (out / "pattern.svg").read_text().startswith("<svg")
    rep = json.loads((out / "report.json").read_text())
    assert REPORT_KEYS <= set(rep)
    assert rep["iterations"] > 0 and rep["ms_per_iteration"]["total"] > 0
    assert np.isfinite(rep["penetration_mm"]["max"])
    # the strain guard is reported with how much of the last settle window it acted in
    assert rep["strain"]["guard"] == pytest.approx(DrapeTuning().step.strain_guard) and 0.0 <= rep["strain"]["guard_share"] <= 1.0
    # the skirt stays on the body: its top is near the waist (the sample body's waist ~1.08 m)
    import trimesh

    g = trimesh.load(out / "garment.obj", process=False)
    assert 0.95 < g.vertices[:, 1].max() < 1.15
    assert g.vertices[:, 1].min() > 0.3


def test_a_garment_that_slid_down_or_bunched_up_is_flagged():
    """The report says when a drape did not end hanging where it was placed."""
    from engine.scene.tryon import SLID_OFF, hang_shift, hang_warnings
    from engine.scene.tryon import slid as slid_off

    rng = np.random.default_rng(0)
    placed = rng.uniform([-0.2, 0.5, -0.15], [0.2, 1.4, 0.15], (500, 3))  # a dress, shoulders to knees
    placed[:2, 1] = 0.5, 1.4

    def shifted(lo, hi):
        y = placed[:, 1]
        return np.column_stack([placed[:, 0], lo + (y - y.min()) / np.ptp(y) * (hi - lo), placed[:, 2]])

    hanging = hang_shift(placed, shifted(0.46, 1.43))  # the hem fell 4 cm, the top rose 3 cm
    assert hanging["top"] == pytest.approx(0.03) and hanging["hem"] == pytest.approx(-0.04)
    assert hang_warnings(hanging) == []
    heap = hang_warnings(hang_shift(placed, shifted(1.1, 1.45)))  # a heap on the shoulders
    assert len(heap) == 1 and "rose 60 cm" in heap[0] and "bunched up" in heap[0]
    slid = hang_warnings(hang_shift(placed, shifted(0.05, 1.2)))  # slid down 20 cm
    assert len(slid) == 1 and "slid 20 cm down" in slid[0]
    ident = np.arange(len(placed))
    assert "slid 20 cm down" in hang_warnings(hang_shift(placed, shifted(0.3, 1.2), ident))[0]  # all of it
    # a collar placed standing up to 1.5 m that folds down to 1.3, the dress below risen 8 cm: not a slide
    collar = placed[:20] * [1, 0, 1] + [0, 1.5, 0]
    worn = np.vstack([shifted(0.58, 1.48)[20:] - [0, 0.1, 0], collar - [0, 0.2, 0]])
    placed_c = np.vstack([placed[20:] - [0, 0.1, 0], collar])
    folded = hang_shift(placed_c, worn, ident)
    assert folded["top"] < -0.10 and folded["bulk"] > 0.05
    assert hang_warnings(folded) == []
    # a dress whose skirt was laid out in a ring reaching above the bodice (GarmentCode's circle
    # skirts: f_smpl 97_006's, to 1.85 m) falls to the hips: judged by its bodice, it did not slide
    ring = placed.copy()
    ring[:, 1] += 0.6  # (the skirt's ring, up to 2.0 m)
    both = np.vstack([placed, ring])
    dropped = np.vstack([shifted(0.47, 1.42), shifted(0.2, 1.0)])  # the bodice hangs, the skirt fell
    every = np.arange(len(both))
    assert slid_off(hang_shift(both, dropped, every), SLID_OFF)  # (the whole garment's top and bulk fell)
    bodice = np.arange(len(both)) < len(placed)
    judged = hang_shift(both, dropped, every, bodice)
    assert not slid_off(judged, SLID_OFF) and judged["hem"] == pytest.approx(0.2 - 0.5)  # (the hem: all of it)


def test_fit_warnings_say_tight_or_unsettled():
    """A drape that ends stretched more than 1 % past the fabric's limit (issue 3's quality bar)
    or not settled within its budget says so in the report's warnings."""
    from engine.cloth.fabrics import get_fabric
    from engine.scene.tryon import fit_warnings

    cotton = get_fabric("cotton")
    assert fit_warnings(0.059, cotton, True, 6.0) == []
    tight, unsettled = fit_warnings(0.08, cotton, False, 6.0)
    assert "tight: stretched 8 % where cotton allows 5 %" in tight and "did not settle within 6 s" in unsettled
    assert "try a larger size" in tight
    # a pattern file has one size: the advice is to grade it, not to pick another size
    (tight,) = fit_warnings(0.08, cotton, True, 6.0, pattern_file=True)
    assert "grade it larger" in tight and "larger size" not in tight


@pytest.mark.parametrize("edge", [0.012, 0.0163])
def test_a_dress_sews_at_other_cloth_resolutions(edge):
    """default:female's dress M at cloth edges 1.2 and 1.63 cm (the benchmark's resolution for
    the seed's 3,840 vertices): placed with its straps standing straight up from the bust, its
    shoulder seams started 31 cm apart, the seam pull swung the straps down below the shoulders
    and the dress slid off sideways (one shoulder seam 15 cm open after the 4 s budget); at 1.1
    to 1.8 cm, 3 of 8 resolutions failed so. The straps now start leaning over the shoulders
    (engine.garment.place._lean_in) and every resolution sews within 0.3 s (sewing only here:
    the drape is cut short)."""
    from engine.body import resolve_body
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon

    b = resolve_body("default:female")
    spec, place, name = resolve_garment("dress", b, "M")
    res, rep = run_tryon(b, spec, TryOnOptions(resolution_cm=100 * edge),
                         Tuning(drape=DrapeTuning(budget=0.01, min_time=0.0)), place=place, source=name)
    assert res.iterations["sewing"] * res.dt < 0.3, res.iterations
    assert rep["seam_gap_mm"]["snapped"] == 0 and rep["cloth_vertices"] < rep["cloth_vertices_unsewn"]
    assert rep["shift_mm"]["top"] > -60.0, rep["shift_mm"]  # on the shoulders (fallen: -400)


def test_flat_panels_whose_seams_stop_closing_are_sewn_again_gently():
    """GarmentCode lays panels out flat round the body (the sample skirt's seams start 30 cm
    apart). If they do not close, sewing starts once more from the placement, pulled at
    SewTuning.far_retry_vmax (GarmentCode's own T-shirt: its sleeves' seams stalled 9 cm
    open at 3 m/s and sewed at 1.5). Here the first pull is made far too slow to close within
    the budget: the second one sews; both attempts count; the progress says why it sews again.
    If both fail, the error says it was sewn twice."""
    from engine.body import resolve_body
    from engine.errors import SimulationError
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon

    body = resolve_body(str(SAMPLE_BODY))
    spec, place, name = resolve_garment(str(SAMPLE_SKIRT), body, None)
    said = []
    o = Tuning(sew=SewTuning(vmax=0.05, far_retry_vmax=3.0, budget=0.5), drape=DrapeTuning(budget=0.3))
    res, rep = run_tryon(body, spec, TryOnOptions(resolution_cm=4.0), o, place=place, source=name,
                         progress=lambda stage, f, msg: said.append(msg))
    assert rep["seam_gap_mm"]["snapped"] == 0 and rep["cloth_vertices"] < rep["cloth_vertices_unsewn"]
    budget = int(np.ceil(0.5 / res.dt))
    assert rep["iterations_by_stage"]["sewing"] > budget  # the failed first attempt, then the second
    assert any("sewing again, pulled at 3 m/s" in m for m in said)
    with pytest.raises(SimulationError, match=r"sewn twice, pulled at 0.05 and 0.06 m/s"):
        run_tryon(body, spec, TryOnOptions(resolution_cm=4.0),
                  Tuning(sew=SewTuning(vmax=0.05, far_retry_vmax=0.06, budget=0.3)), place=place, source=name)


def test_a_stalled_flat_layout_is_sewn_again_within_half_a_second():
    """GarmentCode's T-shirt on its own body sews in one pull now that a flat layout's pairs close
    together (SewTuning.far_together), and so it does when the pairs whose path runs through the
    arm meet beside it (SewTuning.meet_outside). Without either, each pulled at 3 m/s as before, its sleeve seams stall ~9 cm
    open from ~0.15 s on: with a second pull to come, the stall is judged over
    SewTuning.retry_stall windows, so it is sewn again after ~0.5 s of sewing, not after 1 s
    (progress reports come every 5 ms of simulated time while sewing), and then sews and drapes."""
    from engine.body import resolve_body
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon
    from engine.scene.tuning import SewTuning, Tuning
    from tests.samples import GC_SHIRT

    body = resolve_body(str(SAMPLE_BODY))
    spec, place, name = resolve_garment(str(GC_SHIRT), body, None)
    for together, meet in ((True, True), (False, True), (False, False)):
        said = []
        res, rep = run_tryon(body, spec, TryOnOptions(resolution_cm=3.0),
                             replace(Tuning(), sew=replace(SewTuning(), far_together=together, meet_outside=meet)),
                             place=place, source=name, progress=lambda stage, f, msg: said.append((stage, msg)))
        again = [k for k, (_, m) in enumerate(said) if "sewing again" in m]
        if together or meet:  # either closes the sleeve seams in one pull (the pairs meet beside the arm)
            assert not again
        else:
            assert len(again) == 1
            first = sum(1 for stage, m in said[:again[0]] if stage == "sewing" and m.startswith("largest open seam gap"))
            assert 0.45 <= first * 0.005 <= 0.6, first
        assert rep["seam_gap_mm"]["snapped"] == 0 and rep["settled"] and rep["strain"]["max"] <= 0.06


def test_a_garment_that_slides_off_the_body_is_an_error_not_a_result(tmp_path, monkeypatch):
    """An XXL skirt (waist 93 cm) on a thin body (default:female, weight 0: waist ~60 cm) slides
    down the legs and settles around the feet, with every bar met (no penetration, strain
    within the limit, settled): `tryon drape` ends with an error that says it slid off and
    what to do, writes the picture of where it ended (failed.png) and no result files. (The
    catalogue's waistbands take in to the body's waist now, catalogue.waistband_girth: here the
    size's own waist, as a pattern's fixed waist would be.)"""
    import engine.pattern.catalogue as catalogue

    monkeypatch.setattr(catalogue, "waistband_girth", lambda f: f.waist)
    out = tmp_path / "xxl"
    r = _drape_cli(["--body", "default:female,weight=0.0", "--garment", "skirt", "--size", "XXL",
                    "--resolution", "3", "--out", str(out)])
    assert r.exit_code == 2, (r.exit_code, r.output)
    err = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(err) == 1 and "slid" in err[0] and "cm down the body" in err[0] and "smaller size" in err[0], r.stderr
    assert "Traceback" not in r.output
    assert (out / "failed.png").stat().st_size > 0
    assert not (out / "report.json").exists() and not (out / "scene.glb").exists()


@pytest.mark.slow
def test_a_garment_far_too_small_is_refused():
    """The sample scan's XS sleeveless shirt (chart bust 82 cm on a 97.5 cm bust) is refused
    with a clear error that says it is too small, with a picture's positions, marked too_small
    (for --size auto and the size hint) -- by one of two rules, as the sewing goes: its side
    seams stay open and sewing gives up once they stopped closing, more than snap_gap open,
    from snap_after on (measured with 4 contact rounds a step: after 2.0 s and, with the force
    pass's sums in another order, 2.4 s of simulated time; at the 4 s budget they were still
    2.1-2.3 cm open); or they close with the cloth stretched round the bust and the drape
    refuses it as stretched past the fabric's limit + too_tight (measured with 2 contact rounds
    a step, engine.cloth.model.ClothParams: 17 %; before the straps leaned over the shoulders,
    at least 16 %; sewn with checks every 3rd step, 15 %: the rule refuses past threshold + 10 %);
    or it rides up over the bust to where the body is narrower (9 cm, ending 6.3 % stretched) and
    is refused for that (tryon._rode_up). Each rule alone is tested fast: test_sewing_gives_up_when_the_seams_stop_closing,
    test_a_drape_that_stays_stretched_is_refused_early, test_a_catalogue_garment_that_rode_up_tight_is_refused."""
    from engine.body import resolve_body
    from engine.errors import SimulationError
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon

    body = resolve_body(str(SAMPLE_BODY))
    spec, place, name = resolve_garment("sleeveless-shirt", body, "XS")
    open_seams = (r"sewing stopped closing after [23]\.\d s of simulated time \(the widest gap stayed .* open seams: "
                  r".* may be too small for this body \(try a larger size\)")
    stretched = (r"too small for this body: (after draping it is|for \d\.\d s of draping it stayed) stretched "
                 r"(at least )?(1[5-9]|[2-9]\d) % where cotton allows 5 %")
    rode_up = r"too small for this body: it rode \d+ cm up from where it is worn and is stretched \d+ %"
    with pytest.raises(SimulationError, match=f"{open_seams}|{stretched}|{rode_up}") as e:
        run_tryon(body, spec, place=place, source=name)
    assert e.value.too_small and e.value.positions.shape[1] == 3


def test_a_catalogue_garment_that_rode_up_tight_is_refused():
    """An XS shirt over a 97.5 cm bust (chart 82 cm) rose 9 cm to where the body is narrower and
    ended 6.3 % stretched: too small (tryon.rode_up). Rising into place with ease to spare, or
    tight where it was placed, is not that."""
    from engine.cloth.fabrics import get_fabric
    from engine.scene.tryon import RODE_UP, rode_up

    cotton = get_fabric("cotton")
    up = {"top": 0.05, "hem": 0.115, "bulk": 0.09}
    assert rode_up(up, 0.063, cotton)
    assert not rode_up(up, 0.055, cotton)  # rose, and fits
    assert not rode_up({"top": 0.0, "hem": 0.01, "bulk": 0.5 * RODE_UP}, 0.07, cotton)  # tight where placed


@pytest.mark.parametrize("spec_body", ["default:female", "default:male", "default:female,height=1.5",
                                       "default:male,height=1.9,weight=1.0"])
def test_a_garmentcode_pattern_is_placed_round_another_body(spec_body):
    """GarmentCode places panels round its mean body standing Y up, facing +Z -- our world's
    conventions. On another body the placed panels are carried over landmark by landmark and
    pushed out of the body (engine.garment.place.pattern_placement): the sample skirt sits
    round the hips, front panels in front, nothing inside the body's cross-sections. (Through
    ANNY's Z-up map it landed 0.6-1.2 m behind default:female and fell to the floor; in
    GarmentCode's frame as given it hung at a 1.5 m body's wrists and a 1.9 m body's crotch,
    and sewing failed on both.)"""
    from engine.body import resolve_body
    from engine.body.measure import measure
    from engine.garment.garment import build_garment
    from engine.garment.place import CLEARANCE, BodySections, pattern_placement
    from engine.pattern.io import load_pattern

    body = resolve_body(spec_body)
    m = measure(body)
    spec = load_pattern(SAMPLE_SKIRT)
    place, note = pattern_placement(spec, body)
    assert note is not None and "landmarks" in note
    g = build_garment(spec, h=0.03, place=place)
    x = g.positions
    assert np.abs(x[:, [0, 2]]).max() < 0.6  # round the body's axis
    wb = np.isin(g.panel, [g.panel_names.index("wb_front"), g.panel_names.index("wb_back")])
    assert abs(x[wb, 1].max() - m.waist_height) < 0.05  # the waistband at the waist
    assert x[:, 1].min() > m.knee_height  # the hem above the knees
    front = np.isin(g.panel, [g.panel_names.index("skirt_front"), g.panel_names.index("wb_front")])
    assert x[front, 2].mean() > 0.05 and x[~front, 2].mean() < -0.05
    cx, cz, a, b = BodySections(body).at(x[:, 1]).T
    r = np.hypot((x[:, 0] - cx) / (a + CLEARANCE), (x[:, 2] - cz) / (b + CLEARANCE))
    assert r.min() > 1.0 - 1e-6  # clear of the body


def test_a_garmentcode_pattern_keeps_its_own_placement_on_its_own_body():
    from engine.body import resolve_body
    from engine.garment.garment import build_garment, spec_placement
    from engine.garment.place import pattern_placement
    from engine.pattern.io import load_pattern

    body = resolve_body(str(SAMPLE_BODY))
    spec = load_pattern(SAMPLE_SKIRT)
    place, note = pattern_placement(spec, body)
    assert note is None
    a = build_garment(spec, h=0.03, place=place).positions
    b = build_garment(spec, h=0.03, place=spec_placement(spec, body.to_world)).positions
    np.testing.assert_array_equal(a, b)


def test_a_garmentcode_t_shirt_is_wrapped_round_another_body():
    """GarmentCode lays its T-shirt out round its mean body: flat front and back halves 45 cm
    apart, half sleeves flat beside the arms. Carried onto another body by heights alone it fell
    from the shoulders before the shoulder seams closed; now (pattern_placement) the torso
    halves are wrapped round the torso, front in front, and the half sleeves round the body's
    own arms, clear of the body."""
    from engine.body import resolve_body
    from engine.collide.bvh import MeshBVH, penetration_depth
    from engine.garment.garment import build_garment
    from engine.garment.place import CARRIED, arm_path, pattern_placement
    from engine.pattern.catalogue import arm_joints
    from engine.pattern.io import load_pattern

    body = resolve_body("default:female")
    spec = load_pattern(GC_SHIRT)
    place, note = pattern_placement(spec, body)
    assert note == CARRIED
    g = build_garment(spec, h=0.03, place=place)
    x = g.positions
    arms = arm_joints(body)
    for name in g.panel_names:
        sel = g.panel == g.panel_names.index(name)
        if "sleeve" in name:  # round its own arm: within 12 cm of the arm's axis, that side
            side = "left" if name.startswith("left") else "right"
            path = arm_path(arms[side])
            d = np.linalg.norm(x[sel][:, None, :] - path[None], axis=2).min(axis=1)
            assert d.max() < 0.12, (name, d.max())
            assert np.all(np.sign(x[sel, 0]) == (1 if side == "left" else -1))
        else:  # round the torso: front halves in front, back halves behind, within 20 cm of it
            front = "ftorso" in name
            assert (x[sel, 2].mean() > 0) == front, name
            assert np.abs(x[sel][:, [0, 2]]).max() < 0.3, name
    depth, _ = penetration_depth(MeshBVH(body.vertices, body.faces), x)
    assert (depth > 0).mean() < 0.01 and depth.max() < 0.02, (int((depth > 0).sum()), float(depth.max()))


@pytest.mark.parametrize("scan", [False, True])
def test_a_garmentcode_t_shirt_dresses_a_body_it_was_not_made_for(tmp_path, scan):
    """... and dresses it: default:female, and the same body as a scan (no rig: its arms come
    from the default skeleton fitted to it). Every seam closes, the quality bars hold, and the
    shirt stays on the shoulders (its top ends where it was placed)."""
    from engine.body import resolve_body
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon

    arg = "default:female"
    if scan:
        arg = str(write_arms_lowered_scan(tmp_path / "scan.obj", 0.0))
    body = resolve_body(arg)
    _, rep = run_tryon(body, load_pattern(GC_SHIRT), TryOnOptions(resolution_cm=2.0))  # (welds close <= half an edge: 1 cm)
    assert "landmarks and arms" in rep["placement"]
    _check_quality(rep)
    assert rep["seam_gap_mm"]["snapped"] == 0


@pytest.mark.parametrize("body_arg, says", [("default:female,weight=1.0,height=1.70", "carried"),
                                             (str(SAMPLE_BODY), None), ("default:female", "another body")])
def test_a_carried_pattern_whose_seams_stay_open_says_the_placement_may_be_why(body_arg, says):
    """Sewing that fails (here: a sewing budget far too short to close the sample skirt's seams)
    on a body the pattern was not made for (girths 3-7 cm from the mean body's) says that its
    placement was carried from GarmentCode's mean body, and what to do; on a body of other girths
    (the default female's bust is 12 cm smaller), first that the pattern is for another body, both
    bodies' girths named; on its own body neither."""
    from engine.body import resolve_body
    from engine.errors import SimulationError
    from engine.garment.place import CARRIED_HINT
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon

    body = resolve_body(body_arg)
    with pytest.raises(SimulationError) as e:
        run_tryon(body, load_pattern(SAMPLE_SKIRT), TryOnOptions(resolution_cm=5.0),
                  Tuning(sew=SewTuning(budget=0.01, far_retry_vmax=0.0)))
    msg = str(e.value)
    assert "did not close" in msg
    assert (CARRIED_HINT in msg) == (says == "carried")
    assert msg.startswith("this pattern is for another body") == (says == "another body")
    if says == "another body":
        assert re.search(r"mean body \(bust \d+, waist \d+, hips \d+ cm\), and this body's are bust \d+, "
                         r"waist \d+, hips \d+ cm", msg), msg


def test_a_layout_that_clears_a_like_body_keeps_its_own_placement():
    """GarmentCode makes patterns for any body (its sampler's --body): on a body whose landmarks and
    girths are like its mean body's (the SMPL body) a pattern's own layout is kept where it
    clears the body; moved 12 cm back, through the torso, it is carried by the landmarks instead;
    on a body of other girths (default:female) it is carried."""
    from engine.body import resolve_body
    from engine.garment.place import CARRIED, OWN_CLEARS, pattern_placement
    from engine.pattern.io import load_pattern

    from engine.collide.bvh import MeshBVH

    def inside(body):
        return lambda p: MeshBVH(body.vertices, body.faces).signed_distance(p, max_distance=0.1) < 0.0

    smpl, female = resolve_body(str(SMPL_BODY)), resolve_body("default:female")
    spec = load_pattern(GC_SHIRT)
    assert pattern_placement(spec, smpl, inside(smpl))[1] == OWN_CLEARS
    assert pattern_placement(spec, female, inside(female))[1] == CARRIED
    for p in spec.pattern.panels.values():
        p.translation = [p.translation[0], p.translation[1], p.translation[2] - 12.0]  # cm
    assert pattern_placement(spec, smpl, inside(smpl))[1] == CARRIED
    # a hood's halves laid through the head (as GarmentCode lays them on any body) are not
    # counted: f_smpl 127_010's layout clears the rest of the body
    hooded = load_pattern(ROOT / "tests" / "garmentcode" / "designs" / "f_smpl_average_A40_127_010_specification.json")
    assert pattern_placement(hooded, smpl, inside(smpl))[1] == OWN_CLEARS


def test_a_garment_that_falls_off_the_body_is_refused():
    """A pattern placed beside the body (the sample skirt moved 1 m to the side) falls past the
    feet: a clear error, not a result with a warning that it slid 27 m down."""
    from engine.body import resolve_body
    from engine.errors import SimulationError
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon

    spec = load_pattern(SAMPLE_SKIRT)
    for p in spec.pattern.panels.values():
        p.translation = [p.translation[0] + 100.0, p.translation[1], p.translation[2]]  # cm
    with pytest.raises(SimulationError, match=r"fell off the body .* far too large for this body, or its pattern "
                                              r"places it away from the body"):
        run_tryon(resolve_body("default:female"), spec, TryOnOptions(resolution_cm=3.0))


def test_sewing_gives_up_when_the_seams_stop_closing():
    """A skirt far too small for the body (XS on a heavy man, default:male at weight 1, coarse
    cloth): its seams stop closing 3-6 cm apart, wider than snap_gap; sewing gives up once they
    stalled for snap_stall (measured: at 1.1 s of simulated time; 2.4 s when wide stalls too waited
    for snap_after), not at the end of the 4 s budget, and says how far they stayed open and that
    the garment may be too small. (On
    default:male itself its seams stalled with 4 contact rounds a step; with 2 they close,
    stretched 41 %, and the drape refuses it: test_a_drape_that_stays_stretched_is_refused_early.)
    Sewn as by default -- the pull taken again after the collision response (StepConfig.
    sew_after_contact) -- its seams close on the body, stretched, and the drape refuses it as too
    small; the stall is tested without that."""
    from engine.body.default import default_body
    from engine.errors import SimulationError
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon

    body = default_body("male", weight=1.0)
    spec, place, name = resolve_garment("skirt", body, "XS")
    side = r"front\[\d\]-back\[\d\] \(\d+.\d cm\)"  # the seams still open, the widest first
    t = Tuning()
    t = replace(t, drape=replace(t.drape, step=replace(t.drape.step, sew_after_contact=False)))
    with pytest.raises(SimulationError, match=r"^sewing stopped closing after [123].\d s of simulated time \(the widest "
                                              r"gap stayed \d+.\d-\d+.\d cm for 0.5 s\); open seams: "
                                              + side + "(, " + side + r")*\. The garment may be too small") as e:
        run_tryon(body, spec, TryOnOptions(resolution_cm=3.0), t, place=place, source=name)
    assert e.value.too_small and e.value.positions.shape[1] == 3
    with pytest.raises(SimulationError, match=r"^the garment is too small for this body: for [\d.]+ s of draping"):
        run_tryon(body, spec, TryOnOptions(resolution_cm=3.0), place=place, source=name)


def test_a_drape_that_stays_stretched_is_refused_early():
    """The drape refuses a garment that stays stretched past the fabric's limit + too_tight at
    every strain check for refuse_after (after drape_min), then, not after the whole budget.
    (The sample scan's L dress meets it for real: refused after 2 s of draping, at least 20 %,
    in test_auto_size_on_the_sample_scan, slow.) Here it runs fast, with the bar lowered to 1 %
    (too_tight -4 %) on the coarse M skirt, which drapes at 5-6 %."""
    from engine.body.default import default_body
    from engine.errors import SimulationError
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon

    body = default_body("female")
    spec, place, name = resolve_garment("skirt", body, "M")
    opts = Tuning(drape=DrapeTuning(too_tight=-0.04, refuse_after=0.2, min_time=0.1))
    with pytest.raises(SimulationError, match=r"too small for this body: for 0.2 s of draping it stayed "
                                              r"stretched at least \d+ % where cotton allows 5 %") as e:
        run_tryon(body, spec, TryOnOptions(resolution_cm=3.0), opts, place=place, source=name)
    assert e.value.too_small and e.value.positions.shape[1] == 3


@pytest.mark.integration
def test_a_drape_another_fabric_follows_gives_up_as_soon_as_it_stays_tight():
    """DrapeTuning.give_up (set by run_tryon when a knit follows a pattern's default cotton): the
    drape stops once it stayed past the threshold + knit_give_up for knit_give_up_after -- marked
    gave_up, so the knit is tried at once and the full drape in cotton only if the knit fails too.
    Off, the same drape runs on. Here with the bar lowered to 1 % on the coarse M skirt (5-6 %)."""
    from engine.body.default import default_body
    from engine.errors import SimulationError
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon

    body = default_body("female")
    spec, place, name = resolve_garment("skirt", body, "M")
    low = dict(knit_give_up=-0.04, knit_give_up_after=0.1, min_time=0.1)
    with pytest.raises(SimulationError, match=r"too small for this body: for 0.10 s of draping it stayed "
                                              r"stretched at least \d+ % where cotton allows 5 %") as e:
        run_tryon(body, spec, TryOnOptions(resolution_cm=3.0), Tuning(drape=DrapeTuning(give_up=True, **low)),
                  place=place, source=name)
    assert e.value.gave_up and e.value.too_small
    _, rep = run_tryon(body, spec, TryOnOptions(resolution_cm=3.0), Tuning(drape=DrapeTuning(**low)),
                       place=place, source=name)
    assert rep["settled"]


@pytest.mark.slow
def test_a_dress_on_a_scan_with_the_arms_closer_is_sewn_with_friction(tmp_path):
    """default:female as a scan with its arms lowered 20 degrees (5.4 cm from the torso 10 cm
    below the armpits). Sewn without friction, the dress's straps slid off the shoulders and it
    fell to the hips (a shoulder seam 15 cm open, in every size); friction while sewing
    (engine.scene.tryon.ARMS_CLOSE_SEW_FRICTION) holds them: the dress is on the shoulders
    (its top within 6 cm of where it was placed) to the issue's quality. Its last shoulder pairs
    close slowly: on one machine they stopped 1.3 cm apart and were welded there
    (seam_gap_mm.snapped), on another (same code, same packages) they closed to 7.5 mm and were
    welded as usual -- either way within 2 cm (the default bodies' welds close within 1 cm)."""
    from engine.body import resolve_body
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import ARMS_CLOSE_SEW_FRICTION, run_tryon

    body = resolve_body(str(write_arms_lowered_scan(tmp_path / "arms20.obj", 20.0)))
    spec, place, name = resolve_garment("dress", body, "L")
    _, rep = run_tryon(body, spec, place=place, source=name)
    assert rep["sew_friction"]["scale"] == ARMS_CLOSE_SEW_FRICTION
    assert "the arms hang 5.4 cm from the torso" in rep["sew_friction"]["why"]
    assert rep["penetration_mm"]["max"] <= 3.0 and rep["penetration_mm"]["p99"] <= 1.0, rep["penetration_mm"]
    assert rep["strain"]["max"] <= rep["strain"]["threshold"] + 0.01, rep["strain"]
    assert rep["settled"] and rep["cloth_vertices"] < rep["cloth_vertices_unsewn"]
    # the last shoulder pairs close, or stall and are welded where they are (SewTuning.snap_gap)
    assert rep["seam_gap_mm"]["max"] <= 20.0, rep["seam_gap_mm"]
    assert rep["shift_mm"]["top"] > -60.0, rep["shift_mm"]  # on the shoulders (fallen: -400)


def _drape_cli(args):
    from typer.testing import CliRunner

    from engine.cli import app

    return CliRunner().invoke(app, ["drape"] + args)


@pytest.mark.slow
@pytest.mark.parametrize("garment", ["shirt", "dress"])
def test_a_top_on_a_scan_with_the_arms_close_is_dressed_with_the_arms_turned_out(tmp_path, garment):
    """default:female saved as a scan with its arms lowered 30 degrees (2.4 cm from the torso
    10 cm below the armpits): sewn as loaded, the seams beside the arms stayed open (the shirt's
    9.4 cm; the dress's 2.3 cm even with friction while sewing). Dressing it with the arms raised
    and lowering them onto the cloth left tops 24-36 % stretched between arm and torso; `tryon
    drape` turns the arms out to an A-pose first (engine.scene.arms.clear_arms, saying so) and
    dresses that body: on the shoulders, outside the body, within the strain bar."""
    import json

    scan = write_arms_lowered_scan(tmp_path / "arms30.obj", 30.0)
    out = tmp_path / "out"
    r = _drape_cli(["--body", str(scan), "--garment", garment, "--size", "M", "--out", str(out)])
    assert r.exit_code == 0, r.stderr
    assert "the arms were turned" in r.stderr and "out from the body for dressing and walking" in r.stderr
    rep = json.loads((out / "report.json").read_text())
    assert "arms_lowered" not in rep
    assert rep["penetration_mm"]["max"] <= 2.0 and rep["penetration_mm"]["p99"] <= 0.5, rep["penetration_mm"]
    assert rep["shift_mm"]["top"] > -60.0, rep["shift_mm"]  # on the shoulders (fallen: -400)
    assert rep["strain"]["max"] <= rep["strain"]["threshold"] + 0.01, rep["strain"]
    assert rep["settled"] and not rep["tight"]
    assert (out / "front.png").exists() and (out / "scene.glb").exists()


@pytest.mark.slow
def test_a_shirt_sewn_shut_between_close_arms_and_torso_is_dressed_again_with_the_arms_raised(tmp_path):
    """The 30-degree scan's shirt sewn at 1000 x damping (SewTuning.damping): its underarm
    seams close as loaded -- at 20 x they stall, and that raises the arms -- and the drape is
    refused 17 % stretched at the armhole. The refusal lies beside the close arms, so the shirt is
    dressed again with them raised and lowered (measured: 5.9 %, penetration 1.9 mm)."""
    from engine.body import resolve_body
    from engine.scene.garments import dress_in_size
    from engine.scene.tryon import run_tryon

    body = resolve_body(str(write_arms_lowered_scan(tmp_path / "arms30.obj", 30.0)))

    def dress(spec, place, name, **kw):
        return run_tryon(body, spec, TryOnOptions(), Tuning(sew=SewTuning(damping=1000.0)), place=place, source=name,
                         **kw)

    _, rep = dress_in_size("shirt", body, "M", dress)
    assert "dressed with the arms raised 30 degrees" in rep["arms_lowered"]["why"]
    assert rep["penetration_mm"]["max"] <= 3.0 and rep["penetration_mm"]["p99"] <= 1.0, rep["penetration_mm"]
    assert rep["strain"]["max"] <= rep["strain"]["threshold"] + 0.02, rep["strain"]
    assert rep["shift_mm"]["top"] > -60.0, rep["shift_mm"]


@pytest.mark.slow
@pytest.mark.parametrize("spec,size", [(str(SAMPLE_BODY), "L"), ("default:female,gender=0.5,weight=1", "M")])
def test_sleeveless_shirt_fits_round_thick_arms(spec, size):
    """The size --size auto picks from the girths now fits bodies with thick arms: their
    armholes were 13 % (the sample scan, L) and 32 % (M) stretched and auto went on to XL, two
    or three drapes (84 s for the avatar) instead of one (ARMHOLE_PER_ARM_ROOT)."""
    from engine.body import resolve_body
    from engine.pattern.catalogue import recommend_size
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon

    body = resolve_body(spec)
    assert recommend_size("sleeveless-shirt", body) == size
    s, place, name = resolve_garment("sleeveless-shirt", body, size)
    _, rep = run_tryon(body, s, place=place, source=name)
    _check_quality(rep)
    assert not rep["tight"]


@pytest.mark.slow
def test_sample_skirt_quality(tmp_path):
    from engine.body import resolve_body
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon

    body = resolve_body(str(SAMPLE_BODY))
    _, rep = run_tryon(body, load_pattern(SAMPLE_SKIRT), source="sample skirt")
    _check_quality(rep)
    assert rep["sharp_folds"]["count"] <= SKIRT_SHARP_FOLDS, rep["sharp_folds"]


SKIRT_SHARP_FOLDS = 40  # a hanging flared skirt: 0-29 edges folded back; crumpled, 74-88


@pytest.mark.slow
@pytest.mark.parametrize("seed", [1, 2])
def test_the_sample_skirt_hangs_however_its_outline_rounds(seed):
    """The sample skirt with its outline moved by 1e-9 cm (rounding; the mesher's boundary
    triangles change): sewn at 20 x damping, both these runs came out with the hem crumpled at
    the side seams and the waistband askew (74 and 88 edges folded back, sharp_folds), though
    welded, settled and within the strain and penetration bars. Now they hang like the
    unperturbed one."""
    from engine.body import resolve_body
    from engine.pattern.io import parse_pattern
    from engine.scene.tryon import run_tryon

    d = json.loads(SAMPLE_SKIRT.read_text())
    rng = np.random.default_rng(seed)
    for p in d["pattern"]["panels"].values():
        p["vertices"] = [[x + rng.normal() * 1e-9, y + rng.normal() * 1e-9] for x, y in p["vertices"]]
    _, rep = run_tryon(resolve_body(str(SAMPLE_BODY)), parse_pattern(d), source="sample skirt")
    _check_quality(rep)
    assert rep["sharp_folds"]["count"] <= SKIRT_SHARP_FOLDS, rep["sharp_folds"]


@pytest.mark.slow
def test_sleeved_shirt_on_the_sample_scan():
    """The scan has no skeleton; its sleeves are placed along a fitted one (make_garment) and the
    shirt drapes to the same quality as on the default bodies (measured: 14.6k iterations,
    strain 5.9 %, penetration 0.4 mm)."""
    from engine.body import resolve_body
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon

    b = resolve_body(str(SAMPLE_BODY))
    spec, place, name = resolve_garment("shirt", b, "auto")
    _, rep = run_tryon(b, spec, place=place, source=name)
    _check_quality(rep)


@pytest.mark.slow
@pytest.mark.parametrize("garment,tried,size", [("dress", ["L"], "XL"), ("sleeveless-shirt", [], "L")])
def test_auto_size_on_the_sample_scan(garment, tried, size):
    """--size auto on the sample scan: the girths pick L. The L dress is too small at the
    shoulders and underarms (measured: 23 % strain); the next size, XL, drapes to the quality
    bar. The L sleeveless shirt fits (it was 13 % stretched round armholes that did not follow
    the scan's thick arms). The CLI and the service dress through dress_in_size."""
    from engine.body import resolve_body
    from engine.scene.garments import dress_in_size
    from engine.scene.tryon import run_tryon

    b = resolve_body(str(SAMPLE_BODY))
    _, rep = dress_in_size(garment, b, "auto", lambda spec, place, name: run_tryon(b, spec, place=place,
                                                                                 source=name))
    _check_quality(rep)
    assert [t["size"] for t in rep["sizes_tried"]] == tried, rep["sizes_tried"]
    how = "chosen by draping: L too small" if tried else "chosen from the body's girths"
    assert rep["garment"] == f"{garment} ({size}, women's chart, {how})"


@pytest.mark.slow
def test_a_short_heavy_avatars_dress_closes_its_shoulder_seams():
    """A short heavy avatar's dress: one pair of a shoulder seam stayed 1.1-1.9 cm open from
    0.3 s on (the strap pulled tight over the shoulder; the strain limit takes back the seam's
    pull), and the whole try-on failed after the 4 s sewing budget, in every size; the stall
    rule (SewTuning.snap_gap) then welded such pairs where they were, M ended tight (12 %)
    and --size auto dressed L. With armholes that follow its thick arms (ARMHOLE_PER_ARM_ROOT,
    2.8 cm deeper here) every pair closes by itself in the size its girths pick. (The stall
    rule is exercised by test_a_dress_on_a_scan_with_the_arms_closer_is_sewn_with_friction.)"""
    from engine.body import resolve_body
    from engine.scene.garments import dress_in_size
    from engine.scene.tryon import run_tryon

    b = resolve_body("default:female,weight=1.0,height=1.45")
    _, rep = dress_in_size("dress", b, "auto", lambda spec, place, name: run_tryon(b, spec, place=place,
                                                                                 source=name))
    assert rep["seam_gap_mm"]["snapped"] == 0 and rep["sizes_tried"] == [], rep
    _check_quality(rep)


@pytest.mark.slow
@pytest.mark.parametrize("body", ["default:female", "default:male"])
@pytest.mark.parametrize("garment", ["skirt", "trousers", "sleeveless-shirt", "dress", "shirt"])
def test_catalogue_quality(body, garment):
    from engine.body import resolve_body
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon

    b = resolve_body(body)
    spec, place, name = resolve_garment(garment, b, "M")
    _, rep = run_tryon(b, spec, place=place, source=name)
    _check_quality(rep)


@pytest.mark.parametrize("collision", ["image", "object"])
def test_coarse_skirt_quality_both_collisions(collision):
    """The object-space baseline passes the same checks as the image-space path: a coarse catalogue
    skirt on the default woman, sewn and draped: seams welded, no penetration past the issue's
    limits (measured exactly), strain within the threshold + 1 %, the skirt at the waist."""
    from engine.body.default import default_body
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon

    body = default_body("female")
    spec, place, name = resolve_garment("skirt", body, "M")
    res, rep = run_tryon(body, spec, TryOnOptions(resolution_cm=3.0, collision=collision), place=place, source=name)
    assert rep["collision"] == collision
    assert rep["seam_gap_mm"]["max"] <= 30.0 and rep["cloth_vertices"] < rep["cloth_vertices_unsewn"]
    assert rep["penetration_mm"]["max"] <= 3.0 and rep["penetration_mm"]["p99"] <= 1.0, rep["penetration_mm"]
    assert rep["strain"]["max"] <= rep["strain"]["threshold"] + 0.01, rep["strain"]
    assert 0.9 < res.positions[:, 1].max() < 1.15 and res.positions[:, 1].min() > 0.25  # hem ~0.30 m


def test_a_pattern_too_small_is_told_to_grade_it_not_to_pick_a_size():
    """A catalogue garment too small for the body is told to try a larger size; a pattern file
    has one size, so its errors say to grade it larger (a 1.9 m, weight 1.0 man in the sample
    skirt: its seams stop closing 5-8 cm apart)."""
    from engine.body import resolve_body
    from engine.errors import SimulationError
    from engine.scene.garments import add_size_hint

    body = resolve_body("default:female")
    for text in ("sewing stopped closing; open seams: x (7.3 cm). The garment may be too small for this body "
                 "(try a larger size) or the panels start too far apart",
                 "the garment is too small for this body: after draping it is stretched 16 % where cotton "
                 "allows 5 %; try a larger size"):
        err = SimulationError(text)
        err.too_small = True
        add_size_hint(err, str(SAMPLE_SKIRT), body, None)
        assert "grade it larger" in str(err) and "larger size" not in str(err), str(err)


def test_collisions_are_checked_as_often_as_the_cloth_moves_far_enough():
    """Sewing checks the body every floor(sew_check_travel / (pull cap x dt)) steps (at most 3),
    draping every floor(drape_check_time / dt) (at most 2): at the default 1.5 cm cloth 3 and 2,
    at 3 cm (twice the eq. 4 step) every step; Tuning.collide_every sets both; the report
    says what was used, and a drape at 1.5 cm checked that way meets the quality bars. A drape
    stretched past threshold + tight_every_step checks every step from then on."""
    from engine.body.default import default_body
    from engine.errors import InputError
    from engine.scene.drape import _drape_every, _sew_every
    from engine.scene.garments import resolve_garment
    from engine.scene.tryon import run_tryon

    o = Tuning()
    assert (_sew_every(o, 0.147e-3, o.sew.vmax), _drape_every(o, 0.147e-3)) == (3, 2)
    assert (_sew_every(o, 0.3e-3, o.sew.vmax), _drape_every(o, 0.3e-3)) == (1, 1)
    assert _sew_every(o, 0.147e-3, 1.5) == 3  # a gentler pull: no more than max_check_every apart
    every = Tuning(collide_every=1)
    assert (_sew_every(every, 0.147e-3, 3.0), _drape_every(every, 0.147e-3)) == (1, 1)
    for bad, what in ((Tuning(collide_every=0), "collide_every 0"),
                      (Tuning(sew=SewTuning(check_travel=-1.0)), "check_travel"),
                      (Tuning(drape=DrapeTuning(check_time=0.0)), "check_time")):
        with pytest.raises(InputError, match=what):
            bad.validate()

    body = default_body("female")
    spec, place, name = resolve_garment("skirt", body, "M")
    _, rep = run_tryon(body, spec, place=place, source=name)
    assert rep["collision_every_steps"] == {"sewing": 3, "draping": 2}, rep["collision_every_steps"]
    _check_quality(rep)
    _, coarse = run_tryon(body, spec, TryOnOptions(resolution_cm=3.0), place=place, source=name)
    assert coarse["collision_every_steps"] == {"sewing": 1, "draping": 1}, coarse["collision_every_steps"]
    # stretched past the bar (here lowered to the threshold itself: the skirt drapes at 5-6 %),
    # draping goes back to a check at every step at the first strain check after tight_grace
    TIGHT_GRACE = DrapeTuning().tight_grace
    _, tight = run_tryon(body, spec, TryOnOptions(), Tuning(drape=DrapeTuning(tight_every_step=0.0)), place=place,
                         source=name)
    ce = tight["collision_every_steps"]
    assert ce["draping"] == 2 and TIGHT_GRACE < ce["every_step_from_s"] <= TIGHT_GRACE + 0.0105, ce


def test_a_seam_pair_straddling_a_leg_meets_on_the_side_its_edges_lie():
    """An inseam placed across the middle of a leg: each pair's straight path runs through the leg
    (front end in front of it, back end behind). It is to meet just outside the leg on the side its
    edges lie on as placed (-x here, the inner side), not through the leg nor round the outer side."""
    from types import SimpleNamespace

    import trimesh

    from engine.cloth.config import Sewing
    from engine.collide.bvh import MeshBVH
    from engine.scene.drape import _meet_beside

    leg = trimesh.creation.cylinder(radius=0.06, height=0.6, sections=48)
    leg.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))  # axis along y
    body = MeshBVH(np.asarray(leg.vertices), np.asarray(leg.faces))
    ys = np.linspace(-0.2, 0.2, 5)
    front = np.stack([np.full(5, 0.01), ys, np.full(5, 0.12)], axis=1)  # just inner of the leg's axis
    back = front * [1, 1, -1]
    x = np.concatenate([front, back])
    pairs = np.stack([np.arange(5), np.arange(5, 10)], axis=1)
    sewing = Sewing(pairs, np.zeros(5, np.bool_), 0.02, 3.0, meet=np.zeros((5, 3)), meet_on=np.zeros(5, np.bool_))
    # the panels' middles lie to +x of their inseams (the panels reach round the outer side)
    job = SimpleNamespace(body=body, meet_side=np.tile([-0.15, 0.0, 0.0], (5, 1)), tuning=Tuning(), beside_arm=None)
    gaps = np.linalg.norm(back - front, axis=1)
    _meet_beside(job, x, sewing, gaps, weld_gap=0.0075)
    assert sewing.meet_on.all()
    margin = Tuning().cloth.tolerance + Tuning().sew.meet_margin
    np.testing.assert_allclose(sewing.meet[:, 0], -0.06 - margin, atol=0.004)  # just outside, inner side
    np.testing.assert_allclose(sewing.meet[:, 1], ys, atol=1e-9)
    assert np.all(body.signed_distance(sewing.meet) > 0.0)
    # a pair whose midpoint is outside the body (its path clear of it) is pulled to its partner as before
    x2 = x.copy()
    x2[:, 0] = -0.3
    _meet_beside(job, x2, sewing, gaps, weld_gap=0.0075)
    assert not sewing.meet_on.any()


def test_a_pair_whose_way_out_crosses_the_body_meets_at_the_nearest_surface():
    """A sleeve's underarm pair at the armpit end: its midpoint lies just inside the torso's side
    and its way out (square to the underarm edge) points across the torso. Stepping that way would
    pull both ends to the far side, farther than they are apart; the pair meets at the surface
    nearest its midpoint instead (the armpit side)."""
    from types import SimpleNamespace

    import trimesh

    from engine.cloth.config import Sewing
    from engine.collide.bvh import MeshBVH
    from engine.scene.drape import _meet_beside

    torso = trimesh.creation.cylinder(radius=0.15, height=0.6, sections=64)
    torso.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))  # axis along y
    body = MeshBVH(np.asarray(torso.vertices), np.asarray(torso.faces))
    x = np.array([[-0.13, 0.0, 0.12], [-0.13, 0.0, -0.12]])  # 24 cm apart, the midpoint 2 cm inside
    sewing = Sewing(np.array([[0, 1]]), np.zeros(1, np.bool_), 0.02, 3.0, meet=np.zeros((1, 3)),
                    meet_on=np.zeros(1, np.bool_))
    job = SimpleNamespace(body=body, meet_side=np.array([[1.0, 0.0, 0.0]]), tuning=Tuning(), beside_arm=None)
    _meet_beside(job, x, sewing, np.array([0.24]), weld_gap=0.0075)
    assert sewing.meet_on[0]
    margin = Tuning().cloth.tolerance + Tuning().sew.meet_margin
    np.testing.assert_allclose(sewing.meet[0], [-0.15 - margin, 0.0, 0.0], atol=0.004)  # this side, not +0.15


def test_a_trunk_panels_pair_caught_round_a_hanging_arm_meets_on_the_trunks_side():
    """A side seam laid out beyond an A-posed arm (a wide sleeveless dress, mean_female 89_016):
    its pair's path runs inside the arm. Its own way out (square to its edges, outwards) goes round
    the arm's outer side and stalled there, the arm through the seam; a pair of panels over the
    trunk (_Dressing.beside_arm) meets on the side of the arm towards the body's axis -- the arm
    leaves by the armhole. A sleeve's pair (not beside_arm) still goes its own way."""
    from types import SimpleNamespace

    import trimesh

    from engine.cloth.config import Sewing
    from engine.collide.bvh import MeshBVH
    from engine.scene.drape import _meet_beside

    arm = trimesh.creation.cylinder(radius=0.04, height=0.5, sections=48)
    arm.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))  # along y
    arm.apply_translation([0.35, 1.0, 0.0])
    body = MeshBVH(np.asarray(arm.vertices), np.asarray(arm.faces))
    x = np.array([[0.35, 1.0, 0.06], [0.35, 1.0, -0.06]])  # front and back edge, the arm between
    margin = Tuning().cloth.tolerance + Tuning().sew.meet_margin
    for trunk, side in ((True, -1.0), (False, 1.0)):
        sewing = Sewing(np.array([[0, 1]]), np.zeros(1, np.bool_), 0.02, 3.0, meet=np.zeros((1, 3)),
                        meet_on=np.zeros(1, np.bool_))
        job = SimpleNamespace(body=body, meet_side=np.array([[1.0, 0.0, 0.0]]), tuning=Tuning(),
                              beside_arm=np.array([trunk]), arms=(np.ones(len(arm.vertices), bool),) * 2,
                              body_axis=(0.0, 0.0))
        _meet_beside(job, x, sewing, np.array([0.12]), weld_gap=0.0075)
        assert sewing.meet_on[0]
        np.testing.assert_allclose(sewing.meet[0], [0.35 + side * (0.04 + margin), 1.0, 0.0], atol=0.004)


def test_a_pairs_way_out_is_square_to_its_edges():
    """The way out of a sleeve's underarm pairs is straight down from the underarm edge at every
    pair, the pair at the armpit end too (from the panel's middle it would point along the sleeve,
    into the torso)."""
    from types import SimpleNamespace

    from engine.scene.drape import _Dressing

    xs = np.linspace(0.0, 0.4, 9)
    grid = np.array([[u, v] for v in np.linspace(0.0, 0.2, 5) for u in xs])  # a 40 x 20 cm panel
    front = np.column_stack([grid, np.full(len(grid), 0.1)])
    back = front * [1, 1, -1]
    under = np.arange(len(xs))  # its bottom row (y = 0)
    garment = SimpleNamespace(positions=np.concatenate([front, back]), panel=np.repeat([0, 1], len(grid)),
                              seams=np.column_stack([under, len(grid) + under]), seam_id=np.zeros(len(xs), int))
    job = _Dressing(garment, None, None, Tuning(), None, None)
    d = job.meet_side / np.linalg.norm(job.meet_side, axis=1)[:, None]
    np.testing.assert_allclose(d, np.tile([0.0, -1.0, 0.0], (len(xs), 1)), atol=1e-9)


def test_a_stall_beside_a_panel_stretched_far_past_the_fabric_names_that_panel():
    """Sewing that stalls with a cuff's cloth stretched round the arm far past what the fabric
    allows (a cuff cut smaller round than the limb it closes round) names the cuff as too small;
    a panel only a little stretched, or stretched in a few springs, is not named."""
    from types import SimpleNamespace

    from engine.cloth.model import FLEXION, STRUCTURAL
    from engine.scene.drape import _too_small_panels

    n = 40  # two strips of 20 vertices (panels 0 and 1), each a chain of 19 springs
    rest = np.full(38, 0.01)
    springs = np.array([[i, i + 1] for i in range(19)] + [[i, i + 1] for i in range(20, 39)], dtype=np.int32)
    x = np.zeros((n, 3))
    x[:20, 0] = np.arange(20) * 0.01 * 1.40  # panel 0: every spring 40 % long
    x[20:, 0] = np.arange(20) * 0.01 * 1.03  # panel 1: 3 %
    x[30:, 0] += 0.01  # ... one spring 100 % long
    garment = SimpleNamespace(panel=np.repeat([0, 1], 20), seams=np.array([[0, 20]]), panel_names=["cuff", "sleeve"])
    job = SimpleNamespace(garment=garment, request=TryOnOptions(fabric="cotton"), tuning=Tuning())
    rest = np.concatenate([rest, [0.02]])  # (straight chains: no shear, measured from their rest)
    model = SimpleNamespace(springs=np.concatenate([springs, [[0, 2]]]), rest=rest, limit_rest=rest,
                            kind=np.array([STRUCTURAL] * 38 + [FLEXION]))
    said, strain, names = _too_small_panels(job, model, SimpleNamespace(x=x), np.zeros(1, dtype=bool))
    assert "'cuff' 40 %" in said and "sleeve" not in said and names == ["cuff"], (said, names)
    assert abs(strain - 0.40) < 1e-6, strain
    x[:20, 0] = np.arange(20) * 0.01 * 1.05
    assert _too_small_panels(job, model, SimpleNamespace(x=x), np.zeros(1, dtype=bool)) is None


def test_a_panel_that_rose_into_place_hanging_full_length_is_not_bunched_up():
    """GarmentCode stacks a jumpsuit's trousers below its bodice in the flat layout: they rise
    15-50 cm into place, hanging their full length. A risen hem is called bunched up only where a
    panel placed at least PANEL_TALL tall also hangs shorter than BUNCHED of that height."""
    from types import SimpleNamespace

    from engine.scene.tryon import BUNCHED, hang_shift, hang_warnings, shortest_panel

    y = np.linspace(0.0, 1.0, 11)
    placed = np.column_stack([np.zeros(22), np.concatenate([y - 0.5, y + 0.5]), np.zeros(22)])  # legs, bodice
    garment = SimpleNamespace(positions=placed, uv=placed[:, :2].copy(), panel=np.repeat([0, 1], 11),
                              panel_names=["pant", "bodice"], seams=np.zeros((0, 2), int), seam_id=np.zeros(0, int))
    risen = placed.copy()
    risen[:11, 1] += 0.3  # the trousers rose 30 cm into place, full length
    res = SimpleNamespace(positions=risen, vertex_map=np.arange(22))
    shrunk = shortest_panel(garment, res)
    assert shrunk[0] == pytest.approx(1.0)
    assert hang_warnings(hang_shift(placed, risen), None, shrunk) == []
    heaped = risen.copy()
    heaped[:11, 1] = 0.5 + 0.3 * (heaped[:11, 1] - 0.5) / 1.0  # ... and crumpled to 30 cm tall
    shrunk = shortest_panel(garment, SimpleNamespace(positions=heaped, vertex_map=np.arange(22)))
    assert shrunk[1] == "pant" and shrunk[0] < BUNCHED
    said = hang_warnings(hang_shift(placed, heaped), None, shrunk)
    assert len(said) == 1 and "bunched up" in said[0] and "panel 'pant' hangs 30 cm tall, 90 cm long" in said[0]  # (its top 3 cm: two of the 11 points)
    # without a map from the garment's vertices the risen hem alone says so (as before)
    assert shortest_panel(garment, SimpleNamespace(positions=risen, vertex_map=None)) is None
    assert "bunched up" in hang_warnings(hang_shift(placed, risen))[0]


def test_a_band_between_a_bodice_and_shorts_is_not_judged_by_its_own_height():
    """mean_female 83_014: a curved waistband 18 cm long sewn under a bodice and over shorts
    (its lower edge gathered into them) stands out in a ruffle 10 cm tall; the shorts, laid out
    below, rose into place. The band joins the parts above and below (tryon._joins): its height is
    theirs to set, so it is not called bunched up; the shorts hanging full length are judged. A
    shorts panel heaped is still found."""
    from types import SimpleNamespace

    from engine.scene.tryon import BUNCHED, shortest_panel

    y = np.linspace(0.0, 1.0, 11)

    def panel(lo, tall):  # 11 rows of 3 points 5 cm apart, bottom row first
        return np.array([[x, lo + tall * t, 0.0] for t in y for x in (0.0, 0.05, 0.1)])

    placed = np.concatenate([panel(1.2, 0.4), panel(0.82, 0.18), panel(0.2, 0.4)])  # bodice, band, shorts
    bottom, top = np.arange(3), np.arange(30, 33)
    seams = np.concatenate([np.column_stack([bottom, 33 + top]), np.column_stack([33 + bottom, 66 + top])])
    garment = SimpleNamespace(positions=placed, uv=placed[:, :2].copy(), panel=np.repeat([0, 1, 2], 33),
                              panel_names=["bodice", "band", "shorts"], seams=seams, seam_id=np.repeat([0, 1], 3))
    worn = np.concatenate([panel(1.1, 0.4), panel(1.0, 0.1), panel(0.6, 0.4)])  # the band 10 cm tall
    ratio, name, _, _ = shortest_panel(garment, SimpleNamespace(positions=worn, vertex_map=np.arange(99)))
    assert name != "band" and ratio >= BUNCHED, (ratio, name)
    heaped = worn.copy()
    heaped[66:] = panel(0.9, 0.1)  # the shorts heaped 10 cm tall under the band
    ratio, name, _, _ = shortest_panel(garment, SimpleNamespace(positions=heaped, vertex_map=np.arange(99)))
    assert name == "shorts" and ratio < BUNCHED, (ratio, name)


def test_a_hood_worn_up_over_the_head_is_not_judged_for_hanging():
    """A hood rests on the head, 35 cm tall for the 61 cm it could hang from its crown seam
    (f_smpl 269_022, its dress risen 20 cm to the waist: called bunched): panels whose drape
    reaches OVER_HEAD above the shoulders are left out of shortest_panel's judging; a collar
    standing 8 cm above them, and everything where the shoulders are not measured, is judged."""
    from types import SimpleNamespace

    from engine.scene.tryon import OVER_HEAD, over_the_head

    y = np.concatenate([np.linspace(0.9, 1.40, 11), np.linspace(1.32, 1.67, 11), np.linspace(1.40, 1.48, 11)])
    x = np.column_stack([np.zeros(33), y, np.zeros(33)])
    garment = SimpleNamespace(positions=x, panel=np.repeat([0, 1, 2], 11), panel_names=["bodice", "hood", "collar"])
    res = SimpleNamespace(positions=x, vertex_map=np.arange(33))
    assert 1.40 + OVER_HEAD < 1.67 and 1.48 < 1.40 + OVER_HEAD
    assert over_the_head(garment, res, 1.40) == {"hood"}
    assert over_the_head(garment, res, float("nan")) == set()
    assert over_the_head(garment, SimpleNamespace(positions=x, vertex_map=None), 1.40) == set()


def test_a_ring_tier_laid_out_tall_hangs_its_width_and_is_not_bunched_up():
    """A ruffle tier is a ring sector: GarmentCode lays it out flat and upright, 95 cm tall for a
    17 cm wide ring, and it hangs from its seam to the tier above 17 cm (its width), that seam
    dipping at the sides -- not bunched up. The same cloth heaped to 5 cm is."""
    from types import SimpleNamespace

    from engine.scene.tryon import BUNCHED, shortest_panel

    r, a = np.meshgrid(np.linspace(0.78, 0.95, 8), np.linspace(0.0, np.pi, 60))
    uv = np.column_stack([(r * np.cos(a)).ravel(), (r * np.sin(a)).ravel()])  # a half ring, 1.9 x 0.95 m
    inner = np.flatnonzero(np.isclose(r.ravel(), 0.78))
    n, m = len(uv), len(inner)
    above = np.column_stack([uv[inner, 0], np.linspace(0.0, 0.01, m)])  # the tier above's hem, 1 cm tall
    placed = np.concatenate([np.column_stack([uv, np.zeros(n)]), np.column_stack([above, np.zeros(m)])])
    garment = SimpleNamespace(positions=placed, uv=np.concatenate([uv, above]),
                              panel=np.repeat([0, 1], [n, m]), panel_names=["tier", "above"],
                              seams=np.column_stack([inner, n + np.arange(m)]), seam_id=np.zeros(m, int))
    # hung round the hips from that seam, which dips 6 cm at the sides (more than HUNG_FROM)
    rr, aa = np.hypot(uv[:, 0], uv[:, 1]), a.ravel()
    hung = np.column_stack([0.2 * np.cos(aa), 1.0 - 0.06 * np.cos(aa) ** 2 - (rr - 0.78), 0.2 * np.sin(aa)])
    hung = np.concatenate([hung, hung[inner] + [0.0, 0.005, 0.0]])
    vmap = np.arange(len(placed))
    ratio, name, draped, length = shortest_panel(garment, SimpleNamespace(positions=hung, vertex_map=vmap))
    assert name == "tier" and length == pytest.approx(0.17, abs=0.01) and ratio > 0.9
    heaped = hung.copy()
    heaped[:n, 1] = 1.0 - 0.3 * (rr - 0.78)
    assert shortest_panel(garment, SimpleNamespace(positions=heaped, vertex_map=vmap))[0] < BUNCHED
    # a stub of a seam at its end (2.4 cm, GarmentCode's high-low tiers have 3.5 cm sides), level and
    # higher than the seam it hangs from, is not what it hangs from (it hung 5 cm and was called
    # bunched: 32 cm tall of a 179 cm length)
    side = np.array([[0.78, -0.01], [0.804, -0.01]])
    garment.uv = np.concatenate([garment.uv, side])
    garment.positions = np.concatenate([placed, np.column_stack([side, np.zeros(2)])])
    garment.panel = np.concatenate([garment.panel, [2, 2]])
    garment.panel_names = ["tier", "above", "side"]
    garment.seams = np.concatenate([garment.seams, [[0, n + m], [1, n + m + 1]]])
    garment.seam_id = np.concatenate([garment.seam_id, [1, 1]])
    stub = np.concatenate([hung, [[0.2, 1.05, 0.0], [0.21, 1.05, 0.0]]])
    stub[[0, 1], 1] = 1.05
    vmap = np.arange(len(stub))
    ratio, name, _, length = shortest_panel(garment, SimpleNamespace(positions=stub, vertex_map=vmap))
    assert length == pytest.approx(0.17, abs=0.01) and ratio > 0.9, (name, length, ratio)


def test_a_collar_sewn_down_a_v_neckline_hangs_from_that_seam():
    """A collar sewn only along a V neckline (its one seam drops 20 cm over its 34 cm: it runs
    down, not across) lies on the chest 20 cm tall: it hangs from its whole seam, its 10 cm
    width -- not from its top point 34 cm away (GarmentCode's mean_female 13_025 was called
    bunched up, 20 cm tall of a 34 cm length). Crumpled onto its seam, 2 cm wide, it is bunched."""
    from types import SimpleNamespace

    from engine.scene.tryon import BUNCHED, shortest_panel

    u, w = np.meshgrid(np.linspace(0.0, 0.34, 18), np.linspace(0.0, 0.10, 6), indexing="ij")
    uv = np.column_stack([u.ravel(), w.ravel()])
    seam = np.flatnonzero(np.isclose(uv[:, 1], 0.0))
    n, m = len(uv), len(seam)
    neck = np.column_stack([uv[seam, 0], np.zeros(m)])  # the bodice's neckline edge
    placed = np.column_stack([0.3 + uv[:, 1], 1.0 + uv[:, 0], np.full(n, 0.2)])  # laid upright, 34 cm tall
    placed = np.concatenate([placed, np.column_stack([np.full(m, 0.3), 1.0 + neck[:, 0], np.full(m, 0.2)])])
    garment = SimpleNamespace(positions=placed, uv=np.concatenate([uv, neck]), panel=np.repeat([0, 1], [n, m]),
                              panel_names=["collar", "neck"], seams=np.column_stack([seam, n + np.arange(m)]),
                              seam_id=np.zeros(m, int))

    def worn(width):  # down the V: 20 cm in 34 cm, the collar lying out to the side over the chest
        y = 1.45 - 0.2 * uv[:, 0] / 0.34 - 0.3 * uv[:, 1] * width / 0.10
        x = 0.05 + 0.16 * uv[:, 0] / 0.34 + uv[:, 1] * width / 0.10
        col = np.column_stack([x, y, np.full(n, 0.15)])
        return np.concatenate([col, col[seam]])

    vmap = np.arange(len(placed))
    ratio, name, draped, length = shortest_panel(garment, SimpleNamespace(positions=worn(0.10), vertex_map=vmap))
    assert name == "collar" and length == pytest.approx(0.10, abs=0.01) and ratio > 1.0
    crumpled = worn(0.10)
    crumpled[:n, 1] = 1.45  # the whole collar heaped level at the top of the V
    crumpled[:n, 1] -= 0.02 * uv[:, 1] / 0.10
    assert shortest_panel(garment, SimpleNamespace(positions=crumpled, vertex_map=vmap))[0] < BUNCHED


def test_a_small_part_lying_short_does_not_make_a_garment_bunched():
    """A collar along a deep V or a flounce round a wrist on a sloping arm lies as the body has it
    lie, shorter than the length it could hang: run_tryon skips such parts (under SMALL_PART of
    the cloth) when it judges bunching. The largest panel still says so; where every panel placed
    that tall is skipped, none hangs to judge (inf), not the risen hem alone."""
    from types import SimpleNamespace

    from engine.scene.tryon import BUNCHED, hang_shift, hang_warnings, shortest_panel

    y = np.linspace(0.0, 0.5, 11)
    placed = np.column_stack([np.zeros(22), np.concatenate([y, 0.5 + y / 5]), np.zeros(22)])  # flounce 50, body 10 cm
    garment = SimpleNamespace(positions=placed, uv=placed[:, :2].copy(), panel=np.repeat([0, 1], 11),
                              panel_names=["flounce", "body"], seams=np.zeros((0, 2), int), seam_id=np.zeros(0, int))
    worn = placed.copy()
    worn[:11, 1] = 0.9 + 0.1 * y  # the flounce risen 90 cm round a wrist, 5 cm tall
    res = SimpleNamespace(positions=worn, vertex_map=np.arange(22))
    ratio, name, _, _ = shortest_panel(garment, res)
    assert name == "flounce" and ratio < BUNCHED
    assert "bunched up" in hang_warnings(hang_shift(placed, worn, np.arange(22)), None, shortest_panel(garment, res))[0]
    skipped = shortest_panel(garment, res, skip={"flounce"})
    assert skipped[0] == np.inf and not skipped[0] < BUNCHED
    assert hang_warnings(hang_shift(placed, worn, np.arange(22)), None, skipped) == []


def test_a_knit_is_guarded_closer_to_its_threshold_than_cotton():
    """The strain guard holds a knit (jersey: allowed 15 %) 0.3 % past its threshold and cotton
    0.5 %: the softer cloth overshoots the guard more between its passes, and at 0.5 % jersey
    drapes ended either side of the threshold + 1 % bar by chance."""
    from engine.scene.drape import dressing_config

    assert dressing_config(TryOnOptions(fabric="cotton"), Tuning()).strain_guard == pytest.approx(0.005)
    assert dressing_config(TryOnOptions(fabric="jersey"), Tuning()).strain_guard == pytest.approx(0.003)
    off = replace(Tuning(), drape=replace(DrapeTuning(), soft_guard=None))
    assert dressing_config(TryOnOptions(fabric="jersey"), off).strain_guard == pytest.approx(0.005)


def test_a_stall_of_lone_pairs_is_eased_in_up_to_snap_lone_gap():
    """Sewing stalled with every open pair alone on its stitch (the last pair of a seam where four
    panels meet, 2.4 cm apart on GarmentCode's hooded dress 1_019): welded where they are up to
    snap_lone_gap; the same gap over two neighbouring pairs of one stitch (a seam open along a
    stretch) is given up, as any stall wider than snap_gap."""
    from collections import deque

    from engine.scene.drape import _lone_open, _Pull, _stalled

    seam_id = np.array([0, 0, 0, 0, 1, 1, 1])
    welded = np.array([True, True, True, False, True, True, False])  # each stitch's end pair open
    assert _lone_open(welded, seam_id)
    assert _lone_open(np.array([False, True, False, True, False, True, True]), seam_id)
    assert not _lone_open(np.array([True, True, False, False, True, True, True]), seam_id)
    # (pairs of different stitches side by side in the list are not neighbours)
    assert _lone_open(np.array([True, True, True, False, False, True, True]), seam_id)

    t = Tuning().sew
    assert t.snap_gap < 0.025 < t.snap_lone_gap

    def stall(lone):
        out = _Pull(welded=welded.copy(), gaps=np.zeros(len(welded)))
        done = _stalled(out, deque([0.025] * 10, maxlen=10), 1000, 1e-3, t, lone)
        return done, bool(out.welded.all()), out.gave_up is not None

    assert stall(lone=True) == (True, True, False)  # eased in
    assert stall(lone=False) == (True, False, True)  # given up


def test_a_stall_wider_than_snap_gap_gives_up_before_snap_after():
    """Before SewTuning.snap_after, a stall within snap_gap sews on (it may yet close by itself)
    but one wider gives up as soon as it is judged: a too-small cotton top's seams stuck 9-10 cm
    open had sewn on to snap_after (f_smpl 127_002: 53 s of wall time) before its knit was tried."""
    from collections import deque

    from engine.scene.drape import _Pull, _stalled

    t = Tuning().sew
    welded = np.array([True, False, False])

    def stall(gap, snap):
        out = _Pull(welded=welded.copy(), gaps=np.zeros(3))
        done = _stalled(out, deque([gap] * 10, maxlen=10), 500, 1e-3, t, False, snap=snap)
        return done, bool(out.welded.all()), out.gave_up is not None

    assert stall(0.09, snap=False) == (True, False, True)  # given up at once
    assert stall(0.015, snap=False) == (False, False, False)  # sews on
    assert stall(0.015, snap=True) == (True, True, False)  # welded where it is
    closing = _Pull(welded=welded.copy(), gaps=np.zeros(3))
    assert not _stalled(closing, deque(np.linspace(0.12, 0.09, 10), maxlen=10), 500, 1e-3, t, False, snap=False)


def test_the_outline_through_the_crotch_is_measured_below_a_height():
    """sagittal_length: a box 0.4 wide, 0.6 tall, 0.2 deep standing on the floor, cut at x = 0.01
    below 0.5 m: down the front (0.5), across the bottom (0.2), up the back (0.5)."""
    import trimesh

    from engine.scene.drape import sagittal_length

    box = trimesh.creation.box(extents=(0.4, 0.6, 0.2))
    box.apply_translation((0.0, 0.3, 0.0))
    length, low = sagittal_length(np.asarray(box.vertices), np.asarray(box.faces), 0.01, 0.5)
    assert length == pytest.approx(1.2, abs=1e-9) and low == pytest.approx(0.0, abs=1e-12)
    assert sagittal_length(np.asarray(box.vertices), np.asarray(box.faces), 0.3, 0.5)[0] == 0.0  # (misses it)


def test_a_stall_is_the_small_parts_only_where_its_seams_are_open_about_as_wide():
    """engine.scene.drape._stalls_at: seams that stall beside a part too small (a cuff stretched
    far past the fabric) are that part's stall where a seam of it is open at least half as wide as
    the widest -- the fabric ladder then sews the part from a knit; a skirt seam 22 cm open beside
    a cuff 7 cm open stalls elsewhere (no knit closes it), and a part whose seams closed is not
    the stall."""
    from types import SimpleNamespace

    from engine.scene.drape import _stalls_at

    g = SimpleNamespace(panel=np.array([0, 0, 1, 1, 2, 2, 3, 3]), seams=np.array([[0, 2], [1, 3], [4, 6], [5, 7]]),
                        panel_names=["cuff_f", "cuff_b", "skirt_f", "skirt_b"])
    open_ = np.zeros(4, dtype=bool)
    assert _stalls_at(g, open_, np.array([0.05, 0.04, 0.06, 0.02]), ["cuff_f"])  # (5 cm at the cuff, 6 widest)
    assert not _stalls_at(g, open_, np.array([0.07, 0.02, 0.22, 0.10]), ["cuff_f", "cuff_b"])  # (7 of 22)
    assert not _stalls_at(g, np.array([True, True, False, False]), np.array([0.0, 0.0, 0.06, 0.02]), ["cuff_f"])


def test_a_crotch_seam_left_open_under_the_body_names_a_rise_too_short():
    """An open pair under mean_female's crotch (front and back 12 cm apart): with 25 cm of flat
    cloth from each side up its panel to the panel's top at 1.07 m (50 cm) against the body's
    ~80 cm through the crotch from there, the stall is said to be a rise too short, with both
    lengths; with 45 cm each (90 cm) nothing is said; nor for a pair far from the crotch, nor for
    one 2 cm from its panels' tops (no crotch seam hanging from a waist)."""
    from types import SimpleNamespace

    from engine.body import resolve_body
    from engine.collide.bvh import MeshBVH
    from engine.scene.drape import _crotch_short

    body = resolve_body(str(SAMPLE_BODY))
    bvh = MeshBVH(body.vertices, body.faces)
    xc = float(np.median(body.vertices[:, 0]))
    x = np.array([[xc, 0.74, 0.06], [xc, 1.07, 0.10], [xc, 0.74, -0.06], [xc, 1.07, -0.10]])

    def said(reach: float, at: np.ndarray = x):
        uv = np.array([[0.0, 0.0], [0.0, reach], [0.0, 0.0], [0.0, reach]])
        garment = SimpleNamespace(panel=np.array([0, 0, 1, 1]), uv=uv, seams=np.array([[0, 2]]))
        return _crotch_short(SimpleNamespace(body=bvh, garment=garment), SimpleNamespace(x=at), np.zeros(1, bool))[0]

    short = said(0.25)
    assert short is not None and "at most 50 cm of cloth" in short and "rise is too short" in short, short
    body_cm = float(re.search(r"the body measures (\d+) cm", short).group(1))
    assert 70 <= body_cm <= 90, short
    # how far lower the tops must hang for 50 cm of cloth to reach round: the body's outline
    # from there is 50 cm (at most 2 mm off), and from higher it is longer
    from engine.scene.drape import _crotch_length, crotch_fit_drop

    drop = crotch_fit_drop(bvh.verts, bvh.faces, 0.50, 1.07, xc, 0.3)
    assert drop is not None and 0.05 < drop < 0.3, drop
    assert abs(_crotch_length(bvh.verts, bvh.faces, xc, 1.07 - drop)[0] - 0.50) < 0.002
    assert crotch_fit_drop(bvh.verts, bvh.faces, 0.10, 1.07, xc, 0.05) is None  # (not within 5 cm)
    assert said(0.45) is None
    # (a pair at its panels' tops -- a skirt level's side seam caught at crotch height -- is no rise)
    assert said(0.02) is None
    aside = x.copy()
    aside[[0, 2], 0] += 0.15  # (the pair beside a thigh, not under the crotch)
    assert said(0.25, aside) is None
    before = x.copy()
    before[[0, 2], 2] = 0.10
    before[[0, 2], 0] += (-0.02, 0.02)  # (both ends in front, apart sideways: a skirt's centre seam open there)
    assert said(0.25, before) is None
    # both ends in front of the body's middle there, apart from front to back: trousers pulled up
    # into the crotch (f_smpl 109_006: its crotch seams open 3 cm across it, the buttocks reaching
    # further back than the front)
    pulled = x.copy()
    pulled[[0, 2], 2] = (0.10, 0.07)
    assert said(0.25, pulled) is not None
    # (and where another pair is open over twice as wide -- shorts' cuffs 30 cm open round a thigh
    # -- the stall is not the rise's: nothing is said)
    cuffs = np.vstack([x, [[xc + 0.12, 0.55, 0.15], [xc + 0.12, 0.55, -0.15]]])
    uv = np.array([[0.0, 0.0], [0.0, 0.25], [0.0, 0.0], [0.0, 0.25], [0.0, 0.0], [0.1, 0.0]])
    garment = SimpleNamespace(panel=np.array([0, 0, 1, 1, 2, 2]), uv=uv, seams=np.array([[0, 2], [4, 5]]))
    assert _crotch_short(SimpleNamespace(body=bvh, garment=garment), SimpleNamespace(x=cuffs), np.zeros(2, bool))[0] \
        is None
    cuffs[[4, 5], 2] = (0.05, -0.05)  # (the cuffs' pair 10 cm open, the crotch's 12: the rise is said)
    assert _crotch_short(SimpleNamespace(body=bvh, garment=garment), SimpleNamespace(x=cuffs), np.zeros(2, bool))[0] \
        is not None


def test_trousers_with_a_waistband_may_be_lowered_a_jumpsuit_may_not():
    """_below_arms: trousers whose waistband GarmentCode labels 'body' (not 'leg', f_smpl 109_006)
    are still trousers alone, all under the armpits: lowered for a short rise; a bodice over the
    shoulders is not (a jumpsuit lowered would hang off them)."""
    from types import SimpleNamespace

    from engine.body import resolve_body
    from engine.scene.tryon import _armpit_y, _below_arms

    body = resolve_body(str(SAMPLE_BODY))
    armpit = _armpit_y(body)
    names = ["pant_f", "pant_b", "wb"]
    pos = np.array([[0.0, 0.6, 0.1], [0.0, 0.6, -0.1], [0.0, armpit - 0.3, 0.1]])
    garment = SimpleNamespace(panel_names=names, panel=np.array([0, 1, 2]), positions=pos)
    assert _below_arms(garment, body, frozenset({"pant_f", "pant_b"}))
    pos[2, 1] = armpit + 0.2  # (the 'body' panel a bodice over the shoulders)
    assert not _below_arms(garment, body, frozenset({"pant_f", "pant_b"}))
    assert _below_arms(garment, body, frozenset(names))  # (every panel a lower garment's)


@pytest.mark.integration
def test_a_drape_that_settles_past_polish_at_goes_on_until_it_settles_again():
    """DrapeTuning.polish_at: a drape that settles stretched past the fabric's threshold + it goes
    on with the strain limit and the contacts alternated twice as often (checked every step)
    until it settles again, and ends no more stretched. Here with the mark lowered to the
    threshold itself on the sample GarmentCode skirt at 3 cm (a pattern file: a garment placed
    where it is worn is not polished, tryon); off, the same drape stops at its first settle."""
    from engine.body import resolve_body
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon

    body = resolve_body(str(SAMPLE_BODY))
    spec = load_pattern(SAMPLE_SKIRT)
    runs = {}
    for mark in (None, 0.0):
        res, rep = run_tryon(body, spec, TryOnOptions(resolution_cm=3.0, fabric="cotton"),
                             Tuning(drape=DrapeTuning(polish_at=mark)))
        assert rep["settled"]
        runs[mark] = (rep["iterations_by_stage"]["draping"], rep["strain"]["max"])
    assert runs[None][1] > 0.05, runs  # (the mark is passed, so the polish ran)
    assert runs[0.0][0] > runs[None][0] and runs[0.0][1] <= runs[None][1] + 1e-3, runs


def test_a_top_whose_straps_did_not_hold_fell_off_the_shoulders():
    """fell_off: a top placed over the shoulders (its top at 1.39 m, shoulders 1.37 m) whose top
    ended at 1.12 m -- the straps let go and the rest bunched round the hips, its median vertex
    risen, so it neither slid nor bunched by those tests (GarmentCode's 37_025) -- fell off
    them, said first; a hood that falls back to 1.40 m did not; nor a strapless top placed
    under the shoulders (top 1.25 m) that ends at 1.12 m; nor a skirt whose flat layout rises
    above the shoulders far to the side."""
    from engine.scene.tryon import fell_off, hang_warnings

    placed = np.array([[0.0, 0.77, 0.0], [0.0, 1.39, 0.0]])
    assert fell_off(placed, placed - [0, 0.27, 0], 1.37) == pytest.approx(0.25)
    said = hang_warnings({"top": -0.27, "hem": -0.15, "bulk": 0.065}, "the outlines cross", None, 0.25)
    assert len(said) == 1 and said[0].startswith("the garment fell off the shoulders") and "25 cm" in said[0]
    assert said[0].endswith("(the outlines cross)")
    hood = np.array([[0.0, 0.77, 0.0], [0.0, 1.66, 0.0]])
    assert fell_off(hood, np.array([[0.0, 0.75, 0.0], [0.0, 1.40, 0.0]]), 1.37) is None
    strapless = np.array([[0.0, 0.77, 0.0], [0.0, 1.25, 0.0]])
    assert fell_off(strapless, strapless - [0, 0.13, 0], 1.37) is None
    assert fell_off(placed, placed - [0, 0.27, 0], float("nan")) is None
    # a ruffled skirt laid flat in a ring: its tiers rise above the shoulders 1.3-2.2 m to the
    # side (GarmentCode's mean_female 43_019); worn at the waist, it did not fall off anything
    ring = np.array([[0.0, 1.05, 0.15], [1.29, 1.45, 0.15], [-2.2, 1.64, -0.15]])
    assert fell_off(ring, np.array([[0.0, 1.04, 0.1], [0.3, 0.6, 0.2], [-0.3, 0.6, -0.2]]), 1.37) is None


@pytest.mark.parametrize("bad", [dict(finish_pen=0.0), dict(finish_pen=0.5), dict(finish_budget=0.0),
                                 dict(finish_budget=60.0), dict(knit_tight_after=0.0),
                                 dict(polish_tight_after=-1.0), dict(polish_tight_after=100.0)])
def test_the_exact_finish_refuses_absurd_settings(bad):
    """DrapeTuning.finish_pen (a depth in metres, or None) and finish_budget (simulated seconds):
    outside their ranges, a plain refusal naming the setting."""
    from engine.errors import InputError

    with pytest.raises(InputError, match=next(iter(bad))):
        DrapeTuning(**bad).validate()
    DrapeTuning(finish_pen=None, polish_tight_after=None).validate()


def test_seams_open_over_the_hands_are_said_to_be_there():
    """Sewing that stalled with its open seams past the wrists, over the hands (GarmentCode's
    sleeves run past the wrist, their ends narrower than the hand), says so and what would close
    them, in place of the generic advice; open seams at the waist get no such words."""
    from engine.body import resolve_body
    from engine.body.measure import measure
    from engine.errors import SimulationError
    from engine.scene.drape import OPEN_WHY
    from engine.scene.tryon import _hand_hint

    body = resolve_body("default:female")
    y0 = float(body.vertices[:, 1].min())
    a, w = measure(body).arm_lines[0]
    past = np.array([a + t * (w - a) for t in (1.0, 1.05, 1.1)]) + [0.0, y0, 0.0]
    err = SimulationError(f"sewing stopped closing; open seams: sleeve (3.6 cm). {OPEN_WHY}")
    err.open_points = past
    _hand_hint(err, body)
    assert "over the hands (3 of 3 open pairs)" in str(err) and "shorter sleeves" in str(err)
    assert OPEN_WHY not in str(err) and str(err).startswith("sewing stopped closing")
    waist = SimulationError(f"sewing stopped closing. {OPEN_WHY}")
    waist.open_points = np.array([[0.0, y0 + 1.0, 0.12], [0.1, y0 + 1.0, 0.1]])
    _hand_hint(waist, body)
    assert str(waist).endswith(OPEN_WHY)


def test_cloth_that_flies_off_says_what_may_have_caused_it():
    """Cloth that flew off or became non-finite is refused with what most likely did it at the
    default step (sewn shut tangled round the body) and what may hold it (--dt)."""
    from engine.cloth.model import ClothState
    from engine.errors import SimulationError
    from engine.scene.drape import _check_finite

    x = np.zeros((4, 3))
    _check_finite(ClothState(x.copy(), np.zeros_like(x)), "draping")  # (at rest: nothing said)
    far = x.copy()
    far[2] = [0.0, 1.0, 250.0]
    with pytest.raises(SimulationError, match=r"flew off while draping .*tangled round the body.*--dt"):
        _check_finite(ClothState(far, np.zeros_like(x)), "draping")
    bad = x.copy()
    bad[1, 0] = np.nan
    with pytest.raises(SimulationError, match=r"unstable while sewing .*tangled round the body.*softer fabric"):
        _check_finite(ClothState(bad, np.zeros_like(x)), "sewing")


def _ring_cloth(r0: float, r1: float, y0: float, y1: float, n: int = 48, m: int = 12):
    """A ring of cloth from radius r0 at height y0 to r1 at y1 round the y axis: (vertices, triangles)."""
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    s = np.linspace(0, 1, m)
    r, y = r0 + s * (r1 - r0), y0 + s * (y1 - y0)
    v = np.stack([r[:, None] * np.cos(a)[None], np.repeat(y[:, None], n, 1), r[:, None] * np.sin(a)[None]], -1)
    i, j = np.meshgrid(np.arange(m - 1), np.arange(n), indexing="ij")
    q0, q1 = i * n + j, i * n + (j + 1) % n
    t = np.concatenate([np.stack([q0, q0 + n, q1], -1).reshape(-1, 3), np.stack([q1, q0 + n, q1 + n], -1).reshape(-1, 3)])
    return v.reshape(-1, 3), t


def test_cloth_standing_out_level_from_the_body_is_told_from_cloth_that_hangs():
    """engine.scene.drape.standing_out: a flat ring round a trunk (a circle skirt's fan) stands out
    where it is farther than stand_out_far from the body; the same cloth hanging as a cylinder, or
    lying level on the ground, does not."""
    import trimesh

    from engine.collide.bvh import MeshBVH
    from engine.scene.drape import standing_out
    from engine.scene.tuning import Tuning

    trunk = trimesh.creation.cylinder(radius=0.15, height=1.0, sections=64)
    trunk.apply_transform(trimesh.transformations.rotation_matrix(np.pi / 2, [1, 0, 0]))
    trunk.apply_translation([0, 1.0, 0])
    body = MeshBVH(np.asarray(trunk.vertices), np.asarray(trunk.faces))
    t = Tuning().drape
    x, tri = _ring_cloth(0.16, 0.6, 1.0, 1.0)  # (level from the trunk out to 60 cm)
    share = standing_out(x, tri, body, 0.0, t)
    far = (0.6 ** 2 - (0.15 + t.stand_out_far) ** 2) / (0.6 ** 2 - 0.16 ** 2)
    assert abs(share - far) < 0.05, (share, far)
    x, tri = _ring_cloth(0.3, 0.3, 1.0, 0.5)  # (hanging)
    assert standing_out(x, tri, body, 0.0, t) == 0.0
    x, tri = _ring_cloth(0.16, 0.6, 0.02, 0.02)  # (on the ground at 0)
    assert standing_out(x, tri, body, 0.0, t) == 0.0
    x, tri = _ring_cloth(0.2, 0.5, 1.0, 0.6)  # (a cone 53 degrees from level: between the two marks)
    assert standing_out(x, tri, body, 0.0, t) == 0.0 < standing_out(x, tri, body, 0.0, t, t.stand_out_hung)
