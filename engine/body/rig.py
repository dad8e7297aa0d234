"""Linear-blend skinning with a `Rig` (NumPy reference version).

`skin(rest_vertices, rig, joint_world_transforms)` poses a body: every joint j moves its vertices
by M_j = G_j @ inverse(R_j), where R_j = rig.rest_transforms[j] and G_j the joint's posed world
transform (both (4, 4), world frame), and a vertex takes the weighted blend of its joints' M_j.
With G = R (the rest pose) it returns the rest vertices. The walking stage will replace this with
a numba kernel; this one is the readable reference the tests compare against.
"""

from __future__ import annotations

import numpy as np

from engine.body.types import Rig


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
