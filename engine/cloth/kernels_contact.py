"""Collision response of a cloth step (seed 003 eq. 12, seed 000 eq. 15): the checked points
(vertices, quad midpoints, triangle centroids, seed 003 §6), their response to the body's answer,
alternated with the strain limit, and the hold of contacts between checks. NumPy/numba only.

Arrays: v (N, 3) float64; a collider's answer for M = N + Q + T points: status (M,) int8 (0 clear,
1 in the tolerance band, 2 inside), normal (M, 3), body velocity (M, 3), depth (M,) metres past
the band's outer edge.
"""

from __future__ import annotations

import numpy as np

from engine.cloth.kernels_strain import _modify_passes
from engine.jit import njit, serial_kernel

MAX_PUSH = 1.0  # m/s: fastest a collision response moves a point out of the body


@njit(fastmath=True, cache=True, inline="always")
def _n_corners(p, n, nq):
    """Checked point p: a vertex (p < n, 1 corner), a quad midpoint (4) or a triangle centroid (3)."""
    return 1 if p < n else (4 if p < n + nq else 3)


@njit(fastmath=True, cache=True, inline="always")
def _corner(p, r, n, nq, quads, tris):
    """The vertex at corner r of checked point p."""
    if p < n:
        return p
    if p < n + nq:
        return quads[p - n, r]
    return tris[p - n - nq, r]


@njit(fastmath=True, cache=True, inline="always")
def _report_contact(i, p, normal, body_v, contact_n, vbody_out):
    """Vertex i touches the body through checked point p: keep p's normal and body velocity."""
    for c in range(3):
        contact_n[i, c] = normal[p, c]
        vbody_out[i, c] = body_v[p, c]


@njit(fastmath=True, cache=True, inline="always")
def _point_mean(a, p, n, nq, quads, tris):
    """A per-vertex field (N, 3) at checked point p: the vertex's value, or its face's mean."""
    if p < n:
        return a[p, 0], a[p, 1], a[p, 2]
    if p < n + nq:
        i0, i1, i2, i3 = quads[p - n, 0], quads[p - n, 1], quads[p - n, 2], quads[p - n, 3]
        return (0.25 * (a[i0, 0] + a[i1, 0] + a[i2, 0] + a[i3, 0]),
                0.25 * (a[i0, 1] + a[i1, 1] + a[i2, 1] + a[i3, 1]),
                0.25 * (a[i0, 2] + a[i1, 2] + a[i2, 2] + a[i3, 2]))
    t = p - n - nq
    i0, i1, i2 = tris[t, 0], tris[t, 1], tris[t, 2]
    third = 1.0 / 3.0
    return (third * (a[i0, 0] + a[i1, 0] + a[i2, 0]), third * (a[i0, 1] + a[i1, 1] + a[i2, 1]),
            third * (a[i0, 2] + a[i1, 2] + a[i2, 2]))


@serial_kernel
def point_average(a, quads, tris, out):
    """A per-vertex field (N, 3) at the checked points: the vertices, then quad midpoints, then
    triangle centroids (seed 003 §6's face-body checks), into out (N + Q + T, 3)."""
    n = a.shape[0]
    nq = quads.shape[0]
    for p in range(n + nq + tris.shape[0]):
        out[p, 0], out[p, 1], out[p, 2] = _point_mean(a, p, n, nq, quads, tris)


@serial_kernel
def collision_points(x, v, dt, quads, tris, p_out):
    """The checked points (vertices, quad midpoints, triangle centroids) at their predicted
    positions: the vertices' x + dt v first (rows 0..N-1 of p_out), then each face's point the
    mean of its corners' rows -- three loops without a branch per point, the first a vector
    loop."""
    n = x.shape[0]
    nq = quads.shape[0]
    for i in range(n):
        p_out[i, 0] = x[i, 0] + dt * v[i, 0]
        p_out[i, 1] = x[i, 1] + dt * v[i, 1]
        p_out[i, 2] = x[i, 2] + dt * v[i, 2]
    for q in range(nq):
        i0, i1, i2, i3 = quads[q, 0], quads[q, 1], quads[q, 2], quads[q, 3]
        for c in range(3):
            p_out[n + q, c] = 0.25 * (p_out[i0, c] + p_out[i1, c] + p_out[i2, c] + p_out[i3, c])
    third = 1.0 / 3.0
    for t in range(tris.shape[0]):
        i0, i1, i2 = tris[t, 0], tris[t, 1], tris[t, 2]
        for c in range(3):
            p_out[n + nq + t, c] = third * (p_out[i0, c] + p_out[i1, c] + p_out[i2, c])


@njit(fastmath=True, cache=True, inline="always")
def _respond(vx, vy, vz, nx, ny, nz, bx, by, bz, depth, tol, refl, mu, dt, push_rate):
    """Eq. 12 / eq. 15 for one point: relative velocity to the body, reflected normal part
    (C_refl), Coulomb friction on the tangential part (C_fric = max(0, 1 - mu |dv_n| / |v_t|)),
    and a push that takes a point in the inner half of the band (or inside) back out."""
    rx, ry, rz = vx - bx, vy - by, vz - bz
    vn = rx * nx + ry * ny + rz * nz
    tx, ty, tz = rx - vn * nx, ry - vn * ny, rz - vn * nz
    new_vn = vn
    if vn < 0.0:
        new_vn = -refl * vn
    # depth: metres past the band's outer edge. Points in the inner half of the band drift back
    # out over 1 / push_rate seconds (ClothParams.push_time: a resting contact must not be
    # kicked: at dt ~ 0.2 ms a one-step push would be metres per second of jitter)
    push = (depth - 0.5 * tol) * push_rate
    if push > MAX_PUSH:  # a point deep inside (e.g. pulled through by a seam) leaves gently
        push = MAX_PUSH
    if push > new_vn:
        new_vn = push
    dvn = new_vn - vn
    if dvn < 0.0:
        dvn = 0.0
    vt = np.sqrt(tx * tx + ty * ty + tz * tz)
    cf = 1.0
    if vt > 1e-12:
        cf = max(0.0, 1.0 - mu * dvn / vt)
    return (cf * tx + new_vn * nx + bx, cf * ty + new_vn * ny + by, cf * tz + new_vn * nz + bz)


@serial_kernel
def collision_response(v, status, normal, body_v, depth, pv, n_vertices, quads, tris,
                       tol, refl, mu, dt, contact, contact_n, vbody_out, push_rate):
    """Apply the responses of vertex and face checks: a face's resulting velocity goes to all its
    corners; a vertex with several responses gets their average (seed 003 §6). Marks contacts
    (used by next step's reaction force) and records the body velocity seen by each vertex.
    push_rate: 1 / ClothParams.push_time (_respond)."""
    n = n_vertices
    acc = np.empty((n, 3))  # (no np.zeros in a serial_kernel: see engine/jit.py)
    cnt = np.empty(n, dtype=np.int32)
    hits = 0
    for i in range(n):
        acc[i, 0] = 0.0
        acc[i, 1] = 0.0
        acc[i, 2] = 0.0
        cnt[i] = 0
        contact[i] = False
        vbody_out[i, 0] = 0.0
        vbody_out[i, 1] = 0.0
        vbody_out[i, 2] = 0.0
    m = status.shape[0]
    for p in range(m):
        if status[p] == 0:
            continue
        hits += 1
        rx, ry, rz = _respond(pv[p, 0], pv[p, 1], pv[p, 2], normal[p, 0], normal[p, 1], normal[p, 2],
                              body_v[p, 0], body_v[p, 1], body_v[p, 2], depth[p], tol, refl, mu, dt, push_rate)
        for r in range(_n_corners(p, n, quads.shape[0])):
            i = _corner(p, r, n, quads.shape[0], quads, tris)
            acc[i, 0] += rx
            acc[i, 1] += ry
            acc[i, 2] += rz
            cnt[i] += 1
            contact[i] = True
            _report_contact(i, p, normal, body_v, contact_n, vbody_out)
    for i in range(n):
        if cnt[i] > 0:
            v[i, 0] = acc[i, 0] / cnt[i]
            v[i, 1] = acc[i, 1] / cnt[i]
            v[i, 2] = acc[i, 2] / cnt[i]
    return hits


@serial_kernel
def contact_rounds(v, ends, mode, gravity, dt, passes, work, geo, recover, n_act,
                   rounds, status, normal, body_v, depth, n_vertices, quads, tris, tol, refl, mu,
                   contact, contact_n, vbody_out, hit_buf, touched_buf, push_rate):
    """The collision response of a step alternated with the strain limit on the same contacts,
    in one call: `rounds` times (1) from the second round on, the velocity modification over the
    n_act springs known to be over-elongated (modify_velocities with n_known; their ends in
    `ends`, work and geo as it left them), (2) the response
    of every point in contact (collision_response, each point's velocity averaged from its
    corners as point_average does). The same arithmetic as calling those kernels in turn, but
    only the points in contact and the vertices they touch are visited in each round (those
    kernels sweep all vertices and points every round). hit_buf (N + Q + T,) and touched_buf
    (N,) int32 are work buffers; push_rate is 1 / ClothParams.push_time. Returns the number of
    points in contact."""
    n = n_vertices
    nq = quads.shape[0]
    m = status.shape[0]
    for i in range(n):
        contact[i] = False
        vbody_out[i, 0] = 0.0
        vbody_out[i, 1] = 0.0
        vbody_out[i, 2] = 0.0
    hits = 0
    for p in range(m):
        if status[p] != 0:
            hit_buf[hits] = p
            hits += 1
    # the touched vertices (each once) and the contact each one reports (the last point wins,
    # as in collision_response)
    n_touch = 0
    for h in range(hits):
        p = hit_buf[h]
        for r in range(_n_corners(p, n, nq)):
            i = _corner(p, r, n, nq, quads, tris)
            if not contact[i]:
                contact[i] = True
                touched_buf[n_touch] = i
                n_touch += 1
            _report_contact(i, p, normal, body_v, contact_n, vbody_out)
    acc = np.empty((n, 3))
    cnt = np.empty(n, dtype=np.int32)
    for rnd in range(rounds):
        if rnd > 0:
            _modify_passes(v, ends, geo, n_act, mode, gravity, dt, vbody_out, passes, recover)
        for k in range(n_touch):
            i = touched_buf[k]
            acc[i, 0] = 0.0
            acc[i, 1] = 0.0
            acc[i, 2] = 0.0
            cnt[i] = 0
        for h in range(hits):
            p = hit_buf[h]
            pvx, pvy, pvz = _point_mean(v, p, n, nq, quads, tris)
            rx, ry, rz = _respond(pvx, pvy, pvz, normal[p, 0], normal[p, 1], normal[p, 2],
                                  body_v[p, 0], body_v[p, 1], body_v[p, 2], depth[p], tol, refl, mu, dt,
                                  push_rate)
            for r in range(_n_corners(p, n, nq)):
                i = _corner(p, r, n, nq, quads, tris)
                acc[i, 0] += rx
                acc[i, 1] += ry
                acc[i, 2] += rz
                cnt[i] += 1
        for k in range(n_touch):
            i = touched_buf[k]
            v[i, 0] = acc[i, 0] / cnt[i]
            v[i, 1] = acc[i, 1] / cnt[i]
            v[i, 2] = acc[i, 2] / cnt[i]
    return hits


@njit(fastmath=True, cache=True, inline="always")
def _hold_one(v, i, contact_n, body_v):
    """hold_contacts for vertex i (in contact)."""
    nx, ny, nz = contact_n[i, 0], contact_n[i, 1], contact_n[i, 2]
    vn = (v[i, 0] - body_v[i, 0]) * nx + (v[i, 1] - body_v[i, 1]) * ny + (v[i, 2] - body_v[i, 2]) * nz
    if vn < 0.0:
        v[i, 0] -= vn * nx
        v[i, 1] -= vn * ny
        v[i, 2] -= vn * nz


@serial_kernel
def hold_contacts(v, contact, contact_n, body_v):
    """Between two collision checks: a vertex in contact at the last check may not move into the
    body -- its velocity relative to the body's (as seen then) loses any part along the contact
    normal pointing inward (what the velocity modification and the seams may have given it in
    this step; the reaction force of eq. 16 only cancels forces)."""
    for i in range(v.shape[0]):
        if contact[i]:
            _hold_one(v, i, contact_n, body_v)
