"""DXF cutting patterns (engine.pattern.dxf): ASTM/AAMA-style files read into GarmentCode specs,
specs written out as DXF and read back as the same pattern, and bad files refused clearly."""

from __future__ import annotations

import json

import ezdxf
import numpy as np
import pytest
from typer.testing import CliRunner

from engine.cli import app
from engine.errors import InputError
from engine.pattern import geometry as geo
from engine.pattern.dxf import Assembly, assembly_of, import_dxf, load_assembly, read_dxf, write_dxf
from engine.pattern.io import load_pattern
from engine.pattern.validate import check
from tests.samples import SAMPLE_BODY, SAMPLE_SKIRT


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
    assert any("cut 2 times" in n for n in notes) and any("no assembly file" in n for n in notes)
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
    msp.add_circle((100, 0), 10)  # not a polyline: ignored
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
    # without the assembly: the panels, a note on what is missing, every edge numbered in the SVG
    r = runner.invoke(app, ["pattern", "import", str(tmp_path / "exp" / "pattern.dxf"), "--out", str(tmp_path / "bare")])
    assert r.exit_code == 0, r.output
    assert "no assembly file" in r.output
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


def test_drape_points_a_dxf_to_the_import(tmp_path):
    write_dxf(load_pattern(SAMPLE_SKIRT), tmp_path / "skirt.dxf")
    r = CliRunner().invoke(app, ["drape", "--body", "default:female", "--garment", str(tmp_path / "skirt.dxf"),
                                 "--out", str(tmp_path / "out")])
    assert r.exit_code == 2 and "tryon pattern import skirt.dxf --assembly" in r.output, r.output
    assert not (tmp_path / "out").exists()


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
