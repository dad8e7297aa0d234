"""Colliders for the cloth solver: the protocol of engine.cloth.solver (status, normal, body
velocity, depth past the band's outer edge) answered from image-space collision maps."""

from __future__ import annotations

from collections import namedtuple
from dataclasses import dataclass

import numpy as np

from engine.collide.base import Collider
from engine.collide.maps import CollisionMaps
from engine.collide.query import query_batch_serial, query_point_into, query_points, query_rows_serial
from engine.collide.server import (HELP_WAIT, SpinServer, StallWatch, after_help, chunk_done, claim, helper_default,
                                   register_job)
from engine.jit import serial_kernel

N_ROWS = 4  # the row query server's own word: rows in the request
ROW_CHUNK = 128  # rows a claim takes
SHARE_ROWS = 256  # a query of fewer rows is answered by the solver's thread alone (MapCollider.query_rows)

# A row query shared with the query server: the points rows[:ctl[N_ROWS]] against the maps (the
# eight arrays of CollisionMaps.kernel_args) at tolerance par[0], into the answer arrays
# (status, surface, penetration, normal, velocity, map_index)
RowsJob = namedtuple("RowsJob", "par points rows maps answers")


@serial_kernel(fastmath=False)
def _rows_work(ctl, r, tally, job):
    """Answer chunks of request r of a RowsJob, ROW_CHUNK rows a claim, until none is left to
    claim; the same arithmetic as query_rows_serial (fastmath off as there), whichever thread
    answers a chunk."""
    n_rows = ctl[N_ROWS]
    points, rows, tol = job.points, job.rows, job.par[0]
    surf, vel, has_vel, kind, side_src, geom, layout, zz = job.maps  # (query_point_into is inlined:
    status, surface, penetration, normal, velocity, map_index = job.answers  # no *args there)
    while True:
        c = claim(ctl, r)
        if c < 0:
            return 0
        hi = min(n_rows, (c + 1) * ROW_CHUNK)
        for i in range(c * ROW_CHUNK, hi):
            p = rows[i]
            query_point_into(points[p, 0], points[p, 1], points[p, 2], tol, surf, vel, has_vel, kind, side_src, geom,
                             layout, zz, p, status, surface, penetration, normal, velocity, map_index)
        chunk_done(ctl, tally, hi - c * ROW_CHUNK)


register_job(RowsJob, _rows_work)


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


class MapCollider(Collider):
    """Cloth points against CollisionMaps (vertex and face-midpoint checks, seed 003 §5.3).
    Output arrays are reused between calls (one call per simulation step); set_maps() swaps
    in a new body frame's maps (walking)."""

    depth_along_z = True  # depth is measured along z (query.py), not along the normal
    answers_rows = True

    def __init__(self, maps: CollisionMaps, tol: float | None = None, helper: bool | None = None):
        """helper: a query of many rows is shared with a helper thread (query_rows); None: unless
        the environment says not to (engine.collide.server.helper_default)."""
        self.maps = maps
        self.tol = float(maps.tol if tol is None else tol)
        self._n = -1
        self.version = 0  # bumped when the maps change (solvers re-query then)
        self.helper = helper_default() if helper is None else helper
        self.server: SpinServer | None = None  # the row query server, made at the first shared query
        self._served = None  # its kernel's arguments, and what they were made for
        self.help_wait = HELP_WAIT
        self.stalls = StallWatch()  # (the helper is let go when the machine has no core for it)
        self.stats = {"rows": 0, "shared_rows": 0}

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
        keeps the other points' answers, ClothSolver._contacts).
        With `helper`, SHARE_ROWS rows or more are answered in chunks that a helper thread
        (engine.collide.server.SpinServer; it spins while queries come, and its kernel returns
        after ~0.1 s without one) and this thread claim as they come: each point's answer is
        its rows alone, so the answers are the same bit for bit whoever answers which chunk."""
        if points.shape[0] != self._n:
            return self.query(points)
        self.stats["rows"] += n_rows
        if not self.helper or n_rows < SHARE_ROWS or self.stalls.lost:
            query_rows_serial(points, rows, n_rows, self.tol, *self.maps.kernel_args(), self.status, self.surface,
                              self.depth, self.normal, self.velocity, self.map_index)
            return self.status, self.normal, self.velocity, self.depth
        sv = self.server
        if sv is None:
            sv = self.server = SpinServer("map-query-server")
        key = (points, rows, self.maps, self._n)
        if self._served is None or any(a is not b for a, b in zip(self._served[0], key)):
            self._served = (key, RowsJob(sv.par, points, rows, self.maps.kernel_args(),
                                         (self.status, self.surface, self.depth, self.normal, self.velocity,
                                          self.map_index)))
        job = self._served[1]
        if not sv.running_on(job):
            sv.start(job)
        sv.par[0] = self.tol
        sv.ctl[N_ROWS] = n_rows
        sv.post_chunks(-(-n_rows // ROW_CHUNK))
        lost = after_help(sv.help(job, self.help_wait), self.stalls)
        self.stats["shared_rows"] += n_rows
        if lost:
            self.stats["helper_let_go_after_rows"] = self.stats["rows"]
            self.release()
        return self.status, self.normal, self.velocity, self.depth

    def release(self) -> None:
        """End the row query server's thread (dropping the collider ends it too)."""
        if self.server is not None:
            self.server.close()
            self.server = None
            self._served = None


def face_point_mask(vertex_mask: np.ndarray, quads: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(N + Q + T,) bool: the cloth solver's checked points (vertices, quad midpoints, triangle
    centroids) of which every vertex is in vertex_mask."""
    vm = np.asarray(vertex_mask, bool)
    return np.concatenate([vm, vm[quads].all(axis=1) if len(quads) else np.zeros(0, bool),
                           vm[tris].all(axis=1) if len(tris) else np.zeros(0, bool)])


class ExemptCollider(Collider):
    """A MapCollider whose points in `exempt` (one flag per checked point, face_point_mask) are
    answered from other maps, `without` (the body less some parts: the hanging arms, which a
    lower garment's cloth passes through while it is sewn and until its drape first settles,
    engine.body.hanging). The answers are
    the full collider's buffers, so the solver's carried answers work as with it alone."""

    depth_along_z = True
    answers_rows = True

    def __init__(self, full: MapCollider, without: CollisionMaps, exempt: np.ndarray):
        self.full, self.without = full, without
        self.exempt = np.ascontiguousarray(exempt, dtype=np.bool_)
        self._rows_full = np.zeros(0, np.int64)  # (kept: the full collider's helper keys its job on the array)
        self._rows_ex = np.zeros(0, np.int64)

    @property
    def version(self) -> int:
        return self.full.version

    def _answer_exempt(self, points: np.ndarray, rows: np.ndarray, n: int):
        f = self.full
        query_rows_serial(points, rows, n, f.tol, *self.without.kernel_args(), f.status, f.surface, f.depth,
                          f.normal, f.velocity, f.map_index)
        return f.status, f.normal, f.velocity, f.depth

    def query(self, points: np.ndarray):
        if points.shape[0] != len(self.exempt):
            raise ValueError(f"ExemptCollider: {points.shape[0]} points, {len(self.exempt)} flags")
        self.full.query(points)
        rows = np.flatnonzero(self.exempt)
        return self._answer_exempt(points, rows, len(rows))

    def query_rows(self, points: np.ndarray, rows: np.ndarray, n_rows: int):
        if points.shape[0] != self.full._n:
            return self.query(points)
        if len(self._rows_full) != len(rows):
            self._rows_full, self._rows_ex = np.zeros_like(rows), np.zeros_like(rows)
        asked = rows[:n_rows]
        ex = self.exempt[asked]
        n_ex = int(ex.sum())
        self._rows_ex[:n_ex] = asked[ex]
        self._rows_full[:n_rows - n_ex] = asked[~ex]
        if n_rows - n_ex:
            self.full.query_rows(points, self._rows_full, n_rows - n_ex)
        return self._answer_exempt(points, self._rows_ex, n_ex)

    def release(self) -> None:
        self.full.release()


@dataclass
class PassThrough:
    """Parts of the body that some of the cloth passes through for a while (engine.scene.tryon:
    a lower garment's panels and the hanging arms): `without` is the maps of the body less those
    parts, `vertices` flags the garment's vertices (unsewn) that see only it."""

    without: CollisionMaps
    vertices: np.ndarray  # (N,) bool
    why: str = ""

    def collider(self, full: MapCollider, vertices: np.ndarray, quads: np.ndarray, tris: np.ndarray) -> ExemptCollider:
        """`full` with the flagged `vertices` (of a cloth model's vertices) and their faces' points exempt."""
        return ExemptCollider(full, self.without, face_point_mask(vertices, quads, tris))

    def caught(self, full: MapCollider, x: np.ndarray, vertices: np.ndarray) -> int:
        """How many of the flagged `vertices` of the cloth at `x` the left-out parts touch (in
        contact with the whole body, clear of the body without them)."""
        idx = np.flatnonzero(vertices)
        if not len(idx):
            return 0
        a = query_points(full.maps, x[idx], full.tol).status
        b = query_points(self.without, x[idx], full.tol).status
        return int(((a > 0) & (b == 0)).sum())
