"""The body as the cloth solver sees it: the one interface every collider implements
(engine.cloth.solver asks nothing else of a collider).

    status, normal, body_velocity, depth = collider.query(points)

For M points (M, 3): status (M,) int8 (0 clear, 1 in the tolerance band, 2 inside), the body's
outward normal (M, 3), the body's velocity there (M, 3), depth (M,) metres past the band's outer
edge (> 0 where status > 0). The arrays are the collider's buffers, overwritten by the next query.

A collider says in class attributes which optional abilities the solver may use; the methods of
an ability it does not have are never called.
"""

from __future__ import annotations

from typing import ClassVar

import numpy as np

Answer = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]  # status, normal, body velocity, depth


class Collider:
    """Base class of the colliders (image-space maps, the object-space baseline, moving bodies)."""

    # the solver may carry its last answers between queries while `version` stays the same
    # (False: the body moves every step; such a collider carries answers itself)
    solver_carries: ClassVar[bool] = True
    # depth is measured along z (the maps), not along the normal (how a carried depth changes)
    depth_along_z: ClassVar[bool] = False
    # query_rows answers some points alone (the others keep their last answers)
    answers_rows: ClassVar[bool] = False
    # prefetch answers points ahead of time, while the solver steps on
    prefetches: ClassVar[bool] = False
    # fill_faces: the collider makes the face rows of the points it is asked for
    makes_face_points: ClassVar[bool] = False

    version: int = 0  # changes whenever the body does (answers carried from before are stale)

    def query(self, points: np.ndarray) -> Answer:
        raise NotImplementedError

    def query_rows(self, points: np.ndarray, rows: np.ndarray, n_rows: int) -> Answer:
        """(answers_rows) Answer points[rows[:n_rows]] only, into those rows of the answer."""
        raise NotImplementedError

    def prefetch(self, points: np.ndarray, later: float) -> bool:
        """(prefetches) Start answering `points`, where the solver predicts its points `later`
        seconds from now; `points` must stay unchanged until the next query. Whether it did."""
        raise NotImplementedError

    def fill_faces(self, n_vertices: int, quads: np.ndarray, tris: np.ndarray) -> None:
        """(makes_face_points) From now on the rows of the points asked for from n_vertices on
        are the faces' points (each quad's midpoint, then each triangle's centroid, of the vertex
        rows): the collider makes them, the caller writes the vertex rows only."""
        raise NotImplementedError

    def release(self) -> None:
        """Let go of threads and buffers (a collider is not used after this)."""
