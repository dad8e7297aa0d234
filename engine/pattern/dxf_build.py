"""DXF parts and seams -> a GarmentCode specification.

Each part's outline is cut into edges at its corners and at the ends of its seams (a seam's two
sides are cut at the same fractions of their lengths, so the corners of one side come to the
other too and the seam sews edge to edge). Between two cuts the outline becomes one edge: a
straight line (no point further than STRAIGHT_TOL off it), a circular arc or a cubic Bezier
within FIT_TOL -- or, where one curve does not fit, 2, 4, 8 or 16 of them at equal arc lengths
(both sides of a seam alike).
"""

from __future__ import annotations

import numpy as np

from engine.pattern import geometry as geo
from engine.pattern.dxf_infer import MERGE_CM, Part, Seam, Span, _arc, point_at, span_points
from engine.pattern.spec import PanelHint, PatternSpec

STRAIGHT_TOL = 0.02  # cm: a section no further than this off its chord is a straight edge
FIT_TOL = 0.1  # cm: a curved section is one edge when a circle or cubic is this close to it ...
FIT_TOL_WIDTH = 0.008  # ... or this share of its panel's width where that is less (a 2 cm band: 0.16 mm;
# at 1 mm a neckband's area came out 1.1 % off its cut line's)
MAX_SPLIT = 16  # a section is cut into at most this many edges


# ------------------------------------------------------------------ one curve through points


def fit_cubic(pts: np.ndarray, tol: float = FIT_TOL) -> tuple[np.ndarray, np.ndarray, float]:
    """The cubic Bezier from pts[0] to pts[-1] closest to the points (least squares, chord-length
    parameters refined by projection): (c1, c2, max distance of the points from it)."""
    s, e = pts[0], pts[-1]
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    t = np.concatenate([[0.0], np.cumsum(seg)]) / max(seg.sum(), 1e-18)
    dense_t = np.linspace(0.0, 1.0, 501)
    best = (s + (e - s) / 3, s + 2 * (e - s) / 3, np.inf)
    for _ in range(40):  # alternate: control points for these parameters, parameters by projection
        b1, b2 = 3 * (1 - t) ** 2 * t, 3 * (1 - t) * t ** 2
        rhs = pts - ((1 - t) ** 3)[:, None] * s - (t ** 3)[:, None] * e
        (c1, c2), *_ = np.linalg.lstsq(np.stack([b1, b2], axis=1), rhs, rcond=None)
        curve = geo.bezier3(s, c1, c2, e, dense_t)
        d2 = ((pts[:, None, :] - curve[None, :, :]) ** 2).sum(axis=2)
        err = float(np.sqrt(d2.min(axis=1).max()))
        improved = err < 0.99 * best[2]
        if err < best[2]:
            best = (c1, c2, err)
        if err < tol / 10 or not improved:
            break
        t = dense_t[d2.argmin(axis=1)]
        t[0], t[-1] = 0.0, 1.0
    return best


def fit_arc(pts: np.ndarray, tol: float = FIT_TOL, check: np.ndarray | None = None) -> dict | None:
    """GarmentCode's circle curvature for a section that is a circular arc within tol (the
    circle through its ends and its middle point; `check`: the points to be within tol of it,
    default pts), else None."""
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
    if np.abs(np.linalg.norm((pts if check is None else check) - centre, axis=1) - r).max() > tol:
        return None
    side_m = -cross  # > 0: the middle lies left of start -> end, < 0: right
    side_c = b[0] * cy - b[1] * cx
    right = side_m < 0
    large = bool(side_m * side_c > 0)  # the middle on the same side of the chord as the centre
    return {"type": "circle", "params": [r, int(large), int(right)]}


def densify(pts: np.ndarray, step: float = 0.5) -> np.ndarray:
    """The polyline with points added so that none is more than `step` (cm) from the next: a
    curve fitted to the points then also stays near the lines between them."""
    out = [pts[:1]]
    for a, b in zip(pts[:-1], pts[1:]):
        k = max(1, int(np.ceil(np.linalg.norm(b - a) / step)))
        out.append(a + (b - a) * (np.arange(1, k + 1) / k)[:, None])
    return np.concatenate(out)


_FITTED: dict[bytes, tuple[dict | None, bool]] = {}  # the same section is fitted more than once


def fit_tol(outline: np.ndarray) -> float:
    """The fit tolerance of a panel's edges (cm): FIT_TOL, less on a narrow panel."""
    from engine.pattern.dxf_infer import min_rect

    return min(FIT_TOL, FIT_TOL_WIDTH * min_rect(outline)[1])


def curve_of(pts: np.ndarray, tol: float = FIT_TOL) -> tuple[dict | None, bool]:
    """(GarmentCode curvature or None for a straight edge, whether it fits within tol) of the
    edge through pts (cm) from pts[0] to pts[-1]."""
    key = np.ascontiguousarray(pts, dtype=np.float64).tobytes() + np.float64(tol).tobytes()
    if key not in _FITTED:
        if len(_FITTED) > 20_000:
            _FITTED.clear()
        _FITTED[key] = _curve_of(pts, tol)
    return _FITTED[key]


def _curve_of(pts: np.ndarray, tol: float) -> tuple[dict | None, bool]:
    dense = densify(pts)
    s, e = pts[0], pts[-1]
    chord = e - s
    L = float(np.linalg.norm(chord))
    if len(pts) == 2 or L == 0:
        return None, True
    off = np.abs((pts[:, 0] - s[0]) * chord[1] - (pts[:, 1] - s[1]) * chord[0]) / L
    if off.max() <= min(STRAIGHT_TOL, tol):
        return None, True
    arc = fit_arc(pts, tol, dense)
    if arc is not None:
        return arc, True
    c1, c2, err = fit_cubic(dense, tol)
    curv = {"type": "cubic", "params": [list(geo.to_relative(s, e, c1)), list(geo.to_relative(s, e, c2))]}
    return curv, err <= tol


def section_edges(pts: np.ndarray, tol: float = FIT_TOL) -> list[tuple[np.ndarray, dict | None]]:
    """[(end point, curvature or None)] for one outline section between two corners (halved
    until each half fits)."""
    curv, ok = curve_of(pts, tol)
    if ok or len(pts) < 5:
        return [(pts[-1], curv)]
    mid = len(pts) // 2
    return section_edges(pts[: mid + 1], tol) + section_edges(pts[mid:], tol)


def _resample(pts: np.ndarray, f0: float, f1: float) -> np.ndarray:
    """The polyline's points between arc fractions f0 and f1, ends interpolated."""
    a = np.concatenate([[0.0], np.cumsum(np.linalg.norm(np.diff(pts, axis=0), axis=1))])
    L = a[-1]
    s0, s1 = f0 * L, f1 * L
    inner = pts[(a > s0 + 1e-9) & (a < s1 - 1e-9)]
    ends = [np.array([np.interp(s, a, pts[:, 0]), np.interp(s, a, pts[:, 1])]) for s in (s0, s1)]
    return np.array([ends[0], *inner, ends[1]])


def splits_needed(pts: np.ndarray, tol: float = FIT_TOL) -> int:
    """How many equal-length edges a section needs so that each fits one curve (1, 2, 4 ...)."""
    k = 1
    while k < MAX_SPLIT:
        if all(curve_of(_resample(pts, j / k, (j + 1) / k), tol)[1] for j in range(k)):
            return k
        k *= 2
    return k


# ------------------------------------------------------------------ cutting the outlines


class _Cuts:
    """A part's cut positions (arc length, cm) and the number of edges each section needs."""

    def __init__(self, p: Part):
        self.p, self.total, self.tol = p, p.length, fit_tol(p.outline)
        arc = _arc(p.outline)
        self.pos: list[float] = []
        self.split: dict[float, int] = {}  # section start -> edges forced by a seam
        for c in sorted({float(arc[c]) for c in p.corners}):
            self.add(c)

    def snap(self, s: float) -> float:
        """The cut nearest arc position s (circular)."""
        d = [min(abs(s - c), self.total - abs(s - c)) for c in self.pos]
        return self.pos[int(np.argmin(d))]

    def add(self, s: float) -> float:
        s = s % self.total
        if self.pos:
            near = self.snap(s)
            if min(abs(s - near), self.total - abs(s - near)) <= MERGE_CM:
                return near
        self.pos = sorted(self.pos + [s])
        return s

    def section(self, s0: float, s1: float, d: int) -> tuple[float, float]:
        """(start, end) of the forward section that a span step from cut s0 to cut s1 covers."""
        return (s0, s1) if d > 0 else (s1, s0)

    def points(self, s0: float, s1: float) -> np.ndarray:
        return span_points(self.p.outline, Span(self.p.name, s0, s1, 1))


def _inner_fractions(cuts: _Cuts, span: Span) -> list[float]:
    L = span.length(cuts.total)
    out = []
    for c in cuts.pos:
        f = ((c - span.s0) * span.dir) % cuts.total / max(L, 1e-12)
        if 1e-6 < f < 1 - 1e-6:
            out.append(f)
    return out


def _merge_fractions(fs: list[float], tol: float) -> list[float]:
    out = []
    for f in sorted(fs):
        if not out or f - out[-1] > tol:
            out.append(f)
    if 1.0 - out[-1] <= tol:
        out[-1] = 1.0
    elif out[-1] != 1.0:
        out.append(1.0)
    return out


def cut_parts(parts: list[Part], seams: list[Seam]) -> tuple[dict[str, _Cuts], list[list[tuple]]]:
    """Every part's cuts, and per seam its steps: [(a from, a to, b from, b to)] in cut
    positions, each step one section on either side cut into the same number of edges."""
    cuts = {p.name: _Cuts(p) for p in parts}
    steps_of = []
    for seam in seams:
        ca, cb = cuts[seam.a.part], cuts[seam.b.part]
        la, lb = seam.a.length(ca.total), seam.b.length(cb.total)
        fr = [0.0] + _inner_fractions(ca, seam.a) + _inner_fractions(cb, seam.b)
        fr = _merge_fractions(fr, MERGE_CM / max(min(la, lb), 1e-9))
        pa = [ca.add(seam.a.at(f, ca.total)) for f in fr]
        pb = [cb.add(seam.b.at(f, cb.total)) for f in fr]
        steps_of.append([(pa[k], pa[k + 1], pb[k], pb[k + 1]) for k in range(len(fr) - 1)])
    for seam, steps in zip(seams, steps_of):  # both sides of each step: the same number of edges
        ca, cb = cuts[seam.a.part], cuts[seam.b.part]
        for a0, a1, b0, b1 in steps:
            sa, sb = ca.section(a0, a1, seam.a.dir), cb.section(b0, b1, seam.b.dir)
            k = max(splits_needed(ca.points(*sa), ca.tol), splits_needed(cb.points(*sb), cb.tol))
            ca.split[sa[0]] = max(ca.split.get(sa[0], 1), k)
            cb.split[sb[0]] = max(cb.split.get(sb[0], 1), k)
    return cuts, steps_of


# ------------------------------------------------------------------ the spec


def _starts(c: _Cuts) -> list[float]:
    """Arc positions where the part's edges start: its cuts, each section split as it needs."""
    starts = []
    for i, s0 in enumerate(c.pos):
        s1 = c.pos[(i + 1) % len(c.pos)]
        length = (s1 - s0) % c.total or c.total
        k = c.split.get(s0) or splits_needed(c.points(s0, s1), c.tol)
        starts += [(s0 + j * length / k) % c.total for j in range(k)]
    return starts


def panel_of(p: Part, starts: list[float]) -> dict:
    """The GarmentCode panel whose edges run between the outline's points at the arc positions
    `starts` (cm, in order round the outline from any of them), each one curve."""
    starts = [s % p.length for s in starts]
    tol = fit_tol(p.outline)
    verts, edges = [], []
    for i, s0 in enumerate(starts):
        s1 = starts[(i + 1) % len(starts)]
        pts = span_points(p.outline, Span(p.name, s0, s1, 1))
        curv, _ = curve_of(pts, tol)
        verts.append(point_at(p.outline, s0))
        edges.append({"endpoints": [i, (i + 1) % len(starts)]} | ({"curvature": curv} if curv else {}))
    return {"vertices": [[float(x), float(y)] for x, y in verts], "edges": edges,
            "translation": [0.0, 0.0, 0.0], "rotation": [0.0, 0.0, 0.0]}


def _edges_between(starts: list[float], total: float, s0: float, s1: float, d: int) -> list[int]:
    """The panel's edges (indices) from cut s0 to cut s1 walking in direction d, in that order."""
    def idx(s):
        return int(np.argmin([min(abs(s - t), total - abs(s - t)) for t in starts]))

    i, j = idx(s0), idx(s1)
    n = len(starts)
    if d > 0:
        return [(i + k) % n for k in range((j - i) % n or n)]
    return [(i - 1 - k) % n for k in range((i - j) % n or n)]


def build_spec(parts: list[Part], seams: list[Seam], hints: dict[str, PanelHint],
               fabric: str | None = None) -> tuple[PatternSpec, list[str], dict[str, list[float]]]:
    """(the spec, each stitch's label, each panel's edge starts as arc positions on its part)."""
    cuts, steps_of = cut_parts(parts, seams)
    panels, starts = {}, {}
    for p in parts:
        starts[p.name] = sorted(_starts(cuts[p.name]))
        panels[p.name] = panel_of(p, starts[p.name])
    stitches, labels = [], []
    for seam, steps in zip(seams, steps_of):
        ca, cb = cuts[seam.a.part], cuts[seam.b.part]
        for a0, a1, b0, b1 in steps:
            ea = _edges_between(starts[seam.a.part], ca.total, a0, a1, seam.a.dir)
            eb = _edges_between(starts[seam.b.part], cb.total, b0, b1, seam.b.dir)
            for x, y in zip(ea, eb):
                stitches.append([{"panel": seam.a.part, "edge": x}, {"panel": seam.b.part, "edge": y}])
                labels.append(seam.label)
    tryon = {"placement": {k: v.model_dump(exclude_none=True) for k, v in hints.items()}, "pairing": "placed"}
    if fabric:
        tryon["fabric"] = fabric
    spec = PatternSpec.model_validate({
        "pattern": {"panels": panels, "stitches": stitches, "panel_order": [p.name for p in parts]},
        "properties": {"units_in_meter": 100, "curvature_coords": "relative"}, "tryon": tryon})
    return spec, labels, starts
