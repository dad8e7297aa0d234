"""Patterns: the GarmentCode spec model, JSON/SVG io, edge geometry and the validator."""

from __future__ import annotations

import copy
import json
import xml.etree.ElementTree as ET

import numpy as np
import pytest

from engine.errors import InputError
from engine.pattern import geometry as geo
from engine.pattern.io import load_pattern, parse_pattern, pattern_to_dict, pattern_to_svg, save_pattern
from engine.pattern.spec import Panel, PatternSpec
from engine.pattern.validate import check, validate
from tests.samples import SAMPLE_SKIRT

SVG = "{http://www.w3.org/2000/svg}"


@pytest.fixture(scope="module")
def raw() -> dict:
    return json.loads(SAMPLE_SKIRT.read_text())


@pytest.fixture(scope="module")
def skirt() -> PatternSpec:
    return load_pattern(SAMPLE_SKIRT)


def _spec(d: dict) -> PatternSpec:
    return PatternSpec.model_validate(d)


def _square_panel(size=20.0, **extra) -> dict:
    v = [[0, 0], [size, 0], [size, size], [0, size]]
    return {"vertices": v, "edges": [{"endpoints": [i, (i + 1) % 4]} for i in range(4)], **extra}


def _subset(small, big, path="") -> list[str]:
    """Where `small` (parsed JSON) is not contained in `big`."""
    bad = []
    if isinstance(small, dict):
        for k, v in small.items():
            if not isinstance(big, dict) or k not in big:
                bad.append(f"{path}{k} missing")
            else:
                bad += _subset(v, big[k], f"{path}{k}.")
    elif isinstance(small, list):
        if not isinstance(big, list) or len(small) != len(big):
            return [f"{path} length differs"]
        for i, (a, b) in enumerate(zip(small, big)):
            bad += _subset(a, b, f"{path}{i}.")
    elif small != big:
        bad.append(f"{path}: {small!r} != {big!r}")
    return bad


# --- loading, round trip, SVG ------------------------------------------------------------------

def test_sample_loads(skirt):
    assert set(skirt.pattern.panels) == {"skirt_front", "skirt_back", "wb_back", "wb_front"}
    assert len(skirt.pattern.stitches) == 6
    assert skirt.scale == pytest.approx(0.01)
    assert skirt.pattern.panels["skirt_front"].edges[1].curvature.type == "circle"


def test_sample_validates_clean(skirt):
    problems = validate(skirt)
    assert [p for p in problems if p.level == "error"] == []
    assert check(skirt) == problems  # no errors: check returns the (warning) list, no raise


def test_round_trip_equal(skirt, tmp_path):
    p = save_pattern(skirt, tmp_path / "skirt.json")
    again = load_pattern(p)
    assert pattern_to_dict(again) == pattern_to_dict(skirt)


def test_round_trip_keeps_everything_in_the_file(raw, skirt, tmp_path):
    p = save_pattern(skirt, tmp_path / "skirt.json")
    written = json.loads(p.read_text())
    assert _subset(raw, written) == []  # every key/value of the original survives (labels too)


def test_unmodelled_garmentcode_fields_survive(raw, tmp_path):
    d = copy.deepcopy(raw)
    d["parameters"] = {"length": {"v": 0.7, "range": [0.2, 0.95], "type": "float"}}
    d["parameter_order"] = ["length"]
    d["pattern"]["panels"]["skirt_front"]["mystery"] = {"keep": [1, 2, 3]}
    spec = parse_pattern(json.dumps(d))
    written = json.loads(save_pattern(spec, tmp_path / "p.json").read_text())
    assert written["parameters"] == d["parameters"]
    assert written["parameter_order"] == ["length"]
    assert written["pattern"]["panels"]["skirt_front"]["mystery"] == {"keep": [1, 2, 3]}
    # and the (empty) ones of the sample are not dropped either
    assert "parameters" in pattern_to_dict(load_pattern(SAMPLE_SKIRT))


def test_svg(skirt):
    svg = pattern_to_svg(skirt)
    root = ET.fromstring(svg)  # parseable XML
    assert root.tag == SVG + "svg"
    polys = root.findall(f".//{SVG}polygon")
    assert len(polys) == len(skirt.pattern.panels) == 4
    for poly in polys:
        pts = np.array([[float(c) for c in p.split(",")] for p in poly.get("points").split()])
        assert len(pts) >= 4 and np.all(np.isfinite(pts))
    texts = [t.text for t in root.findall(f".//{SVG}text")]
    for k in range(len(skirt.pattern.stitches)):
        assert texts.count(f"s{k}") == 2, f"stitch s{k} should label both of its edges"
    for name in skirt.pattern.panels:
        assert name in texts
    assert len(root.findall(f".//{SVG}polyline")) == 2 * len(skirt.pattern.stitches)


# --- geometry -------------------------------------------------------------------------------------

def _fit_circle(pts: np.ndarray) -> tuple[np.ndarray, float]:
    """Least-squares (Kasa) circle through 2D points: centre, radius."""
    A = np.column_stack([2 * pts[:, 0], 2 * pts[:, 1], np.ones(len(pts))])
    b = (pts ** 2).sum(axis=1)
    (cx, cy, c), *_ = np.linalg.lstsq(A, b, rcond=None)
    return np.array([cx, cy]), float(np.sqrt(c + cx * cx + cy * cy))


def _side(pts, start, end) -> np.ndarray:
    """> 0 left of start->end, < 0 right."""
    d = end - start
    r = pts - start
    return d[0] * r[:, 1] - d[1] * r[:, 0]


def test_circle_arc_radius_and_bulge(skirt):
    panel = skirt.pattern.panels["skirt_front"]
    hem = panel.edges[1]  # params [58.44, large_arc 0, right 1]
    assert hem.curvature.params[2] == 1
    pts = geo.edge_dense(panel, hem, skirt.scale)
    v = np.asarray(panel.vertices) * skirt.scale
    start, end = v[hem.endpoints[0]], v[hem.endpoints[1]]
    np.testing.assert_allclose(pts[0], start, atol=1e-12)
    np.testing.assert_allclose(pts[-1], end, atol=1e-12)
    centre, r = _fit_circle(pts)
    assert r == pytest.approx(0.5844, abs=2e-4)
    assert np.abs(np.linalg.norm(pts - centre, axis=1) - 0.58438).max() < 1e-4
    side = _side(pts[1:-1], start, end)
    assert np.all(side < 0), "right=1 must bulge to the right of start->end"
    # small arc (large_arc = 0): the bulge is less than the radius
    chord = np.linalg.norm(end - start)
    sag = np.abs(side).max() / chord
    assert 0 < sag < r


def test_circle_arc_right_flag_zero_bulges_left(skirt):
    panel = skirt.pattern.panels["skirt_front"]
    waist = panel.edges[3]  # params [17.9, 0, right 0]
    assert waist.curvature.params[2] == 0
    pts = geo.edge_dense(panel, waist, skirt.scale)
    v = np.asarray(panel.vertices) * skirt.scale
    assert np.all(_side(pts[1:-1], v[waist.endpoints[0]], v[waist.endpoints[1]]) > 0)
    _, r = _fit_circle(pts)
    assert r == pytest.approx(0.17896, abs=2e-4)


def test_flare_skirt_waist_and_hem_are_concentric(skirt):
    """A circle skirt's waist and hem arcs share their centre: a physical check of the `right`
    convention (the opposite reading puts the two centres ~30 cm apart)."""
    panel = skirt.pattern.panels["skirt_front"]
    c_hem, r_hem = _fit_circle(geo.edge_dense(panel, panel.edges[1], skirt.scale))
    c_waist, r_waist = _fit_circle(geo.edge_dense(panel, panel.edges[3], skirt.scale))
    assert np.linalg.norm(c_hem - c_waist) < 1e-3
    assert r_hem - r_waist == pytest.approx(0.5844 - 0.1790, abs=1e-3)


def _unit_quadratic(ctrl=(0.5, 0.2)) -> Panel:
    return Panel(vertices=[(0.0, 0.0), (1.0, 0.0)],
                 edges=[{"endpoints": [0, 1], "curvature": {"type": "quadratic", "params": [list(ctrl)]}}])


def test_quadratic_edge_midpoint():
    panel = _unit_quadratic()
    e = panel.edges[0]
    # B(0.5) = 0.25 s + 0.5 c + 0.25 e with c = (0.5, 0.2) (y: the edge turned +90 deg)
    dense = geo.edge_dense(panel, e, 1.0, n=257)
    np.testing.assert_allclose(dense[128], [0.5, 0.1], atol=1e-12)
    # symmetric curve: the arc-length midpoint is the same point
    mid = geo.edge_samples(panel, e, 1.0, 2)[1]
    np.testing.assert_allclose(mid, [0.5, 0.1], atol=1e-4)
    # the edge is longer than its chord, shorter than the control polygon
    length = geo.edge_length(panel, e, 1.0)
    assert 1.0 < length < 2 * np.hypot(0.5, 0.2)


def test_quadratic_relative_control_follows_the_edge_direction():
    # the same relative control on the reversed edge bulges to the other side in absolute terms
    panel = Panel(vertices=[(1.0, 0.0), (0.0, 0.0)],
                  edges=[{"endpoints": [0, 1], "curvature": {"type": "quadratic", "params": [[0.5, 0.2]]}}])
    dense = geo.edge_dense(panel, panel.edges[0], 1.0, n=257)
    np.testing.assert_allclose(dense[128], [0.5, -0.1], atol=1e-12)


@pytest.mark.parametrize("which", ["circle", "quadratic", "straight"])
def test_edge_samples_uniform_in_arc_length(skirt, which):
    if which == "circle":
        panel = skirt.pattern.panels["skirt_front"]
        e, scale = panel.edges[1], skirt.scale
    elif which == "quadratic":
        panel = _unit_quadratic((0.3, 0.6))  # strongly curved, asymmetric
        e, scale = panel.edges[0], 1.0
    else:
        panel = skirt.pattern.panels["skirt_front"]
        e, scale = panel.edges[0], skirt.scale
    n = 37
    s = geo.edge_samples(panel, e, scale, n)
    assert s.shape == (n + 1, 2)
    d = np.linalg.norm(np.diff(s, axis=0), axis=1)
    assert d.max() / d.min() - 1 < 0.01
    assert d.sum() == pytest.approx(geo.edge_length(panel, e, scale), rel=1e-3)
    v = np.asarray(panel.vertices) * scale
    np.testing.assert_allclose(s[0], v[e.endpoints[0]], atol=1e-12)
    np.testing.assert_allclose(s[-1], v[e.endpoints[1]], atol=1e-12)


# --- validation -----------------------------------------------------------------------------------

def _errors(spec: PatternSpec):
    return [p for p in validate(spec) if p.level == "error"]


def _assert_refused(spec: PatternSpec, panel: str, edge: int, words: str):
    errs = _errors(spec)
    assert any(p.panel == panel and p.edge == edge and words in p.message for p in errs), errs
    with pytest.raises(InputError) as ei:
        check(spec, "bad.json")
    msg = str(ei.value)
    assert "\n" not in msg and msg.startswith("bad.json: ")
    assert f"panel '{panel}' edge {edge}" in msg, msg


def test_stitch_missing_panel(raw):
    d = copy.deepcopy(raw)
    d["pattern"]["stitches"][2][1]["panel"] = "sleeve"
    _assert_refused(_spec(d), "sleeve", 3, "does not exist")


def test_stitch_edge_out_of_range(raw):
    d = copy.deepcopy(raw)
    d["pattern"]["stitches"][0][0]["edge"] = 9
    _assert_refused(_spec(d), "skirt_front", 9, "edges 0..3")


def test_stitched_edges_of_different_length_are_a_gather():
    """GarmentCode sews edges of different lengths on purpose (a skirt gathered into a waistband):
    accepted; only a gather past MAX_GATHER x is refused, naming the panel and edge."""
    d = {"pattern": {"panels": {"a": _square_panel(20.0), "b": _square_panel(23.0)},
                     "stitches": [[{"panel": "a", "edge": 1}, {"panel": "b", "edge": 3}]]}}
    assert _errors(_spec(d)) == []
    d["pattern"]["panels"]["b"] = _square_panel(70.0)
    assert _errors(_spec(d)) == []  # 3.5 x
    d["pattern"]["panels"]["b"] = _square_panel(90.0)
    _assert_refused(_spec(d), "a", 1, "gathered")


def test_bow_tie_outline_is_meshed_as_garmentcode_draws_it():
    """An outline that crosses itself a few times (GarmentCode draws a neckline past the armhole
    so) is a warning naming the edges, and meshes: both parts of a bow tie, joined where its
    edges cross, every vertex in a face."""
    from engine.garment.garment import build_garment

    panel = _square_panel()
    panel["vertices"] = [[0, 0], [20, 0], [0, 20], [20, 20]]  # edges 1 and 3 cross
    spec = _spec({"pattern": {"panels": {"tie": panel}}})
    assert _errors(spec) == []
    warn = [p for p in validate(spec) if "crosses itself" in p.message]
    assert len(warn) == 1 and warn[0].panel == "tie"
    assert {warn[0].edge, int(warn[0].message.split("crosses edge ")[1].split(")")[0])} == {1, 3}
    g = build_garment(spec, h=0.02)
    used = np.zeros(len(g.uv), bool)
    used[g.quads.ravel()] = True
    used[g.tris.ravel()] = True
    assert used.all()
    def cross(a, b):
        return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]

    t, q = g.uv[g.tris], g.uv[g.quads]
    area = 0.5 * np.abs(cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])).sum()
    area += 0.5 * np.abs(cross(q[:, 2] - q[:, 0], q[:, 3] - q[:, 1])).sum()
    assert abs(area - 2 * 0.5 * 0.2 * 0.1) < 0.002  # two triangles of 200 cm^2


def _strip(length=60.0, width=0.02) -> dict:
    return {"vertices": [[0, 0], [length, 0], [length, width], [0, width]],
            "edges": [{"endpoints": [i, (i + 1) % 4]} for i in range(4)]}


def test_a_sliver_hanging_from_one_part_is_left_out_with_a_warning():
    """GarmentCode draws a flounce of zero length as a strip 0.2 mm wide: too thin to mesh, it is
    left out with its seams and a warning naming it; the rest meshes and keeps its seams."""
    from engine.garment.garment import build_garment

    d = {"pattern": {"panels": {"leg": _square_panel(60.0), "frill": _strip()},
                     "stitches": [[{"panel": "leg", "edge": 0}, {"panel": "frill", "edge": 2}],
                                  [{"panel": "leg", "edge": 1}, {"panel": "leg", "edge": 3}]]}}
    g = build_garment(_spec(d), h=0.015)
    assert g.panel_names == ["leg"] and g.stitch_names == ["leg[1]-leg[3]"]
    assert len(g.seams) > 0 and set(np.unique(g.seam_id)) == {0}
    note = [w for w in g.warnings if "frill" in w]
    assert len(note) == 1 and "0.2 mm wide" in note[0] and "left out" in note[0]
    # a bow tie's halves cancel in its signed area: it is no sliver, and meshes whole
    tie = _square_panel(20.0)
    tie["vertices"] = [[0, 0], [20, 0], [0, 20], [20, 20]]
    d["pattern"]["panels"]["frill"] = tie
    d["pattern"]["stitches"][0][1]["edge"] = 0
    g = build_garment(_spec(d), h=0.015)
    assert g.panel_names == ["leg", "frill"] and not [w for w in g.warnings if "left out" in w]


def test_a_sliver_joining_two_parts_is_refused():
    """A sliver sewn between two parts holds them together: leaving it out would drop the garment
    in two, so meshing refuses it, naming it."""
    from engine.garment.garment import build_garment

    d = {"pattern": {"panels": {"top": _square_panel(60.0), "band": _strip(), "skirt": _square_panel(60.0)},
                     "stitches": [[{"panel": "top", "edge": 0}, {"panel": "band", "edge": 2}],
                                  [{"panel": "band", "edge": 0}, {"panel": "skirt", "edge": 2}]]}}
    with pytest.raises(InputError, match="'band' is too small to mesh"):
        build_garment(_spec(d), h=0.015)


def _godet_panel(reach: float) -> dict:
    """A skirt panel 78 x 50 cm with five godet cuts up from its hem whose tips reach `reach` cm
    high, and its waist drawn as one edge per stretch between the cuts' tips (GarmentCode's
    GodetSkirt: a cut taller than the skirt crosses the waist twice)."""
    v, tips = [[0, 0]], [8, 23.5, 39, 54.5, 70]
    for x in tips:  # (each cut: hem, tip, hem)
        v += [[x - 3.3, 0], [x, reach], [x + 3.3, 0]]
    v += [[78, 0], [78, 50]] + [[x, 50] for x in reversed(tips[1:])] + [[0, 50]]
    m = len(v)
    return {"vertices": v, "edges": [{"endpoints": [k, (k + 1) % m]} for k in range(m)]}


def test_godet_cuts_a_little_past_the_waist_are_a_drawing_and_far_past_it_a_mix_up():
    """Ten crossings where five godet cuts reach 4 cm past a 50 cm skirt's waist (mean_female
    151_005): the outline winds once nearly everywhere -- meshed as drawn, with a warning. Cut 30
    cm past it, the tips wind back over a large share of the panel: refused, naming the cause."""
    from engine.garment.garment import build_garment

    from engine.pattern import geometry as geo
    from engine.pattern.validate import MAX_CROSSINGS, _self_intersection

    near = _spec({"pattern": {"panels": {"skirt": _godet_panel(54.0)}}})
    dense = [geo.edge_dense(near.pattern.panels["skirt"], e, near.scale, True, 64) for e in near.pattern.panels["skirt"].edges]
    poly, seg = np.concatenate([d[:-1] for d in dense]), np.concatenate([np.full(len(d) - 1, i) for i, d in enumerate(dense)])
    assert _self_intersection(poly, seg)[2] > MAX_CROSSINGS  # (more crossings than a few: the winding decides)
    assert not _errors(near), _errors(near)
    assert any("crosses itself" in p.message and p.level == "warning" for p in validate(near))
    g = build_garment(near, h=0.015)
    assert g.pinched == ["skirt"] and len(g.positions) > 500
    far = _spec({"pattern": {"panels": {"skirt": _godet_panel(80.0)}}})
    errs = _errors(far)
    assert errs and "pairs of edges" in errs[0].message and "a dart or a cut reaches past" in errs[0].message, errs


def test_an_outline_crossing_itself_many_times_is_refused():
    panel = _square_panel()
    n = 40  # a zigzag up the square, closed by a straight edge down its middle: dozens of crossings
    zig = [[20.0 * (k % 2), 20.0 * k / n] for k in range(n + 1)]
    panel["vertices"] = [[10, -5]] + zig + [[10, 25]]
    m = len(panel["vertices"])
    panel["edges"] = [{"endpoints": [k, (k + 1) % m]} for k in range(m)]
    spec = _spec({"pattern": {"panels": {"zz": panel}}})
    errs = _errors(spec)
    assert errs and errs[0].panel == "zz" and "crosses itself" in errs[0].message and "pairs of edges" in errs[0].message
    assert "a dart or a cut reaches past" in errs[0].message  # (GarmentCode's godet cuts taller than their band)
    with pytest.raises(InputError, match="panel 'zz'"):
        check(spec)


@pytest.mark.parametrize("curved, rel", [(3, [0.5, 3.0]), (1, [0.5, 3.0])])
def test_self_intersection_names_the_right_edges_with_curved_edges(curved, rel):
    # a square whose left (3) or right (1) edge, a quadratic, bulges through the opposite straight edge
    panel = _square_panel()
    panel["edges"][curved]["curvature"] = {"type": "quadratic", "params": [rel]}
    spec = _spec({"pattern": {"panels": {"p": panel}}})
    problems = [p for p in validate(spec) if "crosses itself" in p.message]
    assert problems
    named = {problems[0].edge, int(problems[0].message.split("crosses edge ")[1].split(")")[0])}
    assert named == {1, 3}, problems[0]


def test_degenerate_edge():
    panel = _square_panel()
    panel["vertices"].append([10, 10])
    panel["edges"] = [{"endpoints": [0, 1]}, {"endpoints": [1, 1]}, {"endpoints": [1, 2]},
                      {"endpoints": [2, 3]}, {"endpoints": [3, 0]}]
    _assert_refused(_spec({"pattern": {"panels": {"sq": panel}}}), "sq", 1, "degenerate edge")


def test_outline_edges_do_not_chain():
    panel = _square_panel()
    panel["edges"] = [{"endpoints": [0, 1]}, {"endpoints": [2, 3]}, {"endpoints": [1, 2]}, {"endpoints": [3, 0]}]
    _assert_refused(_spec({"pattern": {"panels": {"sq": panel}}}), "sq", 0, "next edge starts at vertex 2")


def test_good_square_is_clean():
    assert validate(_spec({"pattern": {"panels": {"sq": _square_panel()}}})) == []


@pytest.mark.parametrize("text, words", [
    ("{not json", "not valid JSON"),
    (b"\xff\xfe\x00garbage", "not valid JSON"),
    ('{"panels": {}}', "no 'pattern' object"),
    ("[1, 2, 3]", "no 'pattern' object"),
    ('{"pattern": {"panels": {}}}', "invalid pattern"),
    ('{"pattern": {"panels": {"a": {"vertices": [[0, 0], [1, 0]], "edges": [{"endpoints": [0, 5]}]}}}}',
     "names vertex 5"),
])
def test_parse_pattern_refusals_are_one_line(text, words):
    with pytest.raises(InputError) as ei:
        parse_pattern(text, source="up.json")
    msg = str(ei.value)
    assert words in msg and msg.startswith("up.json: ")
    assert "\n" not in msg


def test_load_pattern_missing_and_empty(tmp_path):
    with pytest.raises(InputError, match="not found"):
        load_pattern(tmp_path / "nope.json")
    (tmp_path / "empty.json").write_text("")
    with pytest.raises(InputError, match="empty"):
        load_pattern(tmp_path / "empty.json")
