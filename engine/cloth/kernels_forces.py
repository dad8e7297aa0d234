"""The force pass of a cloth step (seed 003 §3, seed 000 eq. 16): springs, gravity, damping,
the reaction force, and the velocity half of eq. 3, in one kernel. NumPy/numba only.

Arrays: x, v (N, 3) float64; springs in engine.cloth.model.SpringRuns' order.
"""

from __future__ import annotations

import numpy as np

from engine.cloth.kernels_strain import _store_geo
from engine.jit import njit, serial_kernel


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
    half of eq. 3: v += dt f / m. f_out keeps the force for FIRE (0 rows: not kept).

    The springs come in the order of engine.cloth.model.SpringRuns (sp, perm, runs, n_run;
    sprops (4, S): rest length, stiffness, damping and the listing length -- inf for a spring
    the strain limit leaves alone). Most lie in runs (a0 + t, b0 + t), t < L -- a row of the
    grid against the next -- so positions and velocities are copied into soa (9, N: x, y, z,
    vx, vy, vz, fx, fy, fz) and each run is one loop over contiguous slices, which LLVM turns
    into vector instructions; a run's forces go to tmp (3, >= longest run) first and are then
    added to both ends' rows (adding to both in one loop would make each iteration depend on
    the last when b0 - a0 is small). The springs outside runs are done one by one.

    The slow group (runs[r_fast:], springs from n_fast on: the flexion springs) is evaluated
    only when slow_due; its forces go to f_slow (3, N), added in every step as last evaluated
    (multiple time stepping). So are the forces of the fast group's held runs
    (runs[r_held:r_fast]; the walk's shear springs), which are still listed every step.

    The pass lists the springs longer than their listing length for the velocity modification
    that follows (positions do not move in between): their model indices in `work`, directions
    and excesses in `geo` (_store_geo), ends in `ends` (springs_m at them), in the model's
    order -- the velocity modification's Gauss-Seidel order. A run keeps its lengths in
    `lengths` and counts its long springs; only a run with any is gone through again to mark
    them (listed, a multiple of 8 uint8, and listed_words, the same memory as uint64; geo_s by
    model index). Listed springs past the listing length by more than near_frac x that length
    are near the strain guard's length: their places in the list go to `near` (guard_listed
    measures them again). Returns (listed, near).

    The springs are computed in the precision of soa (tmp, lengths, f_slow and sprops alike;
    one and tiny: 1 and 1e-30 in it): double for the drape, single for the walk. Velocities are
    integrated in double either way."""
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
