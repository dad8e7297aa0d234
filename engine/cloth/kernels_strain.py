"""Strain limiting of a cloth step: the velocity modification against super-elasticity (seed
003 §4.3, seed 000 eq. 5/6), Provot's position modification, and the strain guard behind them.
NumPy/numba only.

Arrays: x, v (N, 3) float64; springs (S, 2) int32 with rest lengths (S,); active (S,) bool: the
springs the strain limit applies to (not the flexion springs).
"""

from __future__ import annotations

import numpy as np

from engine.jit import njit, serial_kernel

VM_ZERO, VM_AVERAGE, VM_DIRECTIONAL, VM_PROVOT = 0, 1, 2, 3
VM_MODES = {"zero": VM_ZERO, "average": VM_AVERAGE, "directional": VM_DIRECTIONAL, "provot": VM_PROVOT}
# The directional rule (eq. 6) applies to a spring whose ends the body drags (in contact, body
# faster than this): with v_object ~ 0, v_dir is g dt and the rule hands a hanging cloth's weight
# down the chain until a spring stretches without bound, so there eq. 5 holds the weight; with one
# end dragged, the free end catches up with the dragged one.
DIR_MIN_OBJECT_SPEED = 0.05  # m/s


@njit(fastmath=True, cache=True, inline="always")
def _store_geo(geo, k, dx, dy, dz, length, limit):
    """geo[k] = the spring's direction (dx, dy, dz) / length and its excess length - limit."""
    geo[k, 0] = dx / length
    geo[k, 1] = dy / length
    geo[k, 2] = dz / length
    geo[k, 3] = length - limit


@njit(fastmath=True, cache=True, inline="always")
def _spring_vector(x, a, b):
    """Spring a-b's vector from a to b and its length."""
    dx = x[b, 0] - x[a, 0]
    dy = x[b, 1] - x[a, 1]
    dz = x[b, 2] - x[a, 2]
    return dx, dy, dz, np.sqrt(dx * dx + dy * dy + dz * dz)


@njit(fastmath=True, cache=True, inline="always")
def _spring_geo(x, a, b, limit, geo, k):
    """If spring a-b is longer than `limit`, store its direction and excess in geo[k] (ux, uy,
    uz, length - limit) and return True. Positions do not move during a step's velocity
    modification, so its passes read this instead of measuring the spring again."""
    dx, dy, dz, length = _spring_vector(x, a, b)
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
    is): the passes read the ends from this small array, not from rows of the whole spring
    array a cache line apart."""
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
    dx, dy, dz, length = _spring_vector(x, a, b)
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
    took back every step, FIRE's power stayed positive and the drape swayed on. Returns the
    number of vertices whose velocity changed."""
    n = 0
    for i in range(x.shape[0]):
        n += _inelastic_one(x, x_before, v, i)
    return n


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
