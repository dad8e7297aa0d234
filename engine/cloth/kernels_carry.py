"""Map answers carried between collision queries (a cloth point moves a fraction of a millimetre
a step, so its last answer holds until it moved far enough): the carry, which points to ask
again, and keeping their fresh answers. NumPy/numba only.

Arrays: points (M, 3) float64, the checked points; q_*: the answers as last asked (q_points where
each point was then); status (M,) int8, normal (M, 3), depth (M,) as a collider answers.
"""

from __future__ import annotations

from engine.jit import njit, serial_kernel

MIN_NZ = 0.2  # a carried depth changes at most 1 / MIN_NZ x the move along the normal (_depth_rate)


@serial_kernel
def stale_contacts(points, q_points, g_points, q_status, q_normal, q_depth, status, depth, reach, slack, rows,
                   z_depth):
    """Between two map queries: carry each checked point's last answer forward, its depth
    corrected by how far it moved along the normal since its answer (a point that left the band
    becomes clear). Returns -1 when the answers may be stale: a point moved more than `reach`
    since the last query of all (g_points), or a point that was clear moved farther than its
    distance from the band (q_depth < 0 is minus that distance) plus `slack` since its answer
    (q_points) -- so nothing gets deeper than `slack` into the band unseen (the response only
    pushes in the band's inner half). Else returns 0 -- or, when `rows` is not empty (a
    collider that can answer some points alone), such clear points do not make every answer
    stale: they are listed in `rows` and their count is returned.
    z_depth: the collider measures depth along z, as the maps do (see _depth_rate)."""
    r2 = reach * reach
    own = rows.shape[0] > 0
    k = 0
    for p in range(points.shape[0]):
        if _moved(points, g_points, p)[3] > r2:
            return -1
        dx, dy, dz, d2 = _moved(points, q_points, p)
        st = q_status[p]
        if st == 0:
            if _may_touch(d2, r2, slack, q_depth[p]):
                if not own:
                    return -1
                rows[k] = p
                k += 1
            status[p] = 0
            continue
        move_n = dx * q_normal[p, 0] + dy * q_normal[p, 1] + dz * q_normal[p, 2]
        d = q_depth[p] - move_n * _depth_rate(q_normal[p, 2], z_depth)
        depth[p] = d
        status[p] = st if d > 0.0 else 0
    return k


@njit(fastmath=True, cache=True, inline="always")
def _moved(points, q_points, p):
    """(dx, dy, dz, squared distance) point p moved since its answer."""
    dx = points[p, 0] - q_points[p, 0]
    dy = points[p, 1] - q_points[p, 1]
    dz = points[p, 2] - q_points[p, 2]
    return dx, dy, dz, dx * dx + dy * dy + dz * dz


@njit(fastmath=True, cache=True, inline="always")
def _may_touch(d2, r2, slack, q_depth):
    """A point answered clear (q_depth: minus its distance from the band) that moved sqrt(d2)
    may be in the band now (or more than `slack` into it): it moved more than `reach` (sqrt(r2))
    or farther than that distance plus slack."""
    lim = slack - q_depth
    return d2 > r2 or d2 > lim * lim


@njit(fastmath=True, cache=True, inline="always")
def _depth_rate(nz, z_depth):
    """How fast a carried depth changes per metre moved along the normal n: a distance (an
    object-space collider, or the maps' side layer, whose n_z is 0) by -(n . m); the maps' depth
    is measured along z (seed 003 §5.3), so there by -(n . m) / |n_z| (capped at 1 / MIN_NZ)."""
    a = abs(nz)
    return 1.0 if (a == 0.0 or not z_depth) else 1.0 / max(a, MIN_NZ)


@serial_kernel
def rows_to_ask(points, q_points, q_status, q_depth, reach, slack, rows):
    """At a new map query: list in `rows` the points whose answer may have changed since their
    last one, and return how many -- every point that was in contact, and every clear point that
    moved more than `reach` or farther than its distance from the band plus `slack` (the rule of
    stale_contacts). A clear point that did neither is still clear and keeps its answer and its
    reference position (most of a garment hangs clear of the body)."""
    r2 = reach * reach
    k = 0
    for p in range(points.shape[0]):
        if q_status[p] != 0 or _may_touch(_moved(points, q_points, p)[3], r2, slack, q_depth[p]):
            rows[k] = p
            k += 1
    return k


@serial_kernel
def keep_rows(rows, n_rows, points, status, normal, body_v, depth, q_points, q_status, q_normal, q_body_v,
              q_depth, c_status, c_depth):
    """Copy the freshly asked rows (rows[:n_rows]) of a map answer into the kept answer (q_*,
    as asked) and into the carried one (c_status, c_depth, see stale_contacts)."""
    for i in range(n_rows):
        p = rows[i]
        q_status[p] = status[p]
        q_depth[p] = depth[p]
        c_status[p] = status[p]
        c_depth[p] = depth[p]
        for c in range(3):
            q_points[p, c] = points[p, c]
            q_normal[p, c] = normal[p, c]
            q_body_v[p, c] = body_v[p, c]
