"""Integration of a cloth step (the position half of seed 003 eq. 3), with FIRE's velocity mix
for the drape and the energy measures. NumPy/numba only."""

from __future__ import annotations

import numpy as np

from engine.cloth.kernels_contact import _hold_one
from engine.jit import serial_kernel


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
def fire_mix(f, v, x, dt, alpha, skip):
    """One FIRE velocity step after a solver step (see engine.cloth.solver.FireRelaxer): the
    power P = sum f.v over the vertices not `skip`ped (N,) bool; when P > 0, v <- (1 - alpha) v
    + alpha |v| f / |f| (all vertices as one vector), else the positions go back half the step
    just taken (x -= dt v / 2, FIRE 2.0) and every velocity is zeroed. Returns P."""
    p = 0.0
    vv = 0.0
    ff = 0.0
    for i in range(v.shape[0]):
        for c in range(3):
            if not skip[i]:
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


@serial_kernel
def fire_mix_free(f, v, x, dt, alpha, skip, free):
    """fire_mix over the vertices not `free` (N,) bool alone: their power decides, their velocities
    turn or stop; the free ones move on as the solver left them (cloth let fall, drape's
    stand_out). Apart from fire_mix, not fire_mix with a mask: the mask's test changes how the
    compiled loops sum, and every drape on the edge of chaos would change with it."""
    p = 0.0
    vv = 0.0
    ff = 0.0
    for i in range(v.shape[0]):
        if free[i]:
            continue
        for c in range(3):
            if not skip[i]:
                p += f[i, c] * v[i, c]
            vv += v[i, c] * v[i, c]
            ff += f[i, c] * f[i, c]
    if p > 0.0:
        if ff > 0.0:
            a = 1.0 - alpha
            b = alpha * np.sqrt(vv / ff)
            for i in range(v.shape[0]):
                if not free[i]:
                    for c in range(3):
                        v[i, c] = a * v[i, c] + b * f[i, c]
    else:
        h = 0.5 * dt
        for i in range(v.shape[0]):
            if not free[i]:
                for c in range(3):
                    x[i, c] -= h * v[i, c]
                    v[i, c] = 0.0
    return p
