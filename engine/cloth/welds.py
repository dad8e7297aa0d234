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
def pull_seams(x, v, mass, pairs, welded, tau, vmax, contact, contact_n, meet, meet_on):
    """Sewing as a velocity modification (in the spirit of seed 003 §4.3): each open seam pair
    gets the relative velocity that closes its gap in time tau (at most vmax), shared so the
    pair's momentum is unchanged. A seam end lying on the body is not pulled into it: the part
    of its pull along the contact normal, if inward, is dropped, so pairs on either side of a
    shoulder slide over it instead of pressing into it. Welded pairs are held by hold_welds.
    A pair whose straight path runs through the body (meet_on[k]: the scene found its midpoint
    inside) has each end pulled instead toward meet[k], a point just outside the body on the side
    its edges lie on (engine.scene.drape._meet_beside): straddling a leg or a shoulder, the ends
    go round it to that side instead of pressing into it from both sides."""
    for k in range(pairs.shape[0]):
        if welded[k]:
            continue
        a, b = pairs[k, 0], pairs[k, 1]
        if meet_on[k]:
            for end in (a, b):
                dx = meet[k, 0] - x[end, 0]
                dy = meet[k, 1] - x[end, 1]
                dz = meet[k, 2] - x[end, 2]
                d = np.sqrt(dx * dx + dy * dy + dz * dz)
                if d < 1e-12:
                    continue
                ux, uy, uz = dx / d, dy / d, dz / d
                speed = min(d / tau, vmax)
                along = v[end, 0] * ux + v[end, 1] * uy + v[end, 2] * uz
                if along >= speed:
                    continue
                dv = speed - along
                px, py, pz = outward_only(dv * ux, dv * uy, dv * uz, end, contact, contact_n)
                v[end, 0] += px
                v[end, 1] += py
                v[end, 2] += pz
            continue
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


@serial_kernel(fastmath=False)
def damp_about_panels(v, mass, panel, n_panels, keep):
    """Each vertex's velocity relative to its panel's mass-weighted mean velocity scaled by keep
    (0..1): the panel's own motion is not damped, its flapping is."""
    mv = np.zeros((n_panels, 3))
    m = np.zeros(n_panels)
    for i in range(v.shape[0]):
        p = panel[i]
        m[p] += mass[i]
        for c in range(3):
            mv[p, c] += mass[i] * v[i, c]
    for p in range(n_panels):
        if m[p] > 0.0:
            for c in range(3):
                mv[p, c] /= m[p]
    for i in range(v.shape[0]):
        p = panel[i]
        for c in range(3):
            v[i, c] = mv[p, c] + keep * (v[i, c] - mv[p, c])


@serial_kernel(fastmath=False)
def hold_on_planes(x, v, idx, points, normals, tau, vmax):
    """Attachment (GarmentCode's simulator keeps some edges from sliding while sewing): each
    vertex idx[k] is kept on the side of the plane through points[k] that normals[k] points to.
    Its velocity along the normal is at least -d / tau[k] (d: its distance in front of the
    plane; behind it, d < 0, that brings it back, at most vmax[k] fast), so it eases onto the
    plane instead of crossing it; any velocity away from the plane, and along it, is kept."""
    for k in range(idx.shape[0]):
        i = idx[k]
        nx, ny, nz = normals[k, 0], normals[k, 1], normals[k, 2]
        d = (x[i, 0] - points[k, 0]) * nx + (x[i, 1] - points[k, 1]) * ny + (x[i, 2] - points[k, 2]) * nz
        want = min(-d / tau[k], vmax[k])
        vn = v[i, 0] * nx + v[i, 1] * ny + v[i, 2] * nz
        if vn < want:
            v[i, 0] += (want - vn) * nx
            v[i, 1] += (want - vn) * ny
            v[i, 2] += (want - vn) * nz


@serial_kernel
def rest_on_floor(x, v, y0, dt, mu, vmax):
    """The ground (Control.floor): a vertex that would end the step below the height y0 has its
    downward velocity cut to what reaches y0 (one below it -- a layout that put a hem under the
    feet -- comes back up at most vmax fast), and its velocity along the ground reduced by mu x
    that change (Coulomb friction on the impulse): a hem longer than the body is tall lies on
    the floor instead of hanging through it."""
    for i in range(x.shape[0]):
        want = min((y0 - x[i, 1]) / dt, vmax)
        if v[i, 1] < want:
            dv = want - v[i, 1]
            v[i, 1] = want
            h = np.sqrt(v[i, 0] * v[i, 0] + v[i, 2] * v[i, 2])
            if h > 0.0:
                keep = max(0.0, 1.0 - mu * dv / h)
                v[i, 0] *= keep
                v[i, 2] *= keep
