"""Cutting patterns as DXF files, the way pattern CAD systems exchange them (ASTM D6673 / AAMA):
import into a GarmentCode specification (`import_pattern`), export (`write_dxf`).

Reading is engine.pattern.dxf_read (every piece in every graded size, every layer). A pattern
is imported in one of its sizes (`default_size`: the file's sample size, else the middle one):
- without an assembly file, the garment is inferred (engine.pattern.dxf_infer: the pieces'
  roles, the seams, where each piece goes on the body) and built edge by edge
  (engine.pattern.dxf_build); `Imported.assembly` is that inference as an assembly file, which a
  user can correct and give back;
- with one, the assembly says it. Two kinds: the inferred kind (`panels` with `piece` and `role`;
  `seams`, each two spans of panel outlines from [corner, fraction of the way to the next
  corner] to another, the corners as numbered in pattern.svg -- the same in every size, so one
  assembly serves all sizes), or GarmentCode's placement (`panels` with `translation` (cm) and
  `rotation` (degrees) of each piece, `copy_of` for a piece cut twice, `stitches` by {panel,
  edge}; the piece's edges run between its corners, dxf_read.corners_of).

Writing (`write_dxf`): each panel a block (boundary on layer 1, turn points on layer 2, piece
name and quantity as text), in millimetres ($INSUNITS = 4, "Units: METRIC").
"""

from __future__ import annotations

import json
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from typing import Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationError

from engine.errors import InputError, parser
from engine.pattern import geometry as geo
from engine.pattern.dxf_build import build_spec, fit_tol, section_edges
from engine.pattern.dxf_infer import BAND_ROLES, Inference, Part, Seam, Span, frame_part, hints_of, infer
from engine.pattern.dxf_read import DxfPattern, corners_of, read_pattern
from engine.pattern.spec import PatternSpec, StitchSide, TryonExtension

AREA_SAMPLES = 64  # points per edge when a panel's area is measured against its piece's


# ------------------------------------------------------------------ pieces (one size)


@dataclass
class Piece:
    """One piece in one size, as GarmentCode's placement path uses it."""

    name: str
    outline: np.ndarray  # (M, 2) cm, closed (first point not repeated), in the piece's own frame
    corners: list[int]  # indices into outline, ascending
    quantity: int = 1
    notes: list[str] = field(default_factory=list)


def default_size(pattern: DxfPattern) -> str:
    """The size a pattern is imported in when none is asked for: its sample size, else the middle one."""
    return pattern.sample_size or pattern.sizes[len(pattern.sizes) // 2]


def pick_size(pattern: DxfPattern, size: str | None) -> str:
    if size is None:
        return default_size(pattern)
    if size not in pattern.sizes:
        raise InputError(f"{pattern.source}: no size '{size}'; its sizes are {', '.join(pattern.sizes)}")
    return size


def read_dxf(path: str | Path, units: str | None = None, size: str | None = None) -> list[Piece]:
    """The pattern's pieces in one size (default_size), outlines in cm, with their corners."""
    pattern = read_pattern(path, units)
    size = pick_size(pattern, size)
    out = []
    seen: dict[str, int] = {}
    for p in pattern.pieces:
        if size not in p.shapes:
            continue
        outline, corners = corners_of(p, size)
        base = re.sub(r"[^\w.-]+", "_", p.name.strip()) or "piece"
        seen[base] = seen.get(base, 0) + 1
        out.append(Piece(name=base if seen[base] == 1 else f"{base}_{seen[base]}", outline=outline, corners=corners,
                         quantity=p.cut, notes=list(p.notes)))
    return out


def piece_to_panel(piece: Piece) -> dict:
    """A GarmentCode panel dict (cm, relative curvature) from a piece's outline and corners."""
    poly, c = piece.outline, piece.corners
    tol = fit_tol(poly)
    verts, edges = [poly[c[0]]], []
    for k in range(len(c)):
        a, b = c[k], c[(k + 1) % len(c)]
        sec = poly[a: b + 1] if b > a else np.vstack([poly[a:], poly[: b + 1]])
        parts = section_edges(sec, tol)
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
    """One panel: either a piece in an inferred role (`piece`, `role`, `side`, `pair`, `stretch`)
    or, GarmentCode's way, where the piece goes (translation in cm, rotation in
    degrees, intrinsic XYZ) and, for a piece cut twice, which piece it copies (mirrored
    left-right by default)."""

    model_config = ConfigDict(extra="forbid")
    piece: str | None = None  # the DXF piece (by its "Piece Name:")
    role: str | None = None  # front, back, sleeve, leg, collar, cuff, waistband, binding
    side: str | None = None  # left / right (sleeves, legs, cuffs)
    pair: bool = False  # the second of a pair cut twice (the fabric's other face out)
    stretch: float = Field(1.0, gt=0.2, lt=5.0)  # a band lengthened for the drape (a rib)
    copy_of: str | None = None
    mirror: bool = True  # only for a copy
    translation: tuple[float, float, float] = (0.0, 0.0, 0.0)
    rotation: tuple[float, float, float] = (0.0, 0.0, 0.0)


class SpanAssembly(BaseModel):
    """A stretch of a panel's outline: from [corner, fraction of the way to the next corner] to
    another, forward (dir 1: the way the corners are numbered) or backward (-1)."""

    model_config = ConfigDict(extra="forbid")
    panel: str
    start: tuple[int, float]
    end: tuple[int, float]
    dir: Literal[1, -1] = 1


class SeamAssembly(BaseModel):
    """Two spans sewn together, start to start."""

    model_config = ConfigDict(extra="forbid")
    label: str = ""
    a: SpanAssembly
    b: SpanAssembly


# an assembly's size: a garment has a few dozen pieces and a few hundred stitches at most (the
# samples: 17 pieces, 44 stitches, 18 seams); a file past these is no garment and takes seconds to check
MAX_PANELS, MAX_SEAMS, MAX_STITCHES = 200, 1000, 5000


class Assembly(BaseModel):
    """The assembly file: what a DXF does not hold."""

    model_config = ConfigDict(extra="forbid")
    panels: dict[str, PanelAssembly] = Field(default_factory=dict, max_length=MAX_PANELS)
    seams: list[SeamAssembly] = Field(default_factory=list, max_length=MAX_SEAMS)  # the inferred kind
    stitches: list[tuple[StitchSide, StitchSide]] = Field(default_factory=list, max_length=MAX_STITCHES)  # GarmentCode's
    panel_order: list[str] | None = None  # the order the panels are meshed in (default: the DXF's, then copies)
    tryon: TryonExtension | None = None
    size: str | None = None  # the size it was inferred in (any size of the pattern takes it)

    @property
    def inferred_kind(self) -> bool:
        return any(p.role is not None for p in self.panels.values())


@parser("an assembly file (JSON)")
def load_assembly(path: str | Path) -> Assembly:
    path = Path(path)
    if not path.is_file():
        raise InputError(f"assembly file not found: {path}")
    try:
        data = json.loads(path.read_bytes())
    except (json.JSONDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"{path.name}: not valid JSON ({e})") from None
    return parse_assembly(data, path.name)


@parser("an assembly", name_of=lambda data, source="assembly": source)
def parse_assembly(data, source: str = "assembly") -> Assembly:
    if isinstance(data, dict) and isinstance(data.get("stitches"), list):  # [panel, edge] pairs allowed
        data["stitches"] = [[{"panel": s[0], "edge": s[1]} if isinstance(s, list) and len(s) == 2 else s
                             for s in pair] if isinstance(pair, list) else pair for pair in data["stitches"]]
    try:
        return Assembly.model_validate(data)
    except ValidationError as e:
        errs = e.errors()
        parts = [f"{'.'.join(_printable(x) for x in err['loc'])}: {err['msg']}" for err in errs[:3]]
        raise InputError(f"{source}: invalid assembly: " + "; ".join(parts)) from None


def _printable(key, most: int = 40) -> str:
    """A key of the user's file as an error names it: one line, not too long."""
    text = "".join(c if c.isprintable() else "?" for c in str(key))
    return text if len(text) <= most else text[:most] + "..."


# ------------------------------------------------------------------ import


@dataclass
class Imported:
    """A DXF pattern imported in one size."""

    pattern: DxfPattern
    size: str
    spec: PatternSpec
    labels: list[str]  # what each stitch sews
    notes: list[str]
    unsure: list[str] = field(default_factory=list)
    left_out: list[str] = field(default_factory=list)
    kind: str = "pieces"  # top, bottom, pieces (nothing sewn)
    assembly: dict | None = None  # the inferred assembly (None when one was given)
    fabric: tuple[str, str] | None = None  # (fabric, why) where the pattern suggests one (engine.pattern.dxf_fabric)
    areas: dict[str, tuple[float, float]] = field(default_factory=dict)  # panel -> (its area, its piece's) cm^2
    parts: list[Part] = field(default_factory=list)
    seams: list[Seam] = field(default_factory=list)

    def svg(self) -> str:
        """pattern.svg: the panels with their seams numbered (engine.pattern.dxf_svg)."""
        from engine.pattern.dxf_svg import imported_svg

        if not self.parts:  # nothing inferred: the pieces as they are, every edge numbered
            from engine.pattern.io import pattern_to_svg

            return pattern_to_svg(self.spec, edge_numbers=True)
        title = (f"{self.pattern.source}, size {self.size} of {', '.join(self.pattern.sizes)} -- "
                 f"{self.kind}; seams:")
        notes = [f"left out: {x}" for x in self.left_out] + [f"unsure: {x}" for x in self.unsure]
        return imported_svg(self.parts, self.seams, title, notes)


def import_pattern(path: str | Path, size: str | None = None, units: str | None = None,
                   assembly: Assembly | None = None, pattern: DxfPattern | None = None) -> Imported:
    """A DXF pattern in one size as a GarmentCode spec: inferred, or as the assembly says."""
    pattern = pattern or read_pattern(path, units)
    size = pick_size(pattern, size if size is not None else (assembly.size if assembly is not None else None))
    if assembly is not None and not assembly.inferred_kind:
        spec, notes = _placed_import(pattern, size, assembly)
        out = Imported(pattern, size, spec, [""] * len(spec.pattern.stitches), notes)
        _suggest_fabric(out, [])
        return out
    if assembly is not None:
        parts = [_part_of(pattern, size, name, pa) for name, pa in assembly.panels.items()]
        seams = [_seam_of(parts, sa) for sa in assembly.seams]
        spec, labels, _ = build_spec(parts, seams, hints_of(parts), assembly.tryon.fabric if assembly.tryon else None)
        out = Imported(pattern, size, spec, labels, ["assembled as the assembly file says"], kind="assembled",
                       parts=parts, seams=seams)
    else:
        inf = infer(pattern, size)
        if inf.kind == "pieces":
            spec, labels = _pieces_spec(pattern, size), []
        else:
            spec, labels, _ = build_spec(inf.parts, inf.seams, hints_of(inf.parts))
        out = Imported(pattern, size, spec, labels, inf.notes, inf.unsure, inf.left_out, inf.kind)
        if inf.kind != "pieces":
            out.assembly = assembly_of_inferred(inf, size)
            out.parts, out.seams = inf.parts, inf.seams
        parts = inf.parts
    out.areas = _areas(out.spec, parts, pattern, size)
    _suggest_fabric(out, parts)
    return out


def _suggest_fabric(imp: Imported, parts: list[Part]) -> None:
    """The fabric the pattern's pieces say it is made of, as the spec's own fabric, where the
    assembly names none (engine.pattern.dxf_fabric); said in the notes."""
    from engine.pattern.dxf_fabric import suggest_fabric
    from engine.pattern.spec import TryonExtension

    spec = imp.spec
    if spec.tryon is not None and spec.tryon.fabric:
        return
    found = suggest_fabric(imp.pattern, parts)
    if found is None:
        return
    imp.fabric = found
    if imp.assembly is not None:  # (the inferred assembly a user corrects: the fabric is theirs to change)
        imp.assembly["tryon"] = {"fabric": found[0]}
    spec.tryon = (spec.tryon or TryonExtension()).model_copy(update={"fabric": found[0], "fabric_why": found[1]})
    imp.notes.append(f"fabric: {found[0]}, because {found[1]} (a fabric you choose wins)")


def import_dxf(path: str | Path, assembly: Assembly | None = None, units: str | None = None,
               size: str | None = None) -> tuple[PatternSpec, list[str]]:
    """(PatternSpec, notes) from a DXF (and its assembly, if given)."""
    imp = import_pattern(path, size, units, assembly)
    return imp.spec, imp.notes + [f"unsure: {u}" for u in imp.unsure] + imp.left_out


def _areas(spec: PatternSpec, parts: list[Part], pattern: DxfPattern, size: str) -> dict:
    """Each panel's area against its piece's cut line (the file's chained layer 1, twice where
    the piece is cut on the fold and unfolded; bands as lengthened for the drape)."""
    out = {}
    for p in parts:
        panel = spec.pattern.panels[p.name]
        area = abs(geo.signed_area(geo.outline(panel, 1.0, True, AREA_SAMPLES)))
        file_area = pattern.piece(p.piece).shapes[size].area * (2 if p.unfolded else 1) * p.stretch
        out[p.name] = (area, file_area)
    return out


def _part_of(pattern: DxfPattern, size: str, name: str, pa: PanelAssembly) -> Part:
    if pa.piece is None or pa.role is None:
        raise InputError(f"assembly: panel '{name}' needs both `piece` and `role` (or neither, with translation "
                         "and rotation)")
    piece = pattern.piece(pa.piece)
    if size not in piece.shapes:
        raise InputError(f"assembly: piece '{pa.piece}' is not graded in size {size}")
    roles = ("front", "back", "sleeve", "leg", *BAND_ROLES)
    if pa.role not in roles:
        raise InputError(f"assembly: panel '{name}': role '{pa.role}'; use one of {', '.join(roles)}")
    return frame_part(name, piece, size, pa.role, pa.side, pa.pair, pa.stretch)


def _corner_arcs(part: Part) -> tuple[list[float], float]:
    from engine.pattern.dxf_infer import _arc

    arc = _arc(part.outline)
    return [float(arc[c]) for c in part.corners], float(arc[-1])


def _pos(part: Part, at: tuple[int, float]) -> float:
    """Arc position of [corner, fraction of the way to the next corner]."""
    cs, total = _corner_arcs(part)
    k, f = at
    if not 0 <= k < len(cs) or not 0.0 <= f <= 1.0:
        raise InputError(f"assembly: panel '{part.name}': [{k}, {f}] is not [corner 0..{len(cs) - 1}, fraction 0..1]")
    nxt = cs[k + 1] if k + 1 < len(cs) else cs[0] + total
    return (cs[k] + f * (nxt - cs[k])) % total


def _at(part: Part, s: float) -> list:
    """[corner, fraction] of arc position s (the inverse of _pos)."""
    cs, total = _corner_arcs(part)
    s = s % total
    k = max((i for i, c in enumerate(cs) if c <= s + 1e-9), default=len(cs) - 1)
    nxt = cs[k + 1] if k + 1 < len(cs) else cs[0] + total
    s = s + total if s < cs[k] - 1e-9 else s
    return [k, round(min(float((s - cs[k]) / max(nxt - cs[k], 1e-12)), 1.0), 6)]


def _seam_of(parts: list[Part], sa: SeamAssembly) -> Seam:
    by = {p.name: p for p in parts}
    spans = []
    for side in (sa.a, sa.b):
        if side.panel not in by:
            raise InputError(f"assembly: seam '{sa.label}' names panel '{side.panel}', which is not one of "
                             f"{', '.join(by)}")
        p = by[side.panel]
        spans.append(Span(p.name, _pos(p, side.start), _pos(p, side.end), side.dir))
    return Seam(spans[0], spans[1], sa.label)


def assembly_of_inferred(inf: Inference, size: str) -> dict:
    """The inference as an assembly file (see PanelAssembly, SeamAssembly): what a user corrects
    and gives back; its corner numbers are those of pattern.svg."""
    panels = {}
    for p in inf.parts:
        entry = {"piece": p.piece, "role": p.role}
        entry |= {"side": p.side} if p.side else {}
        entry |= {"pair": True} if p.pair else {}
        entry |= {"stretch": round(p.stretch, 6)} if p.stretch != 1.0 else {}
        panels[p.name] = entry
    by = {p.name: p for p in inf.parts}
    seams = [{"label": s.label, **{k: {"panel": sp.part, "start": _at(by[sp.part], sp.s0),
                                       "end": _at(by[sp.part], sp.s1), "dir": sp.dir}
                                   for k, sp in (("a", s.a), ("b", s.b))}} for s in inf.seams]
    return {"size": size, "panels": panels, "seams": seams, "panel_order": [p.name for p in inf.parts]}


def _pieces_spec(pattern: DxfPattern, size: str) -> PatternSpec:
    """Every piece of the size as a panel, nothing sewn (no garment could be inferred)."""
    pieces = [Piece(name=p.name, outline=o, corners=c, quantity=p.cut)
              for p in pattern.pieces if size in p.shapes for o, c in [corners_of(p, size)]]
    return PatternSpec.model_validate({
        "pattern": {"panels": {p.name: piece_to_panel(p) for p in pieces}, "stitches": []},
        "properties": {"units_in_meter": 100, "curvature_coords": "relative"}})


def _placed_import(pattern: DxfPattern, size: str, asm: Assembly) -> tuple[PatternSpec, list[str]]:
    """GarmentCode's way: the pieces between their corners, copies, translation and rotation."""
    pieces = {}
    for p in pattern.pieces:
        if size in p.shapes:
            outline, corners = corners_of(p, size)
            pieces[p.name] = Piece(name=p.name, outline=outline, corners=corners, quantity=p.cut)
    name = pattern.source
    panels = {n: piece_to_panel(p) for n, p in pieces.items()}
    notes = []
    for pname, pa in asm.panels.items():
        if pa.copy_of is not None:
            if pa.copy_of not in panels:
                raise InputError(f"assembly: panel '{pname}' copies '{pa.copy_of}', which is not in {name} "
                                 f"(its pieces: {', '.join(pieces)})")
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
                             f"{', '.join(pieces)}); a copy of a piece needs copy_of")
        panels[pname]["translation"] = list(pa.translation)
        panels[pname]["rotation"] = list(pa.rotation)
    for p in pieces.values():
        copies = sum(1 for pa in asm.panels.values() if pa.copy_of == p.name)
        if p.quantity > 1 + copies:
            notes.append(f"{p.name}: cut {p.quantity} times; the assembly places {1 + copies} "
                         "(add copies with copy_of)")
    spec = PatternSpec.model_validate({
        "pattern": {"panels": panels, "stitches": [[a.model_dump(), b.model_dump()] for a, b in asm.stitches],
                    "panel_order": _order(asm.panel_order, panels)},
        "properties": {"units_in_meter": 100, "curvature_coords": "relative"},
        # mirrored copies wind the other way: their stitches pair up as placed (TryonExtension.pairing)
        "tryon": {"pairing": "placed", **(asm.tryon.model_dump(exclude_none=True) if asm.tryon is not None else {})},
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


def piece_areas(pattern: DxfPattern, sizes: list[str] | None = None) -> dict[tuple[str, str], tuple[float, float]]:
    """(piece, size) -> (the area of its panel between its corners, the shoelace area of its
    chained layer-1 cut line), cm^2, for every piece in every size (or those of `sizes`)."""
    out = {}
    for p in pattern.pieces:
        for size in (s for s in p.shapes if sizes is None or s in sizes):
            outline, corners = corners_of(p, size)
            panel = PatternSpec.model_validate({"pattern": {"panels": {"p": piece_to_panel(
                Piece(p.name, outline, corners))}}}).pattern.panels["p"]
            out[(p.name, size)] = (abs(geo.signed_area(geo.outline(panel, 1.0, True, AREA_SAMPLES))),
                                   p.shapes[size].area)
    return out


# ------------------------------------------------------------------ summary


def summary(pattern: DxfPattern, imported: Imported | None = None) -> dict:
    """What `tryon pattern import --json` prints: units, sizes, pieces (quantity, cut, category,
    per size area cm^2, perimeter cm, notches, grain line), layers, and the garment inferred."""
    from engine.pattern.dxf_read import KNOWN_LAYERS

    pieces = []
    for p in pattern.pieces:
        per = {}
        for size in pattern.sizes:
            sh = p.shapes.get(size)
            if sh is not None:
                per[size] = {"area_cm2": round(sh.file_area, 2),
                             "perimeter_cm": round(float(geo.polyline_length(np.vstack([sh.outline, sh.outline[:1]]))), 2),
                             "notches": int(len(sh.notches)), "grain_line": sh.grain is not None,
                             "drill_holes": int(len(sh.drills)), "internal_lines": len(sh.internal),
                             "mirror_line": bool(sh.mirror), "sew_line": sh.sew is not None,
                             **({"sew_line_area_cm2": round(sh.area, 2)} if sh.sew is not None else {})}
        pieces.append({"name": p.name, "quantity": p.quantity, "cut": p.cut, "category": p.category,
                       "annotation": p.annotation, "fabric": p.fabric, "sizes": per, "notes": p.notes})
    out = {"file": pattern.source, "style": pattern.style, "units": pattern.units, "units_note": pattern.units_note,
           "sizes": pattern.sizes, "sample_size": pattern.sample_size, "pieces": pieces,
           "layers": {k: {"entities": n, "meaning": KNOWN_LAYERS.get(k, "not in the standard: kept, not used")}
                      for k, n in sorted(pattern.layers.items(), key=lambda kv: (len(kv[0]), kv[0]))},
           "notes": pattern.notes}
    if imported is not None:
        out["garment"] = {"size": imported.size, "kind": imported.kind,
                          "panels": list(imported.spec.pattern.panels),
                          "seams": sorted(set(imported.labels) - {""}), "stitches": len(imported.spec.pattern.stitches),
                          "notes": imported.notes, "unsure": imported.unsure, "left_out": imported.left_out,
                          "fabric": ({"name": imported.fabric[0], "why": imported.fabric[1]} if imported.fabric
                                     else None),
                          "area_vs_cut_line_pct": {n: round(100 * (a / f - 1), 3) for n, (a, f) in
                                                   imported.areas.items()}}
    return out


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
