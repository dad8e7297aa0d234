"""Small numba kernels of one cloth step (seed 003 §3-6, seed 000 §3, §5). NumPy/numba only.

Serial on purpose (measured): on this 2-core machine a parallel step kernel saves little when the
machine is idle and is 10-600x slower when another process holds a core (numba's workers wait
for the descheduled one) -- and a try-on service runs several jobs at once.

Arrays: x, v (N, 3) float64; springs (S, 2) int32 with rest lengths and stiffness (S,).
"""

from __future__ import annotations

import numpy as np

from engine.jit import njit, serial_kernel

VM_ZERO, VM_AVERAGE, VM_DIRECTIONAL, VM_PROVOT = 0, 1, 2, 3
MAX_PUSH = 1.0  # m/s: fastest a collision response moves a point out of the body
# Where the directional rule applies. With v_object ~ 0 (a free spring, or cloth on a body at rest)
# v_dir is g dt, and letting the upper end of every hanging spring copy its lower end's velocity
# hands the cloth's weight down the chain to wherever it is held, whose spring then stretches
# without bound (measured: a skirt on a walking body reached 1000 % strain in 0.13 s): there eq. 5
# (the average) holds the weight. A spring with one end dragged by the body (in contact, body
# moving faster than this): the free end catches up with the dragged one, whichever is "rear"
# along v_dir -- when the dragged end is the rear, the seed's rule would set its velocity, and
# the collision response sets it back to the body's, so only the strain control would be lost
# (measured: 30 % strain in 0.25 s). Both ends dragged: the seed's rule along v_dir.
DIR_MIN_OBJECT_SPEED = 0.05  # m/s
MIN_NZ = 0.2  # see _depth_rate
VM_MODES = {"zero": VM_ZERO, "average": VM_AVERAGE, "directional": VM_DIRECTIONAL, "provot": VM_PROVOT}


@njit(fastmath=True, cache=True, inline="always")
def _axial(dx, dy, dz, du, dw, dq, rest, k, c_damp, one, tiny):
    """A spring's force per unit of its vector (dx, dy, dz), the other end's relative velocity
    (du, dw, dq): stiffness times extension plus damping of the rate of stretch, over the length;
    and the length. one, tiny: 1 and 1e-30 in the precision the pass computes in (a literal would
    be a double, and turn single-precision arithmetic into double)."""
    l2 = dx * dx + dy * dy + dz * dz
    inv = one / np.sqrt(l2 + tiny)
    length = l2 * inv
    rate = (du * dx + dw * dy + dq * dz) * inv
    return (k * (length - rest) + c_damp * rate) * inv, length


@njit(fastmath=True, cache=True, inline="always")
def _scatter_run(fx, fy, fz, tx, ty, tz, a0, b0, m):
    """A run's spring forces (tmp rows tx, ty, tz) added to its a ends and taken from its b ends."""
    fa, ga, ha = fx[a0:a0 + m], fy[a0:a0 + m], fz[a0:a0 + m]
    for t in range(m):
        fa[t] += tx[t]
        ga[t] += ty[t]
        ha[t] += tz[t]
    fb, gb, hb = fx[b0:b0 + m], fy[b0:b0 + m], fz[b0:b0 + m]
    for t in range(m):
        fb[t] -= tx[t]
        gb[t] -= ty[t]
        hb[t] -= tz[t]


@njit(fastmath=True, cache=True, inline="always")
def _single_spring(s, sp, xs, ys, zs, vx, vy, vz, rest, k, spring_c, fx, fy, fz):
    """Spring s (outside runs) added to the forces; returns its length and vector."""
    a = sp[s, 0]
    b = sp[s, 1]
    dx = xs[b] - xs[a]
    dy = ys[b] - ys[a]
    dz = zs[b] - zs[a]
    length = np.sqrt(dx * dx + dy * dy + dz * dz)
    if length > 1e-12:
        rate = ((vx[b] - vx[a]) * dx + (vy[b] - vy[a]) * dy + (vz[b] - vz[a]) * dz) / length
        c = (k[s] * (length - rest[s]) + spring_c[s] * rate) / length
        fx[a] += c * dx
        fy[a] += c * dy
        fz[a] += c * dz
        fx[b] -= c * dx
        fy[b] -= c * dy
        fz[b] -= c * dz
    return length, dx, dy, dz


@njit(fastmath=True, cache=True, inline="always")
def _list_mark(length, limit, near_frac):
    """The force pass's mark of a listed spring: 2 if it is past its listing length by more than
    near_frac x that length (near the strain guard's), else 1."""
    return np.uint8(2) if length - limit > near_frac * limit else np.uint8(1)


@serial_kernel(error_model="numpy")
def eval_forces_and_integrate(x, v, inv_mass, mass, sp, perm, runs, n_run, sprops, gravity, damping,
                              contact, contact_n, mu, dt, f_out, work, geo, soa, tmp, lengths, listed, listed_words,
                              geo_s, r_fast, n_fast, n_run_slow, slow_due, f_slow, one, tiny, r_held,
                              springs_m, ends, near, near_frac):
    """Springs (eq. 2) with damping along each spring, gravity, viscous damping, then the
    reaction force of seed 000 eq. 16 where the vertex touched the body in the previous step
    (cancel the force into the body, Coulomb friction on the tangential part), then the velocity
    half of eq. 3: v += dt f / m. f_out keeps the force for diagnostics and FIRE (0 rows: not
    kept, ClothSolver.drop_forces -- 93 KB a step less written on the walking dress).

    The springs come in the order of engine.cloth.model.SpringRuns (sp, perm, runs, n_run;
    sprops (4, S): rest length, stiffness, damping and the length past which the spring is
    listed (below; inf for a spring the strain limit leaves alone), in that order): most lie in runs
    (a0 + t, b0 + t), t < L -- a row of the grid against the next one -- so positions and
    velocities are copied into soa (9, N: x, y, z, vx, vy, vz, fx, fy, fz) and each run is one
    loop over contiguous slices, which LLVM turns into vector instructions (no gathers); its
    forces go to tmp (3, >= longest run) first and are then added to both ends' rows (adding to
    both in the same loop would make each iteration depend on the last when b0 - a0 is small).
    The springs outside runs are done one by one. Measured on a captured step of the dress
    (4,374 vertices, 25.5k springs, 93 % in runs): the whole kernel 0.24 ms median instead of
    0.35 ms for one pass over all springs one by one.

    The slow group (SpringRuns: runs[r_fast:], springs from n_fast on; the flexion springs,
    ClothParams.flexion_every) is evaluated only when slow_due: its forces go to f_slow (3, N),
    which every step adds in as it was last evaluated (multiple time stepping: the force of a
    spring thousands of times softer than the stretch springs, held over a few steps). So are the
    forces of the fast group's held runs (runs[r_held:r_fast]; r_held = r_fast: none), which
    are still listed every step: a vector pass over their squared lengths, without forces (the
    walk's shear springs, ~200 x softer than the stretch springs: ClothSolver.hold_shear).

    The same pass lists the springs longer than their listing length in `work` (their
    model indices; directions and excesses in `geo`, see _store_geo) and returns their count:
    the velocity modification that follows (modify_velocities with n_known) needs no sweep of
    its own, as positions do not move in between. A run keeps its lengths in `lengths` (S,) and
    counts its long springs (a reduction, which stays a vector loop); only a run with any is
    gone through again to mark them (listed (>= S, a multiple of 8) uint8 and listed_words, the
    same memory as uint64; their geo in geo_s (S, 4); both by model index); the list is then
    made in the model's order -- the order the velocity modification goes through them
    (measured: listed in the runs' order instead, the drapes changed enough for default:female's
    M dress at 3 cm to end 6.05 % stretched, reported tight, where it ended at 5.93 % before;
    in model order 5.94 %, in as many iterations as before).

    With the list come each listed spring's ends (ends (>= S, 2) int32: springs_m, the model's
    springs, at the listed ones; what the strain limit's passes read, _modify_passes) and the
    listed springs near the strain guard's length (near (>= S,) int32: their places in the list;
    their excess past the listing length more than near_frac x that length; K.guard_listed
    measures them again). Returns (listed, near).

    The springs are computed in the precision of soa (with tmp, lengths, f_slow and sprops
    alike; one and tiny as 1 and 1e-30 of it): double for the drape, single for the walk
    (ClothSolver.single_precision_forces). Velocities are integrated in double either way."""
    n = x.shape[0]
    xs, ys, zs = soa[0], soa[1], soa[2]
    vx, vy, vz = soa[3], soa[4], soa[5]
    fx, fy, fz = soa[6], soa[7], soa[8]
    for i in range(n):
        xs[i] = x[i, 0]
        ys[i] = x[i, 1]
        zs[i] = x[i, 2]
        vx[i] = v[i, 0]
        vy[i] = v[i, 1]
        vz[i] = v[i, 2]
    rest, k, spring_c, limits = sprops[0], sprops[1], sprops[2], sprops[3]
    tx, ty, tz = tmp[0], tmp[1], tmp[2]
    sx, sy, sz = f_slow[0], f_slow[1], f_slow[2]
    if slow_due:
        for i in range(n):
            sx[i] = 0.0
            sy[i] = 0.0
            sz[i] = 0.0
        for r in range(r_held, runs.shape[0]):
            s0, a0, b0, m = runs[r, 0], runs[r, 1], runs[r, 2], runs[r, 3]
            xa, ya, za = xs[a0:a0 + m], ys[a0:a0 + m], zs[a0:a0 + m]
            xb, yb, zb = xs[b0:b0 + m], ys[b0:b0 + m], zs[b0:b0 + m]
            ua, wa, qa = vx[a0:a0 + m], vy[a0:a0 + m], vz[a0:a0 + m]
            ub, wb, qb = vx[b0:b0 + m], vy[b0:b0 + m], vz[b0:b0 + m]
            r_, k_, c_ = rest[s0:s0 + m], k[s0:s0 + m], spring_c[s0:s0 + m]
            for t in range(m):
                dx = xb[t] - xa[t]
                dy = yb[t] - ya[t]
                dz = zb[t] - za[t]
                c, _ = _axial(dx, dy, dz, ub[t] - ua[t], wb[t] - wa[t], qb[t] - qa[t], r_[t], k_[t], c_[t], one, tiny)
                tx[t] = c * dx
                ty[t] = c * dy
                tz[t] = c * dz
            _scatter_run(sx, sy, sz, tx, ty, tz, a0, b0, m)
        for s in range(n_fast + n_run_slow, sp.shape[0]):
            _single_spring(s, sp, xs, ys, zs, vx, vy, vz, rest, k, spring_c, sx, sy, sz)
    for i in range(n):
        fx[i] = mass[i] * gravity[0] - damping * mass[i] * vx[i] + sx[i]
        fy[i] = mass[i] * gravity[1] - damping * mass[i] * vy[i] + sy[i]
        fz[i] = mass[i] * gravity[2] - damping * mass[i] * vz[i] + sz[i]
    n_act = 0
    for r in range(r_held, r_fast):  # held runs: listed only
        s0, a0, b0, m = runs[r, 0], runs[r, 1], runs[r, 2], runs[r, 3]
        xa, ya, za = xs[a0:a0 + m], ys[a0:a0 + m], zs[a0:a0 + m]
        xb, yb, zb = xs[b0:b0 + m], ys[b0:b0 + m], zs[b0:b0 + m]
        lim_ = limits[s0:s0 + m]
        over = 0
        for t in range(m):
            dx = xb[t] - xa[t]
            dy = yb[t] - ya[t]
            dz = zb[t] - za[t]
            over += dx * dx + dy * dy + dz * dz > lim_[t] * lim_[t]
        if over:
            for t in range(m):
                dx = xb[t] - xa[t]
                dy = yb[t] - ya[t]
                dz = zb[t] - za[t]
                length = np.sqrt(dx * dx + dy * dy + dz * dz)
                if length > lim_[t]:
                    listed[perm[s0 + t]] = _list_mark(length, lim_[t], near_frac)
                    _store_geo(geo_s, perm[s0 + t], dx, dy, dz, length, lim_[t])
                    n_act += 1
    for r in range(r_held):
        s0, a0, b0, m = runs[r, 0], runs[r, 1], runs[r, 2], runs[r, 3]
        xa, ya, za = xs[a0:a0 + m], ys[a0:a0 + m], zs[a0:a0 + m]
        xb, yb, zb = xs[b0:b0 + m], ys[b0:b0 + m], zs[b0:b0 + m]
        ua, wa, qa = vx[a0:a0 + m], vy[a0:a0 + m], vz[a0:a0 + m]
        ub, wb, qb = vx[b0:b0 + m], vy[b0:b0 + m], vz[b0:b0 + m]
        r_, k_, c_, lim_, l_ = rest[s0:s0 + m], k[s0:s0 + m], spring_c[s0:s0 + m], limits[s0:s0 + m], lengths[s0:s0 + m]
        over = 0
        for t in range(m):
            dx = xb[t] - xa[t]
            dy = yb[t] - ya[t]
            dz = zb[t] - za[t]
            c, length = _axial(dx, dy, dz, ub[t] - ua[t], wb[t] - wa[t], qb[t] - qa[t], r_[t], k_[t], c_[t], one, tiny)
            tx[t] = c * dx
            ty[t] = c * dy
            tz[t] = c * dz
            l_[t] = length
            over += length > lim_[t]
        if over:
            for s in range(s0, s0 + m):
                if lengths[s] > limits[s]:
                    a = sp[s, 0]
                    b = sp[s, 1]
                    listed[perm[s]] = _list_mark(lengths[s], limits[s], near_frac)
                    _store_geo(geo_s, perm[s], xs[b] - xs[a], ys[b] - ys[a], zs[b] - zs[a], lengths[s], limits[s])
                    n_act += 1
        _scatter_run(fx, fy, fz, tx, ty, tz, a0, b0, m)
    for s in range(n_run, n_fast):
        length, dx, dy, dz = _single_spring(s, sp, xs, ys, zs, vx, vy, vz, rest, k, spring_c, fx, fy, fz)
        if length > 1e-12 and length > limits[s]:
            listed[perm[s]] = _list_mark(length, limits[s], near_frac)
            _store_geo(geo_s, perm[s], dx, dy, dz, length, limits[s])
            n_act += 1
    # the list in the model's spring order (the velocity modification's Gauss-Seidel order)
    n_list = 0
    n_near = 0
    if n_act:
        for w in range(listed_words.shape[0]):  # eight marks at a time: most words are 0
            if listed_words[w]:
                for s in range(8 * w, 8 * w + 8):
                    if listed[s]:
                        if listed[s] == 2:
                            near[n_near] = n_list
                            n_near += 1
                        listed[s] = 0
                        work[n_list] = s
                        ends[n_list, 0] = springs_m[s, 0]
                        ends[n_list, 1] = springs_m[s, 1]
                        for c in range(4):
                            geo[n_list, c] = geo_s[s, c]
                        n_list += 1
    keep_f = f_out.shape[0] > 0
    for i in range(n):
        fx_, fy_, fz_ = fx[i], fy[i], fz[i]
        if contact[i]:
            nx, ny, nz = contact_n[i, 0], contact_n[i, 1], contact_n[i, 2]
            fn = fx_ * nx + fy_ * ny + fz_ * nz
            if fn < 0.0:  # pushing into the body: the body pushes back (eq. 16, -f_n)
                tx_, ty_, tz_ = fx_ - fn * nx, fy_ - fn * ny, fz_ - fn * nz
                ft = np.sqrt(tx_ * tx_ + ty_ * ty_ + tz_ * tz_)
                # friction: -C_fric f_t with C_fric = min(1, mu |f_n| / |f_t|) (Coulomb)
                scale = 0.0
                if ft > 1e-20:
                    scale = max(0.0, 1.0 - mu * (-fn) / ft)
                fx_, fy_, fz_ = tx_ * scale, ty_ * scale, tz_ * scale
        if keep_f:
            f_out[i, 0] = fx_
            f_out[i, 1] = fy_
            f_out[i, 2] = fz_
        w = dt * inv_mass[i]
        v[i, 0] += w * fx_
        v[i, 1] += w * fy_
        v[i, 2] += w * fz_
    return n_act, n_near


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
    is measured along z (seed 003 §5.3), so there by -(n . m) / |n_z| (capped at 1 / MIN_NZ).
    Measured on the trousers (default:female, first 0.5 s), points carried as contacts that the
    maps had clear: 13 a step carried as a distance, 8 so; the male trousers then settled in
    10.7k iterations, where they had not settled in the 6 s budget."""
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


@njit(fastmath=True, cache=True, inline="always")
def _store_geo(geo, k, dx, dy, dz, length, limit):
    """geo[k] = the spring's direction (dx, dy, dz) / length and its excess length - limit."""
    geo[k, 0] = dx / length
    geo[k, 1] = dy / length
    geo[k, 2] = dz / length
    geo[k, 3] = length - limit


@njit(fastmath=True, cache=True, inline="always")
def _spring_geo(x, a, b, limit, geo, k):
    """If spring a-b is longer than `limit`, store its direction and excess in geo[k] (ux, uy,
    uz, length - limit) and return True. Positions do not move during a step's velocity
    modification, so its passes read this instead of measuring the spring again."""
    dx = x[b, 0] - x[a, 0]
    dy = x[b, 1] - x[a, 1]
    dz = x[b, 2] - x[a, 2]
    length = np.sqrt(dx * dx + dy * dy + dz * dz)
    if length <= limit or length < 1e-12:
        return False
    _store_geo(geo, k, dx, dy, dz, length, limit)
    return True


@njit(fastmath=True, cache=True, inline="always")
def _modify_one(v, a, b, geo, k, mode, gravity, dt, body_v, recover):
    """One over-elongated spring (a, b; its direction and excess in geo[k], see _spring_geo) of
    the velocity modification; returns True if it changed velocities.
    Beyond the seeds, a spring already past the limit by e is also given a closing speed
    e / recover (recover: a time, shared by its ends), so strain that got in anyway (sewing, the
    body pushing cloth outward) is worked off instead of only frozen."""
    ux, uy, uz = geo[k, 0], geo[k, 1], geo[k, 2]
    close = geo[k, 3] / recover  # wanted closing speed
    va = v[a, 0] * ux + v[a, 1] * uy + v[a, 2] * uz
    vb = v[b, 0] * ux + v[b, 1] * uy + v[b, 2] * uz
    if vb - va <= -close + 1e-9:  # already shortening fast enough: leave it
        return False
    if mode == VM_ZERO:
        na, nb = 0.5 * close, -0.5 * close
    elif mode == VM_DIRECTIONAL:
        lim2 = DIR_MIN_OBJECT_SPEED ** 2
        dragged_a = body_v[a, 0] ** 2 + body_v[a, 1] ** 2 + body_v[a, 2] ** 2 >= lim2
        dragged_b = body_v[b, 0] ** 2 + body_v[b, 1] ** 2 + body_v[b, 2] ** 2 >= lim2
        if dragged_a and dragged_b:
            gx = gravity[0] * dt + 0.5 * (body_v[a, 0] + body_v[b, 0])
            gy = gravity[1] * dt + 0.5 * (body_v[a, 1] + body_v[b, 1])
            gz = gravity[2] * dt + 0.5 * (body_v[a, 2] + body_v[b, 2])
            gl = np.sqrt(gx * gx + gy * gy + gz * gz)
            cos = (gx * ux + gy * uy + gz * uz) / gl
        elif dragged_a:  # the free end follows the dragged one
            cos = -1.0
        elif dragged_b:
            cos = 1.0
        else:
            cos = 0.0
        if abs(cos) < 0.3:
            avg = 0.5 * (va + vb)
            na, nb = avg + 0.5 * close, avg - 0.5 * close
        elif cos > 0.0:  # p2 = b is ahead along v_dir: the rear a catches up
            na, nb = vb + close, vb
        else:
            na, nb = va, va - close
    else:  # VM_AVERAGE (and the velocity part of Provot's, which then moves positions)
        avg = 0.5 * (va + vb)
        na, nb = avg + 0.5 * close, avg - 0.5 * close
    v[a, 0] += (na - va) * ux
    v[a, 1] += (na - va) * uy
    v[a, 2] += (na - va) * uz
    v[b, 0] += (nb - vb) * ux
    v[b, 1] += (nb - vb) * uy
    v[b, 2] += (nb - vb) * uz
    return True


@serial_kernel
def modify_velocities(x, v, springs, rest, active, threshold, mode, gravity, dt, body_v, passes, work, geo,
                      ends, recover, n_known=-1):
    """Velocity modification against super-elasticity, after each step. For a spring longer
    than (1 + threshold) x rest whose ends move apart, the stretching (along-spring) velocity
    components v1t, v2t are changed:
      VM_ZERO (seed 003 §4.3): both set to zero;
      VM_AVERAGE (seed 000 eq. 5): both set to their average;
      VM_DIRECTIONAL (seed 000 eq. 6 + §3.2 rules): v_dir = g dt + v_object; if the spring is
        about perpendicular to v_dir (|cos| < 0.3) use eq. 5, else the rear point (along v_dir)
        takes the front point's component so it catches up -- where the body drags both ends;
        with one end dragged the free end catches up; with none, eq. 5 (DIR_MIN_OBJECT_SPEED).
    One Gauss-Seidel sweep over all springs collects the over-elongated ones into `work`
    (int32, len >= S); the remaining passes sweep only those, so many passes stay cheap --
    they are needed when a whole region is stretched at once (a waistband pushed out by the
    hips), where each spring's change undoes part of its neighbours'.
    n_known >= 0: positions have not moved since the call that found n_known over-elongated
    springs in `work`, so the full sweep is skipped (later rounds of the same step).
    Returns the number of over-elongated springs.
    geo (S, 4): the listed springs' directions and excesses (_spring_geo), and ends (S, 2)
    int32 their ends, written by the sweep (or by eval_forces_and_integrate, whose list n_known
    is): the passes read the ends from this small array instead of from springs[work[k]] --
    rows of the whole spring array, a cache line apart (measured on four captured walking steps
    of the dress, 693-1,102 springs listed, six passes, 2,000 interleaved calls each: 0.78-0.79
    x the time, the same velocities bit for bit)."""
    n_act = n_known
    if n_known < 0:
        n_act = 0
        for s in range(springs.shape[0]):
            if active[s] and _spring_geo(x, springs[s, 0], springs[s, 1], (1.0 + threshold) * rest[s], geo, n_act):
                work[n_act] = s
                ends[n_act, 0] = springs[s, 0]
                ends[n_act, 1] = springs[s, 1]
                _modify_one(v, springs[s, 0], springs[s, 1], geo, n_act, mode, gravity, dt, body_v, recover)
                n_act += 1
        passes -= 1
    _modify_passes(v, ends, geo, n_act, mode, gravity, dt, body_v, passes, recover)
    return n_act


@njit(fastmath=True, cache=True, inline="always")
def _modify_passes(v, ab, geo, n_act, mode, gravity, dt, body_v, passes, recover):
    """Up to `passes` Gauss-Seidel passes over the n_act listed springs (their ends in ab),
    until one changes nothing."""
    for _ in range(passes):
        changed = 0
        for k in range(n_act):
            if _modify_one(v, ab[k, 0], ab[k, 1], geo, k, mode, gravity, dt, body_v, recover):
                changed += 1
        if changed == 0:
            break


@njit(fastmath=True, cache=True, inline="always")
def outward_only(px, py, pz, i, contact, contact_n):
    """A move (px, py, pz) of vertex i without its part into the body: where i touches the body
    and the move points inward along the contact normal, that part is dropped."""
    if contact[i]:
        nx, ny, nz = contact_n[i, 0], contact_n[i, 1], contact_n[i, 2]
        pn = px * nx + py * ny + pz * nz
        if pn < 0.0:
            return px - pn * nx, py - pn * ny, pz - pn * nz
    return px, py, pz


@njit(fastmath=True, cache=True, inline="always")
def _project_one(x, a, b, lmax, inv_mass, keep_out, contact, contact_n, max_move):
    """Move a and b toward each other (mass-weighted) back to length lmax, shortening the spring
    by at most max_move. keep_out: an end touching the body is not moved into it
    (outward_only), so the spring may stay a little long."""
    dx = x[b, 0] - x[a, 0]
    dy = x[b, 1] - x[a, 1]
    dz = x[b, 2] - x[a, 2]
    length = np.sqrt(dx * dx + dy * dy + dz * dz)
    if length <= lmax or length < 1e-12:
        return False
    wa, wb = inv_mass[a], inv_mass[b]
    corr = min(length - lmax, max_move) / (length * (wa + wb))
    ax, ay, az = wa * corr * dx, wa * corr * dy, wa * corr * dz
    bx, by, bz = -wb * corr * dx, -wb * corr * dy, -wb * corr * dz
    if keep_out:
        ax, ay, az = outward_only(ax, ay, az, a, contact, contact_n)
        bx, by, bz = outward_only(bx, by, bz, b, contact, contact_n)
    x[a, 0] += ax
    x[a, 1] += ay
    x[a, 2] += az
    x[b, 0] += bx
    x[b, 1] += by
    x[b, 2] += bz
    return True


@serial_kernel
def provot_positions(x, springs, rest, active, threshold, inv_mass, passes, work, keep_out, contact, contact_n,
                     max_move=np.inf):
    """Provot (1995) position modification: move the ends of springs longer than
    (1 + threshold) x rest toward each other (mass-weighted) back to that length. One sweep
    finds them (into `work`), further passes revisit only those. Used as the comparison mode
    and, with a slightly larger threshold, as the strain guard behind the velocity modification
    (keep_out: the guard never pulls cloth into the body -- see _project_one).
    Returns the number of springs found over the limit."""
    n_act = 0
    for s in range(springs.shape[0]):
        if active[s] and _project_one(x, springs[s, 0], springs[s, 1], (1.0 + threshold) * rest[s], inv_mass,
                                          keep_out, contact, contact_n, max_move):
            work[n_act] = s
            n_act += 1
    _project_passes(x, springs, rest, threshold, inv_mass, passes - 1, work, n_act, keep_out, contact, contact_n,
                    max_move)
    return n_act


@njit(fastmath=True, cache=True, inline="always")
def _project_passes(x, springs, rest, threshold, inv_mass, passes, work, n_act, keep_out, contact, contact_n,
                    max_move):
    """Up to `passes` passes of _project_one over the springs work[:n_act], until one moves nothing."""
    for _ in range(passes):
        changed = 0
        for k in range(n_act):
            s = work[k]
            if _project_one(x, springs[s, 0], springs[s, 1], (1.0 + threshold) * rest[s], inv_mass,
                            keep_out, contact, contact_n, max_move):
                changed += 1
        if changed == 0:
            break


@serial_kernel
def guard_positions(x, v, springs, rest, active, threshold, inv_mass, passes, work, contact, contact_n, max_move,
                    perm, runs, run_springs, n_run, lim2, soa, flags, flag_words, adj_ptr, adj_spring,
                    x_before, saved, saved_list):
    """The strain guard: provot_positions(..., keep_out=True, max_move) followed by
    inelastic_guard, giving the same positions and velocities bit for bit, without going
    through every spring one by one.
    A vector pass over the force pass's runs (engine.cloth.model.SpringRuns: perm, runs,
    run_springs, n_run; positions copied into soa rows 0-2) flags the springs whose squared
    length passes lim2 (run order: a hair below ((1 + threshold) rest)^2, inf for springs the
    strain limit leaves alone) -- a superset of those provot_positions' sweep finds long before
    it moves anything. The sweep then goes, in the model's order, through the flagged springs
    only: a spring not flagged is not long, and stays so until one of its ends moves, so a
    projection flags the later springs at both of its ends (adj_ptr, adj_spring: the model's
    CSR adjacency). The points it moves have their positions saved first (x_before, saved,
    saved_list), and the inelastic guard runs over those points only.
    flags: uint8, length a multiple of 8, zero on entry and on return (flag_words: the same
    memory as uint64); saved: uint8 (N,), zero on entry and on return.
    Returns the number of springs found over the limit (as provot_positions)."""
    n = x.shape[0]
    xs, ys, zs = soa[0], soa[1], soa[2]
    for i in range(n):
        xs[i] = x[i, 0]
        ys[i] = x[i, 1]
        zs[i] = x[i, 2]
    any_long = False
    for r in range(runs.shape[0]):
        s0, a0, b0, m = runs[r, 0], runs[r, 1], runs[r, 2], runs[r, 3]
        xa, ya, za = xs[a0:a0 + m], ys[a0:a0 + m], zs[a0:a0 + m]
        xb, yb, zb = xs[b0:b0 + m], ys[b0:b0 + m], zs[b0:b0 + m]
        g = lim2[s0:s0 + m]
        over = 0
        for t in range(m):
            dx = xb[t] - xa[t]
            dy = yb[t] - ya[t]
            dz = zb[t] - za[t]
            over += dx * dx + dy * dy + dz * dz > g[t]
        if over:
            any_long = True
            for t in range(m):
                dx = xb[t] - xa[t]
                dy = yb[t] - ya[t]
                dz = zb[t] - za[t]
                if dx * dx + dy * dy + dz * dz > g[t]:
                    flags[perm[s0 + t]] = 1
    for s in range(n_run, run_springs.shape[0]):
        a = run_springs[s, 0]
        b = run_springs[s, 1]
        dx = xs[b] - xs[a]
        dy = ys[b] - ys[a]
        dz = zs[b] - zs[a]
        if dx * dx + dy * dy + dz * dz > lim2[s]:
            flags[perm[s]] = 1
            any_long = True
    if not any_long:
        return 0
    n_act, n_saved = _guard_sweep(x, springs, rest, active, threshold, inv_mass, passes, work, contact, contact_n,
                                  max_move, flags, flag_words, adj_ptr, adj_spring, x_before, saved, saved_list)
    _guard_release(x, x_before, v, saved, saved_list, n_saved, n_act)
    return n_act


@njit(fastmath=True, cache=True, inline="always")
def _guard_sweep(x, springs, rest, active, threshold, inv_mass, passes, work, contact, contact_n, max_move,
                 flags, flag_words, adj_ptr, adj_spring, x_before, saved, saved_list):
    """The strain guard's projections (guard_positions) over the flagged springs (flags, a
    superset of the long ones), in the model's order; a projection flags the later springs at
    both of its ends. Saves the positions of the points it moves (x_before; saved, saved_list)
    and clears the flags. Returns (springs projected -- listed in work --, points saved)."""
    n_act = 0
    n_saved = 0
    n_springs = springs.shape[0]
    for w in range(flag_words.shape[0]):
        if flag_words[w] == 0:
            continue
        for s in range(8 * w, min(8 * w + 8, n_springs)):
            if not flags[s]:
                continue
            flags[s] = 0
            if not active[s]:
                continue
            a = springs[s, 0]
            b = springs[s, 1]
            for e in (a, b):
                if not saved[e]:
                    saved[e] = 1
                    saved_list[n_saved] = e
                    n_saved += 1
                    for c in range(3):
                        x_before[e, c] = x[e, c]
            if _project_one(x, a, b, (1.0 + threshold) * rest[s], inv_mass, True, contact, contact_n, max_move):
                work[n_act] = s
                n_act += 1
                for e in (a, b):
                    for k in range(adj_ptr[e], adj_ptr[e + 1]):
                        j = adj_spring[k]
                        if j > s:
                            flags[j] = 1
    _project_passes(x, springs, rest, threshold, inv_mass, passes - 1, work, n_act, True, contact, contact_n,
                    max_move)
    return n_act, n_saved


@njit(fastmath=True, cache=True, inline="always")
def _guard_release(x, x_before, v, saved, saved_list, n_saved, n_act):
    """After _guard_sweep: clear the saved marks and, if anything was projected, the inelastic
    guard on the saved points."""
    for k in range(n_saved):
        i = saved_list[k]
        saved[i] = 0
        if n_act:
            _inelastic_one(x, x_before, v, i)


@serial_kernel
def guard_listed(x, v, springs, rest, active, threshold, inv_mass, passes, work, contact, contact_n, max_move,
                 flags, flag_words, adj_ptr, adj_spring, x_before, saved, saved_list,
                 listed, listed_geo, listed_ends, n_listed, near, n_near, lim2, listed_threshold):
    """The strain guard of guard_positions (the same projections and inelastic guard, bit for
    bit, on the same positions) found from a list instead of a pass over every spring: the
    springs the force pass listed for the velocity modification (listed[:n_listed], their
    excess over the listing length, (1 + listed_threshold) rest, in listed_geo[:, 3], their
    ends in listed_ends; see eval_forces_and_integrate). Those it found near the guard's length
    (near[:n_near], places in the list: past the listing length by more than half the guard's
    excess, far above the error of the list's single precision lengths) are measured in double
    and flagged past lim2 (by model index: a hair below ((1 + threshold) rest)^2, as
    guard_positions flags). Then the listed springs at the points the guard looked at are
    measured again (listed_geo, in double; one no longer long gets an excess of -1e30, which
    the velocity modification leaves alone).
    For a step that guards right after its force pass (ClothSolver.late_guard). `work` gets
    the projected springs: it must not be `listed`. Returns the number projected."""
    any_long = False
    for c in range(n_near):
        k = near[c]
        s = listed[k]
        a = listed_ends[k, 0]
        b = listed_ends[k, 1]
        dx = x[b, 0] - x[a, 0]
        dy = x[b, 1] - x[a, 1]
        dz = x[b, 2] - x[a, 2]
        if dx * dx + dy * dy + dz * dz > lim2[s]:
            flags[s] = 1
            any_long = True
    if not any_long:
        return 0
    n_act, n_saved = _guard_sweep(x, springs, rest, active, threshold, inv_mass, passes, work, contact, contact_n,
                                  max_move, flags, flag_words, adj_ptr, adj_spring, x_before, saved, saved_list)
    if n_act:
        for k in range(n_listed):
            a = listed_ends[k, 0]
            b = listed_ends[k, 1]
            if saved[a] or saved[b]:
                if not _spring_geo(x, a, b, (1.0 + listed_threshold) * rest[listed[k]], listed_geo, k):
                    listed_geo[k, 3] = -1e30
    _guard_release(x, x_before, v, saved, saved_list, n_saved, n_act)
    return n_act


@njit(fastmath=True, cache=True, inline="always")
def _inelastic_one(x, x_before, v, i):
    """inelastic_guard for vertex i; True if its velocity changed."""
    dx = x[i, 0] - x_before[i, 0]
    dy = x[i, 1] - x_before[i, 1]
    dz = x[i, 2] - x_before[i, 2]
    dd = dx * dx + dy * dy + dz * dz
    if dd > 0.0:
        vd = v[i, 0] * dx + v[i, 1] * dy + v[i, 2] * dz
        if vd < 0.0:
            c = vd / dd
            v[i, 0] -= c * dx
            v[i, 1] -= c * dy
            v[i, 2] -= c * dz
            return True
    return False


@serial_kernel
def inelastic_guard(x, x_before, v):
    """After the strain guard moved positions (x_before -> x): each moved vertex loses the part
    of its velocity that points back against its move (v <- v - min(0, v.d) d / |d|^2, d its
    move), as an inelastic constraint would -- the guard's springs stop being stretched again
    by that velocity next step. Without it a vertex the guard held kept a velocity the guard
    took back every step (measured: 0.5-0.7 m/s at default:female's armpits), FIRE's power
    stayed positive and the drape swayed on: the 3 cm dress settled after 17.3k steps instead
    of 1.3k. Returns the number of vertices whose velocity changed."""
    n = 0
    for i in range(x.shape[0]):
        n += _inelastic_one(x, x_before, v, i)
    return n


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
    loop (measured on the dress, 9.2k points: 38 instead of 69 us, median of interleaved runs,
    against one loop asking _point_mean for x and v at every point)."""
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


@serial_kernel
def hold_and_integrate(x, v, dt, contact, contact_n, body_v):
    """hold_contacts, then integrate_positions, in one pass over the vertices (the same
    arithmetic: each vertex's velocity is held before its position moves)."""
    for i in range(x.shape[0]):
        if contact[i]:
            _hold_one(v, i, contact_n, body_v)
        x[i, 0] += dt * v[i, 0]
        x[i, 1] += dt * v[i, 1]
        x[i, 2] += dt * v[i, 2]


@serial_kernel
def integrate_positions(x, v, dt):
    """The position half of eq. 3: p += dt v."""
    for i in range(x.shape[0]):
        x[i, 0] += dt * v[i, 0]
        x[i, 1] += dt * v[i, 1]
        x[i, 2] += dt * v[i, 2]


@serial_kernel
def kinetic_energy(v, mass):
    e = 0.0
    for i in range(v.shape[0]):
        e += 0.5 * mass[i] * (v[i, 0] ** 2 + v[i, 1] ** 2 + v[i, 2] ** 2)
    return e


@serial_kernel
def max_strain(x, springs, rest, active):
    """Largest strain (length / rest - 1) over the springs, inactive ones counting as 0; 0 when
    there are none."""
    best = -np.inf
    for s in range(springs.shape[0]):
        strain = 0.0
        if active[s]:
            a = springs[s, 0]
            b = springs[s, 1]
            d = np.sqrt((x[b, 0] - x[a, 0]) ** 2 + (x[b, 1] - x[a, 1]) ** 2 + (x[b, 2] - x[a, 2]) ** 2)
            strain = d / rest[s] - 1.0
        best = max(best, strain)
    return best if best > -np.inf else 0.0


@serial_kernel
def fire_mix(f, v, x, dt, alpha):
    """One FIRE velocity step after a solver step (see engine.cloth.solver.FireRelaxer): the
    power P = sum f.v; when P > 0, v <- (1 - alpha) v + alpha |v| f / |f| (all vertices as one
    vector), else the positions go back half the step just taken (x -= dt v / 2, FIRE 2.0) and
    every velocity is zeroed. Returns P."""
    p = 0.0
    vv = 0.0
    ff = 0.0
    for i in range(v.shape[0]):
        for c in range(3):
            p += f[i, c] * v[i, c]
            vv += v[i, c] * v[i, c]
            ff += f[i, c] * f[i, c]
    if p > 0.0:
        if ff > 0.0:
            a = 1.0 - alpha
            b = alpha * np.sqrt(vv / ff)
            for i in range(v.shape[0]):
                for c in range(3):
                    v[i, c] = a * v[i, c] + b * f[i, c]
    else:
        h = 0.5 * dt
        for i in range(v.shape[0]):
            for c in range(3):
                x[i, c] -= h * v[i, c]
                v[i, c] = 0.0
    return p
