"""Cloth-cloth contact within one cloth (self-collision): a spatial hash of the triangles, the
vertex-triangle pairs closer than the cloth's thickness (now, or at the next check, the points
predicted ahead), and their response -- Bridson, Fedkiw and Anderson's proximity impulses (SIGGRAPH
2002, §7.1), as velocities set the way seed 003 sets a point's velocity against the body. Also the
count of triangles that cross other triangles, the measure of what the pass is for. NumPy/numba only.

Arrays: x, v (N, 3) float64; tris (F, 3) int32 (quads split in two); boxes lo, hi (F, 3); the hash:
start (T + 1,) int64 bucket starts, T a power of two, entries (E,) int32 triangle indices; the rest
neighbours of each vertex (pairs never pushed apart) as CSR near_ptr (N + 1,) int64, near (K,) int32.
"""

from __future__ import annotations

import numpy as np

from engine.cloth.kernels_contact import MAX_PUSH
from engine.jit import njit, serial_kernel

MAX_CELLS = 4  # a box wider than this many cells on a side is left out of the hash (at most 125 entries a box)


@njit(cache=True, inline="always")
def _key(ix, iy, iz, mask):
    """The bucket of grid cell (ix, iy, iz) (Teschner et al. 2003's primes)."""
    return ((ix * 73856093) ^ (iy * 19349663) ^ (iz * 83492791)) & mask


@njit(cache=True, inline="always")
def _cell(a, inv_c):
    return np.int64(np.floor(a * inv_c))


@njit(cache=True, inline="always")
def _too_wide(l0, l1, l2, h0, h1, h2, inv_c):
    """A box wider than MAX_CELLS cells on a side: a torn triangle or a point flying off, left out
    (the positions are finite: the callers check)."""
    return (h0 - l0) * inv_c > MAX_CELLS or (h1 - l1) * inv_c > MAX_CELLS or (h2 - l2) * inv_c > MAX_CELLS


@serial_kernel
def triangle_boxes(x, xp, tris, pad, lo, hi):
    """Each triangle's box over its corners now (x) and predicted (xp), grown by pad on every side."""
    for t in range(tris.shape[0]):
        for c in range(3):
            a = x[tris[t, 0], c]
            b = a
            for r in range(3):
                i = tris[t, r]
                a = min(a, x[i, c], xp[i, c])
                b = max(b, x[i, c], xp[i, c])
            lo[t, c] = a - pad
            hi[t, c] = b + pad


@serial_kernel
def fill_hash(lo, hi, inv_c, start, entries, packed):
    """The boxes into the hashed grid of cells 1 / inv_c wide: bucket k holds entries[start[k]:
    start[k + 1]], each box once in every bucket of a cell it overlaps, its corners beside it in
    packed (E, 6) float32 (lo, hi: a bucket's boxes read in one sweep). Returns the entries it
    needed: more than len(entries) and nothing was filled (call again with room)."""
    mask = start.shape[0] - 2
    for k in range(start.shape[0]):
        start[k] = 0
    total = 0
    # pass 0 counts each bucket's entries into start[k + 1]; between the passes start becomes
    # where each bucket begins, pass 1 fills with it as the cursor, then it is shifted back
    for filling in range(2):
        if filling:
            for k in range(1, start.shape[0]):
                start[k] += start[k - 1]
            total = start[start.shape[0] - 1]
            if total > entries.shape[0]:
                return total
        for b in range(lo.shape[0]):
            if _too_wide(lo[b, 0], lo[b, 1], lo[b, 2], hi[b, 0], hi[b, 1], hi[b, 2], inv_c):
                continue
            for ix in range(_cell(lo[b, 0], inv_c), _cell(hi[b, 0], inv_c) + 1):
                for iy in range(_cell(lo[b, 1], inv_c), _cell(hi[b, 1], inv_c) + 1):
                    for iz in range(_cell(lo[b, 2], inv_c), _cell(hi[b, 2], inv_c) + 1):
                        k = _key(ix, iy, iz, mask)
                        if not filling:
                            start[k + 1] += 1
                            continue
                        e = start[k]
                        entries[e] = b
                        for c in range(3):
                            packed[e, c] = lo[b, c]
                            packed[e, 3 + c] = hi[b, c]
                        start[k] += 1
    for k in range(start.shape[0] - 1, 0, -1):
        start[k] = start[k - 1]
    start[0] = 0
    return total


@njit(cache=True, fastmath=True, inline="always")
def _segment_t(px, py, pz, ax, ay, az, bx, by, bz):
    """(t, squared distance): the point a + t (b - a), t in [0, 1], of segment AB nearest P."""
    ex, ey, ez = bx - ax, by - ay, bz - az
    ee = ex * ex + ey * ey + ez * ez
    t = 0.0
    if ee > 0.0:
        t = min(1.0, max(0.0, ((px - ax) * ex + (py - ay) * ey + (pz - az) * ez) / ee))
    dx, dy, dz = ax + t * ex - px, ay + t * ey - py, az + t * ez - pz
    return t, dx * dx + dy * dy + dz * dz


@njit(cache=True, fastmath=True, inline="always")
def _nearest_on_triangle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """(squared distance, wa, wb, wc): the point of triangle ABC nearest P as weights of its
    corners -- P's projection on the plane when it falls inside, else the nearest of the three
    edges' points."""
    e1x, e1y, e1z = bx - ax, by - ay, bz - az
    e2x, e2y, e2z = cx - ax, cy - ay, cz - az
    nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
    nn = nx * nx + ny * ny + nz * nz
    rx, ry, rz = px - ax, py - ay, pz - az
    if nn > 1e-30:
        # the projection's coordinates along e1 and e2: ((r x e2) . n) / nn and ((e1 x r) . n) / nn
        s = ((ry * e2z - rz * e2y) * nx + (rz * e2x - rx * e2z) * ny + (rx * e2y - ry * e2x) * nz) / nn
        u = ((e1y * rz - e1z * ry) * nx + (e1z * rx - e1x * rz) * ny + (e1x * ry - e1y * rx) * nz) / nn
        if s >= 0.0 and u >= 0.0 and s + u <= 1.0:
            h = rx * nx + ry * ny + rz * nz
            return h * h / nn, 1.0 - s - u, s, u
    t, d = _segment_t(px, py, pz, ax, ay, az, bx, by, bz)
    best, wa, wb, wc = d, 1.0 - t, t, 0.0
    t, d = _segment_t(px, py, pz, bx, by, bz, cx, cy, cz)
    if d < best:
        best, wa, wb, wc = d, 0.0, 1.0 - t, t
    t, d = _segment_t(px, py, pz, cx, cy, cz, ax, ay, az)
    if d < best:
        best, wa, wb, wc = d, t, 0.0, 1.0 - t
    return best, wa, wb, wc


@serial_kernel
def find_near(x, tris, packed, inv_c, start, entries, near_ptr, near, reach, c_v, c_t, mark, tmark):
    """The candidate pairs: every vertex c_v and triangle (corners c_t) closer than `reach`, the
    vertex's rest neighbours' triangles left out. Triangle boxes of x grown by reach, hashed by
    fill_hash. Returns how many pairs it found; past len(c_v) they are counted, not kept.
    mark (N,), tmark (F,) int32: scratch (mark[q] == p: q is p or one of its rest neighbours;
    tmark[t] == p: t already met, in a bucket two of its cells share)."""
    mask = start.shape[0] - 2
    m = 0
    r2 = reach * reach
    for q in range(x.shape[0]):
        mark[q] = -1
    for t in range(tris.shape[0]):
        tmark[t] = -1
    for p in range(x.shape[0]):
        mark[p] = p
        for k in range(near_ptr[p], near_ptr[p + 1]):
            mark[near[k]] = p
        px, py, pz = x[p, 0], x[p, 1], x[p, 2]
        k = _key(_cell(px, inv_c), _cell(py, inv_c), _cell(pz, inv_c), mask)
        for e in range(start[k], start[k + 1]):
            if (packed[e, 0] > px or packed[e, 3] < px or packed[e, 1] > py or packed[e, 4] < py
                    or packed[e, 2] > pz or packed[e, 5] < pz):
                continue
            t = entries[e]
            a, b, c = tris[t, 0], tris[t, 1], tris[t, 2]
            if mark[a] == p or mark[b] == p or mark[c] == p or tmark[t] == p:  # p's own, a rest neighbour's, met
                continue
            tmark[t] = p
            d2, wa, wb, wc = _nearest_on_triangle(px, py, pz, x[a, 0], x[a, 1], x[a, 2], x[b, 0], x[b, 1], x[b, 2],
                                                  x[c, 0], x[c, 1], x[c, 2])
            if d2 >= r2:
                continue
            if m < c_v.shape[0]:
                c_v[m] = p
                c_t[m, 0], c_t[m, 1], c_t[m, 2] = a, b, c
            m += 1
    return m


@serial_kernel
def moved_past(x, xp, x0, limit):
    """Whether any vertex now (x) or predicted (xp) is farther than `limit` from x0."""
    l2 = limit * limit
    for i in range(x.shape[0]):
        d1 = (x[i, 0] - x0[i, 0]) ** 2 + (x[i, 1] - x0[i, 1]) ** 2 + (x[i, 2] - x0[i, 2]) ** 2
        d2 = (xp[i, 0] - x0[i, 0]) ** 2 + (xp[i, 1] - x0[i, 1]) ** 2 + (xp[i, 2] - x0[i, 2]) ** 2
        if d1 > l2 or d2 > l2:
            return True
    return False


@serial_kernel
def find_contacts(x, xp, cand_v, cand_t, n_cand, thickness, c_v, c_t, c_w, c_n, c_d):
    """Of the candidate pairs (find_near), those closer than `thickness` now (x) or predicted
    (xp): vertex c_v, triangle corners c_t, the weights of the triangle's point nearest the vertex
    c_w, the unit normal c_n from that point to the vertex now (the side the vertex is on), the
    distance now c_d. Returns how many (the arrays hold n_cand)."""
    m = 0
    for k in range(n_cand):
        p, a, b, c = cand_v[k], cand_t[k, 0], cand_t[k, 1], cand_t[k, 2]
        px, py, pz = x[p, 0], x[p, 1], x[p, 2]
        d2, wa, wb, wc = _nearest_on_triangle(px, py, pz, x[a, 0], x[a, 1], x[a, 2], x[b, 0], x[b, 1], x[b, 2],
                                              x[c, 0], x[c, 1], x[c, 2])
        d = np.sqrt(d2)
        sx = wa * x[a, 0] + wb * x[b, 0] + wc * x[c, 0]
        sy = wa * x[a, 1] + wb * x[b, 1] + wc * x[c, 1]
        sz = wa * x[a, 2] + wb * x[b, 2] + wc * x[c, 2]
        if d > 1e-9:
            nx, ny, nz = (px - sx) / d, (py - sy) / d, (pz - sz) / d
        else:  # on the triangle: its normal, toward where the vertex is going
            e1x, e1y, e1z = x[b, 0] - x[a, 0], x[b, 1] - x[a, 1], x[b, 2] - x[a, 2]
            e2x, e2y, e2z = x[c, 0] - x[a, 0], x[c, 1] - x[a, 1], x[c, 2] - x[a, 2]
            nx, ny, nz = e1y * e2z - e1z * e2y, e1z * e2x - e1x * e2z, e1x * e2y - e1y * e2x
            nl = np.sqrt(nx * nx + ny * ny + nz * nz)
            if nl < 1e-30:
                continue
            sgn = 1.0 if (xp[p, 0] - px) * nx + (xp[p, 1] - py) * ny + (xp[p, 2] - pz) * nz >= 0.0 else -1.0
            nx, ny, nz = sgn * nx / nl, sgn * ny / nl, sgn * nz / nl
        # the gap at the next check, along the normal of now
        gx = xp[p, 0] - (wa * xp[a, 0] + wb * xp[b, 0] + wc * xp[c, 0])
        gy = xp[p, 1] - (wa * xp[a, 1] + wb * xp[b, 1] + wc * xp[c, 1])
        gz = xp[p, 2] - (wa * xp[a, 2] + wb * xp[b, 2] + wc * xp[c, 2])
        if d >= thickness and gx * nx + gy * ny + gz * nz >= thickness:
            continue
        c_v[m] = p
        c_t[m, 0], c_t[m, 1], c_t[m, 2] = a, b, c
        c_w[m, 0], c_w[m, 1], c_w[m, 2] = wa, wb, wc
        c_n[m, 0], c_n[m, 1], c_n[m, 2] = nx, ny, nz
        c_d[m] = d
        m += 1
    return m


@serial_kernel
def respond_contacts(v, inv_mass, c_v, c_t, c_w, c_n, c_d, n_c, thickness, ahead, push_rate, friction, passes):
    """Each pair's relative normal velocity (vertex minus the triangle's point) brought up to what
    keeps it `thickness` apart at the next check, `ahead` seconds on -- an approach slower than the
    gap allows is left alone; a pair in the inner half of the thickness drifts apart at
    push_rate x its depth there (at most MAX_PUSH), one in the outer half stops approaching --
    with Coulomb friction (coefficient `friction`) on the relative tangential velocity, as an
    impulse shared by mass and weight (momentum kept: Bridson et al. 2002, eq. 7). Gauss-Seidel,
    `passes` times over the pairs. Returns the pairs that were changed in the last pass."""
    changed = 0
    for _ in range(passes):
        changed = 0
        for k in range(n_c):
            p, a, b, c = c_v[k], c_t[k, 0], c_t[k, 1], c_t[k, 2]
            wa, wb, wc = c_w[k, 0], c_w[k, 1], c_w[k, 2]
            nx, ny, nz = c_n[k, 0], c_n[k, 1], c_n[k, 2]
            d = c_d[k]
            rx = v[p, 0] - (wa * v[a, 0] + wb * v[b, 0] + wc * v[c, 0])
            ry = v[p, 1] - (wa * v[a, 1] + wb * v[b, 1] + wc * v[c, 1])
            rz = v[p, 2] - (wa * v[a, 2] + wb * v[b, 2] + wc * v[c, 2])
            vn = rx * nx + ry * ny + rz * nz
            if d >= thickness:
                need = (thickness - d) / ahead
            else:
                need = min(max(0.0, (0.5 * thickness - d) * push_rate), MAX_PUSH)
            den = inv_mass[p] + wa * wa * inv_mass[a] + wb * wb * inv_mass[b] + wc * wc * inv_mass[c]
            if vn >= need or den <= 0.0:  # (den 0: all four held, nothing can move)
                continue
            changed += 1
            dvn = need - vn
            tx, ty, tz = rx - vn * nx, ry - vn * ny, rz - vn * nz
            vt = np.sqrt(tx * tx + ty * ty + tz * tz)
            slow = min(1.0, friction * dvn / vt) if vt > 1e-12 else 0.0
            # the change of the relative velocity, and the impulse (over mass) that makes it
            jx, jy, jz = dvn * nx - slow * tx, dvn * ny - slow * ty, dvn * nz - slow * tz
            jx, jy, jz = jx / den, jy / den, jz / den
            ip = inv_mass[p]
            v[p, 0] += ip * jx
            v[p, 1] += ip * jy
            v[p, 2] += ip * jz
            for i, w in ((a, wa), (b, wb), (c, wc)):
                s = w * inv_mass[i]
                v[i, 0] -= s * jx
                v[i, 1] -= s * jy
                v[i, 2] -= s * jz
    return changed


@serial_kernel(fastmath=False)  # (inf marks a vertex not reached yet)
def rest_neighbours(ptr, other, length, radius, out_ptr, out, dist, seen):
    """For every vertex, the vertices within `radius` of it along the graph (ptr, other, length:
    CSR adjacency with edge lengths; the flat pattern's lengths), by Dijkstra cut at the radius.
    Counts into out_ptr (N + 1,) when `out` is empty, else fills out (out_ptr[N],) by them.
    dist (N,) float64 all inf, seen (N,) int32: scratch, left as given."""
    n = ptr.shape[0] - 1
    filling = out.shape[0] > 0
    if not filling:
        out_ptr[0] = 0
    todo = np.empty(n, dtype=np.int64)
    for s in range(n):
        m = 0
        todo[0] = s
        dist[s] = 0.0
        n_todo = 1
        done = 0
        # a small Dijkstra: todo[:done] are settled (in order), todo[done:n_todo] wait
        while done < n_todo:
            best = done
            for j in range(done + 1, n_todo):
                if dist[todo[j]] < dist[todo[best]]:
                    best = j
            todo[done], todo[best] = todo[best], todo[done]
            u = todo[done]
            done += 1
            seen[u] = 1
            if u != s:
                if filling:
                    out[out_ptr[s] + m] = u
                m += 1
            for e in range(ptr[u], ptr[u + 1]):
                w = other[e]
                nd = dist[u] + length[e]
                if seen[w] == 0 and nd <= radius and nd < dist[w]:
                    if dist[w] == np.inf:
                        todo[n_todo] = w
                        n_todo += 1
                    dist[w] = nd
        for j in range(n_todo):
            dist[todo[j]] = np.inf
            seen[todo[j]] = 0
        if not filling:
            out_ptr[s + 1] = out_ptr[s] + m


@njit(cache=True, fastmath=True, inline="always")
def _segment_crosses(px, py, pz, qx, qy, qz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Whether segment PQ passes through triangle ABC (Moller-Trumbore; a segment in the
    triangle's plane does not count)."""
    dx, dy, dz = qx - px, qy - py, qz - pz
    e1x, e1y, e1z = bx - ax, by - ay, bz - az
    e2x, e2y, e2z = cx - ax, cy - ay, cz - az
    hx, hy, hz = dy * e2z - dz * e2y, dz * e2x - dx * e2z, dx * e2y - dy * e2x
    det = e1x * hx + e1y * hy + e1z * hz
    if abs(det) < 1e-20:
        return False
    f = 1.0 / det
    sx, sy, sz = px - ax, py - ay, pz - az
    u = f * (sx * hx + sy * hy + sz * hz)
    if u < 0.0 or u > 1.0:
        return False
    rx, ry, rz = sy * e1z - sz * e1y, sz * e1x - sx * e1z, sx * e1y - sy * e1x
    w = f * (dx * rx + dy * ry + dz * rz)
    if w < 0.0 or u + w > 1.0:
        return False
    t = f * (e2x * rx + e2y * ry + e2z * rz)
    return 0.0 <= t <= 1.0


@njit(cache=True, inline="always")
def _edge_through(x, i, j, a, b, c):
    return _segment_crosses(x[i, 0], x[i, 1], x[i, 2], x[j, 0], x[j, 1], x[j, 2], x[a, 0], x[a, 1], x[a, 2],
                            x[b, 0], x[b, 1], x[b, 2], x[c, 0], x[c, 1], x[c, 2])


@njit(cache=True, inline="always")
def _triangles_cross(x, a0, a1, a2, b0, b1, b2):
    """Whether two triangles (sharing no corner) cross: an edge of one through the other."""
    return (_edge_through(x, a0, a1, b0, b1, b2) or _edge_through(x, a1, a2, b0, b1, b2)
            or _edge_through(x, a2, a0, b0, b1, b2) or _edge_through(x, b0, b1, a0, a1, a2)
            or _edge_through(x, b1, b2, a0, a1, a2) or _edge_through(x, b2, b0, a0, a1, a2))


@serial_kernel
def mark_crossings(x, tris, lo, hi, inv_c, start, entries, packed, hit):
    """hit[t] = 1 for every triangle that crosses another triangle sharing no corner with it
    (boxes lo/hi of x hashed by fill_hash); returns the crossing pairs."""
    mask = start.shape[0] - 2
    pairs = 0
    for t in range(tris.shape[0]):
        hit[t] = 0
    for t in range(tris.shape[0]):
        if _too_wide(lo[t, 0], lo[t, 1], lo[t, 2], hi[t, 0], hi[t, 1], hi[t, 2], inv_c):
            continue
        a0, a1, a2 = tris[t, 0], tris[t, 1], tris[t, 2]
        for ix in range(_cell(lo[t, 0], inv_c), _cell(hi[t, 0], inv_c) + 1):
            for iy in range(_cell(lo[t, 1], inv_c), _cell(hi[t, 1], inv_c) + 1):
                for iz in range(_cell(lo[t, 2], inv_c), _cell(hi[t, 2], inv_c) + 1):
                    k = _key(ix, iy, iz, mask)
                    for e in range(start[k], start[k + 1]):
                        u = entries[e]
                        if u <= t or lo[u, 0] > hi[t, 0] or hi[u, 0] < lo[t, 0] or lo[u, 1] > hi[t, 1] \
                                or hi[u, 1] < lo[t, 1] or lo[u, 2] > hi[t, 2] or hi[u, 2] < lo[t, 2]:
                            continue
                        if (_cell(max(lo[t, 0], lo[u, 0]), inv_c) != ix or _cell(max(lo[t, 1], lo[u, 1]), inv_c) != iy
                                or _cell(max(lo[t, 2], lo[u, 2]), inv_c) != iz):
                            continue
                        b0, b1, b2 = tris[u, 0], tris[u, 1], tris[u, 2]
                        if (a0 == b0 or a0 == b1 or a0 == b2 or a1 == b0 or a1 == b1 or a1 == b2
                                or a2 == b0 or a2 == b1 or a2 == b2):
                            continue
                        if _triangles_cross(x, a0, a1, a2, b0, b1, b2):
                            hit[t] = 1
                            hit[u] = 1
                            pairs += 1
    return pairs
