"""Checks a pattern before anything is simulated. Each problem names the panel and the edge.

Errors make the pattern unusable (a stitch naming a missing panel or edge, stitched edges whose
lengths differ by more than 10 %, a self-intersecting or open outline, a degenerate edge);
warnings are shown but do not stop a run (an edge sewn twice, a very small panel).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.errors import InputError
from engine.pattern import geometry as geo
from engine.pattern.spec import PatternSpec

SEAM_LENGTH_TOLERANCE = 0.10  # stitched edges may differ by this fraction (ease, gathering)


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
    panels = spec.pattern.panels
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
    poly = geo.outline(panel, scale, rel)
    if not np.all(np.isfinite(poly)):
        return [Problem("error", name, None, "outline has non-finite coordinates")]
    seg_edge = np.concatenate([np.full(len(geo.edge_dense(panel, e, scale, rel, 64)) - 1, i)
                               for i, e in enumerate(edges)])
    crossing = _self_intersection(poly, seg_edge)
    if crossing is not None:
        i, j = crossing
        out.append(Problem("error", name, i, f"outline crosses itself (edge {i} crosses edge {j})"))
    area = abs(geo.signed_area(poly))
    if area < 1e-4:
        out.append(Problem("warning", name, None, f"very small panel ({area * 1e4:.2f} cm^2)"))
    return out


def _self_intersection(poly: np.ndarray, seg_edge: np.ndarray) -> tuple[int, int] | None:
    """First pair of non-adjacent outline segments that properly cross, as (edge, edge);
    seg_edge: (M,) the edge each outline segment belongs to."""
    m = len(poly)
    a, b = poly, np.roll(poly, -1, axis=0)
    # proper intersection of segments i and j via orientation tests, all pairs at once
    d1 = b - a
    i, j = np.triu_indices(m, k=2)
    keep = ~((i == 0) & (j == m - 1))  # first and last segments share a vertex
    i, j = i[keep], j[keep]

    def orient(p, q, r):
        return (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])

    o1 = orient(a[i], b[i], a[j])
    o2 = orient(a[i], b[i], b[j])
    o3 = orient(a[j], b[j], a[i])
    o4 = orient(a[j], b[j], b[i])
    eps = 1e-14 * (1 + np.abs(d1).max()) ** 2
    hit = (o1 * o2 < -eps) & (o3 * o4 < -eps)
    if not hit.any():
        return None
    k = int(np.argmax(hit))
    return int(seg_edge[i[k]]), int(seg_edge[j[k]])


def check(spec: PatternSpec, source: str = "pattern") -> list[Problem]:
    """Raise InputError (one line, all errors) if the pattern has errors; return the warnings."""
    problems = validate(spec)
    errors = [p for p in problems if p.level == "error"]
    if errors:
        more = f" (+{len(errors) - 3} more)" if len(errors) > 3 else ""
        raise InputError(f"{source}: " + "; ".join(str(p) for p in errors[:3]) + more)
    return problems
