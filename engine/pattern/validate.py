"""Checks a pattern before anything is simulated. Each problem names the panel and the edge.

Errors make the pattern unusable (a stitch naming a missing panel or edge, an open outline, a
degenerate edge, non-finite numbers, edges gathered past MAX_GATHER); warnings are shown but do
not stop a run (an edge sewn twice, a very small panel, an outline that crosses itself a few
times, or more where it still winds once over nearly all of the panel -- meshed as GarmentCode
draws it, engine.garment.mesh). Stitched edges of different lengths are a gather:
the longer is sewn evenly into the shorter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from engine.errors import InputError, parser
from engine.pattern import geometry as geo
from engine.pattern.spec import PatternSpec

MAX_GATHER = 4.0  # a stitched edge at most this many times the length of the edge it is sewn to
MAX_CROSSINGS = 8  # pairs of edges of an outline that cross: more is not a drawing but a mix-up ...
# ... where the outline winds back over more than this share of what it encloses (geometry.winding_shares):
# GarmentCode's godet cuts reaching a little past a skirt's waist cross it many times and wind back
# over almost none of it -- a drawing, meshed as drawn; cuts far past a narrow band wind back over most
MAX_WOUND_BACK = 0.02
TWIST = 0.01  # m: ... or where it crosses itself within this along the outline (neighbouring vertices out of order)
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
        if max(la, lb) > MAX_GATHER * min(la, lb):
            out.append(Problem("error", a.panel, a.edge,
                               f"stitch {k}: this edge is {la * 100:.1f} cm long and panel '{b.panel}' edge "
                               f"{b.edge} {lb * 100:.1f} cm: more than {MAX_GATHER:g} x gathered into the "
                               "other; check the stitch's edges"))
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
        i, j, n = crossing
        if n > MAX_CROSSINGS and (geo.winding_shares(poly)[1] > MAX_WOUND_BACK or
                                  float(geo.crossing_spans(poly).min()) < TWIST):
            out.append(Problem("error", name, i, f"outline crosses itself between {n} pairs of edges (edge {i} "
                                                 f"crosses edge {j}): check the order of its vertices and edges, "
                                                 "and whether a dart or a cut reaches past the panel's other side"))
        else:
            out.append(Problem("warning", name, i, f"outline crosses itself (edge {i} crosses edge {j}): meshed "
                                                   "as GarmentCode draws it, its parts joined where the edges cross"))
    area = abs(geo.signed_area(poly))
    if area < 1e-4:
        out.append(Problem("warning", name, None, f"very small panel ({area * 1e4:.2f} cm^2)"))
    return out


def _self_intersection(poly: np.ndarray, seg_edge: np.ndarray) -> tuple[int, int, int] | None:
    """The first pair (smallest first segment, then second) of non-adjacent outline segments that
    properly cross, as (edge, edge, how many crossings in all); seg_edge: (M,) the edge each
    outline segment belongs to."""
    i, j, _ = geo.segment_crossings(poly)
    if not len(i):
        return None
    k = np.lexsort((j, i))[0]
    pairs = len({(int(a), int(b)) for a, b in zip(seg_edge[i], seg_edge[j])})  # (a curve may graze another)
    return int(seg_edge[i[k]]), int(seg_edge[j[k]]), pairs


@parser("a pattern", name_of=lambda spec, source="pattern": source)
def check(spec: PatternSpec, source: str = "pattern") -> list[Problem]:
    """Raise InputError (one line, all errors) if the pattern has errors; return the warnings."""
    problems = validate(spec)
    errors = [p for p in problems if p.level == "error"]
    if errors:
        more = f" (+{len(errors) - 3} more)" if len(errors) > 3 else ""
        raise InputError(f"{source}: " + "; ".join(str(p) for p in errors[:3]) + more)
    return problems
