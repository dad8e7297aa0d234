"""Linear-blend skinning with a `Rig` (NumPy reference version).

`skin(rest_vertices, rig, joint_world_transforms)` poses a body: every joint j moves its vertices
by M_j = G_j @ inverse(R_j), where R_j = rig.rest_transforms[j] and G_j the joint's posed world
transform (both (4, 4), world frame), and a vertex takes the weighted blend of its joints' M_j.
With G = R (the rest pose) it returns the rest vertices. `skin_fast` is the same in a numba
kernel (the walking stage poses the body every frame); `skin` is the readable reference the
tests compare it against.
"""

from __future__ import annotations

import numpy as np

from engine.body.types import Rig
from engine.jit import serial_kernel


def invert_rigid(transforms: np.ndarray) -> np.ndarray:
    """(..., 4, 4) rigid transforms -> their inverses (R^T, -R^T t)."""
    r = transforms[..., :3, :3]
    t = transforms[..., :3, 3]
    out = np.zeros_like(transforms)
    rt = np.swapaxes(r, -1, -2)
    out[..., :3, :3] = rt
    out[..., :3, 3] = -np.einsum("...ij,...j->...i", rt, t)
    out[..., 3, 3] = 1.0
    return out


def skin(rest_vertices: np.ndarray, rig: Rig, joint_world_transforms: np.ndarray) -> np.ndarray:
    """Pose `rest_vertices` (N, 3) with joint world transforms (J, 4, 4) -> (N, 3) float64.

    rest_vertices are the body's rest-pose vertices (the ones the rig was made for);
    joint_world_transforms are the posed world transforms of the rig's joints, in the same frame
    as rig.rest_transforms.
    """
    g = np.asarray(joint_world_transforms, dtype=np.float64)
    if g.shape != rig.rest_transforms.shape:
        raise ValueError(f"joint transforms must have shape {rig.rest_transforms.shape}, got {g.shape}")
    m = g @ invert_rigid(np.asarray(rig.rest_transforms, dtype=np.float64))  # (J, 4, 4)
    w = np.asarray(rig.skin_weights, dtype=np.float64)  # (N, K)
    blended = np.einsum("nk,nkij->nij", w, m[rig.skin_indices][:, :, :3, :])  # (N, 3, 4)
    v = np.asarray(rest_vertices, dtype=np.float64)
    return np.einsum("nij,nj->ni", blended[:, :, :3], v) + blended[:, :, 3]


def joint_matrices(rig: Rig, joint_world_transforms: np.ndarray) -> np.ndarray:
    """(J, 3, 4) float64 skinning matrices M_j = G_j @ inverse(R_j) (top three rows)."""
    g = np.asarray(joint_world_transforms, dtype=np.float64)
    if g.shape != rig.rest_transforms.shape:
        raise ValueError(f"joint transforms must have shape {rig.rest_transforms.shape}, got {g.shape}")
    return np.ascontiguousarray((g @ invert_rigid(np.asarray(rig.rest_transforms, dtype=np.float64)))[:, :3, :])


def skin_fast(rest_vertices: np.ndarray, rig: Rig, joint_world_transforms: np.ndarray,
              out: np.ndarray | None = None) -> np.ndarray:
    """As `skin`, in a numba kernel; writes into `out` ((N, 3) float64) when given."""
    m = joint_matrices(rig, joint_world_transforms)
    v = np.ascontiguousarray(rest_vertices, dtype=np.float64)
    if out is None:
        out = np.empty_like(v)
    _skin_kernel(v, np.ascontiguousarray(rig.skin_indices, dtype=np.int32),
                 np.ascontiguousarray(rig.skin_weights, dtype=np.float64), m, out)
    return out


@serial_kernel
def _skin_kernel(v, idx, w, m, out):
    for i in range(v.shape[0]):
        x, y, z = v[i, 0], v[i, 1], v[i, 2]
        ox = 0.0
        oy = 0.0
        oz = 0.0
        for k in range(idx.shape[1]):
            wk = w[i, k]
            if wk == 0.0:
                continue
            j = idx[i, k]
            ox += wk * (m[j, 0, 0] * x + m[j, 0, 1] * y + m[j, 0, 2] * z + m[j, 0, 3])
            oy += wk * (m[j, 1, 0] * x + m[j, 1, 1] * y + m[j, 1, 2] * z + m[j, 1, 3])
            oz += wk * (m[j, 2, 0] * x + m[j, 2, 1] * y + m[j, 2, 2] * z + m[j, 2, 3])
        out[i, 0] = ox
        out[i, 1] = oy
        out[i, 2] = oz
