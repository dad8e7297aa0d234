"""Object-space collision baseline: exact point queries against a triangle mesh through a BVH.

The image-space method (maps.py, query.py) is measured against this (seed 003, Table 1): the same
status/depth/normal/velocity protocol, answered exactly from the body triangles instead of from
rendered maps. It is also what reports "penetration measured exactly against the body mesh".

Hierarchy: binary tree of axis-aligned boxes over the triangles, built in numba with binned SAH
(16 bins on each axis, leaves of <= 4 triangles). Flattened arrays, M nodes (M <= 2F - 1):
    node_lo, node_hi  (M, 3) float64   box corners
    node_a            (M,)  int32      internal: index of the left child (right = a + 1);
                                        leaf: first slot in `prim`
    node_n            (M,)  int32      0 for internal nodes, else the leaf's triangle count
    prim              (F,)  int32      triangle ids in leaf order (a leaf owns prim[a : a + n])
    tri_xyz           (F, 15) float64  row j: triangle prim[j]'s corners A, B, C, then its box lo,
                                        hi (leaf order: a leaf reads one contiguous block)
Children always have larger indices than their parent, so a refit is one reverse sweep.

Sign (Baerentzen & Aanaes 2005): sign(dot(p - c, N)) where c is the closest point and N the
angle-weighted pseudonormal of the feature c lies on: the face normal in a face's interior, the
sum of the two face normals on an edge, the angle-weighted sum of the incident face normals at a
vertex. This is exact for a closed, consistently oriented (CCW outward) mesh, with no ray casting.

Kernel API (plain @njit, callable from other numba kernels; spell `bvh.kernel_args()` out):
    d2, f, cx, cy, cz, u, v, w = bvh_closest(px, py, pz, max_d2, node_lo, node_hi, node_a,
                                              node_n, prim, tri_xyz)
    sd, f, cx, cy, cz, u, v, w, nx, ny, nz = bvh_signed(px, py, pz, max_d2, *kernel_args)
with f == -1 when no triangle lies within sqrt(max_d2). (u, v, w) are the barycentrics of c on
triangle f (c = u*A + v*B + w*C), n is the smooth normal (interpolated vertex pseudonormals).
"""

from __future__ import annotations

import math

import numpy as np

from engine.collide.base import Collider
from engine.jit import njit, prange

CLEAR, BAND, INSIDE = 0, 1, 2

_LEAF_SIZE = 4
_NBINS = 16
_STACK = 64          # traversal stack; SAH trees over bodies are ~25 deep, 64 leaves slack
_BARY_EPS = 1e-9     # barycentric below this: the closest point is on the edge/vertex (see _feature_normal)


# --------------------------------------------------------------------------------------------
# build / refit

@njit(cache=True, nogil=True)
def _tri_boxes(verts, faces, lo, hi):
    for f in range(faces.shape[0]):
        for k in range(3):
            a = verts[faces[f, 0], k]
            b = verts[faces[f, 1], k]
            c = verts[faces[f, 2], k]
            lo[f, k] = min(a, min(b, c))
            hi[f, k] = max(a, max(b, c))


@njit(cache=True, nogil=True)
def _build(tlo, thi, leaf_size):
    """Binned-SAH build over triangle boxes (F, 3). Returns (node_lo, node_hi, node_a, node_n,
    prim), trimmed to the nodes used. Iterative (explicit stack): degenerate inputs cannot blow
    the call stack."""
    F = tlo.shape[0]
    cent = 0.5 * (tlo + thi)
    prim = np.arange(F).astype(np.int32)
    M = max(2 * F - 1, 1)
    node_lo = np.empty((M, 3))
    node_hi = np.empty((M, 3))
    node_a = np.zeros(M, np.int32)
    node_n = np.zeros(M, np.int32)
    # work stack: (node, start, end); at most one pending sibling per level
    st_node = np.empty(M, np.int64)
    st_s = np.empty(M, np.int64)
    st_e = np.empty(M, np.int64)
    sp = 0
    st_node[0] = 0
    st_s[0] = 0
    st_e[0] = F
    sp = 1
    used = 1
    bin_cnt = np.zeros(_NBINS, np.int64)
    bin_lo = np.empty((_NBINS, 3))
    bin_hi = np.empty((_NBINS, 3))
    right_area = np.empty(_NBINS)
    right_cnt = np.empty(_NBINS, np.int64)
    while sp > 0:
        sp -= 1
        node = st_node[sp]
        s = st_s[sp]
        e = st_e[sp]
        blo = np.full(3, np.inf)
        bhi = np.full(3, -np.inf)
        clo = np.full(3, np.inf)
        chi = np.full(3, -np.inf)
        for i in range(s, e):
            t = prim[i]
            for k in range(3):
                blo[k] = min(blo[k], tlo[t, k])
                bhi[k] = max(bhi[k], thi[t, k])
                clo[k] = min(clo[k], cent[t, k])
                chi[k] = max(chi[k], cent[t, k])
        node_lo[node] = blo
        node_hi[node] = bhi
        cnt = e - s
        if cnt <= leaf_size:
            node_a[node] = s
            node_n[node] = cnt
            continue
        # SAH over binned centroids, every axis; cost = area_L * n_L + area_R * n_R
        best_cost = np.inf
        best_axis = -1
        best_bin = -1
        for ax in range(3):
            ext = chi[ax] - clo[ax]
            if ext <= 0.0:
                continue
            scale = _NBINS / ext
            bin_cnt[:] = 0
            bin_lo[:] = np.inf
            bin_hi[:] = -np.inf
            for i in range(s, e):
                t = prim[i]
                b = min(int((cent[t, ax] - clo[ax]) * scale), _NBINS - 1)
                bin_cnt[b] += 1
                for k in range(3):
                    bin_lo[b, k] = min(bin_lo[b, k], tlo[t, k])
                    bin_hi[b, k] = max(bin_hi[b, k], thi[t, k])
            # sweep from the right: area/count of bins b.. end
            rl = np.full(3, np.inf)
            rh = np.full(3, -np.inf)
            rc = 0
            for b in range(_NBINS - 1, 0, -1):
                rc += bin_cnt[b]
                for k in range(3):
                    rl[k] = min(rl[k], bin_lo[b, k])
                    rh[k] = max(rh[k], bin_hi[b, k])
                right_cnt[b] = rc
                right_area[b] = _half_area(rl, rh) if rc > 0 else 0.0
            ll = np.full(3, np.inf)
            lh = np.full(3, -np.inf)
            lc = 0
            for b in range(1, _NBINS):      # split: bins < b go left
                lc += bin_cnt[b - 1]
                for k in range(3):
                    ll[k] = min(ll[k], bin_lo[b - 1, k])
                    lh[k] = max(lh[k], bin_hi[b - 1, k])
                if lc == 0 or right_cnt[b] == 0:
                    continue
                cost = _half_area(ll, lh) * lc + right_area[b] * right_cnt[b]
                if cost < best_cost:
                    best_cost = cost
                    best_axis = ax
                    best_bin = b
        if best_axis < 0:
            # all centroids coincide: any split is as good as another; halve by index
            mid = s + cnt // 2
        else:
            # in-place partition of prim[s:e] by bin
            ax = best_axis
            scale = _NBINS / (chi[ax] - clo[ax])
            i = s
            j = e - 1
            while i <= j:
                b = min(int((cent[prim[i], ax] - clo[ax]) * scale), _NBINS - 1)
                if b < best_bin:
                    i += 1
                else:
                    tmp = prim[i]
                    prim[i] = prim[j]
                    prim[j] = tmp
                    j -= 1
            mid = i
        left = used
        used += 2
        node_a[node] = left
        node_n[node] = 0
        # right pushed first so the left subtree is built (and laid out) first
        st_node[sp] = left + 1
        st_s[sp] = mid
        st_e[sp] = e
        sp += 1
        st_node[sp] = left
        st_s[sp] = s
        st_e[sp] = mid
        sp += 1
    return node_lo[:used].copy(), node_hi[:used].copy(), node_a[:used].copy(), \
        node_n[:used].copy(), prim


@njit(cache=True, nogil=True)
def _tree_depth(node_a, node_n):
    # children have larger indices than parents: one forward sweep assigns every depth
    depth = np.zeros(node_a.shape[0], np.int64)
    for i in range(node_a.shape[0]):
        if node_n[i] == 0:
            depth[node_a[i]] = depth[i] + 1
            depth[node_a[i] + 1] = depth[i] + 1
    return depth.max()


@njit(cache=True, inline="always")
def _half_area(lo, hi):
    dx = hi[0] - lo[0]
    dy = hi[1] - lo[1]
    dz = hi[2] - lo[2]
    return dx * dy + dy * dz + dz * dx


@njit(cache=True)
def _refit(tlo, thi, node_lo, node_hi, node_a, node_n, prim):
    """Recompute the boxes bottom-up for moved vertices; children have larger indices than their
    parent, so one reverse sweep sees every child before its parent."""
    for i in range(node_a.shape[0] - 1, -1, -1):
        n = node_n[i]
        a = node_a[i]
        if n > 0:
            for k in range(3):
                lo = np.inf
                hi = -np.inf
                for j in range(a, a + n):
                    t = prim[j]
                    lo = min(lo, tlo[t, k])
                    hi = max(hi, thi[t, k])
                node_lo[i, k] = lo
                node_hi[i, k] = hi
        else:
            for k in range(3):
                node_lo[i, k] = min(node_lo[a, k], node_lo[a + 1, k])
                node_hi[i, k] = max(node_hi[a, k], node_hi[a + 1, k])


@njit(cache=True, nogil=True)
def _normals(verts, faces, edge_id, n_edges, face_n, edge_n, vert_n):
    """Face normals (F,3) unit; edge pseudonormals per face-edge (F,3,3): edge e of face f runs
    faces[f,e] -> faces[f,(e+1)%3] and gets the sum of the unit normals of the faces sharing it
    (the angle weight is pi for each of them); vertex pseudonormals (V,3): sum of incident unit
    face normals weighted by the face's angle at the vertex, normalised (they double as the
    smooth shading normals)."""
    F = faces.shape[0]
    esum = np.zeros((n_edges, 3))
    vert_n[:] = 0.0
    e = np.empty((3, 3))                  # edge vectors k -> k+1, reused (no per-face arrays)
    for f in range(F):
        for k in range(3):
            for d in range(3):
                e[k, d] = verts[faces[f, (k + 1) % 3], d] - verts[faces[f, k], d]
        nx = e[0, 1] * e[1, 2] - e[0, 2] * e[1, 1]
        ny = e[0, 2] * e[1, 0] - e[0, 0] * e[1, 2]
        nz = e[0, 0] * e[1, 1] - e[0, 1] * e[1, 0]
        ln = math.sqrt(nx * nx + ny * ny + nz * nz)
        if ln > 0.0:
            nx /= ln; ny /= ln; nz /= ln
        face_n[f, 0] = nx; face_n[f, 1] = ny; face_n[f, 2] = nz
        for k in range(3):
            # angle at corner k, between the edge leaving it and the (reversed) edge arriving
            km = (k + 2) % 3
            ang = _angle(e[k, 0], e[k, 1], e[k, 2], -e[km, 0], -e[km, 1], -e[km, 2])
            vi = faces[f, k]
            vert_n[vi, 0] += ang * nx; vert_n[vi, 1] += ang * ny; vert_n[vi, 2] += ang * nz
            ei = edge_id[f, k]
            esum[ei, 0] += nx; esum[ei, 1] += ny; esum[ei, 2] += nz
    for f in range(F):
        for k in range(3):
            for d in range(3):
                edge_n[f, k, d] = esum[edge_id[f, k], d]
    for i in range(vert_n.shape[0]):
        ln = math.sqrt(vert_n[i, 0] ** 2 + vert_n[i, 1] ** 2 + vert_n[i, 2] ** 2)
        if ln > 0.0:
            vert_n[i, 0] /= ln; vert_n[i, 1] /= ln; vert_n[i, 2] /= ln


@njit(cache=True, inline="always")
def _angle(ux, uy, uz, vx, vy, vz):
    # atan2(|u x v|, u.v): accurate for small and near-pi angles, unlike acos
    cx = uy * vz - uz * vy
    cy = uz * vx - ux * vz
    cz = ux * vy - uy * vx
    return math.atan2(math.sqrt(cx * cx + cy * cy + cz * cz), ux * vx + uy * vy + uz * vz)


# --------------------------------------------------------------------------------------------
# per-point kernels

@njit(cache=True, inline="always")
def closest_on_triangle(px, py, pz, ax, ay, az, bx, by, bz, cx, cy, cz):
    """Ericson, Real-Time Collision Detection 5.1.5: closest point of triangle ABC to P by
    Voronoi regions. Returns (d2, qx, qy, qz, u, v, w) with Q = u*A + v*B + w*C. Divisions are
    guarded so zero-length edges (degenerate triangles) fall back to an endpoint instead of NaN."""
    abx = bx - ax; aby = by - ay; abz = bz - az
    acx = cx - ax; acy = cy - ay; acz = cz - az
    apx = px - ax; apy = py - ay; apz = pz - az
    d1 = abx * apx + aby * apy + abz * apz
    d2 = acx * apx + acy * apy + acz * apz
    u = 1.0
    v = 0.0
    w = 0.0
    d3 = d4 = d5 = d6 = va = vb = vc = 0.0     # typed up front: later regions read them
    done = False
    if d1 <= 0.0 and d2 <= 0.0:                       # vertex A
        done = True
    if not done:
        bpx = px - bx; bpy = py - by; bpz = pz - bz
        d3 = abx * bpx + aby * bpy + abz * bpz
        d4 = acx * bpx + acy * bpy + acz * bpz
        if d3 >= 0.0 and d4 <= d3:                    # vertex B
            u = 0.0; v = 1.0
            done = True
    if not done:
        vc = d1 * d4 - d3 * d2
        if vc <= 0.0 and d1 >= 0.0 and d3 <= 0.0:     # edge AB
            den = d1 - d3
            t = d1 / den if den > 0.0 else 0.0
            u = 1.0 - t; v = t
            done = True
    if not done:
        cpx = px - cx; cpy = py - cy; cpz = pz - cz
        d5 = abx * cpx + aby * cpy + abz * cpz
        d6 = acx * cpx + acy * cpy + acz * cpz
        if d6 >= 0.0 and d5 <= d6:                    # vertex C
            u = 0.0; w = 1.0
            done = True
    if not done:
        vb = d5 * d2 - d1 * d6
        if vb <= 0.0 and d2 >= 0.0 and d6 <= 0.0:     # edge AC
            den = d2 - d6
            t = d2 / den if den > 0.0 else 0.0
            u = 1.0 - t; w = t
            done = True
    if not done:
        va = d3 * d6 - d5 * d4
        e1 = d4 - d3
        e2 = d5 - d6
        if va <= 0.0 and e1 >= 0.0 and e2 >= 0.0:     # edge BC
            den = e1 + e2
            t = e1 / den if den > 0.0 else 0.0
            u = 0.0; v = 1.0 - t; w = t
            done = True
    if not done:                                      # interior: va, vb, vc > 0, so den > 0
        den = 1.0 / (va + vb + vc)
        v = vb * den
        w = vc * den
        u = 1.0 - v - w
    qx = u * ax + v * bx + w * cx
    qy = u * ay + v * by + w * cy
    qz = u * az + v * bz + w * cz
    dx = px - qx; dy = py - qy; dz = pz - qz
    return dx * dx + dy * dy + dz * dz, qx, qy, qz, u, v, w


@njit(cache=True, inline="always")
def _box_d2(px, py, pz, node_lo, node_hi, i):
    # branch-free (max compiles to a select): box tests are the most frequent operation and
    # their in/out outcome is unpredictable, so branches here cost more than the arithmetic
    tx = max(node_lo[i, 0] - px, px - node_hi[i, 0], 0.0)
    ty = max(node_lo[i, 1] - py, py - node_hi[i, 1], 0.0)
    tz = max(node_lo[i, 2] - pz, pz - node_hi[i, 2], 0.0)
    return tx * tx + ty * ty + tz * tz


@njit(cache=True, nogil=True)
def _gather_tris(verts, faces, prim, tri_xyz):
    # leaf order: corners, then the triangle's box (lo, hi); a leaf reads one contiguous block
    # instead of faces -> verts hops
    for j in range(prim.shape[0]):
        f = prim[j]
        for c in range(3):
            for k in range(3):
                tri_xyz[j, 3 * c + k] = verts[faces[f, c], k]
        for k in range(3):
            a = tri_xyz[j, k]
            b = tri_xyz[j, 3 + k]
            c = tri_xyz[j, 6 + k]
            tri_xyz[j, 9 + k] = min(a, min(b, c))
            tri_xyz[j, 12 + k] = max(a, max(b, c))


@njit(cache=True)
def bvh_closest(px, py, pz, max_d2, node_lo, node_hi, node_a, node_n, prim, tri_xyz):
    """Closest point on the mesh to P among triangles closer than sqrt(max_d2) (np.inf: no
    limit). Returns (d2, face, cx, cy, cz, u, v, w); face = -1 and d2 = inf when none is.
    Depth-first, nearer child first, pruning boxes no nearer than the best so far: near-surface
    points touch a handful of leaves, and max_d2 lets far points stop at the root."""
    stack = np.empty(_STACK, np.int32)
    sdist = np.empty(_STACK)
    best = max_d2
    bf = -1
    bcx = bcy = bcz = np.nan
    bu = bv = bw = 0.0
    d0 = _box_d2(px, py, pz, node_lo, node_hi, 0)
    if not d0 < best:
        return np.inf, -1, bcx, bcy, bcz, bu, bv, bw
    stack[0] = 0
    sdist[0] = d0
    sp = 1
    while sp > 0:
        sp -= 1
        if not sdist[sp] < best:          # a nearer triangle was found since it was pushed
            continue
        i = stack[sp]
        n = node_n[i]
        a = node_a[i]
        if n > 0:
            for j in range(a, a + n):
                # the triangle's own box first: a third to a half of the triangles in the leaves
                # reached are rejected by it, at a tenth of the exact test's cost
                tx = max(tri_xyz[j, 9] - px, px - tri_xyz[j, 12], 0.0)
                ty = max(tri_xyz[j, 10] - py, py - tri_xyz[j, 13], 0.0)
                tz = max(tri_xyz[j, 11] - pz, pz - tri_xyz[j, 14], 0.0)
                if not tx * tx + ty * ty + tz * tz < best:
                    continue
                r = closest_on_triangle(px, py, pz,
                                        tri_xyz[j, 0], tri_xyz[j, 1], tri_xyz[j, 2],
                                        tri_xyz[j, 3], tri_xyz[j, 4], tri_xyz[j, 5],
                                        tri_xyz[j, 6], tri_xyz[j, 7], tri_xyz[j, 8])
                if r[0] < best:
                    best = r[0]
                    bf = prim[j]
                    bcx = r[1]; bcy = r[2]; bcz = r[3]
                    bu = r[4]; bv = r[5]; bw = r[6]
            continue
        dl = _box_d2(px, py, pz, node_lo, node_hi, a)
        dr = _box_d2(px, py, pz, node_lo, node_hi, a + 1)
        # push the farther first so the nearer is popped next
        if dl <= dr:
            if dr < best and sp < _STACK:
                stack[sp] = a + 1; sdist[sp] = dr; sp += 1
            if dl < best and sp < _STACK:
                stack[sp] = a; sdist[sp] = dl; sp += 1
        else:
            if dl < best and sp < _STACK:
                stack[sp] = a; sdist[sp] = dl; sp += 1
            if dr < best and sp < _STACK:
                stack[sp] = a + 1; sdist[sp] = dr; sp += 1
    if bf < 0:
        return np.inf, -1, bcx, bcy, bcz, bu, bv, bw
    return best, bf, bcx, bcy, bcz, bu, bv, bw


@njit(cache=True, inline="always")
def _feature_normal(f, u, v, w, face_n, edge_n, vert_n, faces):
    """Pseudonormal of the feature the closest point lies on, read off its barycentrics. A
    coordinate below _BARY_EPS counts as zero: the point is taken to be on the edge (one zero) or
    the vertex (two) even when rounding put it a hair inside the face -- near a sharp edge the face
    normal can give the wrong sign, the edge's cannot, and a point truly in the face interior that
    close to an edge gets the same sign from either (the dihedral angle is < 180 deg)."""
    z0 = u <= _BARY_EPS
    z1 = v <= _BARY_EPS
    z2 = w <= _BARY_EPS
    nz = int(z0) + int(z1) + int(z2)
    if nz == 0:
        return face_n[f, 0], face_n[f, 1], face_n[f, 2]
    if nz == 1:
        # edge k runs faces[f,k] -> faces[f,k+1]; it is opposite vertex k+2
        k = 1 if z0 else (2 if z1 else 0)
        return edge_n[f, k, 0], edge_n[f, k, 1], edge_n[f, k, 2]
    vi = faces[f, 0] if not z0 else (faces[f, 1] if not z1 else faces[f, 2])
    return vert_n[vi, 0], vert_n[vi, 1], vert_n[vi, 2]


@njit(cache=True)
def bvh_signed(px, py, pz, max_d2, node_lo, node_hi, node_a, node_n, prim, tri_xyz, faces,
               face_n, edge_n, vert_n):
    """Signed distance (negative inside) with the closest point and the smooth normal there.
    Returns (sd, face, cx, cy, cz, u, v, w, nx, ny, nz); face = -1 (sd = +inf, normal 0) when no
    triangle is within sqrt(max_d2) -- the sign is then unknown, callers treat it as clear."""
    r = bvh_closest(px, py, pz, max_d2, node_lo, node_hi, node_a, node_n, prim, tri_xyz)
    d2 = r[0]
    f = r[1]
    if f < 0:
        return np.inf, -1, r[2], r[3], r[4], 0.0, 0.0, 0.0, 0.0, 0.0, 0.0
    cx = r[2]; cy = r[3]; cz = r[4]
    u = r[5]; v = r[6]; w = r[7]
    pn = _feature_normal(f, u, v, w, face_n, edge_n, vert_n, faces)
    d = math.sqrt(d2)
    s = (px - cx) * pn[0] + (py - cy) * pn[1] + (pz - cz) * pn[2]
    sd = -d if s < 0.0 else d
    i0 = faces[f, 0]; i1 = faces[f, 1]; i2 = faces[f, 2]
    nx = u * vert_n[i0, 0] + v * vert_n[i1, 0] + w * vert_n[i2, 0]
    ny = u * vert_n[i0, 1] + v * vert_n[i1, 1] + w * vert_n[i2, 1]
    nz = u * vert_n[i0, 2] + v * vert_n[i1, 2] + w * vert_n[i2, 2]
    ln = math.sqrt(nx * nx + ny * ny + nz * nz)
    if ln > 0.0:
        nx /= ln; ny /= ln; nz /= ln
    else:                                  # opposite vertex normals cancel: use the face's
        nx = face_n[f, 0]; ny = face_n[f, 1]; nz = face_n[f, 2]
    return sd, f, cx, cy, cz, u, v, w, nx, ny, nz


@njit(cache=True, inline="always")
def interp_vertex_field(faces, f, u, v, w, field):
    """Barycentric interpolation of a per-vertex (V, 3) field on triangle f; zeros for f < 0."""
    if f < 0:
        return 0.0, 0.0, 0.0
    i0 = faces[f, 0]; i1 = faces[f, 1]; i2 = faces[f, 2]
    return (u * field[i0, 0] + v * field[i1, 0] + w * field[i2, 0],
            u * field[i0, 1] + v * field[i1, 1] + w * field[i2, 1],
            u * field[i0, 2] + v * field[i1, 2] + w * field[i2, 2])


# --------------------------------------------------------------------------------------------
# batches (prange over points)

@njit(cache=True, parallel=True)
def closest_batch(points, max_d2, node_lo, node_hi, node_a, node_n, prim, tri_xyz, faces,
                  face_n, edge_n, vert_n, sd, cpt, normal, face, bary):
    """bvh_signed over points (N, 3) into preallocated sd (N,), cpt (N,3), normal (N,3),
    face (N,) int32, bary (N,3)."""
    for p in prange(points.shape[0]):
        r = bvh_signed(points[p, 0], points[p, 1], points[p, 2], max_d2, node_lo, node_hi,
                       node_a, node_n, prim, tri_xyz, faces, face_n, edge_n, vert_n)
        sd[p] = r[0]
        face[p] = r[1]
        cpt[p, 0] = r[2]; cpt[p, 1] = r[3]; cpt[p, 2] = r[4]
        bary[p, 0] = r[5]; bary[p, 1] = r[6]; bary[p, 2] = r[7]
        normal[p, 0] = r[8]; normal[p, 1] = r[9]; normal[p, 2] = r[10]


@njit(cache=True, parallel=True)
def signed_batch(points, max_d2, node_lo, node_hi, node_a, node_n, prim, tri_xyz, faces,
                 face_n, edge_n, vert_n, sd):
    for p in prange(points.shape[0]):
        sd[p] = bvh_signed(points[p, 0], points[p, 1], points[p, 2], max_d2, node_lo, node_hi,
                           node_a, node_n, prim, tri_xyz, faces, face_n, edge_n, vert_n)[0]


@njit(cache=True, parallel=True)
def interp_batch(faces, face, bary, field, out):
    for p in prange(face.shape[0]):
        r = interp_vertex_field(faces, face[p], bary[p, 0], bary[p, 1], bary[p, 2], field)
        out[p, 0] = r[0]; out[p, 1] = r[1]; out[p, 2] = r[2]


@njit(cache=True)
def collide_batch(points, tol, max_d2, node_lo, node_hi, node_a, node_n, prim, tri_xyz, faces,
                  face_n, edge_n, vert_n, vvel, has_vel, status, normal, velocity, depth):
    """The collider protocol per point (ObjectSpaceCollider.query); outputs preallocated. Serial:
    it runs every simulation step (see engine/jit.py on parallel step kernels)."""
    for p in range(points.shape[0]):
        r = bvh_signed(points[p, 0], points[p, 1], points[p, 2], max_d2, node_lo, node_hi,
                       node_a, node_n, prim, tri_xyz, faces, face_n, edge_n, vert_n)
        sd = r[0]
        f = r[1]
        if f < 0:
            # nothing within the search radius: clear; depth is the bound tol - radius
            status[p] = 0
            depth[p] = tol - math.sqrt(max_d2)
            normal[p, 0] = 0.0; normal[p, 1] = 0.0; normal[p, 2] = 0.0
            velocity[p, 0] = 0.0; velocity[p, 1] = 0.0; velocity[p, 2] = 0.0
            continue
        status[p] = 2 if sd < 0.0 else (1 if sd < tol else 0)
        depth[p] = tol - sd
        normal[p, 0] = r[8]; normal[p, 1] = r[9]; normal[p, 2] = r[10]
        if has_vel:
            v = interp_vertex_field(faces, f, r[5], r[6], r[7], vvel)
            velocity[p, 0] = v[0]; velocity[p, 1] = v[1]; velocity[p, 2] = v[2]
        else:
            velocity[p, 0] = 0.0; velocity[p, 1] = 0.0; velocity[p, 2] = 0.0


# --------------------------------------------------------------------------------------------
# Python API

def _as_points(points) -> np.ndarray:
    return np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)


def _max_d2(max_distance) -> float:
    return np.inf if max_distance is None else float(max_distance) ** 2


class MeshBVH:
    """BVH over a triangle mesh with exact closest-point / signed-distance queries.

    vertices (V, 3) float64 metres; faces (F, 3) int32/int64, CCW seen from outside (outward
    normals); vertex_velocities (V, 3) float64 m/s or None (zero velocity). The sign of
    signed_distance needs a closed, consistently oriented mesh; closest() does not.
    Attributes (read by kernels; do not write): verts, faces (int32), face_normals (F,3),
    edge_normals (F,3,3), vertex_normals (V,3), node_lo/node_hi/node_a/node_n/prim/tri_xyz
    (module doc).
    """

    def __init__(self, vertices, faces, vertex_velocities=None):
        self.verts = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3).copy()
        self.faces = np.ascontiguousarray(faces, dtype=np.int32).reshape(-1, 3)
        if self.faces.shape[0] == 0:
            raise ValueError("MeshBVH needs at least one triangle")
        if self.faces.min() < 0 or self.faces.max() >= self.verts.shape[0]:
            raise ValueError("face index out of range")
        F = self.faces.shape[0]
        # edge ids per face-edge, fixed by the topology: both orientations of an edge share one
        a = self.faces.astype(np.int64)
        b = np.roll(a, -1, axis=1)
        key = np.minimum(a, b) * self.verts.shape[0] + np.maximum(a, b)   # 1-D unique: fast
        _, inv = np.unique(key.ravel(), return_inverse=True)
        self._edge_id = inv.reshape(F, 3).astype(np.int64)
        self._n_edges = int(inv.max()) + 1
        self.face_normals = np.empty((F, 3))
        self.edge_normals = np.empty((F, 3, 3))
        self.vertex_normals = np.empty_like(self.verts)
        self._tlo = np.empty((F, 3))
        self._thi = np.empty((F, 3))
        self.vel = np.zeros_like(self.verts)
        self.has_velocity = False
        self._set_velocities(vertex_velocities)
        _tri_boxes(self.verts, self.faces, self._tlo, self._thi)
        (self.node_lo, self.node_hi, self.node_a, self.node_n,
         self.prim) = _build(self._tlo, self._thi, _LEAF_SIZE)
        # the traversal stack holds at most depth + 1 entries (each pop pushes <= 2)
        self.depth = int(_tree_depth(self.node_a, self.node_n))
        if self.depth + 1 > _STACK:
            raise RuntimeError(f"BVH depth {self.depth} exceeds the traversal stack ({_STACK})")
        self.tri_xyz = np.empty((F, 15))
        _gather_tris(self.verts, self.faces, self.prim, self.tri_xyz)
        _normals(self.verts, self.faces, self._edge_id, self._n_edges,
                 self.face_normals, self.edge_normals, self.vertex_normals)

    @property
    def n_nodes(self) -> int:
        return int(self.node_a.shape[0])

    def _set_velocities(self, vertex_velocities):
        if vertex_velocities is None:
            self.vel[:] = 0.0
            self.has_velocity = False
        else:
            vv = np.asarray(vertex_velocities, dtype=np.float64).reshape(-1, 3)
            if vv.shape != self.verts.shape:
                raise ValueError(f"vertex_velocities {vv.shape} != vertices {self.verts.shape}")
            self.vel[:] = vv
            self.has_velocity = True

    def update(self, vertices, vertex_velocities=None):
        """Moved mesh, same topology (a walking body's next frame): refit the boxes and
        recompute the normals; no rebuild. The tree quality degrades only if the motion is far
        from rigid per subtree -- rebuild (a new MeshBVH) if queries get slow."""
        v = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        if v.shape != self.verts.shape:
            raise ValueError(f"vertices {v.shape} != {self.verts.shape}: topology changed")
        self.verts[:] = v
        self._set_velocities(vertex_velocities)
        _tri_boxes(self.verts, self.faces, self._tlo, self._thi)
        _refit(self._tlo, self._thi, self.node_lo, self.node_hi, self.node_a, self.node_n,
               self.prim)
        _gather_tris(self.verts, self.faces, self.prim, self.tri_xyz)
        _normals(self.verts, self.faces, self._edge_id, self._n_edges,
                 self.face_normals, self.edge_normals, self.vertex_normals)

    def kernel_args(self):
        """(node_lo, node_hi, node_a, node_n, prim, tri_xyz, faces, face_n, edge_n, vert_n): the
        arrays bvh_signed takes after (px, py, pz, max_d2); bvh_closest takes the first six."""
        return (self.node_lo, self.node_hi, self.node_a, self.node_n, self.prim, self.tri_xyz,
                self.faces, self.face_normals, self.edge_normals, self.vertex_normals)

    def closest(self, points, max_distance=None):
        """points (N, 3) -> (distance (N,) float64 unsigned, point (N, 3) float64 closest
        surface point, normal (N, 3) float64 smooth outward normal there, face (N,) int32,
        bary (N, 3) float64 with point = bary . triangle corners). Points farther than
        max_distance (None: no limit) get distance inf, face -1, point NaN, normal/bary 0.
        The flat face normal is self.face_normals[face]."""
        sd, cpt, normal, face, bary = self._closest_signed(points, max_distance)
        return np.abs(sd), cpt, normal, face, bary

    def _closest_signed(self, points, max_distance=None):
        pts = _as_points(points)
        n = pts.shape[0]
        sd = np.empty(n)
        cpt = np.empty((n, 3))
        normal = np.empty((n, 3))
        face = np.empty(n, np.int32)
        bary = np.empty((n, 3))
        closest_batch(pts, _max_d2(max_distance), *self.kernel_args(), sd, cpt, normal, face, bary)
        return sd, cpt, normal, face, bary

    def signed_distance(self, points, max_distance=None):
        """points (N, 3) -> (N,) float64 metres, negative inside. Points with no triangle within
        max_distance (None: exact everywhere) get +inf, whatever side they are on."""
        pts = _as_points(points)
        sd = np.empty(pts.shape[0])
        signed_batch(pts, _max_d2(max_distance), *self.kernel_args(), sd)
        return sd

    def velocity_at(self, points=None, *, face=None, bary=None, max_distance=None):
        """Body velocity (N, 3) float64 at the closest surface point: barycentric interpolation
        of the vertex velocities (zeros without them). Give points (N, 3), or the face (N,) and
        bary (N, 3) a closest() call returned (saves the search)."""
        if points is not None:
            _, _, _, face, bary = self._closest_signed(points, max_distance)
        if face is None or bary is None:
            raise ValueError("velocity_at needs points, or face and bary")
        face = np.ascontiguousarray(face, dtype=np.int32).reshape(-1)
        bary = np.ascontiguousarray(bary, dtype=np.float64).reshape(-1, 3)
        out = np.empty((face.shape[0], 3))
        interp_batch(self.faces, face, bary, self.vel, out)
        return out


class ObjectSpaceCollider(Collider):
    """The image-space maps' query protocol answered exactly from the body mesh.

    body_vertices (V, 3) float64, body_faces (F, 3) int, CCW outward, closed; tolerance metres;
    vertex_velocities (V, 3) or None; max_distance: search radius, None = exact everywhere. With
    a radius r, a point with no triangle within r is reported clear (status 0, normal and
    velocity 0, depth = tolerance - r) even if it is deep inside: keep r above the deepest
    penetration expected (a few cm for cloth), or leave it None.

    query(points (M, 3)) -> (status (M,) int8, normal (M, 3) float64, body_velocity (M, 3)
    float64, depth (M,) float64) with sd the signed distance to the body:
        status 0 clear (sd >= tol), 1 band (0 <= sd < tol), 2 inside (sd < 0);
        depth = tol - sd, > 0 exactly when status > 0: metres to move along normal to leave
        the band; normal = smooth outward normal at the closest point.
    The returned arrays are buffers owned by the collider and overwritten by the next query
    (called every step; no allocation while M stays the same). Copy them to keep them.
    """

    def __init__(self, body_vertices, body_faces, tolerance=0.005, vertex_velocities=None,
                 max_distance=None):
        self.bvh = MeshBVH(body_vertices, body_faces, vertex_velocities)
        self.tolerance = float(tolerance)
        self.max_distance = max_distance
        self.version = 0  # bumped when the body moves (solvers re-query then)
        self._alloc(0)

    def _alloc(self, m):
        self.status = np.zeros(m, np.int8)
        self.normal = np.zeros((m, 3))
        self.velocity = np.zeros((m, 3))
        self.depth = np.zeros(m)

    def update(self, body_vertices, vertex_velocities=None):
        """Next body frame (same topology): refit."""
        self.bvh.update(body_vertices, vertex_velocities)
        self.version += 1

    def query(self, points):
        pts = _as_points(points)
        m = pts.shape[0]
        if self.status.shape[0] != m:
            self._alloc(m)
        b = self.bvh
        collide_batch(pts, self.tolerance, _max_d2(self.max_distance), *b.kernel_args(),
                      b.vel, b.has_velocity, self.status, self.normal, self.velocity, self.depth)
        return self.status, self.normal, self.velocity, self.depth


class RowsObjectSpaceCollider(ObjectSpaceCollider):
    """ObjectSpaceCollider that answers some points alone (Collider.answers_rows): the solver's
    carried answers (engine.cloth.carry) then ask only for the points in contact and the clear
    points that may have reached the band, not for all of them at every query."""

    answers_rows = True

    def query_rows(self, points, rows, n_rows):
        pts = _as_points(points)
        if self.status.shape[0] != pts.shape[0]:
            self._alloc(pts.shape[0])
        k = rows[:n_rows]
        st, nr, ve, de = np.empty(n_rows, np.int8), np.empty((n_rows, 3)), np.empty((n_rows, 3)), np.empty(n_rows)
        b = self.bvh
        collide_batch(pts[k], self.tolerance, _max_d2(self.max_distance), *b.kernel_args(),
                      b.vel, b.has_velocity, st, nr, ve, de)
        self.status[k], self.normal[k], self.velocity[k], self.depth[k] = st, nr, ve, de
        return self.status, self.normal, self.velocity, self.depth


def penetration_stats(body_vertices, body_faces, points, bvh: MeshBVH | None = None) -> dict:
    """How deep points (N, 3) are inside the body, measured exactly against its mesh.

    depth (penetration_depth) over ALL points. Returns a dict of floats (metres): max, p99
    (99th percentile over all points, so 0 unless >= ~1 % are inside), mean (mean depth of the
    points that are inside, 0 if none), mean_all (over all points), count_inside (int), count
    (int), outside_by_winding (int: points the pseudonormal sign put inside and the winding
    number outside, counted as outside). Pass bvh to reuse one already built for this body
    (then body_vertices/body_faces are ignored)."""
    if bvh is None:
        bvh = MeshBVH(body_vertices, body_faces)
    depth, n_fixed = penetration_depth(bvh, points)
    inside = depth > 0.0
    n_in = int(inside.sum())
    n = int(depth.shape[0])
    return dict(
        max=float(depth.max()) if n else 0.0,
        p99=float(np.percentile(depth, 99)) if n else 0.0,
        mean=float(depth[inside].mean()) if n_in else 0.0,
        mean_all=float(depth.mean()) if n else 0.0,
        count_inside=n_in,
        count=n,
        outside_by_winding=n_fixed,
    )


WINDING_CHECK = 64  # penetration_depth asks at most this many points again by winding number
# (about 2 ms a point on a 47k-triangle scan; the max and the deepest points are what matter)


def penetration_depth(bvh: MeshBVH, points) -> tuple[np.ndarray, int]:
    """(depth (N,) metres inside the body, 0 outside; how many points the sign put inside and
    the winding number outside). The pseudonormal sign needs a cleanly closed surface; a
    walking body's skin can fold inside out (behind a scan's bent knees), and points centimetres
    away then read "inside". The points that read inside (the deepest
    WINDING_CHECK of them) are asked again by winding number, which a fold does not fool."""
    pts = np.asarray(points, dtype=np.float64)
    sd = bvh.signed_distance(pts)
    ins = np.flatnonzero(sd < 0.0)
    n_fixed = 0
    if len(ins):
        ins = ins[np.argsort(sd[ins])[:WINDING_CHECK]]
        out = winding_numbers(bvh.verts, bvh.faces, pts[ins]) < 0.5
        n_fixed = int(out.sum())
        sd[ins[out]] = -sd[ins[out]]
    return np.where(sd < 0.0, -sd, 0.0), n_fixed


@njit(cache=True, fastmath=False)
def _winding_batch(verts, faces, pts, out):
    """winding_numbers of pts (K, 3) for the mesh (verts, faces) into out (K,)."""
    for k in range(pts.shape[0]):
        px, py, pz = pts[k, 0], pts[k, 1], pts[k, 2]
        acc = 0.0
        for f in range(faces.shape[0]):
            a, b, c = faces[f, 0], faces[f, 1], faces[f, 2]
            ax, ay, az = verts[a, 0] - px, verts[a, 1] - py, verts[a, 2] - pz
            bx, by, bz = verts[b, 0] - px, verts[b, 1] - py, verts[b, 2] - pz
            cx, cy, cz = verts[c, 0] - px, verts[c, 1] - py, verts[c, 2] - pz
            la = np.sqrt(ax * ax + ay * ay + az * az)
            lb = np.sqrt(bx * bx + by * by + bz * bz)
            lc = np.sqrt(cx * cx + cy * cy + cz * cz)
            num = ax * (by * cz - bz * cy) + ay * (bz * cx - bx * cz) + az * (bx * cy - by * cx)
            den = la * lb * lc + (ax * bx + ay * by + az * bz) * lc + (bx * cx + by * cy + bz * cz) * la \
                + (cx * ax + cy * ay + cz * az) * lb
            acc += np.arctan2(num, den)
        out[k] = acc / (2.0 * np.pi)


def winding_numbers(verts: np.ndarray, faces: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Generalised winding numbers (K,) of points (K, 3) for the mesh (verts, faces): the sum of
    the signed solid angles its triangles subtend (Van Oosterom & Strackee 1983) over 4 pi.
    About 1 inside a closed, outward-oriented surface, 0 outside; a fold turned inside out adds
    nothing away from it."""
    pts = np.ascontiguousarray(points, dtype=np.float64).reshape(-1, 3)
    out = np.empty(len(pts))
    _winding_batch(np.ascontiguousarray(verts, dtype=np.float64), np.ascontiguousarray(faces, dtype=np.int64),
                   pts, out)
    return out
