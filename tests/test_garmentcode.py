"""Patterns that GarmentCode's own generator writes (issue 47), as it writes them: twenty designs
drawn by ../shared/garmentcode/sample_designs.py on mean_female and f_smpl_average_A40 (kept in
tests/garmentcode/designs/, MIT; its README says which seed drew each and what it covers: a waistband,
a fitted dress, pants with cuffs, a gathered skirt, a collar with skirt levels, a hood, a wide skirt
laid out over the hands, a top on narrow straps, sleeves with a fifteen-gore skirt, a strapless top,
a sleeveless dress and a bodice cut with no ease, cuffs cut smaller than the arm, a jumpsuit
gathered at the waist, a top whose straps do not hold, a gown pooled on the floor, a skirt and a
flounce laid out in rings past the armpits, a sleeveless sack dress wider than the A-pose's arms, a
high-low circle skirt that came to rest standing out, a godet skirt whose cuts reach past its waist). The default suite
reads, checks and meshes them all and drapes several; the slow suite draws a fresh seeded sample and
drapes it (scripts/bench_garmentcode.py's bars)."""

from __future__ import annotations

import importlib.util
import json
import re
import sys
from pathlib import Path

import numpy as np
import pytest

from tests.samples import ROOT, SAMPLES, SMPL_BODY

DESIGNS = ROOT / "tests" / "garmentcode" / "designs"
FILES = sorted(DESIGNS.glob("*_specification.json"))
BODY = SAMPLES / "mean_female.obj"


def _bench():
    spec = importlib.util.spec_from_file_location("bench_garmentcode", ROOT / "scripts" / "bench_garmentcode.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def _panels(path: Path) -> set[str]:
    return set(json.loads(path.read_text())["pattern"]["panels"])


def test_the_handful_covers_what_it_says():
    """The kept designs hold what the tests claim to cover (a changed handful cannot silently
    drop a kind of part)."""
    names = set().union(*(_panels(p) for p in FILES))
    for part in ("wb_front", "pant_l_cuff_f", "hood", "collar_front", "ins_skirt_front", "sleeve_f", "skirt_panel"):
        assert any(n.startswith(part) or part in n for n in names), part
    assert len(FILES) == 30


@pytest.mark.parametrize("path", FILES, ids=lambda p: p.name[:17])
def test_each_design_is_read_checked_and_meshed(path):
    """Every design reads and checks with no error (warnings allowed: an outline GarmentCode draws
    crossing itself), and meshes: every stitch has pairs on both edges, every vertex is in a
    face, the labelled edges have vertices."""
    from engine.garment.garment import build_garment
    from engine.pattern.io import load_pattern
    from engine.pattern.validate import check

    spec = load_pattern(path)
    check(spec, source=path.name)
    g = build_garment(spec, h=0.015, source=path.name)
    assert len(g.stitch_names) == len(spec.pattern.stitches)
    assert set(np.unique(g.seam_id)) == set(range(len(spec.pattern.stitches)))  # every stitch sewn
    used = np.zeros(len(g.uv), bool)
    used[g.quads.ravel()] = True
    used[g.tris.ravel()] = True
    assert used.all()
    assert np.all(np.isfinite(g.positions))
    doc = json.loads(path.read_text())
    labels = {e["label"] for p in doc["pattern"]["panels"].values() for e in p["edges"] if e.get("label")}
    assert set(g.labelled) >= labels & {"lower_interface", "strapless_top", "right_collar", "left_collar"}


def test_a_collar_keeps_its_sewing_side():
    """GarmentCode's third stitch element (the collar's "right_wrong") is kept as written."""
    from engine.pattern.io import load_pattern

    sided = [p for p in FILES if any(len(s) > 2 for s in json.loads(p.read_text())["pattern"]["stitches"])]
    assert sided, "no kept design has a sided stitch"  # (mean_female_1_015's collar has)
    for path in sided:
        written = [s[2] for s in json.loads(path.read_text())["pattern"]["stitches"] if len(s) > 2]
        sides = [s.side for s in load_pattern(path).pattern.stitches if s.side is not None]
        assert sides == written, path.name


def _starts_at(g, spec, side, pairs) -> bool:
    """Whether a stitch side's first pair lies at its edge's first end (in the panel's plane)."""
    panel = spec.pattern.panels[side.panel]
    start = np.array(panel.vertices[panel.edges[side.edge].endpoints[0]]) * spec.scale
    d = np.linalg.norm(g.uv[pairs[[0, -1]]] - start, axis=1)
    return bool(d[0] < d[1])


def test_stitched_edges_pair_head_to_tail_as_garmentcode_sews_them():
    """GarmentCode sews a stitch's edges head to tail (right side to right side) and a "right_wrong"
    stitch the same way round -- whatever the flat layout suggests: a waist edge curled round the
    body or a hood's neckline can lie closer the other way round (1_019's hood, 1_022's sleeves were
    paired wrongly by nearness and twisted their seams). A DXF import's stitches (pairing
    "placed") pair the way their ends lie closer."""
    from engine.garment.garment import build_garment
    from engine.pattern.io import load_pattern
    from engine.pattern.spec import PatternSpec

    sided = 0
    for path in FILES:
        spec = load_pattern(path)
        g = build_garment(spec, h=0.015)
        for s, st in enumerate(spec.pattern.stitches):
            pairs = g.seams[g.seam_id == s]
            if len(pairs) < 2:
                continue
            same_way = _starts_at(g, spec, st.a, pairs[:, 0]) == _starts_at(g, spec, st.b, pairs[:, 1])
            assert same_way == (st.side == "right_wrong"), (path.name, g.stitch_names[s])
            sided += st.side == "right_wrong"
    assert sided >= 2

    # b placed upside down above a: its edge 3 lies nearer a's edge 1 the same way round
    square = {"vertices": [[0, 0], [30, 0], [30, 40], [0, 40]], "edges": [{"endpoints": [i, (i + 1) % 4]} for i in range(4)]}
    doc = {"pattern": {"panels": {"a": {**square, "translation": [0, 0, 0]},
                                  "b": {**square, "translation": [31, 40, 0], "rotation": [0, 0, 180]}},
                       "stitches": [[{"panel": "a", "edge": 1}, {"panel": "b", "edge": 3}]]}}
    for pairing, want_same in ((None, False), ("placed", True)):
        spec = PatternSpec.model_validate({**doc, "tryon": {"pairing": pairing}})
        g = build_garment(spec, h=0.05)
        pairs = g.seams
        same_way = _starts_at(g, spec, spec.pattern.stitches[0].a, pairs[:, 0]) == \
            _starts_at(g, spec, spec.pattern.stitches[0].b, pairs[:, 1])
        assert same_way == want_same, pairing


def test_panels_turn_as_garmentcodes_simulator_turns_them():
    """GarmentCode's simulator and pattern core turn a panel by Rz Ry Rx of its Euler angles
    (Maya's xyz); a collar's [90, 45, 0] lands where they put it (scipy's intrinsic "XYZ", which
    its generator writes with, would turn it elsewhere)."""
    from engine.pattern.geometry import panel_rotation_matrix

    a, b, c = np.deg2rad([90.0, 45.0, 0.0])
    rx = np.array([[1, 0, 0], [0, np.cos(a), -np.sin(a)], [0, np.sin(a), np.cos(a)]])
    ry = np.array([[np.cos(b), 0, np.sin(b)], [0, 1, 0], [-np.sin(b), 0, np.cos(b)]])
    rz = np.array([[np.cos(c), -np.sin(c), 0], [np.sin(c), np.cos(c), 0], [0, 0, 1]])
    assert np.allclose(panel_rotation_matrix([90, 45, 0]), rz @ ry @ rx)
    assert not np.allclose(panel_rotation_matrix([90, 45, 0]), rx @ ry @ rz)


def test_gathered_seams_pair_their_edges_evenly():
    """Edges of different lengths sewn together (a trouser leg gathered into its cuff, a skirt into
    a bodice): each pair lies at the same share of both edges' lengths -- the longer edge
    gathered evenly into the shorter."""
    from engine.garment.garment import build_garment
    from engine.pattern import geometry as geo
    from engine.pattern.io import load_pattern

    gathered = 0
    for path in FILES:
        spec = load_pattern(path)
        g = build_garment(spec, h=0.015)
        scale, rel = spec.scale, spec.properties.curvature_coords == "relative"
        panels = spec.pattern.panels
        for s, st in enumerate(spec.pattern.stitches):
            la = geo.edge_length(panels[st.a.panel], panels[st.a.panel].edges[st.a.edge], scale, rel)
            lb = geo.edge_length(panels[st.b.panel], panels[st.b.panel].edges[st.b.edge], scale, rel)
            if max(la, lb) < 1.3 * min(la, lb) or min(la, lb) < 0.02:  # (a millimetre edge is a corner, not a gather)
                continue
            if {st.a.panel, st.b.panel} & set(g.pinched):  # (an outline sample moved onto a crossing: 151_005's godets)
                continue
            gathered += 1
            pairs = g.seams[g.seam_id == s]
            share = []
            for side in (0, 1):  # the arc length share of each pair's end along its own edge
                x = g.uv[pairs[:, side]]
                d = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(x, axis=0), axis=1))]
                share.append(d / d[-1])
            assert np.abs(share[1] - share[0]).max() < 0.05, (path.name, s)
    assert gathered >= 4, "the handful lost its gathered seams"


def test_a_design_whose_outlines_cross_says_so_when_it_falls():
    """GarmentCode's hood design (019) cuts its bodice's neckline past the armholes: the warning
    that the garment slid names those panels and why they may not hold; a waistband (001) has no
    such panel and its warning says nothing of it."""
    from engine.garment.garment import build_garment
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import crossing_hint, hang_warnings

    crossed = build_garment(load_pattern(DESIGNS / "mean_female_1_019_specification.json"), h=0.03)
    hint = crossing_hint(crossed)
    assert hint is not None and "ftorso" in hint and "neckline cut past the armhole" in hint
    slid = hang_warnings({"top": -0.2, "hem": 0.0}, hint)
    assert len(slid) == 1 and slid[0].startswith("the garment slid") and hint in slid[0]
    plain = build_garment(load_pattern(DESIGNS / "mean_female_1_001_specification.json"), h=0.03)
    assert crossing_hint(plain) is None


def test_a_stall_is_put_down_to_a_crossed_outline_only_beside_its_widest_gaps():
    """pinched_open: the hooded dress 019's bodice panels cross themselves; a stall whose widest
    open pairs lie on a bodice seam names them, one whose widest lie elsewhere (a skirt seam) does
    not, though a bodice pair is open too, a little."""
    from engine.garment.garment import build_garment
    from engine.pattern.io import load_pattern
    from engine.scene.drape import pinched_open

    g = build_garment(load_pattern(DESIGNS / "mean_female_1_019_specification.json"), h=0.03)
    assert g.pinched
    names = np.array(g.panel_names)
    on_pinched = np.isin(names[g.panel[g.seams]], g.pinched).any(axis=1)
    assert on_pinched.any() and (~on_pinched).any()
    welded = np.ones(len(g.seams), dtype=bool)
    a, b = np.flatnonzero(on_pinched)[0], np.flatnonzero(~on_pinched)[0]
    welded[[a, b]] = False
    gaps = np.zeros(len(g.seams))
    gaps[a], gaps[b] = 0.10, 0.02
    found = pinched_open(g, welded, gaps)
    assert found and set(found) <= set(g.pinched)
    gaps[a], gaps[b] = 0.02, 0.10
    assert pinched_open(g, welded, gaps) == []
    assert pinched_open(g, np.ones(len(g.seams), dtype=bool), gaps) == []


@pytest.mark.integration
def test_a_circle_skirt_standing_out_round_the_hips_is_let_fall_until_it_hangs():
    """f_smpl 149_007, a strapless dress with a high-low circle skirt: FIRE came to rest with the
    skirt standing out level round the hips (8 % of the cloth 10 cm or more from the body within
    45 degrees of level). The cloth away from the body is let fall (drape's stand_out): the report
    says so, the drape ends hanging (under half the mark left even within 60 degrees of level),
    the bodice still up (no warning that it slid), and the bars hold."""
    from engine.body import resolve_body
    from engine.collide.bvh import MeshBVH
    from engine.pattern.io import load_pattern
    from engine.scene.drape import standing_out
    from engine.scene.tryon import run_tryon
    from engine.scene.tuning import Tuning

    body = resolve_body(str(SMPL_BODY))
    res, rep = run_tryon(body, load_pattern(DESIGNS / "f_smpl_average_A40_149_007_specification.json"))
    t = Tuning().drape
    assert rep.get("stood_out") and rep["stood_out"]["share"] > t.stand_out, rep.get("stood_out")
    floor = float(body.vertices[:, 1].min())
    hung = standing_out(res.positions, res.triangles, MeshBVH(body.vertices, body.faces), floor, t, t.stand_out_hung)
    assert hung < t.stand_out, hung
    assert not any("slid" in w or "fell" in w for w in rep["warnings"]), rep["warnings"]
    assert not rep["tight"] and rep["settled"], rep["strain"]
    assert rep["penetration_mm"]["max"] <= 2.0 and rep["penetration_mm"]["p99"] <= 0.5, rep["penetration_mm"]


@pytest.mark.integration
def test_a_skirt_cut_far_wider_than_the_waist_is_gathered_onto_an_elastic():
    """mean_female 181_014: two rectangles with no waistband, 121 cm round at the top where the
    waist measures 81. Held at the waist as GarmentCode's simulator holds it, it stood 6 cm off the
    body as a tube (the benchmark's 'stands off'); its top is gathered onto an elastic 3 % longer
    round than the waist, as a maker sews one: the report says so, the top lies on the body, and
    the bars hold."""
    from engine.body import resolve_body
    from engine.collide.bvh import MeshBVH
    from engine.garment.garment import build_garment
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon

    body = resolve_body(str(BODY))
    path = DESIGNS / "mean_female_181_014_specification.json"
    res, rep = run_tryon(body, load_pattern(path))
    assert _bench().verdict(rep) is None, _bench().verdict(rep)  # (the benchmark's bars: it drapes)
    said = [w for w in rep["warnings"] if "gathered onto an elastic" in w]
    assert len(said) == 1 and re.search(r"cut 121 cm round with no waistband where the body is 8\d cm round", said[0]), \
        rep["warnings"]
    assert "elastic" in rep["attachment"] and not any("stands off" in w for w in rep["warnings"]), rep["warnings"]
    top = build_garment(load_pattern(path), h=0.015).labelled["lower_interface"]
    off = MeshBVH(body.vertices, body.faces).signed_distance(res.positions[res.vertex_map[top]], max_distance=0.2)
    assert float(np.median(off)) < 0.015, np.median(off)


@pytest.mark.integration
def test_a_top_whose_straps_do_not_hold_is_said_to_fall_off_the_shoulders():
    """37_025: GarmentCode cuts the bodice's neckline past the armholes, so each strap hangs from a
    point; the top falls from the shoulders to the hips and bunches there, its median vertex
    risen -- good numbers (settled, 5 % strain, no penetration) on a garment that is not worn. The
    report says it fell off the shoulders, with why the straps may not hold, and the benchmark
    does not count it as draped."""
    from engine.body import resolve_body
    from engine.scene.request import TryOnOptions

    row = _bench().drape_one(DESIGNS / "mean_female_37_025_specification.json", resolve_body(str(BODY)),
                             TryOnOptions())
    assert not row["ok"] and row["reason"] == "fell off the shoulders (a warning)", row
    said = [w for w in row["warnings"] if w.startswith("the garment fell off the shoulders")]
    assert len(said) == 1 and "neckline cut past the armhole" in said[0], row["warnings"]


@pytest.mark.slow
@pytest.mark.integration
def test_seams_beside_an_outline_that_crosses_itself_say_why_they_stayed_open():
    """83_005: GarmentCode cuts the back's neckline in a circle past the armholes, so each side of
    the back hangs from the point where the outline crosses; its side seams stay 11 cm open. The
    error names those panels and why, not "too small or too far apart"."""
    from engine.body import resolve_body
    from engine.scene.request import TryOnOptions

    row = _bench().drape_one(DESIGNS / "mean_female_83_005_specification.json", resolve_body(str(BODY)),
                             TryOnOptions())
    assert not row["ok"] and "btorso" in row["error"] and "cut past the armhole" in row["error"], row
    assert "too far apart" not in row["error"]


@pytest.mark.integration
def test_a_jumpsuit_sewn_to_a_bodice_that_ends_at_the_waist_drapes():
    """11_003: GarmentCode sews trousers cut with a low rise to a bodice that ends at the waist,
    gathered into it. While the gathered edges pushed back at their full length, the inside leg
    seams stalled 8-9 cm open under the crotch and the error said the rise was too short (55 cm
    of cloth where the body measures 85: it counted from where the trousers were laid out, not
    where they hang). Gathered as cloth gathers (engine.cloth.model._gathered), the jumpsuit
    drapes -- in a knit, its bodice bloused over the waist seam (looked at)."""
    from engine.body import resolve_body
    from engine.scene.request import TryOnOptions

    row = _bench().drape_one(DESIGNS / "mean_female_11_003_specification.json", resolve_body(str(BODY)),
                             TryOnOptions())
    assert row["ok"], row.get("error") or row["reason"]
    assert row["fabric"] in ("jersey", "stretch_knit"), row["fabric"]


@pytest.mark.integration
def test_a_sack_dress_wider_than_the_arms_closes_its_side_seams_inside_them():
    """89_016: a sleeveless dress whose side seams GarmentCode lays out beyond the A-posed arms (the
    hanging forearm lies between its front and back panels). Met round the arm's outer side, the
    side seam stalled 7 cm open with the forearm through it; a trunk panel's pair caught round a
    hanging arm meets on the trunk's side of it -- the arm leaves by the armhole (looked at)."""
    from engine.body import resolve_body
    from engine.body.hanging import hanging_arms
    from engine.scene.request import TryOnOptions
    from engine.scene.tryon import _armpit_y

    body = resolve_body(str(BODY))
    row = _bench().drape_one(DESIGNS / "mean_female_89_016_specification.json", body, TryOnOptions())
    assert row["ok"], row.get("error") or row["reason"]
    # the forearms are outside the dress: no cloth within 2 cm of their lower half all round
    from scipy.spatial import cKDTree

    arm = hanging_arms(body, _armpit_y(body))
    pos = row["picture"][0]
    low = arm & (body.vertices[:, 1] < np.percentile(body.vertices[arm, 1], 50))
    near = cKDTree(pos).query(body.vertices[low], distance_upper_bound=0.02)[0] < 0.02
    assert near.mean() < 0.25, near.mean()


@pytest.mark.integration
@pytest.mark.parametrize("name", ["mean_female_1_001", "mean_female_1_012"])
def test_a_waistband_and_a_gathered_skirt_drape_on_their_body(name):
    """Draped on the body they were drawn for, they meet the benchmark's bars: settled, every seam
    closed, penetration max <= 2 mm and p99 <= 0.5 mm, strain <= the fabric's threshold + 1 %."""
    from engine.body import resolve_body
    from engine.scene.request import TryOnOptions

    bench = _bench()
    row = bench.drape_one(DESIGNS / f"{name}_specification.json", resolve_body(str(BODY)), TryOnOptions())
    assert row["ok"], row.get("error") or row.get("reason")


def test_seams_placed_through_the_shoulders_are_raised_over_them():
    """seam_lift: a seam whose straight closing path runs through the body above the armpits
    raises the garment until it clears (plus a margin); one that clears already, one below the
    armpits, and one that would need more than SEAM_LIFT_MAX (round the body, not over it) do not."""
    from engine.garment.place import SEAM_LIFT_MARGIN, SEAM_LIFT_MAX, seam_lift

    def inside(p):  # a shoulder: a ball of 10 cm radius round the origin
        return np.linalg.norm(p, axis=1) < 0.1

    def pair(y, z=0.2):
        return np.array([[0.0, y, z], [0.0, y, -z]])

    lift = seam_lift(pair(0.05), np.array([[0, 1]]), inside, above=0.0)
    assert 0.1 - 0.05 <= lift - SEAM_LIFT_MARGIN <= 0.1 - 0.05 + 0.005
    assert not inside(pair(0.05 + lift)).any()
    assert seam_lift(pair(0.12), np.array([[0, 1]]), inside, above=0.0) == 0.0  # clears
    assert seam_lift(pair(0.05), np.array([[0, 1]]), inside, above=0.08) == 0.0  # below the armpits
    assert SEAM_LIFT_MAX < 0.1 + 0.05
    assert seam_lift(pair(-0.05), np.array([[0, 1]]), inside, above=-1.0) == 0.0  # through the middle


@pytest.mark.integration
def test_a_top_on_narrow_straps_stays_on_the_shoulders():
    """GarmentCode places a top's shoulder seams at its body's shoulder height, 3 cm inside the
    shoulders beside the neck: pulled shut through them, its 1 cm straps slid off and the top fell
    33 cm. Raised until the seams clear the shoulders, it drapes within the bars."""
    from engine.body import resolve_body
    from engine.scene.request import TryOnOptions

    bench = _bench()
    row = bench.drape_one(DESIGNS / "mean_female_1_021_specification.json", resolve_body(str(BODY)), TryOnOptions())
    assert row["ok"], row.get("error") or row.get("reason")


@pytest.mark.integration
def test_a_fitted_dress_sewn_from_its_flat_layout_stays_on_the_shoulders():
    """GarmentCode lays a fitted dress out flat, front and back 55 cm apart. Its darts and waist
    seams closed at once while the shoulder seams took 0.2 s, and the bodice crumpled into a heap
    at the waist (slid 28 cm). Every open pair now closes in the time the widest needs
    (SewTuning.far_together): the bodice is worn, its top at the shoulders. (It is still refused
    as too small: stretched ~30 % under the arms, where the armhole meets the armpit.)"""
    from engine.body import resolve_body
    from engine.body.measure import measure
    from engine.errors import SimulationError
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon

    body = resolve_body(str(BODY))
    try:
        res, _ = run_tryon(body, load_pattern(DESIGNS / "mean_female_1_003_specification.json"))
        x = res.positions
    except SimulationError as e:
        assert "slid" not in str(e), str(e)
        x = e.positions
    shoulders = float(body.vertices[:, 1].min()) + measure(body).shoulder_height
    assert abs(float(x[:, 1].max()) - shoulders) < 0.06, (float(x[:, 1].max()), shoulders)


@pytest.mark.integration
def test_a_band_cut_smaller_than_the_body_is_sewn_from_a_knit():
    """A top with a peplum skirt on a waistband GarmentCode cuts smaller round than f_smpl's waist
    (97_016): in cotton (5 % allowed) the band stays 13 % stretched as its drape begins. The band,
    held at cotton's limit, is sewn from stretch_knit (a rib band), the top in cotton, the report
    saying which parts and why -- unless the user chose the fabric (theirs stands: in cotton it
    ends at the strain guard's limit all over, 5.5-6 % since a settled drape is polished
    (DrapeTuning.polish_at), or past it). (mean_female 11_026, this test's dress until its hem
    band's gather stopped pushing the band out while sewn, now fits in cotton.)"""
    from engine.body import resolve_body
    from engine.errors import SimulationError
    from engine.pattern.io import load_pattern
    from engine.scene.request import TryOnOptions
    from engine.scene.tryon import run_tryon

    body = resolve_body(str(SMPL_BODY))
    spec = load_pattern(DESIGNS / "f_smpl_average_A40_97_016_specification.json")
    said = []
    res, rep = run_tryon(body, spec, progress=lambda stage, f, msg: said.append(msg))
    parts = rep.get("panel_fabrics", {})
    assert rep["fabric"] == "cotton" and {"wb_back", "wb_front"} <= set(parts), (rep["fabric"], parts)
    assert set(parts.values()) == {"stretch_knit"} and len(parts) < len(spec.pattern.panels), parts
    assert any(re.match("in cotton it (ended|stayed)", m) and "again with 'wb_" in m for m in said)
    assert any(re.match(r"'wb_.* sewn from stretch_knit, a knit, .*: in cotton it (ended|stayed) \d+ % stretched", w)
               for w in rep["warnings"]), rep["warnings"]
    assert rep["strain"]["parts"]["stretch_knit"]["max"] <= 0.41, rep["strain"]
    assert not rep["tight"] and rep["settled"] and rep["penetration_mm"]["max"] <= 2.0
    try:  # asked for cotton: cotton it is, at the guard's limit or past it (or refused as too small)
        _, mine = run_tryon(body, spec, TryOnOptions(fabric="cotton"))
        assert mine["fabric"] == "cotton" and mine["strain"]["max"] > 0.055, (mine["fabric"], mine["strain"])
    except SimulationError as e:
        assert "too small" in str(e), str(e)


@pytest.mark.integration
def test_a_pattern_too_tight_for_cotton_is_draped_in_a_knit():
    """43_002: GarmentCode draws its bodice down to a low-rise skirt, 84 cm round where mean_female
    measures 100 cm -- in cotton it stays far past its limit over the whole garment, so it is
    draped in a knit (jersey, or stretch_knit where jersey does not fit either), the report saying
    how each fabric before it did not fit."""
    from engine.body import resolve_body
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon

    res, rep = run_tryon(resolve_body(str(BODY)), load_pattern(DESIGNS / "mean_female_43_002_specification.json"))
    assert rep["fabric"] in ("jersey", "stretch_knit"), (rep["fabric"], rep["warnings"])
    assert re.search(r"in cotton it (stayed|ended) \d+ % stretched", rep["fabric_why"]), rep["fabric_why"]
    assert any(w.startswith(f"draped in {rep['fabric']}, a knit: in cotton") for w in rep["warnings"]), rep["warnings"]
    assert not rep["tight"] and rep["settled"], rep["strain"]
    assert rep["penetration_mm"]["max"] <= 2.0 and rep["penetration_mm"]["p99"] <= 0.5, rep["penetration_mm"]


@pytest.mark.integration
def test_cloth_left_inside_the_body_by_the_maps_settles_against_the_mesh():
    """f_smpl 277_017, a sleeveless top with a collar: against the collision maps (5 mm texels
    round the tight curve at the top of the shoulder) it settles with cloth 1.0 mm inside the
    body's mesh -- under the default DrapeTuning.finish_pen, 1.5 mm, so asked here from 0.5 mm;
    it goes on against the mesh itself until it settles again, shallower, and the report says so.
    (f_smpl 23_017, a gown pooling round the feet, was its design until that gown's drape turned
    out to depend on the machine: docs/tuning.md, finish_pen.)"""
    from dataclasses import replace

    from engine.body import resolve_body
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon
    from engine.scene.tuning import Tuning
    from tests.samples import SMPL_BODY

    spec = load_pattern(DESIGNS / "f_smpl_average_A40_277_017_specification.json")
    t = Tuning()
    res, rep = run_tryon(resolve_body(str(SMPL_BODY)), spec, tuning=replace(t, drape=replace(t.drape, finish_pen=0.0005)))
    fin = rep["exact_finish"]
    assert fin["kept"] and fin["penetration_mm_before"] > 0.5, fin
    assert fin["penetration_mm_after"] < fin["penetration_mm_before"], fin
    assert abs(rep["penetration_mm"]["max"] - fin["penetration_mm_after"]) < 0.05, (rep["penetration_mm"], fin)
    assert rep["penetration_mm"]["max"] <= 2.0 and rep["penetration_mm"]["p99"] <= 0.5, rep["penetration_mm"]
    assert rep["settled"] and not rep["tight"], rep["strain"]


@pytest.mark.integration
def test_cuffs_cut_smaller_than_the_arms_are_sewn_in_a_knit():
    """mean_female 53_009, a loose shirt whose flared cuffs are sewn 22.4 cm round, smaller than the
    arm: in cotton the cuffs' seam stays 40-75 % stretched and the drape gives up; the cuffs --
    and only they, the shirt fitting -- are sewn again from stretch_knit, the shirt in cotton, the
    report naming them, the cuffs' own strain within stretch_knit's 40 % + 1 %."""
    from engine.body import resolve_body
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon

    spec = load_pattern(DESIGNS / "mean_female_53_009_specification.json")
    res, rep = run_tryon(resolve_body(str(BODY)), spec)
    cuffs = {n for n in spec.pattern.panels if "cuff" in n}
    assert rep["fabric"] == "cotton" and set(rep.get("panel_fabrics", {})) == cuffs, rep.get("panel_fabrics")
    assert any(w.startswith("'sl_") and "sewn from stretch_knit" in w for w in rep["warnings"]), rep["warnings"]
    assert rep["strain"]["parts"]["stretch_knit"]["max"] <= 0.41, rep["strain"]
    assert not rep["tight"] and rep["settled"], rep["strain"]
    assert rep["penetration_mm"]["max"] <= 2.0 and rep["penetration_mm"]["p99"] <= 0.5, rep["penetration_mm"]


@pytest.mark.integration
def test_cuffs_too_small_for_a_stretch_knit_are_sewn_from_a_rib():
    """f_smpl 97_010, a dress whose sleeves end on the forearm in cuffs GarmentCode cuts to the
    wrist's girth (17.2 cm round): in cotton their seams stall beside them, and in stretch_knit
    too (held at its 40 %, 4-6 cm open). Sewn from rib_knit (80 %, stretching crosswise at its
    own springs) they close round the forearms and the dress fits cotton; the report names the rib
    and the cuffs' own strain is within its threshold + 1 %."""
    from engine.body import resolve_body
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon
    from tests.samples import SMPL_BODY

    spec = load_pattern(DESIGNS / "f_smpl_average_A40_97_010_specification.json")
    res, rep = run_tryon(resolve_body(str(SMPL_BODY)), spec)
    cuffs = {n for n in spec.pattern.panels if "cuff" in n}
    assert rep["fabric"] == "cotton" and rep.get("panel_fabrics") == {n: "rib_knit" for n in cuffs}, \
        rep.get("panel_fabrics")
    assert any(w.startswith("'sl_") and "sewn from rib_knit" in w for w in rep["warnings"]), rep["warnings"]
    # (to the report's 0.1 %: on one machine its worst spring ended at 81.005 %, on another under 81 %)
    assert round(100 * rep["strain"]["parts"]["rib_knit"]["max"], 1) <= 81.0, rep["strain"]
    assert not rep["tight"] and rep["settled"], rep["strain"]
    assert rep["penetration_mm"]["max"] <= 2.0 and rep["penetration_mm"]["p99"] <= 0.5, rep["penetration_mm"]


@pytest.mark.slow
@pytest.mark.integration
def test_a_hooded_top_with_cuffs_too_small_drapes_or_names_its_cuffs():
    """f_smpl 47_014, a hooded top: in cotton its cuffs' seams stall, the cuffs stretched 21-30 %
    round SMPL's arms, and with the cuffs in stretch_knit its torso is held 35 % past cotton's
    limit (more than a quarter of the cloth: a garment for a knit). It drapes in a knit, or --
    since knits no longer sag (ClothParams.sag_as: their stiffer cuffs' seams stall at 1.9-2.4 cm,
    just past the 2 cm snap) -- the refusal names the cuffs as too small in cotton and says how
    each knit went: a reason a user can act on, not a bare stall."""
    from engine.body import resolve_body
    from engine.errors import SimulationError
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon
    from tests.samples import SMPL_BODY

    spec = load_pattern(DESIGNS / "f_smpl_average_A40_47_014_specification.json")
    try:
        res, rep = run_tryon(resolve_body(str(SMPL_BODY)), spec)
    except SimulationError as e:
        msg = str(e)
        assert re.search(r"'sl_(left|right)_cuff_[fb]' \d+ %: that part is too small for this body", msg), msg
        assert "(in jersey too:" in msg and "(in stretch_knit too:" in msg, msg
        return
    assert rep["fabric"] in ("jersey", "stretch_knit"), rep["fabric"]
    assert not rep["tight"] and rep["settled"], rep["strain"]
    assert rep["penetration_mm"]["max"] <= 2.0 and rep["penetration_mm"]["p99"] <= 0.5, rep["penetration_mm"]


@pytest.mark.slow
@pytest.mark.integration
def test_a_fresh_seeded_sample_drapes(tmp_path):
    """Twenty designs freshly drawn by GarmentCode's sampler (seed 7) on mean_female. Where we
    stand (docs/patterns.md): 75-95 % of GarmentCode's designs meet the bars (seed 7: 17 of 20,
    11 a week before); the target is 95 %. This guards against losing ground, with room for the
    chaos of sewing and settling (single designs flip with small changes): at least 14 of 20."""
    from engine.body import resolve_body
    from engine.scene.request import TryOnOptions

    pytest.importorskip("svgpathtools")
    bench = _bench()
    try:
        paths = bench.draw("mean_female", 20, 7, tmp_path / "patterns")
    except SystemExit as e:
        pytest.fail(str(e))
    body = resolve_body(str(BODY))
    rows = [bench.drape_one(p, body, TryOnOptions()) for p in paths]
    ok = [r["design"] for r in rows if r["ok"]]
    print(f"{len(ok)} of {len(rows)} drape:", ok, file=sys.stderr)
    assert len(rows) >= 16 and len(ok) >= 14, [(r["design"], r.get("reason")) for r in rows]


def test_the_benchmark_groups_stalls_beside_a_part_too_small_apart():
    """A seam that stalled beside a panel stretched far past the fabric (a cuff cut smaller round
    than the arm) is the pattern's size, not the sewing: the benchmark's table counts it apart."""
    bench = _bench()
    cuff = ("mean_female_13_003_specification.json: error: sewing stopped closing after 2.0 s of simulated time "
            "(the widest gap stayed 2.4-3.5 cm for 0.5 s) (sewn twice, pulled at 3 and 1.5 m/s); open seams: "
            "sl_left_cuff_f[2]-sl_left_cuff_b[1] (3.2 cm). Beside them the cloth is stretched far past what cotton "
            "allows (5 %) over a tenth of a panel or more: 'sl_left_cuff_f' 49 %: that part is too small for this "
            "body (try a larger size)")
    hood = ("mean_female_11_001_specification.json: error: sewing stopped closing after 2.0 s of simulated time "
            "(the widest gap stayed 2.3-2.8 cm for 0.5 s); open seams: left_ftorso[6]-left_hood[3] (2.5 cm). The "
            "garment may be too small for this body (try a larger size) or the panels start too far apart")
    crossed = ("mean_female_83_005_specification.json: error: sewing stopped closing after 1.1 s of simulated "
               "time (the widest gap stayed 11.1-11.5 cm for 0.5 s); open seams: right_ftorso[5]-right_btorso[1] "
               "(11.4 cm). Beside them the outlines of panels left_btorso, right_btorso cross themselves (meshed "
               "joined where the edges cross): the parts beyond a crossing hang from a point and cannot be held "
               "where their seams meet (a neckline cut past the armhole) -- check those edges in the pattern")
    assert bench.reason(cuff) == "sewing stopped closing after # s of simulated time, beside a part too small for the body"
    assert bench.reason(hood) == "sewing stopped closing after # s of simulated time"
    assert bench.reason(crossed) == "sewing stopped closing after # s of simulated time, beside an outline that crosses itself"


@pytest.mark.parametrize("gave_up_at, runs", [(0.52, 3), (0.12, 4)])
def test_a_pattern_refused_in_cotton_and_in_the_knits_is_not_draped_again(monkeypatch, gave_up_at, runs):
    """run_tryon's knit fallback: the cotton drape gave up (DrapeTuning.give_up), the jersey drape
    gave up too and the stretch knit was refused as too small. Where cotton had stayed past its
    own refusal mark (threshold + too_tight, 15 %) the refusal stands, saying all three (a full
    cotton drape of 11_001 took 60 s to be refused again at 52 %); below it the cotton drape is run
    again to its end before the stretch knit (the least stretchy fabric that fits is the drape)."""
    import engine.scene.tryon as tryon
    from engine.body import resolve_body
    from engine.errors import SimulationError
    from engine.pattern.io import load_pattern

    calls = []

    def scripted(body, spec, request, tuning, why, **kw):
        calls.append((request.fabric, tuning.drape.give_up))
        err = SimulationError(f"the garment is too small for this body ({request.fabric})")
        err.stretched_at, err.too_small = (0.0, 1.0, 0.0), True
        err.strain = gave_up_at if request.fabric == "cotton" else 0.27
        err.gave_up = tuning.drape.give_up
        raise err

    monkeypatch.setattr(tryon, "_run_tryon", scripted)
    spec = load_pattern(DESIGNS / "mean_female_11_026_specification.json")
    with pytest.raises(SimulationError, match=r"\(cotton\) \(in jersey too: the garment is too small for this "
                                              r"body \(jersey\)\) \(in stretch_knit too: .*\(stretch_knit\)\)"):
        tryon.run_tryon(resolve_body(str(BODY)), spec)
    assert calls == [("cotton", True), ("jersey", True)] + [("cotton", False)] * (runs - 3) + [("stretch_knit", False)]


def test_a_stall_beside_a_part_too_small_is_sewn_again_in_the_knits(monkeypatch):
    """Seams that stall in cotton beside a part stretched far past it (a cuff cut smaller round
    than the arm) are the pattern's fit, not the sewing: the knits follow, and the first that
    fits is the drape, the report saying why; a stall for another reason is not retried."""
    import engine.scene.tryon as tryon
    from engine.body import resolve_body
    from engine.errors import SimulationError
    from engine.pattern.io import load_pattern

    calls, small = [], [0.31]

    def scripted(body, spec, request, tuning, why, **kw):
        calls.append(request.fabric)
        if request.fabric != "stretch_knit":
            err = SimulationError(f"sewing stopped closing ({request.fabric})")
            err.small_part = small[0]
            raise err
        return "drape", {"tight": False, "warnings": [], "fabric_why": why}

    monkeypatch.setattr(tryon, "_run_tryon", scripted)
    body, spec = resolve_body(str(BODY)), load_pattern(DESIGNS / "mean_female_11_026_specification.json")
    _, rep = tryon.run_tryon(body, spec)
    assert calls == ["cotton", "jersey", "stretch_knit"], calls
    assert rep["warnings"] == ["draped in stretch_knit, a knit: in cotton its seams stopped closing beside cloth "
                               "stretched 31 % where cotton allows 5 %; in jersey its seams stopped closing beside "
                               "cloth stretched 31 % where jersey allows 15 %"], rep["warnings"]
    assert rep["fabric_why"].startswith("the pattern's fit: in cotton its seams stopped closing"), rep["fabric_why"]
    calls.clear()
    small[0] = None  # (a stall that names no part too small)
    with pytest.raises(SimulationError, match=r"sewing stopped closing \(cotton\)$"):
        tryon.run_tryon(body, spec)
    assert calls == ["cotton"], calls


def test_a_try_on_past_its_time_limit_stops_on_the_ladder_and_says_where(monkeypatch):
    """The wall-time limit (engine.scene.drape.time_limited: the service's TRYON_DRESS_SECONDS,
    `--time-limit`) raises from the progress report of whichever drape is running: the fabric
    ladder does not take it for a garment that did not fit, so no further fabric is tried, and the
    message names the limit and the stage it stopped in."""
    import time

    import engine.scene.tryon as tryon
    from engine.body import resolve_body
    from engine.errors import SimulationError, TimeLimitError
    from engine.pattern.io import load_pattern
    from engine.scene.drape import time_limited

    calls = []

    def scripted(body, spec, request, tuning, why, progress=None, **kw):
        calls.append(request.fabric)
        progress("sewing", 0.5, f"largest open seam gap 9.0 cm ({request.fabric})")
        if request.fabric == "cotton":
            err = SimulationError("sewing stopped closing (cotton)")
            err.small_part = 0.31
            raise err
        time.sleep(0.05)  # (the knit's drape runs on past the limit)
        progress("draping", 0.1, "drift 3.00 cm/s")
        return "drape", {"tight": False, "warnings": [], "fabric_why": why}

    monkeypatch.setattr(tryon, "_run_tryon", scripted)
    body, spec = resolve_body(str(BODY)), load_pattern(DESIGNS / "mean_female_11_026_specification.json")
    with pytest.raises(TimeLimitError, match=r"^stopped after 0\.03 s \(a test's limit\) while still draping "
                                             r"\(largest open seam gap 9\.0 cm \(jersey\)\): "):
        tryon.run_tryon(body, spec, progress=time_limited(None, 0.03, "a test's limit"))
    assert calls == ["cotton", "jersey"], calls
    said = []
    limited = time_limited(lambda *a: said.append(a), 60.0, "a minute")
    limited("sewing", 0.2, "gap 2 cm")  # (within its time: passed on)
    assert said == [("sewing", 0.2, "gap 2 cm")]


def test_a_drape_that_never_came_to_rest_at_the_fabrics_limit_is_draped_in_a_knit(monkeypatch):
    """A cotton drape under the tight mark that never settled, the strain guard holding it at the
    limit all along (mean_female 83_004: 5.8 % for the whole budget, shaking against the body),
    does not fit: the knit that settles is the drape, the warning saying why. One that did not
    settle with the guard mostly idle (cloth still sliding) stands in cotton."""
    from types import SimpleNamespace

    import engine.scene.tryon as tryon
    from engine.body import resolve_body
    from engine.pattern.io import load_pattern

    calls, share = [], [1.0]

    def scripted(body, spec, request, tuning, why, **kw):
        calls.append(request.fabric)
        if request.fabric == "cotton":
            return SimpleNamespace(held=[], lowered=None), {"tight": False, "settled": False, "warnings": [], "fabric_why": why,
                                              "strain": {"max": 0.058, "guard_share": share[0]}}
        return "knit", {"tight": False, "settled": True, "warnings": [], "fabric_why": why,
                        "strain": {"max": 0.153, "guard_share": 1.0}}

    monkeypatch.setattr(tryon, "_run_tryon", scripted)
    body, spec = resolve_body(str(BODY)), load_pattern(DESIGNS / "mean_female_11_026_specification.json")
    res, rep = tryon.run_tryon(body, spec)
    assert res == "knit" and calls == ["cotton", "jersey"], calls
    assert rep["warnings"] == ["draped in jersey, a knit: in cotton it did not come to rest, held at the fabric's "
                               "limit (5.8 % where cotton allows 5 %)"], rep["warnings"]
    calls.clear()
    share[0] = 0.2
    res, rep = tryon.run_tryon(body, spec)
    assert calls == ["cotton"] and rep["strain"]["max"] == 0.058, calls


def test_parts_held_at_the_fabrics_limit_are_sewn_from_a_knit(monkeypatch):
    """The cotton drape gave up naming the parts it held at cotton's limit (a cuff): it is draped
    again with that part in stretch_knit, the rest in cotton; where that names another part, once
    more with both, and the report says which parts and why. Where the parts named are the whole
    garment, the rung is skipped: the whole garment goes to the knits."""
    import engine.scene.tryon as tryon
    from engine.body import resolve_body
    from engine.errors import SimulationError
    from engine.pattern.io import load_pattern

    calls, named = [], {}

    def scripted(body, spec, request, tuning, why, panel_fabrics=None, **kw):
        calls.append((request.fabric, dict(panel_fabrics or {})))
        tight = [n for n in named.get(len(panel_fabrics or {}), []) if n not in (panel_fabrics or {})] \
            if request.fabric == "cotton" else []
        if tight or request.fabric == "jersey":
            err = SimulationError(f"the garment is too small for this body ({request.fabric})")
            err.stretched_at, err.strain, err.gave_up, err.tight_panels = (0, 1, 0), 0.3, True, tight
            raise err
        return "drape", {"tight": False, "warnings": [], "fabric_why": why}

    monkeypatch.setattr(tryon, "_run_tryon", scripted)
    body, spec = resolve_body(str(BODY)), load_pattern(DESIGNS / "mean_female_11_026_specification.json")
    named.update({0: ["cuff_l"], 1: ["cuff_l", "cuff_r"]})
    _, rep = tryon.run_tryon(body, spec)
    knit = "stretch_knit"
    assert calls == [("cotton", {}), ("cotton", {"cuff_l": knit}), ("cotton", {"cuff_l": knit, "cuff_r": knit})]
    assert rep["warnings"] == ["'cuff_l', 'cuff_r' sewn from stretch_knit, a knit, as a maker sews a part cut "
                               "smaller round than the body (a rib cuff or band): in cotton it stayed 30 % "
                               "stretched where cotton allows 5 %"], rep["warnings"]
    calls.clear()
    named.clear()
    named[0] = list(spec.pattern.panels)  # (every panel: the whole garment in a knit instead)
    _, rep = tryon.run_tryon(body, spec)
    assert calls == [("cotton", {}), ("jersey", {}), ("stretch_knit", {})], calls


def test_parts_still_held_in_the_knit_are_sewn_from_a_rib(monkeypatch):
    """Parts held in cotton and, sewn from stretch_knit, held again or stalled open round the limb
    (a cuff cut to the wrist's girth on a sleeve that ends on the forearm: f_smpl 97_010) are sewn
    once more from rib_knit, which stretches twice as far round, the parts that fitted staying in
    stretch_knit; the report names each part's fabric. Where
    the knit parts' drape stalled elsewhere, naming no part, the rib is not tried: the whole
    garment goes to the knits."""
    import engine.scene.tryon as tryon
    from engine.body import resolve_body
    from engine.errors import SimulationError
    from engine.pattern.io import load_pattern

    calls, stalled_at = [], [["cuff_l", "sleeve_l"]]

    def scripted(body, spec, request, tuning, why, panel_fabrics=None, **kw):
        parts = dict(panel_fabrics or {})
        calls.append((request.fabric, parts))
        if request.fabric == "cotton" and not parts:
            err = SimulationError("the garment is too small for this body (cotton)")
            err.stretched_at, err.strain, err.gave_up, err.tight_panels = (0, 1, 0), 0.3, True, ["cuff_l", "band"]
            raise err
        if parts.get("cuff_l") == "rib_knit":
            return "drape", {"tight": False, "warnings": [], "fabric_why": why}
        err = SimulationError(f"sewing stopped closing ({request.fabric})")
        err.open_panels = stalled_at[0]
        err.small_part = 0.3 if request.fabric != "cotton" else None  # (the knits: a part too small, on to the next)
        raise err

    monkeypatch.setattr(tryon, "_run_tryon", scripted)
    body, spec = resolve_body(str(BODY)), load_pattern(DESIGNS / "mean_female_11_026_specification.json")
    _, rep = tryon.run_tryon(body, spec)
    knit = {"cuff_l": "stretch_knit", "band": "stretch_knit"}
    # (only the cuff, stalled open at, goes to the rib: the band fitted in stretch_knit)
    assert calls == [("cotton", {}), ("cotton", knit), ("cotton", {**knit, "cuff_l": "rib_knit"})], calls
    assert rep["warnings"] == ["'cuff_l' sewn from rib_knit, a knit, and 'band' sewn from stretch_knit, a knit, as "
                               "a maker sews a part cut smaller round than the body (a rib cuff or band): in cotton "
                               "it stayed 30 % stretched where cotton allows 5 %"], rep["warnings"]
    calls.clear()
    stalled_at[0] = ["skirt_front", "skirt_back"]  # (the knit cuff's drape stalled elsewhere)
    with pytest.raises(SimulationError):
        tryon.run_tryon(body, spec)
    assert [c[0] for c in calls] == ["cotton", "cotton", "jersey", "stretch_knit"], calls
    assert all(parts.get("cuff_l") != "rib_knit" for _, parts in calls), calls
    # (the knits keep the parts found in a stretchier knit than theirs: jersey, not stretch_knit)
    assert calls[2][1] == {"cuff_l": "stretch_knit", "band": "stretch_knit"} and calls[3][1] == {}, calls


def test_parts_the_rib_drape_holds_next_are_sewn_from_a_knit(monkeypatch):
    """Cuffs held in cotton, stalled open in stretch_knit, sewn on in rib_knit -- and that drape
    holds the next part at cotton's limit, the cuff's flared skirt below its band (mean_female
    193_011): once more with that part in stretch_knit, the cuffs kept in rib; the report names
    both. Where that fails too, the whole garment goes to the knits with the parts found held in a
    stretchier knit than theirs kept (a knit with rib cuffs: the rib in jersey and in
    stretch_knit, the stretch_knit part in jersey only)."""
    import engine.scene.tryon as tryon
    from engine.body import resolve_body
    from engine.errors import SimulationError
    from engine.pattern.io import load_pattern

    calls, frill_fits = [], [True]

    def scripted(body, spec, request, tuning, why, panel_fabrics=None, **kw):
        parts = dict(panel_fabrics or {})
        calls.append((request.fabric, parts))
        if request.fabric == "cotton" and not parts or parts.get("cuff_l") == "rib_knit" and "frill_l" not in parts:
            err = SimulationError(f"the garment is too small for this body ({request.fabric})")
            err.stretched_at, err.strain, err.gave_up = (0, 1, 0), 0.3, True
            err.tight_panels = ["frill_l"] if parts else ["cuff_l"]
            raise err
        if parts.get("cuff_l") == "stretch_knit" or not frill_fits[0]:
            err = SimulationError(f"sewing stopped closing ({request.fabric})")
            err.open_panels, err.small_part = ["cuff_l"], 0.3
            raise err
        return "drape", {"tight": False, "warnings": [], "fabric_why": why}

    monkeypatch.setattr(tryon, "_run_tryon", scripted)
    body, spec = resolve_body(str(BODY)), load_pattern(DESIGNS / "mean_female_11_026_specification.json")
    _, rep = tryon.run_tryon(body, spec)
    sk, rib = "stretch_knit", "rib_knit"
    assert calls == [("cotton", {}), ("cotton", {"cuff_l": sk}), ("cotton", {"cuff_l": rib}),
                     ("cotton", {"cuff_l": rib, "frill_l": sk})], calls
    assert rep["warnings"][0].startswith("'cuff_l' sewn from rib_knit, a knit, and 'frill_l' sewn from stretch_knit"), \
        rep["warnings"]
    calls.clear()
    frill_fits[0] = False
    with pytest.raises(SimulationError):
        tryon.run_tryon(body, spec)
    assert calls[4:] == [("jersey", {"cuff_l": rib, "frill_l": sk}), ("stretch_knit", {"cuff_l": rib})], calls


def test_a_skirt_alone_is_judged_by_its_waist():
    """A circle skirt alone whose two panels GarmentCode lays out in a ring reaching past the
    shoulders (f_smpl 109_013): whether it slid or fell off the shoulders is judged by its waist
    (the attachment holds it), not by the ring's top, which falls by design (it was reported as
    "fell off the shoulders" while it hung at the waist). A dress keeps its bodice as the judged
    part."""
    from engine.body import resolve_body
    from engine.garment.garment import build_garment
    from engine.garment.place import pattern_placement
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import _world_height, fell_off, judged_part, lower_labelled
    from tests.samples import SMPL_BODY

    body = resolve_body(str(SMPL_BODY))
    spec = load_pattern(DESIGNS / "f_smpl_average_A40_109_013_specification.json")
    place, _ = pattern_placement(spec, body, lambda p: np.zeros(len(p), bool))
    g = build_garment(spec, h=0.015, place=place)
    lower = lower_labelled(spec)
    assert lower == set(spec.pattern.panels)
    judged = judged_part(g, lower)
    waist = g.labelled["lower_interface"]
    assert judged.sum() == len(np.unique(waist)) and judged[waist].all()
    y, shoulders = g.positions[:, 1], _world_height(body, "shoulder_height")
    assert y.max() > shoulders > y[judged].max() + 0.2, (y.max(), shoulders, y[judged].max())
    # the ring falls to hang from the waist, the waist held: not "fell off the shoulders" -- as
    # the whole garment judged, it would be
    draped = g.positions.copy()
    draped[~judged, 1] = np.minimum(draped[~judged, 1], y[judged].min())
    assert fell_off(g.positions[judged], draped[judged], shoulders, same=True) is None
    assert fell_off(g.positions, draped, shoulders) is not None
    dress = load_pattern(DESIGNS / "mean_female_83_010_specification.json")
    gd = build_garment(dress, h=0.015)
    skirt = lower_labelled(dress)
    assert skirt and np.array_equal(judged_part(gd, skirt), ~np.isin(gd.panel_names, list(skirt))[gd.panel])


@pytest.mark.integration
def test_trousers_whose_rise_is_short_are_worn_lower():
    """f_smpl 127_009, culottes GarmentCode drafts with a rise of 60 cm through the crotch, placed
    with their top 2.6 cm under f_smpl's waist where the body measures 87 cm through its crotch:
    their crotch seams stalled 6 cm open. Placed 13 cm lower -- where the rise reaches round, as a
    wearer would wear them -- they sew and drape, and the report says how they were placed. (In
    cotton they end either side of its limit: placed 0.05 mm higher, after a stall judged at 1.4 s
    instead of 2.0 s, cotton stayed 11 % stretched and they drape in jersey; the report then says
    so.)"""
    from engine.body import resolve_body
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon
    from tests.samples import SMPL_BODY

    said = []
    res, rep = run_tryon(resolve_body(str(SMPL_BODY)), load_pattern(DESIGNS / "f_smpl_average_A40_127_009_specification.json"),
                         progress=lambda stage, f, msg: said.append(msg))
    assert any(m.startswith("the rise is too short for where the top was placed: sewing it again") for m in said)
    m = re.search(r"lowered (\d+) cm: its rise, (\d+) cm through the crotch, is shorter than the body's (\d+) cm",
                  json.dumps(rep))
    assert m and 5 <= int(m.group(1)) <= 15 and int(m.group(2)) < int(m.group(3)), m
    assert rep["settled"] and not rep["tight"], (rep["fabric"], rep["strain"])
    assert rep["fabric"] == "cotton" or any(w.startswith(f"draped in {rep['fabric']}, a knit: in cotton it stayed")
                                            for w in rep["warnings"]), (rep["fabric"], rep["warnings"])
    assert rep["penetration_mm"]["max"] <= 2.0 and rep["penetration_mm"]["p99"] <= 0.5, rep["penetration_mm"]


@pytest.mark.slow
@pytest.mark.integration
def test_trousers_with_a_waistband_pulled_up_into_the_crotch_are_worn_lower_in_every_fabric():
    """f_smpl 109_006, wide culottes with a waistband (labelled 'body', not 'leg'): their crotch
    seams stalled 3 cm open across the crotch, both ends of each pair a little in front of the
    middle of the body's cut there. The stall is read as a short rise (62 cm of cloth against the
    body's 73); the waistband lies under the armpits, so they are placed lower, and every fabric
    after the first is placed as low (the report says so): they drape."""
    from engine.body import resolve_body
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon
    from tests.samples import SMPL_BODY

    said = []
    res, rep = run_tryon(resolve_body(str(SMPL_BODY)), load_pattern(DESIGNS / "f_smpl_average_A40_109_006_specification.json"),
                         progress=lambda stage, f, msg: said.append(msg))
    assert sum(m.startswith("the rise is too short for where the top was placed") for m in said) == 1, said
    assert re.search(r"lowered \d+ cm: its rise, \d+ cm through the crotch", rep.get("placement", "")), rep.get("placement")
    assert rep["settled"] and not rep["tight"], (rep["fabric"], rep["strain"])
    assert rep["penetration_mm"]["max"] <= 2.0 and rep["penetration_mm"]["p99"] <= 0.5, rep["penetration_mm"]


@pytest.mark.slow
@pytest.mark.integration
def test_a_hood_laid_through_the_head_is_sewn_round_it():
    """f_smpl 127_010, a hooded dress: GarmentCode lays the hood's halves through the head (47 % of
    their points inside f_smpl's). Its own layout is kept (carried by the landmarks instead, the
    hood's seams stalled 10 cm open); the hood is sewn round the head and sits on the shoulders."""
    from engine.body import resolve_body
    from engine.body.measure import measure
    from engine.pattern.io import load_pattern
    from engine.scene.tryon import run_tryon
    from tests.samples import SMPL_BODY

    body = resolve_body(str(SMPL_BODY))
    res, rep = run_tryon(body, load_pattern(DESIGNS / "f_smpl_average_A40_127_010_specification.json"))
    assert rep.get("placement", "").startswith("the pattern's own placement"), rep.get("placement")
    assert rep["settled"] and not rep["tight"], (rep["fabric"], rep["strain"])
    assert rep["penetration_mm"]["max"] <= 2.0 and rep["penetration_mm"]["p99"] <= 0.5, rep["penetration_mm"]
    shoulders = float(body.vertices[:, 1].min()) + measure(body).shoulder_height
    assert float(res.positions[:, 1].max()) > shoulders + 0.15  # (the hood up round the head, not fallen back)
