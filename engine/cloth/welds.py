"""Seam pairs during sewing: gaps, progressive welding, and the final vertex merge map."""

from __future__ import annotations

import numpy as np

from engine.cloth.kernels_strain import outward_only
from engine.jit import serial_kernel


@serial_kernel(fastmath=False)
def seam_gaps(x, pairs, out):
    for k in range(pairs.shape[0]):
        a, b = pairs[k, 0], pairs[k, 1]
        out[k] = np.sqrt((x[a, 0] - x[b, 0]) ** 2 + (x[a, 1] - x[b, 1]) ** 2 + (x[a, 2] - x[b, 2]) ** 2)
    return out


@serial_kernel(fastmath=False)
def hold_welds(x, v, mass, pairs, welded):
    """Welded pairs move as one point: mass-weighted mean position and velocity."""
    for k in range(pairs.shape[0]):
        if not welded[k]:
            continue
        a, b = pairs[k, 0], pairs[k, 1]
        wa, wb = mass[a], mass[b]
        w = 1.0 / (wa + wb)
        for c in range(3):
            xm = (wa * x[a, c] + wb * x[b, c]) * w
            vm = (wa * v[a, c] + wb * v[b, c]) * w
            x[a, c] = xm
            x[b, c] = xm
            v[a, c] = vm
            v[b, c] = vm


def merge_map(n: int, pairs: np.ndarray) -> np.ndarray:
    """(n,) new vertex index after merging all pairs (union-find; chains at corners merge too)."""
    parent = np.arange(n)

    def find(i: int) -> int:
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    for a, b in pairs.tolist():
        ra, rb = find(a), find(b)
        if ra != rb:
            parent[max(ra, rb)] = min(ra, rb)
    roots = np.array([find(i) for i in range(n)])
    _, new = np.unique(roots, return_inverse=True)
    return new.astype(np.int64)


@serial_kernel(fastmath=False)
def pull_seams(x, v, mass, pairs, welded, tau, vmax, contact, contact_n):
    """Sewing as a velocity modification (in the spirit of seed 003 §4.3): each open seam pair
    gets the relative velocity that closes its gap in time tau (at most vmax), shared so the
    pair's momentum is unchanged. A seam end lying on the body is not pulled into it: the part
    of its pull along the contact normal, if inward, is dropped, so pairs on either side of a
    shoulder slide over it instead of pressing into it. Welded pairs are held by hold_welds."""
    for k in range(pairs.shape[0]):
        if welded[k]:
            continue
        a, b = pairs[k, 0], pairs[k, 1]
        wa = mass[b] / (mass[a] + mass[b])  # a moves by the other's mass share
        wb = mass[a] / (mass[a] + mass[b])
        dx = x[b, 0] - x[a, 0]
        dy = x[b, 1] - x[a, 1]
        dz = x[b, 2] - x[a, 2]
        gap = np.sqrt(dx * dx + dy * dy + dz * dz)
        if gap < 1e-12:
            continue
        speed = min(gap / tau, vmax)
        ux, uy, uz = dx / gap, dy / gap, dz / gap
        # current closing speed along the gap
        closing = (v[a, 0] - v[b, 0]) * ux + (v[a, 1] - v[b, 1]) * uy + (v[a, 2] - v[b, 2]) * uz
        if closing >= speed:
            continue
        dv = speed - closing
        for end, sgn, w in ((a, 1.0, wa), (b, -1.0, wb)):
            px, py, pz = outward_only(sgn * w * dv * ux, sgn * w * dv * uy, sgn * w * dv * uz, end,
                                      contact, contact_n)
            v[end, 0] += px
            v[end, 1] += py
            v[end, 2] += pz
