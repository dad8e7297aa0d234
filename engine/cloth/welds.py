"""Seam pairs during sewing: gaps, progressive welding, and the final vertex merge map."""

from __future__ import annotations

import numpy as np
from numba import njit


@njit(cache=True)
def seam_gaps(x, pairs, out):
    for k in range(pairs.shape[0]):
        a, b = pairs[k, 0], pairs[k, 1]
        out[k] = np.sqrt((x[a, 0] - x[b, 0]) ** 2 + (x[a, 1] - x[b, 1]) ** 2 + (x[a, 2] - x[b, 2]) ** 2)
    return out


@njit(cache=True)
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
