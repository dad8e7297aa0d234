"""Read a DXF cutting pattern as pattern CAD exports it (ASTM D6673 / AAMA, Gerber AccuMark,
Lectra, Optitex, CLO): every piece in every graded size, with everything the pattern maker put in.

A piece is a block inserted in the drawing (a plain drawing without blocks: each closed outline
on layer 1 is a piece). Pattern CAD writes a block per piece *per size*: the blocks of one piece
share its "Piece Name:" text and differ in their "Size:" text; the sizes keep the file's order.
Per block, by layer (the AAMA / ASTM numbering):
  1  the cut line: POLYLINEs / LWPOLYLINEs / LINEs / ARCs / SPLINEs that meet end to end
     (within CHAIN_TOL), chained into one closed outline; where the parts meet is kept
     (`Shape.breaks`: the exporters break the cut line at the piece's corners)
  2  turn points, 3 curve points (the sample size only, in these exports)
  4  notches (and 80-83: T, castle, check, U notches)
  6  mirror (fold) lines, 7 grain line, 8 internal lines, 13 drill holes, 14 the sew line (the
     cut line less the seam allowance, where the file carries allowance)
  5 grade reference, 9-11 stripe/plaid/cutouts, 15 annotation, 84-86 quality validation
     curves: read and listed, not used. Layers outside the standard are kept and listed.
Texts: "Piece Name:", "Size:", "Quantity:" (ASTM writes "Quantity: n,m"), "Category:",
"Annotation:" (Gerber writes the cut count there: "2XFABRIC"), "Fabric:"; the drawing's
"Units:" (ENGLISH: inches; METRIC: millimetres or centimetres, which the file does not say:
decided from the size of its pieces, see `_metric_unit`) and "Style Name:".

Damaged files (CLO writes group codes of the wrong type) are read with ezdxf's `recover`; what
it repaired is noted. A file that neither reads (whatever ezdxf or this reader raise on it),
coordinates that are not numbers: refused in one line (InputError). Limits, each refused with a
message that says which: MAX_DXF_BYTES, MAX_ENTITIES in all, MAX_PIECE_VERTICES and MAX_PARTS per
piece per size.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from engine.errors import MALFORMED, InputError, TryonError, reading
from engine.pattern import geometry as geo

CHAIN_TOL_CM = 0.05  # cut-line parts whose ends are this close (0.5 mm) are joined
MAX_DXF_BYTES = 20_000_000  # the largest real export seen is 1.5 MB (17 pieces x 15 sizes)
MAX_ENTITIES = 1_000_000
MAX_PIECE_VERTICES = 100_000  # per piece and size (a real cut line: 100-1,000)
MAX_PARTS = 2_000  # cut-line parts per piece and size (real: 1-15)
MAX_PIECE_CM = 400.0  # a piece longer than this (after units) is a units mistake
MIN_PIECE_CM = 3.0  # (a belt loop)
UNITS_CM = {"mm": 0.1, "cm": 1.0, "m": 100.0, "in": 2.54}
UNIT_WORDS = {"mm": "millimetres", "cm": "centimetres", "m": "metres", "in": "inches"}
_INSUNITS = {1: "in", 4: "mm", 5: "cm", 6: "m"}
ONE_SIZE = "one size"  # the size of a piece whose blocks say none
KNOWN_LAYERS = {"1": "cut line", "2": "turn points", "3": "curve points", "4": "notches",
                "5": "grade reference line", "6": "mirror line", "7": "grain line", "8": "internal lines",
                "9": "stripe reference line", "10": "plaid reference line", "11": "internal cutouts",
                "13": "drill holes", "14": "sew line", "15": "annotation text", "80": "T notches",
                "81": "castle notches", "82": "check notches", "83": "U notches",
                "84": "cut line quality validation curves", "85": "internal line quality validation curves",
                "86": "grade reference quality validation curves"}
NOTCH_LAYERS = ("4", "80", "81", "82", "83")
USED_LAYERS = {"1", "2", "3", "4", "6", "7", "8", "13", "14", *NOTCH_LAYERS}


@dataclass
class Shape:
    """One piece in one size, in cm, in the piece's own (block) frame."""

    outline: np.ndarray  # (M, 2) the chained cut line, closed (first point not repeated)
    breaks: list[int]  # outline indices where the file's cut-line parts meet, ascending (none: one part)
    file_area: float  # cm^2: the shoelace area of the chained cut line, as the file has it
    turn: np.ndarray  # (K, 2) turn points (layer 2)
    notches: np.ndarray  # (K, 2) notch positions (layer 4, 80-83)
    grain: np.ndarray | None  # (2, 2) the grain line's ends, or None
    mirror: list[np.ndarray]  # (2, 2) each mirror line
    internal: list[np.ndarray]  # (K, 2) each internal line (layer 8)
    drills: np.ndarray  # (K, 2) drill holes (layer 13)
    sew: np.ndarray | None  # (M, 2) the sew line (layer 14), closed, or None
    other: dict[str, list[np.ndarray]] = field(default_factory=dict)  # layer -> point lists

    @property
    def area(self) -> float:
        """cm^2: the shoelace area of the line simulated -- the sew line where there is one, else
        the chained cut line."""
        return self.file_area if self.sew is None else abs(geo.signed_area(self.sew))


@dataclass
class DxfPiece:
    name: str
    shapes: dict[str, Shape]  # size -> shape, in the pattern's size order
    quantity: int | None = None  # the "Quantity:" text (its first number)
    cut: int = 1  # how many to cut: the annotation's "NX..." where given, else the quantity
    category: str | None = None
    annotation: str | None = None
    fabric: str | None = None
    notes: list[str] = field(default_factory=list)


@dataclass
class DxfPattern:
    source: str
    units: str  # 'mm', 'cm', 'm', 'in'
    units_note: str  # how the units were decided
    sizes: list[str]
    pieces: list[DxfPiece]
    style: str | None = None
    sample_size: str | None = None
    notes: list[str] = field(default_factory=list)
    layers: dict[str, int] = field(default_factory=dict)  # layer -> entity count, all blocks

    def piece(self, name: str) -> DxfPiece:
        for p in self.pieces:
            if p.name == name:
                return p
        raise InputError(f"{self.source}: no piece '{name}' (its pieces: {', '.join(p.name for p in self.pieces)})")


# ------------------------------------------------------------------ entities -> points


def _layer(e) -> str:
    return str(e.dxf.layer).strip()


def _text_of(e) -> str | None:
    t = e.dxftype()
    if t == "TEXT":
        return str(e.dxf.text)
    if t == "MTEXT":
        return e.plain_text()
    return None


def _points(e) -> np.ndarray | None:
    """(K, 2) points of a line-like entity in file units (curves flattened to 1/5000 of their
    size), None for other entities or ones ezdxf cannot turn into a path."""
    t = e.dxftype()
    if t == "LINE":
        s, f = e.dxf.start, e.dxf.end
        return np.array([[s.x, s.y], [f.x, f.y]], dtype=np.float64)
    if t == "POLYLINE" and not (e.is_2d_polyline or e.is_3d_polyline):
        return None  # polyface and polygon meshes
    if t == "POLYLINE" and not any(v.dxf.get("bulge", 0) for v in e.vertices):
        pts = np.array([(p[0], p[1]) for p in e.points()], dtype=np.float64).reshape(-1, 2)
    elif t in ("POLYLINE", "LWPOLYLINE", "ARC", "SPLINE"):
        from ezdxf import path as dxfpath

        try:
            p = dxfpath.make_path(e)
            box = np.array([(v.x, v.y) for v in p.control_vertices()], dtype=np.float64).reshape(-1, 2)
            size = float(np.ptp(box, axis=0).max()) if len(box) else 0.0
            pts = np.array([(v.x, v.y) for v in p.flattening(max(size, 1e-9) / 5000.0)], dtype=np.float64)
        except Exception:  # an entity ezdxf cannot flatten: not a cut line
            return None
    else:
        return None
    closed = bool(getattr(e, "closed", False) or getattr(e, "is_closed", False))
    if closed and len(pts) > 1 and np.any(pts[0] != pts[-1]):
        pts = np.vstack([pts, pts[:1]])
    return pts if len(pts) else None


def _dedupe(pts: np.ndarray, tol: float = 0.0) -> np.ndarray:
    """Consecutive repeated points dropped (exporters repeat a vertex at a notch)."""
    if len(pts) < 2:
        return pts
    keep = np.ones(len(pts), dtype=bool)
    keep[1:] = np.linalg.norm(np.diff(pts, axis=0), axis=1) > tol
    return pts[keep]


# ------------------------------------------------------------------ chaining the cut line


class ChainError(InputError):
    pass


def chain(parts: list[np.ndarray], tol: float) -> list[tuple[np.ndarray, list[int], bool]]:
    """Chain open point lists that meet end to end (ends within tol, either way round) into
    outlines: [(points (M, 2), indices where parts meet, closed)], largest first. A closed
    outline's first point is not repeated."""
    parts = [_dedupe(p) for p in parts if len(p) >= 2]
    parts = [p for p in parts if len(p) >= 2]
    used = np.zeros(len(parts), dtype=bool)
    heads = np.array([p[0] for p in parts]).reshape(-1, 2)
    tails = np.array([p[-1] for p in parts]).reshape(-1, 2)
    out = []
    while not used.all():
        k = int(np.flatnonzero(~used)[0])
        used[k] = True
        pts, breaks = [parts[k]], [0]
        for _ in range(len(parts)):  # grow at the end, then at the start
            end = pts[-1][-1]
            dh = np.where(used, np.inf, np.linalg.norm(heads - end, axis=1))
            dt = np.where(used, np.inf, np.linalg.norm(tails - end, axis=1))
            j, rev = (int(dh.argmin()), False) if dh.min() <= dt.min() else (int(dt.argmin()), True)
            if min(dh.min(), dt.min()) > tol:
                break
            used[j] = True
            breaks.append(sum(len(p) - 1 for p in pts))
            pts.append(parts[j][::-1] if rev else parts[j])
        joined = pts[0]
        for p in pts[1:]:
            joined = np.vstack([joined, p[1:]])
        closed = len(joined) >= 4 and float(np.linalg.norm(joined[0] - joined[-1])) <= tol
        if closed:
            joined = joined[:-1]
            # one part closing on itself starts anywhere: no corner there
            breaks = [b for b in breaks if b < len(joined)] if len(pts) > 1 else []
        elif len(pts) > 1 or np.linalg.norm(joined[0] - joined[-1]) > tol:
            breaks = breaks + [len(joined) - 1]
        out.append((joined, sorted(set(breaks)), closed))
    out.sort(key=lambda c: -abs(geo.signed_area(c[0])) if c[2] else 0.0)
    out.sort(key=lambda c: not c[2])
    return out


def _gap_report(chains, to_cm: float) -> str:
    """Where the open cut line's ends are, in words (for the error)."""
    pts, _, _ = max(chains, key=lambda c: len(c[0]))
    a, b = pts[0] * to_cm, pts[-1] * to_cm
    return (f"its {len(chains)} part(s) do not close: the longest chain ends {10 * np.linalg.norm(a - b):.1f} mm from "
            f"where it starts, at ({a[0]:.1f}, {a[1]:.1f}) and ({b[0]:.1f}, {b[1]:.1f}) cm in the piece's frame")


def drop_spikes(outline: np.ndarray, breaks: list[int], tol: float = 1e-3) -> tuple[np.ndarray, list[int]]:
    """The outline without its zero-width spikes (a slit notch cut into the line: out to a
    point and back the same way) and repeated points; breaks moved onto the points kept."""
    pts = list(map(tuple, outline))
    marks = [k in set(breaks) for k in range(len(pts))]
    changed = True
    while changed and len(pts) > 3:
        changed = False
        for i in range(len(pts)):
            a, b = np.array(pts[i - 1]), np.array(pts[(i + 1) % len(pts)])
            here = np.array(pts[i])
            if np.linalg.norm(here - np.array(pts[i - 1])) <= tol:  # a repeated point
                marks[i - 1] = marks[i - 1] or marks[i]
                del pts[i], marks[i]
                changed = True
                break
            if np.linalg.norm(a - b) <= tol:  # out and back: drop the tip and the point back
                j = (i + 1) % len(pts)
                marks[i - 1] = marks[i - 1] or marks[j]
                for k in sorted({i, j}, reverse=True):
                    del pts[k], marks[k]
                changed = True
                break
    return np.array(pts), [k for k, m in enumerate(marks) if m]


# ------------------------------------------------------------------ one block -> a shape


@dataclass
class _Raw:
    """A block's entities sorted by layer (file units), and its texts."""

    lines: dict[str, list[np.ndarray]] = field(default_factory=dict)
    points: dict[str, list[np.ndarray]] = field(default_factory=dict)
    texts: list[tuple[str, str]] = field(default_factory=list)  # (layer, text)
    count: dict[str, int] = field(default_factory=dict)


def _raw(entities, budget: list[int]) -> _Raw:
    r = _Raw()
    for e in entities:
        budget[0] -= 1
        if budget[0] < 0:
            raise InputError(f"the drawing has more than {MAX_ENTITIES:,} entities: this is no cutting pattern "
                             "(or split it into several files)")
        lay = _layer(e)
        r.count[lay] = r.count.get(lay, 0) + 1
        t = e.dxftype()
        if t == "POINT":
            loc = e.dxf.location
            r.points.setdefault(lay, []).append(_finite(np.array([loc.x, loc.y], dtype=np.float64), t, lay))
            continue
        text = _text_of(e)
        if text is not None:
            r.texts.append((lay, text))
            continue
        pts = _points(e)
        if pts is not None:
            r.lines.setdefault(lay, []).append(_finite(pts, t, lay))
    return r


def _finite(pts: np.ndarray, kind: str, layer: str) -> np.ndarray:
    if not np.isfinite(pts).all():
        raise InputError(f"a {kind} on layer {layer} has a coordinate that is not a number (nan or inf): the file "
                         "is damaged; export it again")
    return pts


def _shape(raw: _Raw, to_cm: float, label: str) -> Shape | None:
    """The shape of one block (None if it has no line on layer 1 nor any other line)."""
    parts = raw.lines.get("1") or [p for lay, ps in raw.lines.items() if lay not in USED_LAYERS for p in ps]
    if not parts:
        return None
    n = sum(len(p) for p in parts)
    if n > MAX_PIECE_VERTICES:
        raise InputError(f"{label}: the cut line has {n:,} vertices (at most {MAX_PIECE_VERTICES:,}): simplify it "
                         "in the pattern software (a curve tolerance of 0.1-0.2 mm is plenty)")
    if len(parts) > MAX_PARTS:
        raise InputError(f"{label}: the cut line is in {len(parts):,} parts (at most {MAX_PARTS:,})")
    tol = CHAIN_TOL_CM / to_cm
    chains = chain(parts, tol)
    closed = [c for c in chains if c[2]]
    if not closed:
        raise ChainError(f"{label}: the cut line (layer 1) does not close -- {_gap_report(chains, to_cm)}; "
                         f"parts are joined where their ends are within {10 * CHAIN_TOL_CM:.1f} mm: close it in "
                         "the pattern software and export again")
    pts, breaks, _ = closed[0]
    outline, breaks = drop_spikes(pts * to_cm, breaks)
    area = abs(geo.signed_area(outline))
    if area <= 0.0:
        raise InputError(f"{label}: the cut line encloses no area")
    sew = None
    if raw.lines.get("14"):
        sew_chains = [c for c in chain(raw.lines["14"], tol) if c[2]]
        sew = sew_chains[0][0] * to_cm if sew_chains else None

    def pts_of(layers):
        got = [p for lay in layers for p in raw.points.get(lay, [])]
        got += [ln[0] for lay in layers for ln in raw.lines.get(lay, [])]  # a notch drawn as a short line
        return np.array(got, dtype=np.float64).reshape(-1, 2) * to_cm

    grain = raw.lines.get("7")
    grain_line = None
    if grain:
        g = max(grain, key=lambda p: np.linalg.norm(p[-1] - p[0]))
        grain_line = np.array([g[0], g[-1]]) * to_cm
    other = {lay: [p * to_cm for p in ps] for lay, ps in raw.lines.items() if lay not in USED_LAYERS}
    for lay, ps in raw.points.items():
        if lay not in USED_LAYERS:
            other.setdefault(lay, []).extend(p[None] * to_cm for p in ps)
    return Shape(outline=outline, breaks=breaks, file_area=area, turn=pts_of(["2"]), notches=pts_of(NOTCH_LAYERS),
                 grain=grain_line, mirror=[np.array([m[0], m[-1]]) * to_cm for m in raw.lines.get("6", [])],
                 internal=[p * to_cm for p in raw.lines.get("8", [])], drills=pts_of(["13"]), sew=sew, other=other)


_FIELDS = {"piece name": "name", "size": "size", "quantity": "quantity", "category": "category",
           "annotation": "annotation", "fabric": "fabric"}


def _fields(texts) -> dict[str, str]:
    out = {}
    for _, t in texts:
        m = re.match(r"\s*([a-z ]+?)\s*:\s*(.*?)\s*$", t, re.I)
        if m and m.group(1).lower() in _FIELDS and _FIELDS[m.group(1).lower()] not in out:
            out[_FIELDS[m.group(1).lower()]] = m.group(2)
    return out


def _cut_count(fields: dict) -> tuple[int | None, int]:
    """(the quantity text's number, how many to cut): Gerber writes the count cut per garment
    in the annotation ("2XFABRIC", "1X RIB"), its quantity field being 0 or 1 for a sleeve cut
    twice; the quantity where the annotation says none."""
    q = None
    m = re.match(r"\s*(\d+)", fields.get("quantity", ""))
    if m:
        q = int(m.group(1))
    m = re.match(r"\s*(\d+)\s*X\s*[A-Z]", fields.get("annotation", ""), re.I)
    if m and 0 < int(m.group(1)) <= 8:
        return q, int(m.group(1))
    return q, max(q or 1, 1)


# ------------------------------------------------------------------ units


def _stated_units(doc, texts: list[str]) -> tuple[str | None, str]:
    """(unit or None for 'metric, mm or cm', how it was decided); InputError when nothing says."""
    for t in texts:  # the standard's own statement first ($INSUNITS is often a CAD default)
        m = re.match(r"\s*units\s*:\s*(\w+)", t, re.I)
        if m:
            word = m.group(1).lower()
            if word in ("english", "inch", "inches", "imperial"):
                return "in", f"'Units: {m.group(1)}': inches"
            if word == "metric":
                return None, f"'Units: {m.group(1)}'"
            if word in UNITS_CM:
                return word, f"'Units: {m.group(1)}'"
    code = int(doc.header.get("$INSUNITS", 0) or 0)
    if code in _INSUNITS:
        u = _INSUNITS[code]
        return u, f"$INSUNITS {code}: {UNIT_WORDS[u]}"
    raise InputError("the DXF does not say its units (no $INSUNITS in its header, no 'Units:' text); "
                     "give them: --units mm, cm, m or in")


def _metric_unit(extent: float) -> tuple[str, str]:
    """'Units: METRIC' says millimetres or centimetres: the one that makes the largest piece
    (extent, file units) a garment's (MIN_PIECE_CM .. MAX_PIECE_CM, nearest 70 cm)."""
    fits = [(abs(np.log(extent * UNITS_CM[u] / 70.0)), u) for u in ("mm", "cm")
            if MIN_PIECE_CM <= extent * UNITS_CM[u] <= MAX_PIECE_CM]
    u = min(fits)[1] if fits else "mm"
    other = "cm" if u == "mm" else "mm"
    return u, (f"{UNIT_WORDS[u]} (the largest piece is then {extent * UNITS_CM[u]:.0f} cm long; in "
               f"{UNIT_WORDS[other]} it would be {extent * UNITS_CM[other]:.3g} cm)")


# ------------------------------------------------------------------ the file


def _open(path: Path):
    import ezdxf
    from ezdxf import recover

    if not path.is_file():
        raise InputError(f"DXF file not found: {path}")
    size = path.stat().st_size
    if size == 0:
        raise InputError(f"{path.name}: empty file")
    if size > MAX_DXF_BYTES:
        raise InputError(f"{path.name}: {size / 1e6:.0f} MB, larger than the {MAX_DXF_BYTES / 1e6:.0f} MB a cutting "
                         "pattern needs: export the pattern's pieces only (no markers, no images)")
    with open(path, "rb") as fh:
        head = fh.read(4096)
    if b"\0" in head:
        raise InputError(f"{path.name}: not a readable DXF file (binary data; a DXF is text: export as "
                         "DXF R12 / AAMA / ASTM)")
    notes = []
    try:
        doc = ezdxf.readfile(str(path))
    except (ezdxf.DXFStructureError, ezdxf.DXFError, ValueError, TypeError):
        try:  # a damaged file (CLO writes floats where integers belong): ezdxf's recover reads it
            doc, auditor = recover.readfile(str(path))
        except (IOError, ezdxf.DXFStructureError, UnicodeDecodeError, ValueError) as e:
            raise InputError(f"{path.name}: not a readable DXF file ({e})") from None
        notes.append(f"the file is not standard DXF; ezdxf's recover read it ({len(auditor.fixes)} repair(s), "
                     f"{len(auditor.errors)} error(s) left)")
    except (IOError, UnicodeDecodeError) as e:
        raise InputError(f"{path.name}: not a readable DXF file ({e})") from None
    return doc, notes


def _blocks(doc, msp) -> list:
    """The pieces' blocks: those inserted in the drawing (each once), else every named block."""
    seen, out = set(), []
    for ins in msp.query("INSERT"):
        name = ins.dxf.name
        if name in seen or name.startswith("*"):
            continue
        block = doc.blocks.get(name)
        if block is not None:
            seen.add(name)
            out.append((name, block, ins))
    if not out:
        out = [(b.name, b, None) for b in doc.blocks if not b.name.startswith("*")]
    return out


def read_pattern(path: str | Path, units: str | None = None) -> DxfPattern:
    """Every piece of a DXF cutting pattern in every size (cm); InputError on anything unusable."""
    path = Path(path)
    if units is not None and units not in UNITS_CM:
        raise InputError(f"units '{units}': use one of {', '.join(UNITS_CM)}")
    with reading(path.name, "a DXF cutting pattern"):  # (the malformed-input errors of our code and ezdxf's)
        try:
            return _read(path, units)
        except Exception as e:
            if isinstance(e, (TryonError, *MALFORMED)) or not _from_ezdxf(e):
                raise
            raise InputError(f"{path.name} could not be read as a DXF cutting pattern ({_one_line(e)}): it is "
                             "damaged; export it again from the pattern software") from None


def _from_ezdxf(e: BaseException) -> bool:
    """Whether ezdxf raised `e`: its own error types, or an error raised inside its code while it
    read a damaged file (a StopIteration in its tag validator)."""
    import traceback

    import ezdxf

    if isinstance(e, ezdxf.DXFError):
        return True
    tb = traceback.extract_tb(e.__traceback__)
    return bool(tb) and "/ezdxf/" in tb[-1].filename.replace("\\", "/")


def _one_line(e: BaseException) -> str:
    msg = str(e).strip().splitlines()[0][:160] if str(e).strip() else ""
    return f"{type(e).__name__}: {msg}" if msg else type(e).__name__


def _read(path: Path, units: str | None) -> DxfPattern:
    doc, notes = _open(path)
    msp = doc.modelspace()
    budget = [MAX_ENTITIES]
    top = _raw(msp, budget)
    texts = [t for _, t in top.texts]
    raws = []  # (block name, _Raw, mirrored)
    for name, block, ins in _blocks(doc, msp):
        r = _raw(block, budget)
        if r.lines:
            mirrored = ins is not None and float(ins.dxf.get("xscale", 1.0)) * float(ins.dxf.get("yscale", 1.0)) < 0
            raws.append((name, r, mirrored))
    if not raws and top.lines:
        raws = [(None, top, False)]
    if not raws:
        raise InputError(f"{path.name}: no pattern pieces found (no lines in a block or in the drawing)")
    if units is not None:
        unit, how = units, f"--units {units}"
    else:
        unit, how = _stated_units(doc, texts)
        if unit is None:
            ext = max(float(np.ptp(np.concatenate(r.lines.get("1") or list(r.lines.values())[0]), axis=0).max())
                      for _, r, _ in raws)
            unit, why = _metric_unit(ext)
            how = f"{how}: {why}"
    to_cm = UNITS_CM[unit]
    pattern = _assemble(path.name, raws, to_cm, texts)
    pattern.units, pattern.units_note = unit, how
    pattern.notes = notes + pattern.notes
    for layer, n in top.count.items():
        pattern.layers[layer] = pattern.layers.get(layer, 0) + n
    _check_sizes(pattern)
    return pattern


def _assemble(source: str, raws, to_cm: float, texts: list[str]) -> DxfPattern:
    pieces: dict[str, DxfPiece] = {}
    sizes: list[str] = []
    layers: dict[str, int] = {}
    notes: list[str] = []
    for block_name, r, mirrored in raws:
        for lay, n in r.count.items():
            layers[lay] = layers.get(lay, 0) + n
        f = _fields(r.texts)
        size = f.get("size") or ONE_SIZE
        if block_name is None:  # a plain drawing: every closed outline is a piece
            _plain_pieces(source, r, to_cm, pieces, sizes)
            continue
        name = f.get("name") or block_name
        label = f"{source}: piece '{name}'" + (f" in size {size}" if size != ONE_SIZE else "")
        shape = _shape(r, to_cm, label)
        if shape is None:
            continue
        if mirrored:
            _mirror_shape(shape)
        piece = pieces.setdefault(name, DxfPiece(name=name, shapes={}))
        if size in piece.shapes:
            notes.append(f"piece '{name}' has two blocks in size {size}: the first is used")
            continue
        piece.shapes[size] = shape
        if size not in sizes:
            sizes.append(size)
        if "quantity" in f or "annotation" in f or "category" in f:
            piece.quantity, piece.cut = _cut_count(f)
            piece.category, piece.annotation, piece.fabric = f.get("category"), f.get("annotation"), f.get("fabric")
    style = next((m.group(1) for t in texts if (m := re.match(r"\s*style\s*name\s*:\s*(.+?)\s*$", t, re.I))), None)
    sample = next((m.group(1) for t in texts if (m := re.match(r"\s*sample\s*size\s*:\s*(.+?)\s*$", t, re.I))), None)
    pattern = DxfPattern(source=source, units="", units_note="", sizes=sizes, pieces=list(pieces.values()),
                         style=style, sample_size=sample if sample in sizes else None, notes=notes, layers=layers)
    if not pattern.pieces:
        raise InputError(f"{source}: no pattern pieces found (no cut line on layer 1 in any block)")
    return pattern


def _plain_pieces(source: str, r: _Raw, to_cm: float, pieces: dict, sizes: list) -> None:
    """A drawing without blocks: each closed outline (layer 1, else any layer) is a piece."""
    parts = r.lines.get("1") or [p for ps in r.lines.values() for p in ps]
    if sum(len(p) for p in parts) > MAX_PIECE_VERTICES * 20:
        raise InputError(f"{source}: the drawing has more than {MAX_PIECE_VERTICES * 20:,} vertices")
    loops = [c for c in chain(parts[:MAX_PARTS * 20], CHAIN_TOL_CM / to_cm) if c[2]]
    if not loops:
        raise InputError(f"{source}: no pattern pieces found (no closed outline, in a block or in the drawing)")
    for k, (pts, breaks, _) in enumerate(loops):
        outline = pts * to_cm
        empty = np.zeros((0, 2))
        shape = Shape(outline=outline, breaks=breaks, file_area=abs(geo.signed_area(outline)), turn=empty,
                      notches=empty, grain=None, mirror=[], internal=[], drills=empty, sew=None)
        pieces[f"piece{k + 1}"] = DxfPiece(name=f"piece{k + 1}", shapes={ONE_SIZE: shape})
    if ONE_SIZE not in sizes:
        sizes.append(ONE_SIZE)


def _mirror_shape(s: Shape) -> None:
    """A block inserted mirrored (negative scale): the piece is cut the other way round."""
    flip = np.array([-1.0, 1.0])
    s.outline = s.outline[::-1] * flip
    s.breaks = sorted({(len(s.outline) - 1 - b) % len(s.outline) for b in s.breaks})
    for name in ("turn", "notches", "drills"):
        setattr(s, name, getattr(s, name) * flip)
    s.grain = None if s.grain is None else s.grain * flip
    s.mirror = [m * flip for m in s.mirror]
    s.internal = [m * flip for m in s.internal]
    s.sew = None if s.sew is None else s.sew[::-1] * flip


def _section_of(outline: np.ndarray, breaks: list[int], q: np.ndarray) -> tuple[int, float, float]:
    """(section k between breaks k and k + 1, fraction of its arc length, distance) of the
    outline point nearest q."""
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(np.vstack([outline, outline[:1]]), axis=0),
                                                          axis=1))])
    a, b = outline, np.roll(outline, -1, axis=0)
    ab = b - a
    t = np.clip(((q - a) * ab).sum(1) / np.maximum((ab * ab).sum(1), 1e-18), 0, 1)
    d = np.linalg.norm(a + t[:, None] * ab - q, axis=1)
    i = int(d.argmin())
    s = arc[i] + t[i] * (arc[i + 1] - arc[i])
    starts = arc[np.array(breaks)]
    k = int(np.searchsorted(starts, s, side="right") - 1) % len(breaks)
    s0, s1 = starts[k], (starts[k + 1] if k + 1 < len(breaks) else starts[0] + arc[-1])
    if s < s0:
        s += arc[-1]
    return k, float((s - s0) / max(s1 - s0, 1e-12)), float(d[i])


def _at_section(outline: np.ndarray, breaks: list[int], k: int, f: float) -> np.ndarray:
    arc = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(np.vstack([outline, outline[:1]]), axis=0),
                                                          axis=1))])
    starts = arc[np.array(breaks)]
    s0, s1 = starts[k], (starts[k + 1] if k + 1 < len(breaks) else starts[0] + arc[-1])
    s = (s0 + f * (s1 - s0)) % arc[-1]
    q = np.vstack([outline, outline[:1]])
    return np.array([np.interp(s, arc, q[:, 0]), np.interp(s, arc, q[:, 1])])


def _transfer_notches(piece: DxfPiece) -> None:
    """Pattern CAD writes the notches in the sample size's block only: carry them to the other
    sizes at the same fraction of the same section of the cut line (the sizes' cut lines break
    at the same corners, which grading keeps)."""
    src = max(piece.shapes.values(), key=lambda sh: len(sh.notches))
    if not len(src.notches) or len(src.breaks) < 2:
        return
    where = [_section_of(src.outline, src.breaks, q) for q in src.notches]
    where = [(k, f) for k, f, d in where if d < 0.5]
    for sh in piece.shapes.values():
        if sh is not src and not len(sh.notches) and len(sh.breaks) == len(src.breaks):
            sh.notches = np.array([_at_section(sh.outline, sh.breaks, k, f) for k, f in where]).reshape(-1, 2)


def _check_sizes(pattern: DxfPattern) -> None:
    """Each piece a garment piece's size (a units mistake otherwise); a piece missing in a size noted."""
    for p in pattern.pieces:
        _transfer_notches(p)
        for size, s in p.shapes.items():
            across = float(np.ptp(s.outline, axis=0).max())
            if not MIN_PIECE_CM <= across <= MAX_PIECE_CM:
                raise InputError(
                    f"{pattern.source}: piece '{p.name}' is {across:.3g} cm across ({pattern.units_note}), which is "
                    f"no garment piece: are the units right? (give them with --units mm, cm, m or in)")
        missing = [s for s in pattern.sizes if s not in p.shapes]
        if missing:
            p.notes.append(f"not graded in size(s) {', '.join(missing)}")


# ------------------------------------------------------------------ corners


CORNER_DEG = 45.0  # without turn points: the outline turning more than this at a vertex is a corner
TURN_SNAP = 0.05  # cm: a turn point this close to the outline marks it (snapped to a vertex, or inserted)


def corners_of(piece: DxfPiece, size: str) -> tuple[np.ndarray, list[int]]:
    """(outline, corner indices) of a piece in a size: its turn points (layer 2) where every size
    of the piece has them (each snapped to its outline vertex, or inserted on its segment), else
    the points where its cut line's parts meet and where the line turns sharper than CORNER_DEG;
    a round piece (fewer than two) gets four corners a quarter of its length apart. The same
    rule in every size, so a piece's edges are numbered alike in all its sizes. Where the file
    carries a sew line (the cut line less its seam allowance), the outline is the sew line,
    where the seams are sewn: the simulated cloth ends there."""
    sh = piece.shapes[size]
    if sh.sew is not None:  # the sew line: where the seams are (its own sharp turns are its corners)
        return _sharp_corners(sh.sew.copy(), [])
    poly = sh.outline.copy()
    if all(len(s.turn) for s in piece.shapes.values()):
        poly, idx = _snap_turns(poly, sh.turn)
        return _round_corners(poly, idx)
    return _sharp_corners(poly, sh.breaks)


def _sharp_corners(poly: np.ndarray, breaks: list[int]) -> tuple[np.ndarray, list[int]]:
    """The breaks and the points where the outline turns sharper than CORNER_DEG."""
    prev, nxt = poly - np.roll(poly, 1, axis=0), np.roll(poly, -1, axis=0) - poly
    cos = (prev * nxt).sum(1) / np.maximum(np.linalg.norm(prev, axis=1) * np.linalg.norm(nxt, axis=1), 1e-18)
    sharp = np.flatnonzero(cos < np.cos(np.radians(CORNER_DEG))).tolist()
    return _round_corners(poly, sorted(set(breaks) | set(sharp)))


def _round_corners(poly: np.ndarray, idx: list[int]) -> tuple[np.ndarray, list[int]]:
    """idx as the corners; a round piece (fewer than two) four, a quarter of its length apart."""
    if len(idx) < 2:  # a round piece: four edges of equal length
        s = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(np.vstack([poly, poly[:1]]), axis=0), axis=1))])
        start, total = (idx[0] if idx else 0), s[-1]
        s = (s[:-1] - s[start]) % total
        idx = sorted({start} | {int(np.abs(s - q * total).argmin()) for q in (0.25, 0.5, 0.75)})
    return poly, [int(i) for i in idx]


def _snap_turns(poly: np.ndarray, turn: np.ndarray) -> tuple[np.ndarray, list[int]]:
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
    return poly, sorted({int(np.linalg.norm(poly - m, axis=1).argmin()) for m in marked})
