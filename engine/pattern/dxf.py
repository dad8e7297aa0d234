"""Cutting patterns as DXF files, the way pattern CAD systems exchange them (ASTM D6673 / AAMA).

Reading (`read_dxf` -> pieces, `import_dxf` -> a PatternSpec):
- a piece is a DXF block inserted in the drawing; its boundary is the closed polyline on layer
  "1" (the largest, if several); its corners are the POINTs on layer "2" (turn points). A
  drawing without blocks gives one piece per closed polyline. Without turn points, a vertex
  where the outline turns by more than CORNER_DEG is a corner.
- the name is the piece's "Piece Name:" text, else the block's name; "Quantity: N" is noted.
- units: --units, else the style text "Units: METRIC" (mm) / "ENGLISH" (inches), else the
  header's $INSUNITS (mm, cm, m, in; often a CAD default, so second); a file that says none is refused (guessing inches for centimetres makes a
  garment 2.5x too large).
- between two corners the outline becomes one edge: straight when no point is more than
  STRAIGHT_TOL off the chord, else the cubic Bezier that fits it within FIT_TOL (split in two
  where one cubic does not).

The standard "is not intended to represent the relationships between pattern pieces", so a DXF
has no seams and no 3D placement. Those come from an assembly file (JSON, see `Assembly`):
stitches between {panel, edge} (edge numbers as in the imported pattern's SVG), each panel's
GarmentCode translation/rotation (cm, degrees), copies of pieces cut twice (mirrored), and the
optional `tryon` block. Without one, the import writes the panels alone and says what is missing.

Writing (`write_dxf`): each panel a block (boundary on layer 1, turn points on layer 2, piece
name and quantity as text), in millimetres ($INSUNITS = 4, "Units: METRIC").
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from pydantic import BaseModel, ConfigDict, Field, ValidationError

from engine.errors import InputError
from engine.pattern import geometry as geo
from engine.pattern.spec import PatternSpec, StitchSide, TryonExtension

CORNER_DEG = 30.0  # without turn points: the outline turning more than this at a vertex is a corner
STRAIGHT_TOL = 0.02  # cm: a section no further than this off its chord is a straight edge
FIT_TOL = 0.1  # cm: a curved section is one cubic edge when the cubic is this close to it
TURN_SNAP = 0.05  # cm: a turn point this close to an outline vertex marks it (else the nearest is split in)
MAX_PIECE_CM = 400.0  # a piece longer than this (after units) is a units mistake
MIN_PIECE_CM = 3.0  # (a belt loop)
UNITS_CM = {"mm": 0.1, "cm": 1.0, "m": 100.0, "in": 2.54}
_INSUNITS = {1: "in", 4: "mm", 5: "cm", 6: "m"}


@dataclass
class Piece:
    name: str
    outline: np.ndarray  # (M, 2) cm, closed (first point not repeated), in the piece's own frame
    corners: list[int]  # indices into outline, ascending
    quantity: int = 1
    notes: list[str] = field(default_factory=list)


# ------------------------------------------------------------------ reading


def _units(doc, units: str | None, texts: list[str], source: str) -> float:
    if units is not None:
        if units not in UNITS_CM:
            raise InputError(f"units '{units}': use one of {', '.join(UNITS_CM)}")
        return UNITS_CM[units]
    for t in texts:  # the standard's own statement first ($INSUNITS is often a CAD default)
        m = re.match(r"\s*units\s*:\s*(\w+)", t, re.I)
        if m:
            word = m.group(1).lower()
            if word in ("metric", "mm"):
                return UNITS_CM["mm"]
            if word in ("english", "inch", "inches", "imperial"):
                return UNITS_CM["in"]
            if word in UNITS_CM:
                return UNITS_CM[word]
    code = int(doc.header.get("$INSUNITS", 0) or 0)
    if code in _INSUNITS:
        return UNITS_CM[_INSUNITS[code]]
    raise InputError(f"{source}: the DXF does not say its units (no $INSUNITS in its header, no 'Units:' text); "
                     "give them: --units mm, cm, m or in")


def _text_of(e) -> str | None:
    t = e.dxftype()
    if t == "TEXT":
        return e.dxf.text
    if t == "MTEXT":
        return e.plain_text()
    return None


def _layer(e) -> str:
    return str(e.dxf.layer).strip()


def _closed_polylines(entities) -> list[np.ndarray]:
    """(K, 2) point lists of the closed (or end-to-start) polylines among entities, curves
    (bulges, splines) flattened to 0.1 units."""
    from ezdxf import path as dxfpath

    out = []
    for e in entities:
        if e.dxftype() not in ("LWPOLYLINE", "POLYLINE", "SPLINE"):
            continue
        try:
            p = dxfpath.make_path(e)
            pts = np.array([(v.x, v.y) for v in p.flattening(0.1)], dtype=np.float64)
        except Exception:  # an entity ezdxf cannot turn into a path (3D mesh polylines, ...)
            continue
        if len(pts) < 3:
            continue
        closed = bool(getattr(e, "closed", False) or getattr(e, "is_closed", False))
        if not closed and np.linalg.norm(pts[0] - pts[-1]) > 1e-6 * max(1.0, np.abs(pts).max()):
            continue
        if np.linalg.norm(pts[0] - pts[-1]) <= 1e-9 * max(1.0, np.abs(pts).max()):
            pts = pts[:-1]
        keep = np.ones(len(pts), dtype=bool)  # drop repeated points
        keep[1:] = np.linalg.norm(np.diff(pts, axis=0), axis=1) > 1e-9
        out.append(pts[keep])
    return out


def _piece_from(name: str, entities, to_cm: float) -> Piece | None:
    ents = list(entities)
    boundary = [e for e in ents if _layer(e) == "1"]
    polys = _closed_polylines(boundary) or _closed_polylines(ents)
    if not polys:
        return None
    notes = []
    if len(polys) > 1:
        notes.append(f"{len(polys)} closed outlines; the largest is the piece's boundary")
    poly = max(polys, key=lambda p: abs(geo.signed_area(p))) * to_cm
    quantity = 1
    for e in ents:
        t = _text_of(e)
        if not t:
            continue
        m = re.match(r"\s*piece\s*name\s*:\s*(.+?)\s*$", t, re.I)
        if m:
            name = m.group(1)
        m = re.match(r"\s*quantity\s*:\s*(\d+)", t, re.I)
        if m:
            quantity = int(m.group(1))
    turn = np.array([(e.dxf.location.x, e.dxf.location.y) for e in ents
                     if e.dxftype() == "POINT" and _layer(e) == "2"], dtype=np.float64).reshape(-1, 2) * to_cm
    poly, corners = _mark_corners(poly, turn)
    return Piece(name=name, outline=poly, corners=corners, quantity=quantity, notes=notes)


def _mark_corners(poly: np.ndarray, turn: np.ndarray) -> tuple[np.ndarray, list[int]]:
    """The outline with its corners: the turn points (each snapped to its outline vertex, or
    inserted on the nearest segment), else the vertices where the outline turns sharply."""
    poly = poly.copy()
    marked: list[np.ndarray] = []
    for t in turn:
        d = np.linalg.norm(poly - t, axis=1)
        if d.min() <= TURN_SNAP:
            marked.append(poly[int(d.argmin())])
            continue
        a, b = poly, np.roll(poly, -1, axis=0)  # the nearest segment, if the point is on the outline
        ab = b - a
        s = np.clip(((t - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-18), 0, 1)
        dist = np.linalg.norm(a + s[:, None] * ab - t, axis=1)
        k = int(dist.argmin())
        if dist[k] <= TURN_SNAP:
            poly = np.insert(poly, k + 1, t, axis=0)
            marked.append(t)
    if marked:
        idx = sorted({int(np.linalg.norm(poly - m, axis=1).argmin()) for m in marked})
    else:
        prev, nxt = poly - np.roll(poly, 1, axis=0), np.roll(poly, -1, axis=0) - poly
        cosang = (prev * nxt).sum(1) / np.maximum(np.linalg.norm(prev, axis=1) * np.linalg.norm(nxt, axis=1), 1e-18)
        idx = list(np.flatnonzero(cosang < np.cos(np.radians(CORNER_DEG))))
    if len(idx) < 2:  # a round piece (no corners): four edges of equal length
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(np.vstack([poly, poly[:1]]), axis=0), axis=1))])
        start, total = (idx[0] if idx else 0), s[-1]
        s = (s[:-1] - s[start]) % total  # arc length from the start corner
        idx = sorted({start} | {int(np.abs(s - q * total).argmin()) for q in (0.25, 0.5, 0.75)})
    return poly, [int(i) for i in idx]


def read_dxf(path: str | Path, units: str | None = None) -> list[Piece]:
    """The pattern pieces of a DXF file (outlines in cm); InputError on anything unusable."""
    import ezdxf
    from ezdxf import recover

    path = Path(path)
    if not path.is_file():
        raise InputError(f"DXF file not found: {path}")
    if path.stat().st_size == 0:
        raise InputError(f"{path.name}: empty file")
    try:
        doc, auditor = recover.readfile(str(path))
    except (IOError, ezdxf.DXFStructureError, UnicodeDecodeError) as e:
        raise InputError(f"{path.name}: not a readable DXF file ({e})") from None
    if auditor.has_errors:
        raise InputError(f"{path.name}: the DXF is damaged ({len(auditor.errors)} error(s), e.g. "
                         f"{auditor.errors[0].message}); export it again from the pattern software")
    msp = doc.modelspace()
    texts = [t for t in (_text_of(e) for e in msp) if t]
    to_cm = _units(doc, units, texts, path.name)
    pieces: list[Piece] = []
    inserted = set()
    for ins in msp.query("INSERT"):
        name = ins.dxf.name
        if name in inserted or name.startswith("*"):
            continue
        block = doc.blocks.get(name)
        if block is None:
            continue
        inserted.add(name)
        p = _piece_from(name, block, to_cm)
        if p is not None:
            pieces.append(p)
    if not pieces:  # a plain drawing: each closed polyline is a piece, in its own frame
        for k, poly in enumerate(_closed_polylines(msp)):
            poly = (poly - poly.min(axis=0)) * to_cm
            poly, corners = _mark_corners(poly, np.zeros((0, 2)))
            pieces.append(Piece(name=f"piece{k + 1}", outline=poly, corners=corners))
    if not pieces:
        raise InputError(f"{path.name}: no pattern pieces found (no closed polyline, in a block or in the drawing)")
    seen: dict[str, int] = {}
    for p in pieces:
        size = float(np.ptp(p.outline, axis=0).max())
        if not MIN_PIECE_CM <= size <= MAX_PIECE_CM:
            raise InputError(f"{path.name}: piece '{p.name}' is {size:.1f} cm across, which is no garment piece: "
                             "are the units right? (give them with --units mm, cm, m or in)")
        base = re.sub(r"[^\w.-]+", "_", p.name.strip()) or "piece"
        seen[base] = seen.get(base, 0) + 1
        p.name = base if seen[base] == 1 else f"{base}_{seen[base]}"
    return pieces


# ------------------------------------------------------------------ outline -> edges


def fit_cubic(pts: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """The cubic Bezier from pts[0] to pts[-1] closest to the points (least squares, chord-length
    parameters refined by projection): (c1, c2, max distance of the points from it)."""
    s, e = pts[0], pts[-1]
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    t = np.concatenate([[0.0], np.cumsum(seg)]) / max(seg.sum(), 1e-18)
    dense_t = np.linspace(0.0, 1.0, 1001)
    best = (s + (e - s) / 3, s + 2 * (e - s) / 3, np.inf)
    for _ in range(40):  # alternate: control points for these parameters, parameters by projection
        b1, b2 = 3 * (1 - t) ** 2 * t, 3 * (1 - t) * t ** 2
        rhs = pts - ((1 - t) ** 3)[:, None] * s - (t ** 3)[:, None] * e
        (c1, c2), *_ = np.linalg.lstsq(np.stack([b1, b2], axis=1), rhs, rcond=None)
        curve = geo.bezier3(s, c1, c2, e, dense_t)
        d = np.linalg.norm(pts[:, None, :] - curve[None, :, :], axis=2)
        err = float(d.min(axis=1).max())
        if err < best[2]:
            best = (c1, c2, err)
        if err < FIT_TOL / 10:
            break
        t = dense_t[d.argmin(axis=1)]
        t[0], t[-1] = 0.0, 1.0
    return best


def _fit_arc(pts: np.ndarray) -> dict | None:
    """GarmentCode's circle curvature for a section that is a circular arc within FIT_TOL (the
    circle through its ends and its middle point), else None."""
    s, e = pts[0], pts[-1]
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    arc_s = np.concatenate([[0.0], np.cumsum(seg)])
    m = pts[int(np.abs(arc_s - arc_s[-1] / 2).argmin())]
    a, b = m - s, e - s
    cross = a[0] * b[1] - a[1] * b[0]
    if abs(cross) < 1e-12:
        return None
    aa, bb = a @ a, b @ b  # circumcentre of s, m, e (relative to s)
    cx = (b[1] * aa - a[1] * bb) / (2 * cross)
    cy = (a[0] * bb - b[0] * aa) / (2 * cross)
    centre = s + np.array([cx, cy])
    r = float(np.hypot(cx, cy))
    if np.abs(np.linalg.norm(pts - centre, axis=1) - r).max() > FIT_TOL:
        return None
    side_m = -cross  # > 0: the middle lies left of start -> end, < 0: right
    side_c = b[0] * cy - b[1] * cx
    right = side_m < 0
    large = bool(side_m * side_c > 0)  # the middle on the same side of the chord as the centre
    return {"type": "circle", "params": [r, int(large), int(right)]}


def _section_edges(pts: np.ndarray) -> list[tuple[np.ndarray, dict | None]]:
    """[(end point, curvature or None)] for one outline section between two corners."""
    s, e = pts[0], pts[-1]
    chord = e - s
    L = float(np.linalg.norm(chord))
    if len(pts) == 2 or L == 0:
        return [(e, None)]
    off = np.abs((pts[:, 0] - s[0]) * chord[1] - (pts[:, 1] - s[1]) * chord[0]) / L
    if off.max() <= STRAIGHT_TOL:
        return [(e, None)]
    arc = _fit_arc(pts)
    if arc is not None:
        return [(e, arc)]
    c1, c2, err = fit_cubic(pts)
    if err <= FIT_TOL or len(pts) < 5:
        return [(e, {"type": "cubic", "params": [list(geo.to_relative(s, e, c1)), list(geo.to_relative(s, e, c2))]})]
    mid = len(pts) // 2
    first = _section_edges(pts[: mid + 1])
    return first + _section_edges(pts[mid:])


def piece_to_panel(piece: Piece) -> dict:
    """A GarmentCode panel dict (cm, relative curvature) from a piece's outline and corners."""
    poly, c = piece.outline, piece.corners
    verts, edges = [poly[c[0]]], []
    for k in range(len(c)):
        a, b = c[k], c[(k + 1) % len(c)]
        sec = poly[a: b + 1] if b > a else np.vstack([poly[a:], poly[: b + 1]])
        parts = _section_edges(sec)
        for j, (end, curv) in enumerate(parts):
            i = len(verts) - 1
            closing = k == len(c) - 1 and j == len(parts) - 1  # back to the first corner
            if not closing:
                verts.append(end)
            edges.append({"endpoints": [i, 0 if closing else i + 1]} | ({"curvature": curv} if curv else {}))
    return {"vertices": [[float(x), float(y)] for x, y in verts], "edges": edges,
            "translation": [0.0, 0.0, 0.0], "rotation": [0.0, 0.0, 0.0]}


# ------------------------------------------------------------------ assembly


class PanelAssembly(BaseModel):
    """Where one panel goes (GarmentCode's translation in cm, rotation in degrees, intrinsic XYZ),
    and, for a piece cut twice, which piece it copies (mirrored left-right by default)."""

    model_config = ConfigDict(extra="forbid")
    copy_of: str | None = None
    mirror: bool = True  # only for a copy
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)


class Assembly(BaseModel):
    """The assembly file: what a DXF does not hold."""

    model_config = ConfigDict(extra="forbid")
    panels: dict[str, PanelAssembly] = Field(default_factory=dict)
    stitches: list[tuple[StitchSide, StitchSide]] = Field(default_factory=list)
    panel_order: list[str] | None = None  # the order the panels are meshed in (default: the DXF's, then copies)
    tryon: TryonExtension | None = None


def load_assembly(path: str | Path) -> Assembly:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"assembly file not found: {path}")
    try:
        data = json.loads(path.read_bytes())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"{path.name}: not valid JSON ({e})") from None
    if isinstance(data, dict) and isinstance(data.get("stitches"), list):  # [panel, edge] pairs allowed
        data["stitches"] = [[{"panel": s[0], "edge": s[1]} if isinstance(s, list) and len(s) == 2 else s
                             for s in pair] if isinstance(pair, list) else pair for pair in data["stitches"]]
    try:
        return Assembly.model_validate(data)
    except ValidationError as e:
        errs = e.errors()
        parts = [f"{'.'.join(str(x) for x in err['loc'])}: {err['msg']}" for err in errs[:3]]
        raise InputError(f"{path.name}: invalid assembly: " + "; ".join(parts)) from None


def import_dxf(path: str | Path, assembly: Assembly | None = None, units: str | None = None) -> tuple[PatternSpec, list[str]]:
    """(PatternSpec, notes) from a DXF and its assembly."""
    pieces = read_dxf(path, units)
    name = Path(path).name
    panels = {p.name: piece_to_panel(p) for p in pieces}
    notes = [f"{p.name}: {n}" for p in pieces for n in p.notes]
    asm = assembly or Assembly()
    for pname, pa in asm.panels.items():
        if pa.copy_of is not None:
            if pa.copy_of not in panels:
                raise InputError(f"assembly: panel '{pname}' copies '{pa.copy_of}', which is not in {name} "
                                 f"(its pieces: {', '.join(p.name for p in pieces)})")
            if pname in panels:
                raise InputError(f"assembly: panel '{pname}' is already a piece of {name}; name the copy otherwise")
            src = json.loads(json.dumps(panels[pa.copy_of]))
            if pa.mirror:  # mirror left-right: the edges keep their numbers (and run the other way round)
                src["vertices"] = [[-x, y] for x, y in src["vertices"]]
                for e in src["edges"]:
                    c = e.get("curvature")
                    if c is None:
                        continue
                    if c["type"] == "circle":  # [radius, large arc, right]: bulges to the other side
                        c["params"][2] = 1 - int(c["params"][2])
                    else:
                        c["params"] = [[a, -b] for a, b in c["params"]]
            panels[pname] = src
        elif pname not in panels:
            raise InputError(f"assembly: panel '{pname}' is not in {name} (its pieces: "
                             f"{', '.join(p.name for p in pieces)}); a copy of a piece needs copy_of")
        panels[pname]["translation"] = list(pa.translation)
        panels[pname]["rotation"] = list(pa.rotation)
    for p in pieces:
        copies = sum(1 for pa in asm.panels.values() if pa.copy_of == p.name)
        if p.quantity > 1 + copies:
            notes.append(f"{p.name}: cut {p.quantity} times; the assembly places {1 + copies} "
                         "(add copies with copy_of)")
    if assembly is None:
        notes.append("no assembly file: the panels have no stitches and no placement yet; write one "
                     "(stitches by panel and edge number, as in the SVG) and import again with --assembly")
    spec = PatternSpec.model_validate({
        "pattern": {"panels": panels, "stitches": [[a.model_dump(), b.model_dump()] for a, b in asm.stitches],
                    "panel_order": _order(asm.panel_order, panels)},
        "properties": {"units_in_meter": 100, "curvature_coords": "relative"},
        **({"tryon": asm.tryon.model_dump(exclude_none=True)} if asm.tryon is not None else {}),
    })
    return spec, notes


def _order(order: list[str] | None, panels: dict) -> list[str]:
    if order is None:
        return list(panels)
    unknown = [n for n in order if n not in panels]
    if unknown:
        raise InputError(f"assembly: panel_order names {', '.join(unknown)}, not a panel of the pattern "
                         f"({', '.join(panels)})")
    return list(order) + [n for n in panels if n not in order]


# ------------------------------------------------------------------ writing


def write_dxf(spec: PatternSpec, path: str | Path, quantity: dict[str, int] | None = None) -> Path:
    """An ASTM/AAMA-style DXF of the spec's panels, in mm: one block per panel (boundary on layer
    1 with curves as dense polylines, turn points on layer 2 at the edges' ends, piece name and
    quantity), inserted side by side."""
    import ezdxf

    path = Path(path)
    doc = ezdxf.new("R2000")
    doc.header["$INSUNITS"] = 4
    doc.header["$MEASUREMENT"] = 1
    for layer in ("1", "2", "7"):
        if layer not in doc.layers:
            doc.layers.add(layer)
    msp = doc.modelspace()
    msp.add_text("Units: METRIC", dxfattribs={"layer": "1", "height": 5.0}).set_placement((0, -20))
    to_mm = spec.scale * 1000.0
    rel = spec.properties.curvature_coords == "relative"
    x_cursor = 0.0
    for k, (name, panel) in enumerate(spec.pattern.panels.items()):
        block_name = f"P{k}_{re.sub(r'[^A-Za-z0-9_]+', '_', name)}"
        blk = doc.blocks.new(name=block_name)
        pts = [geo.edge_dense(panel, e, to_mm / 1000.0, rel, 48)[:-1] * 1000.0 for e in panel.edges]
        outline = np.concatenate(pts)
        blk.add_lwpolyline([tuple(p) for p in outline], close=True, dxfattribs={"layer": "1"})
        for part in pts:
            blk.add_point(tuple(part[0]), dxfattribs={"layer": "2"})
        lo, hi = outline.min(axis=0), outline.max(axis=0)
        centre = (lo + hi) / 2
        blk.add_text(f"Piece Name: {name}", dxfattribs={"layer": "1", "height": 8.0}).set_placement(tuple(centre))
        blk.add_text(f"Quantity: {(quantity or {}).get(name, 1)}",
                     dxfattribs={"layer": "1", "height": 8.0}).set_placement((centre[0], centre[1] - 12))
        blk.add_line((centre[0], lo[1] + 0.2 * (hi[1] - lo[1])), (centre[0], hi[1] - 0.2 * (hi[1] - lo[1])),
                     dxfattribs={"layer": "7"})  # grain line: the panel's own vertical
        msp.add_blockref(block_name, (x_cursor - lo[0], 0.0))
        x_cursor += (hi[0] - lo[0]) + 50.0
    doc.saveas(str(path))
    return path


def assembly_of(spec: PatternSpec) -> dict:
    """The assembly file of a spec (what write_dxf leaves out): its stitches, each panel's
    translation and rotation, its tryon block. With write_dxf's file it imports as the same
    pattern (edge numbers kept: write_dxf marks every edge's ends as turn points)."""
    out = {"panels": {n: {"translation": list(p.translation), "rotation": list(p.rotation)}
                      for n, p in spec.pattern.panels.items()},
           "stitches": [[a.model_dump(), b.model_dump()] for a, b in spec.pattern.stitches]}
    if spec.pattern.panel_order:
        out["panel_order"] = list(spec.pattern.panel_order)
    if spec.tryon is not None:
        out["tryon"] = spec.tryon.model_dump(exclude_none=True)
    return out
