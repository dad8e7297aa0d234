"""DXF cutting patterns (engine.pattern.dxf*): real pattern-CAD exports (../shared/samples/dxf)
read in every graded size, their garments inferred and built; ASTM/AAMA-style files written and
read back as the same pattern; bad files refused clearly."""

from __future__ import annotations

import json
import xml.etree.ElementTree as ET

import ezdxf
import numpy as np
import pytest
from typer.testing import CliRunner

from engine.cli import app
from engine.errors import InputError
from engine.pattern import geometry as geo
from engine.pattern.dxf import (Assembly, assembly_of, import_dxf, import_pattern, load_assembly, parse_assembly,
                                piece_areas, read_dxf, write_dxf)
from engine.pattern.dxf_read import read_pattern
from engine.pattern.io import load_pattern
from engine.pattern.validate import check
from tests.samples import DXF_SAMPLES, SAMPLE_BODY, SAMPLE_SKIRT

# the samples' README: pieces x sizes of each file
SAMPLE_TABLE = {"MEN_CLASSIC_TEE.DXF": (7, 15), "WM_SLIM_TANK.DXF": (2, 14), "GMX1016S18_AAMA.DXF": (10, 15),
                "GMX1016S18_ASTM.DXF": (10, 15), "GMH1006F18_AAMA.DXF": (6, 15), "GLX4802S19_AAMA.DXF": (3, 14),
                "ORILEGWB_AAMA.DXF": (2, 14), "simple.DXF": (4, 14), "drill-holes.DXF": (8, 15),
                "annotation.DXF": (17, 15), "clo-pattern.dxf": (9, 1)}
_READ: dict = {}


def sample(name):
    """A sample file read once per test process (the largest takes a second)."""
    if name not in _READ:
        _READ[name] = read_pattern(DXF_SAMPLES / name)
    return _READ[name]


def _lengths(spec, name):
    p = spec.pattern.panels[name]
    return np.array([geo.edge_length(p, e, spec.scale) for e in p.edges]) * 100


def _edge_points(spec, name, k=24):
    p = spec.pattern.panels[name]
    return [geo.edge_samples(p, e, spec.scale, k) * 100 for e in p.edges]


def _round_trip(spec, tmp_path):
    write_dxf(spec, tmp_path / "p.dxf")
    (tmp_path / "a.json").write_text(json.dumps(assembly_of(spec)))
    back, notes = import_dxf(tmp_path / "p.dxf", load_assembly(tmp_path / "a.json"))
    return back, notes


def test_the_sample_skirt_comes_back_from_dxf_as_the_same_pattern(tmp_path):
    spec = load_pattern(SAMPLE_SKIRT)
    back, notes = _round_trip(spec, tmp_path)
    assert notes == []
    assert list(back.pattern.panels) == list(spec.pattern.panels)
    assert back.pattern.panel_order == spec.pattern.panel_order
    assert [[a.model_dump(), b.model_dump()] for a, b in back.pattern.stitches] == \
        [[a.model_dump(), b.model_dump()] for a, b in spec.pattern.stitches]
    for name, p in spec.pattern.panels.items():
        q = back.pattern.panels[name]
        assert len(q.edges) == len(p.edges), name
        assert q.translation == p.translation and q.rotation == p.rotation
        # the same outline, edge by edge (its arcs come back as arcs)
        for a, b in zip(_edge_points(spec, name), _edge_points(back, name)):
            assert np.abs(a - b).max() < 0.01, name  # cm
    check(back)


def test_a_catalogue_shirt_with_curved_armholes_comes_back_edge_for_edge(tmp_path):
    from engine.body.default import default_body
    from engine.garment.catalogue import make_garment

    spec, _, _ = make_garment("shirt", default_body("female"), "M")
    back, _ = _round_trip(spec, tmp_path)
    for name in spec.pattern.panels:
        la, lb = _lengths(spec, name), _lengths(back, name)
        assert len(la) == len(lb), name  # each curve between two corners is one edge again
        np.testing.assert_allclose(lb, la, rtol=0.003, atol=0.02)
        for a, b in zip(_edge_points(spec, name), _edge_points(back, name)):
            assert np.abs(a - b).max() < 0.15, name  # within the cubic fit's 1 mm
    assert back.tryon.placement == spec.tryon.placement
    # a mirrored copy of the front: its cubic curves mirrored too
    asm = Assembly.model_validate(assembly_of(spec) | {"panels": {"front_m": {"copy_of": "front"}}})
    mirrored, _ = import_dxf(tmp_path / "p.dxf", asm)
    for a, b in zip(_edge_points(mirrored, "front"), _edge_points(mirrored, "front_m")):
        np.testing.assert_allclose(b, a * [-1, 1], atol=1e-9)


def _aama(path, units_text="Units: ENGLISH", insunits=None, turn=True, quantity=2):
    """A file as pattern CAD writes it: a block per piece (old-style POLYLINE boundary on layer
    1 with an arc as a bulge, turn points on layer 2, a notch on layer 4, piece texts),
    inserted rotated; units in the style text."""
    doc = ezdxf.new("R2000")
    doc.header["$INSUNITS"] = 0 if insunits is None else insunits  # ezdxf's default is metres
    for layer in ("1", "2", "4"):
        doc.layers.add(layer)
    blk = doc.blocks.new("SLEEVE")
    # inches: a 16 x 20 sleeve with a curved cap (bulge between the two top corners)
    pts = [(0, 0, 0), (16, 0, 0), (16, 20, 0.4), (0, 20, 0)]  # (x, y, bulge)
    blk.add_polyline2d([(x, y) for x, y, _ in pts], close=True, dxfattribs={"layer": "1"})
    poly = list(blk.query("POLYLINE"))[0]
    for v, (_, _, b) in zip(poly.vertices, pts):
        v.dxf.bulge = b
    if turn:
        for x, y, _ in pts:
            blk.add_point((x, y), dxfattribs={"layer": "2"})
    blk.add_line((8, 0), (8, 0.25), dxfattribs={"layer": "4"})
    blk.add_text("Piece Name: sleeve", dxfattribs={"layer": "1"})
    blk.add_text(f"Quantity: {quantity}", dxfattribs={"layer": "1"})
    msp = doc.modelspace()
    msp.add_blockref("SLEEVE", (100, 50), dxfattribs={"rotation": 90})
    if units_text:
        msp.add_text(units_text, dxfattribs={"layer": "1"})
    doc.saveas(str(path))
    return path


def test_an_aama_file_from_pattern_cad_reads_with_its_units_corners_and_names(tmp_path):
    pieces = read_dxf(_aama(tmp_path / "s.dxf"))
    assert [p.name for p in pieces] == ["sleeve"]
    p = pieces[0]
    assert p.quantity == 2
    lo, hi = p.outline.min(axis=0), p.outline.max(axis=0)
    # inches -> cm, in the piece's own frame (the insert's rotation is the layout's, not the piece's)
    np.testing.assert_allclose(hi[0] - lo[0], 16 * 2.54, atol=1e-6)
    np.testing.assert_allclose(hi[1] - lo[1], (20 + 0.4 * 8) * 2.54, atol=1e-3)  # the cap's sagitta: bulge x half chord
    assert len(p.corners) == 4
    spec, notes = import_dxf(tmp_path / "s.dxf")
    panel = spec.pattern.panels["sleeve"]
    assert len(panel.edges) == 4
    cap = [e for e in panel.edges if e.curvature is not None]
    assert len(cap) == 1 and cap[0].curvature.type == "circle"  # the bulge is an arc
    # a sleeve alone is no garment: the piece is imported, no seams, and the notes say why
    assert spec.pattern.stitches == [] and any("no front and back" in n for n in notes)
    # the standard's units text wins over $INSUNITS (a CAD default, often), --units over both
    assert np.ptp(read_dxf(_aama(tmp_path / "e.dxf", insunits=6))[0].outline[:, 0]) == pytest.approx(16 * 2.54)
    read_cm = read_dxf(_aama(tmp_path / "c.dxf", units_text=None, insunits=5))[0]
    np.testing.assert_allclose(np.ptp(read_cm.outline[:, 0]), 16.0, atol=1e-9)
    read_in = read_dxf(tmp_path / "c.dxf", units="in")[0]
    np.testing.assert_allclose(np.ptp(read_in.outline[:, 0]), 16 * 2.54, atol=1e-9)


def test_without_turn_points_the_sharp_turns_are_the_corners(tmp_path):
    p_turn = read_dxf(_aama(tmp_path / "a.dxf"))[0]
    p_none = read_dxf(_aama(tmp_path / "b.dxf", turn=False))[0]
    assert len(p_none.corners) == 4
    np.testing.assert_allclose(p_none.outline[p_none.corners], p_turn.outline[p_turn.corners], atol=1e-9)


def test_a_plain_drawing_gives_a_piece_per_closed_outline(tmp_path):
    doc = ezdxf.new("R2010")
    doc.header["$INSUNITS"] = 5  # cm
    msp = doc.modelspace()
    msp.add_lwpolyline([(0, 0), (30, 0), (30, 50), (0, 50)], close=True)
    msp.add_circle((100, 0), 10)  # a circle (a drill hole, a marker): no cut line
    msp.add_spline(fit_points=[(200, 0), (220, 10), (200, 20), (180, 10), (200, 0)])  # a round piece, closed
    msp.add_lwpolyline([(0, 100), (10, 100)])  # open: ignored
    doc.saveas(str(tmp_path / "plain.dxf"))
    pieces = read_dxf(tmp_path / "plain.dxf")
    assert [p.name for p in pieces] == ["piece1", "piece2"]
    assert len(pieces[0].corners) == 4 and np.allclose(np.ptp(pieces[0].outline, axis=0), [30, 50])
    assert len(pieces[1].corners) == 4  # no corners: four edges of equal length
    spec, _ = import_dxf(tmp_path / "plain.dxf")
    lengths = _lengths(spec, "piece2")
    assert len(lengths) == 4 and lengths.max() / lengths.min() < 1.1


def test_a_copy_of_a_piece_cut_twice_is_its_mirror_image(tmp_path):
    _aama(tmp_path / "s.dxf")
    asm = Assembly.model_validate({"panels": {
        "sleeve": {"translation": [20, 120, 0], "rotation": [0, 90, 0]},
        "sleeve_l": {"copy_of": "sleeve", "translation": [-20, 120, 0], "rotation": [0, -90, 0]}},
        "stitches": [[{"panel": "sleeve", "edge": 0}, {"panel": "sleeve_l", "edge": 0}]]})
    spec, notes = import_dxf(tmp_path / "s.dxf", asm)
    assert not any("cut 2 times" in n for n in notes)
    a, b = _edge_points(spec, "sleeve"), _edge_points(spec, "sleeve_l")
    for ea, eb in zip(a, b):
        np.testing.assert_allclose(eb, ea * [-1, 1], atol=1e-9)  # the cap's arc mirrored too
    assert spec.pattern.panels["sleeve_l"].translation == (-20, 120, 0)
    check(spec)


@pytest.mark.parametrize("make, units, match", [
    (lambda p: _aama(p, units_text=None), None, "does not say its units"),
    (lambda p: _aama(p), "mm", "which is no garment piece"),  # an inch file read as mm: 4 cm pieces... 1.6 cm
    (lambda p: p.write_text("this is not a DXF\n"), None, "not a readable DXF"),
    (lambda p: p.write_bytes(b""), None, "empty file"),
    (lambda p: ezdxf.new().saveas(str(p)), "cm", "no pattern pieces"),
])
def test_bad_dxf_files_get_clear_errors(tmp_path, make, units, match):
    path = tmp_path / "bad.dxf"
    make(path)
    with pytest.raises(InputError, match=match):
        read_dxf(path, units)


def test_bad_assemblies_get_clear_errors(tmp_path):
    _aama(tmp_path / "s.dxf")
    for asm, match in (({"panels": {"cuff": {}}}, "'cuff' is not in s.dxf .*sleeve"),
                       ({"panels": {"x": {"copy_of": "cuff"}}}, "copies 'cuff'"),
                       ({"panels": {"sleeve": {"copy_of": "sleeve"}}}, "already a piece"),
                       ({"panel_order": ["cuff"]}, "panel_order names cuff")):
        with pytest.raises(InputError, match=match):
            import_dxf(tmp_path / "s.dxf", Assembly.model_validate(asm))
    (tmp_path / "a.json").write_text('{"stitches": [[["sleeve", 0]]], "colour": 3}')
    with pytest.raises(InputError, match="invalid assembly"):
        load_assembly(tmp_path / "a.json")


def test_pattern_commands(tmp_path):
    runner = CliRunner()
    r = runner.invoke(app, ["pattern", "export", str(SAMPLE_SKIRT), "--out", str(tmp_path / "exp")])
    assert r.exit_code == 0, r.output
    assert {p.name for p in (tmp_path / "exp").iterdir()} == {"pattern.dxf", "assembly.json", "pattern.svg"}
    # without the assembly (a skirt is not inferred): the panels, what is missing, every edge numbered
    r = runner.invoke(app, ["pattern", "import", str(tmp_path / "exp" / "pattern.dxf"), "--out", str(tmp_path / "bare")])
    assert r.exit_code == 0, r.output
    assert "give an assembly file" in r.output
    svg = (tmp_path / "bare" / "pattern.svg").read_text()
    assert all(f">e{i}</text>" in svg for i in range(4))
    assert load_pattern(tmp_path / "bare" / "pattern.json").pattern.stitches == []
    # with it: the sample skirt again
    r = runner.invoke(app, ["pattern", "import", str(tmp_path / "exp" / "pattern.dxf"), "--assembly",
                            str(tmp_path / "exp" / "assembly.json"), "--out", str(tmp_path / "imp")])
    assert r.exit_code == 0, r.output
    assert len(load_pattern(tmp_path / "imp" / "pattern.json").pattern.stitches) == 6
    # a stitch to an edge the DXF's panel does not have: exit 2, the reason, nothing written
    asm = json.loads((tmp_path / "exp" / "assembly.json").read_text())
    asm["stitches"][0][1]["edge"] = 9
    (tmp_path / "bad.json").write_text(json.dumps(asm))
    r = runner.invoke(app, ["pattern", "import", str(tmp_path / "exp" / "pattern.dxf"), "--assembly",
                            str(tmp_path / "bad.json"), "--out", str(tmp_path / "bad")])
    assert r.exit_code == 2 and "edge 9" in r.output, r.output
    assert not (tmp_path / "bad").exists()


@pytest.mark.integration
def test_drape_takes_a_dxf_by_its_own_size_names(tmp_path):
    r = CliRunner().invoke(app, ["drape", "--body", "default:male", "--garment", str(DXF_SAMPLES / "WM_SLIM_TANK.DXF"),
                                 "--size", "M", "--out", str(tmp_path / "out")])
    assert r.exit_code == 2 and "no size 'M'; its sizes are 26, 28, 30" in r.output, r.output
    assert not (tmp_path / "out").exists()
    # a DXF whose pieces make no garment the inference knows: the reason, before any simulation
    write_dxf(load_pattern(SAMPLE_SKIRT), tmp_path / "skirt.dxf")
    r = CliRunner().invoke(app, ["drape", "--body", "default:female", "--garment", str(tmp_path / "skirt.dxf"),
                                 "--out", str(tmp_path / "out")])
    assert r.exit_code == 2 and "give an assembly file" in r.output, r.output


@pytest.mark.slow
def test_the_sample_skirt_from_dxf_drapes_on_the_sample_body(tmp_path):
    """The whole way a shop's DXF goes: export, import with the assembly, drape (quality bars of
    the sample skirt)."""
    from engine.body import resolve_body
    from engine.scene.tryon import run_tryon

    back, _ = _round_trip(load_pattern(SAMPLE_SKIRT), tmp_path)
    res, rep = run_tryon(resolve_body(str(SAMPLE_BODY)), back)
    assert rep["settled"]
    assert rep["seam_gap_mm"]["max"] < 10
    assert rep["penetration_mm"]["max"] <= 3.0 and rep["penetration_mm"]["p99"] <= 1.0
    assert rep["strain"]["max"] <= rep["strain"]["threshold"] + 0.01


# --- the real exports ------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(SAMPLE_TABLE))
def test_every_sample_export_imports_all_its_pieces_and_sizes(name):
    p = sample(name)
    assert (len(p.pieces), len(p.sizes)) == SAMPLE_TABLE[name]
    assert all(len(q.shapes) == len(p.sizes) for q in p.pieces)  # every piece graded in every size
    # sizes in the file's order, its sample size one of them
    assert p.sample_size in p.sizes
    if p.sizes[0].isdigit():
        assert [int(s) for s in p.sizes] == sorted(int(s) for s in p.sizes)
    # the sample size's area of every piece within 0.5 % of the shoelace area of its chained cut line
    areas = piece_areas(p, [p.sample_size])
    assert len(areas) == len(p.pieces)
    assert max(abs(a / f - 1) for a, f in areas.values()) < 0.005
    # grading: a piece grows with the size (its first and last sizes)
    for q in p.pieces:
        first, last = q.shapes[p.sizes[0]], q.shapes[p.sizes[-1]]
        assert last.file_area >= first.file_area


def test_units_and_layers_are_read_as_the_files_state_them():
    tee, shirt, clo = sample("MEN_CLASSIC_TEE.DXF"), sample("GMX1016S18_ASTM.DXF"), sample("clo-pattern.dxf")
    assert tee.units == "in" and "ENGLISH" in tee.units_note
    assert shirt.units == "mm" and "millimetres" in shirt.units_note  # METRIC: mm, from the pieces' size
    front = tee.piece("REGULAR TEEFR")
    s50 = front.shapes["50"]
    assert len(s50.breaks) == 6  # the cut line came in six open parts
    assert s50.grain is not None and len(s50.mirror) == 1 and len(s50.notches) == 3
    assert len(front.shapes["42"].notches) == 3  # carried from the sample size
    assert front.quantity == 1 and front.category == "FRONT"
    sleeve = tee.piece("REGULAR TEESL1")
    assert sleeve.quantity == 0 and sleeve.cut == 2  # "Quantity: 0", "ANNOTATION: 2XFABRIC"
    assert shirt.layers.get("84") and shirt.layers.get("85")  # ASTM's validation curves: counted, not used
    assert len(clo.pieces) == 9 and clo.sizes == ["M"]  # CLO's export, its bad group codes recovered


def test_the_tee_is_inferred_with_sleeves_collar_and_seams():
    imp = import_pattern(DXF_SAMPLES / "MEN_CLASSIC_TEE.DXF", "56", pattern=sample("MEN_CLASSIC_TEE.DXF"))
    assert imp.kind == "top"
    assert list(imp.spec.pattern.panels) == ["front", "back", "sleeve_l", "sleeve_r", "collar"]
    labels = set(imp.labels)
    for side in ("left", "right"):
        for seam in ("shoulder", "side", "sleeve cap, front", "sleeve cap, back", "underarm"):
            assert f"{seam} ({side})" in labels
    assert {"collar 1", "collar 2", "collar 3", "collar ends"} <= labels
    # the model's two-piece sleeve is not inferred: its one-piece alternative is used, and said so
    assert any("cut in two pieces" in x and "REGULAR TEESL1" in x for x in imp.left_out)
    assert any("REGULAR TEESFCO" in x and "quantity 0" in x for x in imp.left_out)
    assert any("REGULAR TEECO" in n and "lengthened" in n for n in imp.notes)  # a rib, shorter than the neckline
    assert check(imp.spec) == []  # every stitch's two edges within 10 % of each other
    hints = imp.spec.tryon.placement
    assert hints["front"].role == "bodice" and hints["sleeve_l"].region == "left_arm" and hints["collar"].role == "band"
    # the front is unfolded (cut on the fold): twice its piece's area, within 0.5 %
    a, f = imp.areas["front"]
    assert abs(a / f - 1) < 0.005 and f == pytest.approx(2 * sample("MEN_CLASSIC_TEE.DXF").piece(
        "REGULAR TEEFR").shapes["56"].file_area)


@pytest.mark.parametrize("name, panels", [
    ("GLX4802S19_AAMA.DXF", ["leg_l", "leg_r"]),
    ("ORILEGWB_AAMA.DXF", ["leg_l", "leg_r", "waistband"]),
    ("WM_SLIM_TANK.DXF", ["front", "back"]),
    ("GMH1006F18_AAMA.DXF", ["front", "back", "sleeve_l", "sleeve_r", "collar"]),
    ("drill-holes.DXF", ["front", "back", "sleeve_l", "sleeve_r", "collar"]),
])
def test_the_whole_garments_are_inferred(name, panels):
    p = sample(name)
    imp = import_pattern(DXF_SAMPLES / name, p.sizes[len(p.sizes) // 2], pattern=p)
    assert list(imp.spec.pattern.panels) == panels
    assert check(imp.spec) == []
    assert max(abs(a / f - 1) for a, f in imp.areas.values()) < 0.005
    if "leg_l" in panels:
        assert {"front rise", "back rise", "inseam (left)", "inseam (right)"} <= set(imp.labels)
        # leggings: a stretch knit, said by a piece's category ('TIGHT LEG ...') or by legs' openings
        # narrower than a foot (ORILEGWB's pieces name no fabric); the spec and the assembly carry it
        fabric, why = imp.fabric
        assert fabric == "stretch_knit" and imp.spec.tryon.fabric == fabric and imp.assembly["tryon"]["fabric"] == fabric
        assert ("'TIGHT LEG" in why) if name.startswith("GLX") else ("narrower than a foot" in why)
        assert any(n.startswith("fabric: stretch_knit") for n in imp.notes)
    else:
        assert imp.fabric is None and imp.spec.tryon.fabric is None  # woven tops: the user's fabric or cotton
    if name == "drill-holes.DXF":  # a polo: its placket and interlinings said to be left out
        assert sum("placket" in x or "interlining" in x for x in imp.left_out) == 4


def test_an_inferred_assembly_given_back_serves_every_size_and_can_be_corrected(tmp_path):
    p = sample("MEN_CLASSIC_TEE.DXF")
    imp = import_pattern(DXF_SAMPLES / "MEN_CLASSIC_TEE.DXF", "56", pattern=p)
    asm = json.loads(json.dumps(imp.assembly))
    back = import_pattern(DXF_SAMPLES / "MEN_CLASSIC_TEE.DXF", "56", assembly=parse_assembly(asm), pattern=p)
    assert back.labels == imp.labels
    for (a, b), (c, d) in zip(back.spec.pattern.stitches, imp.spec.pattern.stitches):
        assert (a.panel, a.edge, b.panel, b.edge) == (c.panel, c.edge, d.panel, d.edge)
    for size in ("42", "70"):  # corners and fractions: the same assembly in the smallest and largest size
        other = import_pattern(DXF_SAMPLES / "MEN_CLASSIC_TEE.DXF", size, assembly=parse_assembly(asm), pattern=p)
        assert check(other.spec) == [] and set(other.labels) == set(imp.labels)
    # the user's correction wins: no collar
    asm["panels"].pop("collar")
    asm["seams"] = [s for s in asm["seams"] if "collar" not in s["label"]]
    fixed = import_pattern(DXF_SAMPLES / "MEN_CLASSIC_TEE.DXF", "56", assembly=parse_assembly(asm), pattern=p)
    assert "collar" not in fixed.spec.pattern.panels and not any("collar" in x for x in fixed.labels)
    asm["seams"][0]["a"]["start"] = [40, 0.0]
    with pytest.raises(InputError, match="corner 0..7"):
        import_pattern(DXF_SAMPLES / "MEN_CLASSIC_TEE.DXF", "56", assembly=parse_assembly(asm), pattern=p)


def test_pattern_import_prints_the_summary_and_writes_the_seams(tmp_path):
    r = CliRunner().invoke(app, ["pattern", "import", str(DXF_SAMPLES / "WM_SLIM_TANK.DXF"), "--size", "40",
                                 "--out", str(tmp_path), "--json"])
    assert r.exit_code == 0, r.output
    out = json.loads(r.stdout)
    assert out["units"] == "in" and out["sizes"][:3] == ["26", "28", "30"] and len(out["sizes"]) == 14
    front = next(q for q in out["pieces"] if q["name"] == "TANK_SR_FR")
    assert front["quantity"] == 1 and front["sizes"]["36"]["notches"] == 2 and front["sizes"]["40"]["grain_line"]
    assert front["sizes"]["52"]["area_cm2"] > front["sizes"]["26"]["area_cm2"]
    assert out["garment"]["kind"] == "top" and out["garment"]["size"] == "40"
    assert {"shoulder (left)", "side (right)"} <= set(out["garment"]["seams"])
    assert {p.name for p in tmp_path.iterdir()} == {"pattern.json", "pattern.svg", "assembly.json"}
    svg = ET.fromstring((tmp_path / "pattern.svg").read_text())
    texts = [t.text for t in svg.iter("{http://www.w3.org/2000/svg}text")]
    assert texts.count("1") == 2 and "1  shoulder (left)" in texts  # seam 1 numbered on both sides, in the legend
    assert svg.get("viewBox") and svg.get("width") == "100%"


def _open_cut_line(path, gap):
    doc = ezdxf.new("R12")
    blk = doc.blocks.new("FRONT_M")
    blk.add_text("Piece Name: FRONT")
    blk.add_text("Size: M")
    blk.add_polyline2d([(0, 0), (400, 0), (400, 600)], dxfattribs={"layer": "1"})
    blk.add_polyline2d([(400, 600), (0, 600), (0, gap)], dxfattribs={"layer": "1"})
    doc.modelspace().add_blockref("FRONT_M", (0, 0))
    doc.modelspace().add_text("Units: METRIC")
    doc.saveas(str(path))
    return path


def test_bad_inputs_name_the_piece_and_the_limit(tmp_path, monkeypatch):
    import engine.pattern.dxf_read as dr

    assert len(read_pattern(_open_cut_line(tmp_path / "ok.dxf", 0)).pieces) == 1  # parts that meet: closed
    with pytest.raises(InputError, match=r"piece 'FRONT' in size M: the cut line .* does not close .*3.0 mm"):
        read_pattern(_open_cut_line(tmp_path / "gap.dxf", 3))
    with pytest.raises(InputError, match="no garment piece: are the units right"):
        read_pattern(DXF_SAMPLES / "WM_SLIM_TANK.DXF", units="m")
    (tmp_path / "bin.dxf").write_bytes(b"\x00\x01binary" * 100)
    with pytest.raises(InputError, match="not a readable DXF"):
        read_pattern(tmp_path / "bin.dxf")
    monkeypatch.setattr(dr, "MAX_DXF_BYTES", 50_000)
    with pytest.raises(InputError, match="MB, larger than"):
        read_pattern(DXF_SAMPLES / "WM_SLIM_TANK.DXF")
    monkeypatch.setattr(dr, "MAX_DXF_BYTES", 40_000_000)
    monkeypatch.setattr(dr, "MAX_PIECE_VERTICES", 20)
    with pytest.raises(InputError, match="piece 'TANK_SR_BK' in size 26: the cut line has .* vertices"):
        read_pattern(DXF_SAMPLES / "WM_SLIM_TANK.DXF")
    monkeypatch.undo()
    with pytest.raises(InputError, match="no size '99'; its sizes are 26"):
        import_pattern(DXF_SAMPLES / "WM_SLIM_TANK.DXF", "99")


def test_size_auto_takes_the_smallest_size_with_room_for_the_body():
    from engine.pattern.dxf_size import EASE_CM, garment_girth, recommend_size

    p = sample("MEN_CLASSIC_TEE.DXF")
    chests = [garment_girth(p, s)[1] for s in ("42", "56", "70")]
    assert chests[0] < chests[1] < chests[2]  # graded
    size, why = recommend_size(p, {"chest": 101.0})
    assert garment_girth(p, size)[1] >= 101 + EASE_CM["chest"] and "chest" in why
    smaller = p.sizes[p.sizes.index(size) - 1]
    assert garment_girth(p, smaller)[1] < 101 + EASE_CM["chest"]
    with pytest.raises(InputError, match="larger than the largest size"):
        recommend_size(p, {"chest": 300.0})


@pytest.mark.slow
@pytest.mark.parametrize("name, body, fabric", [
    ("MEN_CLASSIC_TEE.DXF", "default:male", "cotton"),
    ("GMH1006F18_AAMA.DXF", "default:male", "cotton"),
    ("ORILEGWB_AAMA.DXF", "default:female", None),
    ("GLX4802S19_AAMA.DXF", "default:female", None),
])
def test_a_dxf_alone_drapes_in_its_middle_size(name, body, fabric):
    """Seams inferred, nothing else given: settled, seams closed, no penetration beyond the
    usual bars, strain within the fabric's threshold + 1 %; a top's sleeves go round the arms and
    its collar round the neck, leggings' legs round the legs (in the stretch knit they suggest:
    cut 16-18 % under default:female's hips, they are worn stretched)."""
    from engine.body import resolve_body
    from engine.body.measure import measure
    from engine.scene.request import TryOnRequest
    from engine.scene.tryon import dress_request

    b = resolve_body(body)
    p = sample(name)
    res, rep = dress_request(b, TryOnRequest(garment=str(DXF_SAMPLES / name), size=p.sizes[len(p.sizes) // 2],
                                             fabric=fabric))
    spec = res.spec
    assert rep["settled"]
    gap = rep["seam_gap_mm"]  # closed: welded within 1 cm, or a few pairs by the stall rule within 2 cm
    assert gap["max"] < 10 or (gap["snapped"] <= 4 and gap["max"] <= 20), gap
    assert rep["penetration_mm"]["max"] <= 2.0 and rep["penetration_mm"]["p99"] <= 0.5
    assert rep["strain"]["max"] <= rep["strain"]["threshold"] + 0.01 and not rep["tight"]
    x, m = res.positions, measure(b)
    if "leg_l" in spec.pattern.panels:  # cloth round both legs at the knee, none above the waist
        assert rep["fabric"] == "stretch_knit" and rep["fabric_why"].startswith("the pattern's")
        assert rep["shift_mm"]["top"] > -60  # it stays up (friction holds it while it is sewn)
        knee = np.abs(x[:, 1] - m.knee_height) < 0.03
        assert (x[knee, 0] > 0.03).sum() > 20 and (x[knee, 0] < -0.03).sum() > 20
        assert x[:, 1].max() < m.waist_height + 0.05
        return
    sh = m.shoulder_height
    arm = (np.abs(x[:, 0]) > 0.5 * m.shoulder_width + 0.05) & (x[:, 1] < sh)  # out past the shoulders
    assert (arm & (x[:, 0] > 0)).sum() > 100 and (arm & (x[:, 0] < 0)).sum() > 100
    neck = (np.abs(x[:, 0]) < 0.06) & (x[:, 1] > sh + 0.02)  # round the neck: before and behind it
    assert (neck & (x[:, 2] > 0)).sum() > 5 and (neck & (x[:, 2] < 0)).sum() > 5


def test_a_sew_line_is_what_is_simulated(tmp_path):
    """A piece with seam allowance: its sew line (layer 14) is the panel's outline, not the cut line."""
    from engine.pattern.dxf import summary

    doc = ezdxf.new("R12")
    blk = doc.blocks.new("P")
    blk.add_text("Piece Name: PATCH")
    blk.add_polyline2d([(0, 0), (300, 0), (300, 200), (0, 200)], close=True, dxfattribs={"layer": "1"})
    blk.add_polyline2d([(10, 10), (290, 10), (290, 190), (10, 190)], close=True, dxfattribs={"layer": "14"})
    doc.modelspace().add_blockref("P", (0, 0))
    doc.modelspace().add_text("Units: METRIC")
    doc.saveas(str(tmp_path / "patch.dxf"))
    p = read_pattern(tmp_path / "patch.dxf")
    sh = p.pieces[0].shapes["one size"]
    assert sh.file_area == pytest.approx(600.0) and sh.area == pytest.approx(28 * 18)  # cm^2 (mm in the file)
    (a, f), = piece_areas(p).values()
    assert f == pytest.approx(28 * 18) and abs(a / f - 1) < 1e-6
    assert summary(p)["pieces"][0]["sizes"]["one size"]["sew_line_area_cm2"] == pytest.approx(504.0)


def test_the_fabric_is_the_users_else_the_patterns_else_cotton():
    """A try-on's fabric: the one asked for; else the pattern's own (a DXF of leggings suggests the
    stretch knit, and says why); else cotton. A fabric worn stretched is sewn with friction (it
    would slide down the body to where it is least stretched); cotton is not."""
    from engine.body import resolve_body
    from engine.cloth.fabrics import get_fabric
    from engine.scene.request import TryOnOptions
    from engine.scene.tryon import sewing_friction, with_fabric

    p = sample("ORILEGWB_AAMA.DXF")
    legs = import_pattern(DXF_SAMPLES / "ORILEGWB_AAMA.DXF", pattern=p).spec
    req, why = with_fabric(TryOnOptions(), legs)
    assert req.fabric == "stretch_knit" and why.startswith("the pattern's: its legs' openings")
    req, why = with_fabric(TryOnOptions(fabric="denim"), legs)
    assert req.fabric == "denim" and why == "asked for"
    req, why = with_fabric(TryOnOptions(), load_pattern(SAMPLE_SKIRT))
    assert req.fabric == "cotton" and why == "the default"
    body = resolve_body("default:female")
    scale, why = sewing_friction(body, get_fabric("stretch_knit"))
    assert scale == 1.0 and "worn stretched" in why
    assert sewing_friction(body, get_fabric("cotton")) == (0.0, None)


def test_drape_takes_a_dxf_assembly_and_units_and_refuses_them_for_other_patterns(tmp_path):
    """--assembly and --units go with a DXF (the assembly then says how it is sewn, in any of its
    sizes); for a GarmentCode pattern or a catalogue garment they are refused before anything runs."""
    from engine.scene.garments import resolve_garment

    spec = load_pattern(SAMPLE_SKIRT)
    write_dxf(spec, tmp_path / "skirt.dxf")
    (tmp_path / "a.json").write_text(json.dumps(assembly_of(spec)))
    got, place, name = resolve_garment(str(tmp_path / "skirt.dxf"), None, None, units="mm",
                                       assembly=str(tmp_path / "a.json"))
    assert list(got.pattern.panels) == list(spec.pattern.panels) and place is None
    assert len(got.pattern.stitches) == len(spec.pattern.stitches) and name == "skirt.dxf (size one size)"
    for garment in (str(SAMPLE_SKIRT), "skirt"):
        r = CliRunner().invoke(app, ["drape", "--body", "default:female", "--garment", garment, "--assembly",
                                     str(tmp_path / "a.json"), "--out", str(tmp_path / "out")])
        assert r.exit_code == 2 and "go with a DXF pattern" in r.output, r.output


def test_an_assembly_past_a_garments_size_is_refused_at_once(tmp_path):
    """An assembly with thousands of panels (copies of a piece) or stitches is no garment: refused
    when read, before anything is built (building and checking them takes seconds)."""
    from engine.pattern.dxf import MAX_PANELS, MAX_STITCHES

    spec = load_pattern(SAMPLE_SKIRT)
    asm = assembly_of(spec)
    first = next(iter(asm["panels"]))
    many = dict(asm, panels={**asm["panels"], **{f"copy{k}": {"copy_of": first} for k in range(MAX_PANELS)}})
    with pytest.raises(InputError, match="panels: Dictionary should have at most 200"):
        parse_assembly(many, "a.json")
    with pytest.raises(InputError, match="stitches: List should have at most"):
        parse_assembly(dict(asm, stitches=asm["stitches"] * (MAX_STITCHES // len(asm["stitches"]) + 1)), "a.json")
    assert parse_assembly(asm, "a.json").panels.keys() == asm["panels"].keys()
