"""The body as the engine sees it: a triangle mesh in the world frame of DESIGN.md
(metres, Y up, facing +Z, feet on y = 0, centred on x = z = 0), plus optional rig data."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from engine.jit import serial_kernel

# Segment labels (per vertex, uint8). Order matters: the value is the index.
SEGMENTS = ("head", "torso", "left_arm", "right_arm", "left_leg", "right_leg")
SEGMENT_ID = {name: i for i, name in enumerate(SEGMENTS)}


@dataclass
class Rig:
    """Skeleton and linear-blend-skinning weights of a body in its rest pose.

    joint_names: J names; parents: (J,) int32, -1 for the root;
    rest_transforms: (J, 4, 4) float64 world transforms of the joints in the rest pose
    (world frame of DESIGN.md); skin_indices / skin_weights: (N, K) int32 / float32,
    K influences per vertex, weights summing to 1.
    """

    joint_names: list[str]
    parents: np.ndarray
    rest_transforms: np.ndarray
    skin_indices: np.ndarray
    skin_weights: np.ndarray


@dataclass
class Body:
    """A normalised body mesh.

    vertices: (N, 3) float64, metres, world frame; faces: (F, 3) int32, counter-clockwise
    seen from outside; segments: (N,) uint8 indices into SEGMENTS, or None when unknown;
    rig: skeleton + weights when the body can be posed (the default body), else None;
    notes: human-readable lines about what loading did (units found, axes, repairs);
    to_world: source-file coordinates -> world (see field comment).
    """

    vertices: np.ndarray
    faces: np.ndarray
    name: str = "body"
    segments: np.ndarray | None = None
    rig: Rig | None = None
    notes: list[str] = field(default_factory=list)
    # (4, 4) float64: maps the source file's coordinates (as loaded, any unit/axes) to this
    # world frame. A GarmentCode spec made for that file's body uses it to keep its placement.
    to_world: np.ndarray = field(default_factory=lambda: np.eye(4))

    @property
    def height(self) -> float:
        return float(self.vertices[:, 1].max() - self.vertices[:, 1].min())

    def vertex_normals(self) -> np.ndarray:
        """(N, 3) float64 area-weighted unit vertex normals."""
        v, f = self.vertices, self.faces
        # one pass (numba; the NumPy form with np.add.at took 16 of the ~40 ms a walking frame's
        # collision maps took to render)
        out = np.empty((len(v), 3))
        _vertex_normals(np.ascontiguousarray(v, dtype=np.float64), np.ascontiguousarray(f, dtype=np.int64), out)
        return out


@serial_kernel
def _vertex_normals(v, f, out):
    """Each face's cross product (twice its area along its normal) added to its three
    corners, then normalised."""
    for i in range(out.shape[0]):
        out[i, 0] = 0.0
        out[i, 1] = 0.0
        out[i, 2] = 0.0
    for t in range(f.shape[0]):
        a, b, c = f[t, 0], f[t, 1], f[t, 2]
        ux, uy, uz = v[b, 0] - v[a, 0], v[b, 1] - v[a, 1], v[b, 2] - v[a, 2]
        wx, wy, wz = v[c, 0] - v[a, 0], v[c, 1] - v[a, 1], v[c, 2] - v[a, 2]
        nx, ny, nz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
        for k in (a, b, c):
            out[k, 0] += nx
            out[k, 1] += ny
            out[k, 2] += nz
    for i in range(out.shape[0]):
        ln = np.sqrt(out[i, 0] * out[i, 0] + out[i, 1] * out[i, 1] + out[i, 2] * out[i, 2])
        ln = max(ln, 1e-20)
        out[i, 0] /= ln
        out[i, 1] /= ln
        out[i, 2] /= ln
