"""Checks a pattern before anything is simulated. Each problem names the panel and the edge.

Errors make the pattern unusable (a stitch naming a missing panel or edge, stitched edges whose
lengths differ by more than 10 %, a self-intersecting or open outline, a degenerate edge);
warnings are shown but do not stop a run (an edge sewn twice, a very small panel).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.errors import InputError, parser
from engine.pattern import geometry as geo
from engine.pattern.spec import PatternSpec

SEAM_LENGTH_TOLERANCE = 0.10  # stitched edges may differ by this fraction (ease, gathering)
MAX_EDGES = 20_000  # in a whole pattern: garments have hundreds; a large DXF a few thousand


@dataclass(frozen=True)
class Problem:
    level: str  # "error" or "warning"
    panel: str | None
    edge: int | None
    message: str

    def __str__(self) -> str:
        where = ""
        if self.panel is not None:
            where = f"panel '{self.panel}'" + (f" edge {self.edge}" if self.edge is not None else "") + ": "
        return f"{self.level}: {where}{self.message}"


def validate(spec: PatternSpec) -> list[Problem]:
    """All problems found, errors first."""
    out: list[Problem] = []
    scale, rel = spec.scale, spec.properties.curvature_coords == "relative"
    if not (np.isfinite(scale) and scale > 0):
        return [Problem("error", None, None, f"the pattern's units give a scale of {scale}: use cm, mm, m or inch")]
    panels = spec.pattern.panels
    n_edges = sum(len(p.edges) for p in panels.values())
    if n_edges > MAX_EDGES:
        return [Problem("error", None, None, f"{n_edges:,} edges, more than {MAX_EDGES:,}: simplify the pattern")]
    for name, panel in panels.items():
        out += _check_panel(name, panel, scale, rel)
    used: dict[tuple[str, int], int] = {}
    for k, (a, b) in enumerate(spec.pattern.stitches):
        ok = True
        for side in (a, b):
            if side.panel not in panels:
                out.append(Problem("error", side.panel, side.edge,
                                   f"stitch {k} names panel '{side.panel}', which does not exist "
                                   f"(panels: {', '.join(panels)})"))
                ok = False
            elif not 0 <= side.edge < len(panels[side.panel].edges):
                out.append(Problem("error", side.panel, side.edge,
                                   f"stitch {k} names edge {side.edge}, but the panel has edges "
                                   f"0..{len(panels[side.panel].edges) - 1}"))
                ok = False
            else:
                key = (side.panel, side.edge)
                if key in used:
                    out.append(Problem("warning", side.panel, side.edge,
                                       f"edge is sewn by stitches {used[key]} and {k}"))
                used[key] = k
        if not ok:
            continue
        pa, pb = panels[a.panel], panels[b.panel]
        la = geo.edge_length(pa, pa.edges[a.edge], scale, rel)
        lb = geo.edge_length(pb, pb.edges[b.edge], scale, rel)
        if max(la, lb) > 0 and abs(la - lb) / max(la, lb) > SEAM_LENGTH_TOLERANCE:
            out.append(Problem("error", a.panel, a.edge,
                               f"stitch {k}: this edge is {la * 100:.1f} cm long but panel '{b.panel}' "
                               f"edge {b.edge} is {lb * 100:.1f} cm (differ by more than "
                               f"{SEAM_LENGTH_TOLERANCE:.0%}); make the stitched edges the same length"))
    out.sort(key=lambda p: p.level != "error")
    return out


def _check_panel(name: str, panel, scale: float, rel: bool) -> list[Problem]:
    out: list[Problem] = []
    edges = panel.edges
    if not (np.all(np.isfinite(panel.translation)) and np.all(np.isfinite(panel.rotation))):
        return [Problem("error", name, None, "placement (translation or rotation) is not a finite number")]
    if len(edges) < 2:
        return [Problem("error", name, None, f"a panel needs a closed outline of at least 2 edges, got {len(edges)}")]
    for i, e in enumerate(edges):
        nxt = edges[(i + 1) % len(edges)]
        if e.endpoints[1] != nxt.endpoints[0]:
            out.append(Problem("error", name, i,
                               f"edge ends at vertex {e.endpoints[1]} but the next edge starts at vertex "
                               f"{nxt.endpoints[0]}: the outline must be one closed loop of edges in order"))
        if e.endpoints[0] == e.endpoints[1]:
            out.append(Problem("error", name, i, "degenerate edge: both endpoints are the same vertex"))
            continue
        length = geo.edge_length(panel, e, scale, rel)
        if not np.isfinite(length) or length < 1e-4:
            out.append(Problem("error", name, i, f"degenerate edge: length {length * 1000:.2f} mm"))
    if any(p.level == "error" for p in out):
        return out
    dense = [geo.edge_dense(panel, e, scale, rel, 64) for e in edges]  # once: outline and its edge numbers
    poly = np.concatenate([d[:-1] for d in dense], axis=0)  # = geo.outline(panel, scale, rel)
    if not np.all(np.isfinite(poly)):
        return [Problem("error", name, None, "outline has non-finite coordinates")]
    seg_edge = np.concatenate([np.full(len(d) - 1, i) for i, d in enumerate(dense)])
    try:
        crossing = _self_intersection(poly, seg_edge)
    except InputError as e:  # too intricate to check: said for this panel
        return [Problem("error", name, None, str(e))]
    if crossing is not None:
        i, j = crossing
        out.append(Problem("error", name, i, f"outline crosses itself (edge {i} crosses edge {j})"))
    area = abs(geo.signed_area(poly))
    if area < 1e-4:
        out.append(Problem("warning", name, None, f"very small panel ({area * 1e4:.2f} cm^2)"))
    return out


def _self_intersection(poly: np.ndarray, seg_edge: np.ndarray) -> tuple[int, int] | None:
    """First pair (smallest first segment, then second) of non-adjacent outline segments that
    properly cross, as (edge, edge); seg_edge: (M,) the edge each outline segment belongs to.
    Only segments that share a cell of a uniform grid are tested: near-linear in M for outlines
    (all pairs at once took minutes and gigabytes for a DXF of thousands of edges)."""
    m = len(poly)
    a, b = poly, np.roll(poly, -1, axis=0)
    i, j = _grid_pairs(a, b)
    keep = (j - i >= 2) & ~((i == 0) & (j == m - 1))  # neighbours share a vertex
    i, j = i[keep], j[keep]

    def orient(p, q, r):
        return (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])

    o1 = orient(a[i], b[i], a[j])
    o2 = orient(a[i], b[i], b[j])
    o3 = orient(a[j], b[j], a[i])
    o4 = orient(a[j], b[j], b[i])
    eps = 1e-14 * (1 + np.abs(b - a).max()) ** 2
    hit = (o1 * o2 < -eps) & (o3 * o4 < -eps)
    if not hit.any():
        return None
    k = np.lexsort((j[hit], i[hit]))[0]
    return int(seg_edge[i[hit][k]]), int(seg_edge[j[hit][k]])


MAX_GRID_PAIRS = 20_000_000  # candidate segment pairs at most (~1 GB of scratch); more is refused


def _grid_pairs(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(i, j), i < j: the segment pairs (a[k], b[k]) whose bounding boxes share a grid cell; the
    cell is about twice the median segment length, so a segment covers a few cells."""
    m = len(a)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    span = float(np.max(hi.max(axis=0) - lo.min(axis=0))) or 1.0
    cell = max(2.0 * float(np.median(np.linalg.norm(b - a, axis=1))), span / 4096, 1e-12)
    c0 = np.floor((lo - lo.min(axis=0)) / cell).astype(np.int64)
    c1 = np.floor((hi - lo.min(axis=0)) / cell).astype(np.int64)
    nx, ny = c1[:, 0] - c0[:, 0] + 1, c1[:, 1] - c0[:, 1] + 1
    per = nx * ny
    if per.sum() > 64 * m + 1_000_000:
        raise InputError(f"an outline of {m:,} segments is too intricate to check (long segments across "
                         "a dense outline): simplify the pattern")
    seg = np.repeat(np.arange(m), per)
    k = np.arange(len(seg)) - np.repeat(np.cumsum(per) - per, per)  # index of the cell within its box
    cx = np.repeat(c0[:, 0], per) + k % np.repeat(nx, per)
    cy = np.repeat(c0[:, 1], per) + k // np.repeat(nx, per)
    key = cx * (int(c1[:, 1].max()) + 1) + cy
    order = np.lexsort((seg, key))
    key, seg = key[order], seg[order]
    starts = np.flatnonzero(np.r_[True, key[1:] != key[:-1]])  # runs of one cell
    lens = np.diff(np.r_[starts, len(key)])
    if int((lens * (lens - 1) // 2).sum()) > MAX_GRID_PAIRS:
        raise InputError(f"an outline of {m:,} segments has too many overlapping segments to check: "
                         "simplify the pattern")
    after = np.repeat(lens, lens) - (np.arange(len(key)) - np.repeat(starts, lens)) - 1  # partners behind
    p, d, pi, pj = np.flatnonzero(after > 0), 1, [], []
    while len(p):  # each member with the one d places behind it in its run: work ~ the pairs
        pi.append(seg[p])
        pj.append(seg[p + d])
        d += 1
        p = p[after[p] >= d]
    if not pi:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    i, j = np.concatenate(pi), np.concatenate(pj)
    return np.minimum(i, j), np.maximum(i, j)


@parser("a pattern", name_of=lambda spec, source="pattern": source)
def check(spec: PatternSpec, source: str = "pattern") -> list[Problem]:
    """Raise InputError (one line, all errors) if the pattern has errors; return the warnings."""
    problems = validate(spec)
    errors = [p for p in problems if p.level == "error"]
    if errors:
        more = f" (+{len(errors) - 3} more)" if len(errors) > 3 else ""
        raise InputError(f"{source}: " + "; ".join(str(p) for p in errors[:3]) + more)
    return problems
