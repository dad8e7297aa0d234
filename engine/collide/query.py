"""Point queries against collision maps (seed 003 §5.3, seed 000 §4): is a cloth point inside
the body, within the tolerance band, or clear -- and where is the surface to push it to.

Rule, per map whose window contains the point's (x, y): at that pixel the body occupies
z in [zb, zf] (back and front depth). A point with zb - tol < z < zf + tol is in contact; it is
answered by the nearer face -- the front if z is above the midpoint (zb + zf) / 2, else the
back. With d = depth below that face (zf - z or z - zb):
    status 2 (inside) if d > 0, status 1 (band) if -tol < d <= 0, else 0 (clear);
    penetration = d + tol, the distance to move along the normal to leave the band
    (positive exactly when status > 0).
Depth, normal and velocity are bilinear between the four nearest pixel centres when all four
are body pixels, else taken from the pixel under the point (bilinear across the silhouette
would blend with empty pixels).

Side-layer pixel (the ring beside the silhouette, maps.py): the body's rim is taken as the
line half a texel beyond the nearest body pixel's centre c, across the side pixel's stored
outward in-plane normal n; with rho = max(n . (p - c) - texel/2, 0) and dz how far z lies
outside [zb, zf] at c, the distance to the rim is sqrt(rho^2 + dz^2); within tol the point is
in the band (status 1, never inside), with normal n and penetration tol - that distance.

Several maps (segment maps): every map covering (x, y) is asked; the answer with the LARGEST
penetration wins. So "inside" any segment beats a band contact, and among overlapping segments
(at joints) the one the point is deepest in answers -- the one it is hitting hardest. Points in
the gap between an arm and the torso are clear, because each segment sees only itself.

`query_point_into` is a plain @njit function so the cloth solver can call it inside its own
kernels; it writes row p of the caller's output arrays (shapes as QueryResult) and returns the
status -- writing into arrays instead of returning a 12-tuple keeps it at ~20-30 ns a point:
    st = query_point_into(x, y, z, tol, surf, vel, has_vel, kind, side_src, geom, layout, zz,
                          p, status, surface, penetration, normal, velocity, map_index)
(the eight map arrays are maps.kernel_args(), in that order; zz: maps.depth_pairs).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from engine.collide.maps import CollisionMaps
from engine.jit import njit, prange, serial_kernel

CLEAR, BAND, INSIDE = 0, 1, 2


@njit(cache=True, inline="always")
def _sample(x, y, kind, zz, x0, y0, t, h, w, r0, cf):
    """Pixel lookup of one map at (x, y): (k, bil, ra, ca, fx, fy, zf, zb).
    k: -1 outside the window, else the pixel kind (0 empty, 1 body, 2 side); for a body pixel
    zf / zb are front / back depth, bilinear (bil) from the 4 centres around (x, y) whose
    lower-left is atlas (ra, ca) with weights fx, fy, else from the pixel (ra, ca) itself."""
    u = (x - x0) / t
    v = (y - y0) / t
    if not (u >= 0.0 and v >= 0.0 and u < w and v < h):
        return -1, False, 0, 0, 0.0, 0.0, 0.0, 0.0
    j = int(u)
    i = int(v)
    k = kind[r0 + i, cf + j]
    if k != 1:
        return k, False, r0 + i, cf + j, 0.0, 0.0, 0.0, 0.0
    j0 = int(math.floor(u - 0.5))
    i0 = int(math.floor(v - 0.5))
    ra = r0 + i0
    ca = cf + j0
    if (j0 >= 0 and i0 >= 0 and j0 + 1 < w and i0 + 1 < h
            and kind[ra, ca] == 1 and kind[ra, ca + 1] == 1
            and kind[ra + 1, ca] == 1 and kind[ra + 1, ca + 1] == 1):
        fx = u - 0.5 - j0
        fy = v - 0.5 - i0
        zf = ((1.0 - fy) * ((1.0 - fx) * zz[ra, ca, 0] + fx * zz[ra, ca + 1, 0])
              + fy * ((1.0 - fx) * zz[ra + 1, ca, 0] + fx * zz[ra + 1, ca + 1, 0]))
        zb = ((1.0 - fy) * ((1.0 - fx) * zz[ra, ca, 1] + fx * zz[ra, ca + 1, 1])
              + fy * ((1.0 - fx) * zz[ra + 1, ca, 1] + fx * zz[ra + 1, ca + 1, 1]))
        return 1, True, ra, ca, fx, fy, zf, zb
    ra = r0 + i
    ca = cf + j
    return 1, False, ra, ca, 0.0, 0.0, float(zz[ra, ca, 0]), float(zz[ra, ca, 1])


@njit(cache=True, inline="always")
def _side_geometry(x, y, z, surf, zz, side_src, ra, ca, x0, y0, t, r0, cf):
    """Side-layer pixel (ra, ca): (pen_without_tol, nx, ny, edge, zf, zb, rs, cs) -- the rim
    line lies half a texel beyond the source body pixel c across the stored outward normal n;
    returns minus the distance to it (add tol for the penetration)."""
    src = side_src[ra, ca]
    wa = side_src.shape[1]
    rs = src // wa
    cs = src - rs * wa
    cx = x0 + (cs - cf + 0.5) * t
    cy = y0 + (rs - r0 + 0.5) * t
    zf = float(zz[rs, cs, 0])
    zb = float(zz[rs, cs, 1])
    nx = float(surf[ra, ca, 0])
    ny = float(surf[ra, ca, 1])
    edge = max((x - cx) * nx + (y - cy) * ny - 0.5 * t, 0.0)
    dz = max(0.0, z - zf, zb - z)
    return -math.sqrt(edge * edge + dz * dz), nx, ny, edge, zf, zb, rs, cs


@njit(cache=True, inline="always")
def query_point_into(x, y, z, tol, surf, vel, has_vel, kind, side_src, geom, layout, zz,
                     p, status, surface, penetration, normal, velocity, map_index):
    """Answer one point (module doc for the rule) into row p of the output arrays; returns
    its status. The map is chosen by penetration (the largest); each map is sampled once and
    the chosen one's sample is kept for the surface point, normal and velocity (sampling it
    again cost ~15 % of a query)."""
    best_pen = -np.inf
    best_m = -1
    k, bil, ra, ca, fx, fy, zf, zb = 0, False, 0, 0, 0.0, 0.0, 0.0, 0.0
    for m in range(layout.shape[0]):
        km, bm, ram, cam, fxm, fym, zfm, zbm = _sample(x, y, kind, zz, geom[m, 0], geom[m, 1], geom[m, 2],
                                                       layout[m, 0], layout[m, 1], layout[m, 2], layout[m, 3])
        if km <= 0:
            continue
        if km == 2:
            pen = tol + _side_geometry(x, y, z, surf, zz, side_src, ram, cam, geom[m, 0], geom[m, 1], geom[m, 2],
                                       layout[m, 2], layout[m, 3])[0]
        elif z > 0.5 * (zfm + zbm):
            pen = zfm - z + tol
        else:
            pen = z - zbm + tol
        if pen > best_pen:
            best_pen = pen
            best_m = m
            k, bil, ra, ca, fx, fy, zf, zb = km, bm, ram, cam, fxm, fym, zfm, zbm
    map_index[p] = best_m
    penetration[p] = best_pen
    for c in range(3):
        surface[p, c] = 0.0
        normal[p, c] = 0.0
        velocity[p, c] = 0.0
    if best_m < 0:
        status[p] = 0
        return 0
    m = best_m
    x0, y0, t = geom[m, 0], geom[m, 1], geom[m, 2]
    r0, cf, cb = layout[m, 2], layout[m, 3], layout[m, 4]
    if k == 2:
        d, nx, ny, edge, zf, zb, rs, cs = _side_geometry(x, y, z, surf, zz, side_src, ra, ca,
                                                         x0, y0, t, r0, cf)
        st = 1 if best_pen > 0.0 else 0
        surface[p, 0] = x - edge * nx
        surface[p, 1] = y - edge * ny
        surface[p, 2] = min(max(z, zb), zf)
        normal[p, 0] = nx
        normal[p, 1] = ny
        if has_vel:
            c = cs if z > 0.5 * (zf + zb) else cs + cb - cf
            for q in range(3):
                velocity[p, q] = vel[rs, c, q]
        status[p] = st
        return st
    front = z > 0.5 * (zf + zb)
    d = zf - z if front else z - zb
    st = 0 if best_pen <= 0.0 else (2 if d > 0.0 else 1)
    surface[p, 0] = x
    surface[p, 1] = y
    surface[p, 2] = zf if front else zb
    status[p] = st
    if st == 0:
        return 0        # clear: the nearer face and a negative penetration, no normal
    c = ca if front else ca + cb - cf
    if bil:
        w00 = (1.0 - fx) * (1.0 - fy)
        w01 = fx * (1.0 - fy)
        w10 = (1.0 - fx) * fy
        w11 = fx * fy
    else:
        w00, w01, w10, w11 = 1.0, 0.0, 0.0, 0.0
    b1 = 1 if bil else 0                          # neighbours only read when bilinear
    ln = 0.0
    for q in range(3):
        nq = (w00 * surf[ra, c, q] + w01 * surf[ra, c + b1, q]
              + w10 * surf[ra + b1, c, q] + w11 * surf[ra + b1, c + b1, q])
        normal[p, q] = nq
        ln += nq * nq
    if ln > 0.0:
        ln = 1.0 / math.sqrt(ln)
        for q in range(3):
            normal[p, q] *= ln
    if has_vel:
        for q in range(3):
            velocity[p, q] = (w00 * vel[ra, c, q] + w01 * vel[ra, c + b1, q]
                              + w10 * vel[ra + b1, c, q] + w11 * vel[ra + b1, c + b1, q])
    return st


@njit(cache=True, parallel=True)
def query_batch(points, tol, surf, vel, has_vel, kind, side_src, geom, layout, zz,
                status, surface, penetration, normal, velocity, map_index):
    """query_point_into over points (N, 3) into preallocated outputs (shapes as QueryResult)."""
    for p in prange(points.shape[0]):
        query_point_into(points[p, 0], points[p, 1], points[p, 2], tol, surf, vel, has_vel,
                         kind, side_src, geom, layout, zz, p, status, surface, penetration, normal,
                         velocity, map_index)


@serial_kernel(fastmath=False)
def query_batch_serial(points, tol, surf, vel, has_vel, kind, side_src, geom, layout, zz,
                       status, surface, penetration, normal, velocity, map_index):
    """query_batch on one thread: the cloth solver's per-step query (a parallel region per step
    stalls whenever another process holds a core)."""
    for p in range(points.shape[0]):
        query_point_into(points[p, 0], points[p, 1], points[p, 2], tol, surf, vel, has_vel,
                         kind, side_src, geom, layout, zz, p, status, surface, penetration, normal,
                         velocity, map_index)


@serial_kernel(fastmath=False)
def query_rows_serial(points, rows, n_rows, tol, surf, vel, has_vel, kind, side_src, geom, layout, zz,
                      status, surface, penetration, normal, velocity, map_index):
    """query_batch_serial for the points listed in rows[:n_rows] only: the other rows of the
    outputs keep what they hold (the cloth solver asks again only for the points whose answer
    may have changed, see ClothSolver._contacts)."""
    for i in range(n_rows):
        p = rows[i]
        query_point_into(points[p, 0], points[p, 1], points[p, 2], tol, surf, vel, has_vel,
                         kind, side_src, geom, layout, zz, p, status, surface, penetration, normal,
                         velocity, map_index)


@dataclass
class QueryResult:
    """status: (N,) int8, 0 clear / 1 band / 2 inside; surface: (N, 3) float64 surface point;
    penetration: (N,) float64 metres, > 0 iff status > 0 (distance to leave the band);
    normal: (N, 3) float64 unit outward (0 where nothing answered); velocity: (N, 3) float64
    body velocity at the surface point (0 without velocity maps); map_index: (N,) int32 map
    that answered, -1 none; segment: (N,) int32 index into SEGMENTS, -1 for none / whole body."""

    status: np.ndarray
    surface: np.ndarray
    penetration: np.ndarray
    normal: np.ndarray
    velocity: np.ndarray
    map_index: np.ndarray
    segment: np.ndarray


def query_points(maps: CollisionMaps, points: np.ndarray, tol: float | None = None) -> QueryResult:
    """Query (N, 3) world points against the maps; tol defaults to the maps' tolerance.
    Clear points that a map covers get its nearer face as surface and a negative penetration;
    points no map covers get map_index -1 and penetration -inf."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    n = pts.shape[0]
    out = QueryResult(np.zeros(n, np.int8), np.zeros((n, 3)), np.zeros(n), np.zeros((n, 3)),
                      np.zeros((n, 3)), np.zeros(n, np.int32), np.zeros(n, np.int32))
    query_batch(pts, float(maps.tol if tol is None else tol), *maps.kernel_args(),
                out.status, out.surface, out.penetration, out.normal, out.velocity, out.map_index)
    out.segment = np.where(out.map_index >= 0, maps.segment_ids[np.maximum(out.map_index, 0)], -1
                           ).astype(np.int32)
    return out
