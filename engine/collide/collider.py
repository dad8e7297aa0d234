"""Colliders for the cloth solver: the protocol of engine.cloth.solver (status, normal, body
velocity, depth past the band's outer edge) answered from image-space collision maps."""

from __future__ import annotations

import numpy as np

from engine.collide.maps import CollisionMaps
from engine.collide.query import query_batch_serial, query_rows_serial


def alloc_answers(collider, n: int) -> None:
    """The map query's output buffers for n points, as attributes of `collider` (reused between
    steps; query_batch_serial / query_point_into write them)."""
    collider.status = np.zeros(n, np.int8)
    collider.surface = np.zeros((n, 3))
    collider.depth = np.zeros(n)
    collider.normal = np.zeros((n, 3))
    collider.velocity = np.zeros((n, 3))
    collider.map_index = np.zeros(n, np.int32)
    collider._n = n


class MapCollider:
    """Cloth points against CollisionMaps (vertex and face-midpoint checks, seed 003 §5.3).
    Output arrays are reused between calls (one call per simulation step); set_maps() swaps
    in a new body frame's maps (walking)."""

    depth_along_z = True  # depth is measured along z (query.py), not along the normal

    def __init__(self, maps: CollisionMaps, tol: float | None = None):
        self.maps = maps
        self.tol = float(maps.tol if tol is None else tol)
        self._n = -1
        self.version = 0  # bumped when the maps change (solvers re-query then)

    def set_maps(self, maps: CollisionMaps) -> None:
        self.maps = maps
        self.version += 1

    def _alloc(self, n: int) -> None:
        alloc_answers(self, n)

    def query(self, points: np.ndarray):
        if points.shape[0] != self._n:
            self._alloc(points.shape[0])
        query_batch_serial(points, self.tol, *self.maps.kernel_args(), self.status, self.surface, self.depth,
                    self.normal, self.velocity, self.map_index)
        return self.status, self.normal, self.velocity, self.depth

    def query_rows(self, points: np.ndarray, rows: np.ndarray, n_rows: int):
        """Answer only points[rows[:n_rows]], into those rows of the outputs (the cloth solver
        keeps the other points' answers, ClothSolver._contacts)."""
        if points.shape[0] != self._n:
            return self.query(points)
        query_rows_serial(points, rows, n_rows, self.tol, *self.maps.kernel_args(), self.status, self.surface,
                          self.depth, self.normal, self.velocity, self.map_index)
        return self.status, self.normal, self.velocity, self.depth
