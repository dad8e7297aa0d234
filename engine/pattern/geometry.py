"""2D geometry of pattern panels: edges as curves, sampled at uniform arc length (metres).

All functions take a `Panel` of engine.pattern.spec and a `scale` (metres per pattern unit) and
return NumPy arrays in metres in the panel's own 2D frame.
"""

from __future__ import annotations

import numpy as np

from engine.errors import InputError
from engine.pattern.spec import Edge, Panel

_DENSE = 256  # evaluation points per curved edge before arc-length resampling


def _rel_to_abs(start: np.ndarray, end: np.ndarray, rel) -> np.ndarray:
    """GarmentCode's edge-local coordinates (x along the edge, y along it turned +90 deg)."""
    e = end - start
    perp = np.array([-e[1], e[0]])
    return start + rel[0] * e + rel[1] * perp


def to_relative(start, end, p) -> tuple[float, float]:
    """A point in GarmentCode's edge-local coordinates (the inverse of _rel_to_abs)."""
    s, e, p = (np.asarray(a, dtype=np.float64) for a in (start, end, p))
    d = e - s
    perp = np.array([-d[1], d[0]])
    L2 = float(d @ d)
    return float((p - s) @ d / L2), float((p - s) @ perp / L2)


def _circle_dense(start: np.ndarray, end: np.ndarray, radius: float, large_arc: bool, right: bool,
                  n: int) -> np.ndarray:
    chord = end - start
    d = float(np.linalg.norm(chord))
    r = max(radius, d / 2)  # a radius below half the chord cannot span it: treat as a half circle
    h = np.sqrt(max(r * r - d * d / 4, 0.0))
    sag = r + h if large_arc else r - h
    left = np.array([-chord[1], chord[0]]) / d
    bulge = -left if right else left
    mid = (start + end) / 2 + sag * bulge
    centre = mid - r * bulge
    a0 = np.arctan2(*(start - centre)[::-1])
    am = np.arctan2(*(mid - centre)[::-1])
    a1 = np.arctan2(*(end - centre)[::-1])
    # sweep from a0 to a1 passing through am
    ccw = (a1 - a0) % (2 * np.pi)
    through = (am - a0) % (2 * np.pi)
    sweep = ccw if through <= ccw else ccw - 2 * np.pi
    t = np.linspace(0.0, 1.0, n)
    ang = a0 + sweep * t
    pts = centre + r * np.stack([np.cos(ang), np.sin(ang)], axis=1)
    pts[0], pts[-1] = start, end
    return pts


def edge_dense(panel: Panel, edge: Edge, scale: float, relative: bool = True, n: int = _DENSE) -> np.ndarray:
    """(n, 2) points along the edge from its first to its second endpoint (not uniform)."""
    # the two endpoints only: converting every vertex per edge made a panel's outline O(edges^2)
    s = np.asarray(panel.vertices[edge.endpoints[0]], dtype=np.float64) * scale
    e = np.asarray(panel.vertices[edge.endpoints[1]], dtype=np.float64) * scale
    c = edge.curvature
    if c is None:
        return np.stack([s, e])
    if c.type == "circle":
        radius, large_arc, right = c.params
        return _circle_dense(s, e, float(radius) * scale, bool(large_arc), bool(right), n)
    ctrl = [(_rel_to_abs(s, e, p) if relative else np.asarray(p, dtype=np.float64) * scale) for p in c.params]
    t = np.linspace(0.0, 1.0, n)
    if c.type == "quadratic":
        (c1,) = ctrl
        t = t[:, None]
        return (1 - t) ** 2 * s + 2 * (1 - t) * t * c1 + t**2 * e
    return bezier3(s, *ctrl, e, t)


def bezier3(s, c1, c2, e, t: np.ndarray) -> np.ndarray:
    """(len(t), 2) points of the cubic Bezier s, c1, c2, e at parameters t."""
    t = t[:, None]
    return (1 - t) ** 3 * s + 3 * (1 - t) ** 2 * t * c1 + 3 * (1 - t) * t**2 * c2 + t**3 * e


def polyline_length(pts: np.ndarray) -> float:
    return float(np.linalg.norm(np.diff(pts, axis=0), axis=1).sum())


def resample(pts: np.ndarray, n_segments: int) -> np.ndarray:
    """(n_segments + 1, 2) points at uniform arc length along a polyline (ends kept exactly)."""
    seg = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    s = np.concatenate([[0.0], np.cumsum(seg)])
    target = np.linspace(0.0, s[-1], n_segments + 1)
    out = np.stack([np.interp(target, s, pts[:, 0]), np.interp(target, s, pts[:, 1])], axis=1)
    out[0], out[-1] = pts[0], pts[-1]
    return out


def edge_length(panel: Panel, edge: Edge, scale: float, relative: bool = True) -> float:
    return polyline_length(edge_dense(panel, edge, scale, relative))


def edge_samples(panel: Panel, edge: Edge, scale: float, n_segments: int, relative: bool = True) -> np.ndarray:
    """(n_segments + 1, 2) points at uniform arc length from endpoint 0 to endpoint 1."""
    return resample(edge_dense(panel, edge, scale, relative), n_segments)


def outline(panel: Panel, scale: float, relative: bool = True, n: int = 64) -> np.ndarray:
    """(M, 2) closed outline (first point not repeated), edges in file order, densely sampled."""
    parts = [edge_dense(panel, e, scale, relative, n)[:-1] for e in panel.edges]
    return np.concatenate(parts, axis=0)


def signed_area(poly: np.ndarray) -> float:
    """Shoelace area: positive for a counter-clockwise polygon."""
    x, y = poly[:, 0], poly[:, 1]
    return 0.5 * float(np.dot(x, np.roll(y, -1)) - np.dot(np.roll(x, -1), y))


def panel_rotation_matrix(rotation_deg) -> np.ndarray:
    """(3, 3) rotation from GarmentCode's Euler angles (degrees) as its simulator and its pattern
    core read them: Rz Ry Rx (Maya's xyz; extrinsic). (Its generator writes scipy's intrinsic
    "XYZ" angles; the two differ where two angles are non-zero -- its collars -- and there the
    simulator's reading puts a collar 4-7 cm nearer the edges it is sewn to.)"""
    from scipy.spatial.transform import Rotation

    return Rotation.from_euler("xyz", np.asarray(rotation_deg, dtype=np.float64), degrees=True).as_matrix()


def place_2d(points: np.ndarray, panel: Panel, scale: float) -> np.ndarray:
    """(K, 2) panel-frame points (metres) -> (K, 3) world points using the panel's own
    translation/rotation (GarmentCode placement)."""
    p3 = np.concatenate([points, np.zeros((len(points), 1))], axis=1)
    return p3 @ panel_rotation_matrix(panel.rotation).T + np.asarray(panel.translation) * scale


def row_extent(outline: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(u min, u max) of a closed outline (M, 2) along the horizontal lines at heights v (K,)
    (0 where a line misses it)."""
    a, c = outline, np.roll(outline, -1, axis=0)
    vv = np.asarray(v, dtype=np.float64)[:, None]
    cross = (a[None, :, 1] - vv) * (c[None, :, 1] - vv) <= 0
    rise = np.where(c[:, 1] != a[:, 1], c[:, 1] - a[:, 1], 1.0)
    t = np.clip((vv - a[None, :, 1]) / rise[None, :], 0, 1)
    xs = a[None, :, 0] + t * (c[None, :, 0] - a[None, :, 0])
    lo = np.where(cross, xs, np.inf).min(axis=1)
    hi = np.where(cross, xs, -np.inf).max(axis=1)
    return np.where(np.isfinite(lo), lo, 0.0), np.where(np.isfinite(hi), hi, 0.0)


def winding_shares(poly: np.ndarray, cells: int = 160) -> tuple[float, float]:
    """How the closed polyline poly (M, 2) winds, sampled on a grid of cells x cells over its box:
    (the area it encloses at all, the share of that area wound the other way round or more than
    once). An outline that crosses itself where a cut reaches a little past the panel's other side
    winds once nearly everywhere; one whose vertices are out of order winds back over much of it."""
    lo, hi = poly.min(0), poly.max(0)
    size = np.maximum(hi - lo, 1e-12)
    gx = lo[0] + (np.arange(cells) + 0.5) / cells * size[0]
    gy = lo[1] + (np.arange(cells) + 0.5) / cells * size[1]
    a, b = poly, np.roll(poly, -1, axis=0)
    w = np.zeros((cells, cells), dtype=np.int64)  # (row: y, column: x)
    for r, y in enumerate(gy):  # each row's winding from the segments that cross its height
        up = (a[:, 1] <= y) & (b[:, 1] > y)
        down = (b[:, 1] <= y) & (a[:, 1] > y)
        k = up | down
        if not k.any():
            continue
        t = (y - a[k, 1]) / (b[k, 1] - a[k, 1])
        xc = a[k, 0] + t * (b[k, 0] - a[k, 0])
        sign = np.where(up[k], 1, -1)
        # a point winds by each crossing to its right: +1 going up, -1 going down
        w[r] = (sign[None, :] * (xc[None, :] > gx[:, None])).sum(1)
    filled = w != 0
    if not filled.any():
        return 0.0, 0.0
    main = 1 if (w > 0).sum() >= (w < 0).sum() else -1
    odd = filled & (w != main)
    cell = size[0] * size[1] / cells ** 2
    return float(filled.sum() * cell), float(odd.sum() / filled.sum())


def crossing_spans(poly: np.ndarray) -> np.ndarray:
    """For each place the closed polyline poly (M, 2) crosses itself (segment_crossings), how far
    apart its two points lie along the outline, the shorter way round (m): a few millimetres where
    neighbouring vertices are out of order (a twist), a panel's width where a cut reaches past
    its other side."""
    i, j, t = segment_crossings(poly)
    seg = np.linalg.norm(np.roll(poly, -1, axis=0) - poly, axis=1)
    start = np.r_[0.0, np.cumsum(seg)[:-1]]
    d = np.abs((start[i] + t * seg[i]) - (start[j] + 0.5 * seg[j]))
    return np.minimum(d, seg.sum() - d)


def segment_crossings(poly: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The non-adjacent segments of the closed polyline poly (M, 2) (segment k: poly[k] to
    poly[k + 1]) that properly cross: (i, j, t) with i < j, and t the crossing's fraction along
    segment i. Only segments whose boxes share a cell of a uniform grid are tested: near-linear
    in M for outlines."""
    m = len(poly)
    a, b = poly, np.roll(poly, -1, axis=0)
    i, j = _grid_pairs(a, b)
    ij = np.unique(i.astype(np.int64) * m + j)  # a pair whose boxes share several cells once
    i, j = ij // m, ij % m
    keep = (j - i >= 2) & ~((i == 0) & (j == m - 1))  # neighbours share a vertex
    i, j = i[keep], j[keep]

    def orient(p, q, r):
        return (q[:, 0] - p[:, 0]) * (r[:, 1] - p[:, 1]) - (q[:, 1] - p[:, 1]) * (r[:, 0] - p[:, 0])

    o1 = orient(a[i], b[i], a[j])
    o2 = orient(a[i], b[i], b[j])
    o3 = orient(a[j], b[j], a[i])
    o4 = orient(a[j], b[j], b[i])
    # each orientation compared with a tolerance in the outline's own units squared (their product
    # against one missed the crossings of millimetre segments in metres)
    eps = 1e-12 * float(np.ptp(poly, axis=0).max()) ** 2

    def opposite(p, q):
        return ((p > eps) & (q < -eps)) | ((p < -eps) & (q > eps))

    hit = opposite(o1, o2) & opposite(o3, o4)
    i, j = i[hit], j[hit]
    t = o3[hit] / (o3[hit] - o4[hit])  # (orient of segment j's line at a[i] and b[i])
    return i, j, t


# candidate segment pairs at most, more is refused: they are tested at ~1.7 us each (a fuzzed
# GarmentCode panel of 19,300 segments in a few cells gave 18.8M pairs, 30 s for its eight panels);
# real outlines give a few pairs per segment (GarmentCode ~6)
MAX_GRID_PAIRS = 1_000_000


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


