"""Colliders for the cloth solver: the protocol of engine.cloth.solver (status, normal, body
velocity, depth past the band's outer edge) answered from image-space collision maps."""

from __future__ import annotations

import numpy as np

from engine.collide.maps import CollisionMaps
from engine.collide.query import query_point_into, query_batch_serial, query_rows_serial
from engine.collide.server import DONE, HELP_WAIT, REQ, RUNNING, SERVER_CHUNKS, SOLVER_CHUNKS, SpinServer, StallWatch, \
    after_help, chunk_done, claim, helper_default, serve_wait, wait_chunks
from engine.jit import atomic_load, atomic_store, serial_kernel

# (The kernels below inline engine.collide.server's claim and friends: numba's on-disk cache of a
# kernel is checked against this file only, so a change there must come with a change here --
# 2026-12-04: the claim word's layout changed.)

N_ROWS = 4  # the row query server's own word: rows in the request
ROW_CHUNK = 128  # rows a claim takes
SHARE_ROWS = 256  # a query of fewer rows is answered by the solver's thread alone (MapCollider.query_rows)


@serial_kernel(fastmath=False)
def _rows_work(ctl, r, tally, par, points, rows, surf, vel, has_vel, kind, side_src, geom, layout, zz,
               status, surface, penetration, normal, velocity, map_index):
    """Answer chunks of request r -- the points rows[:ctl[N_ROWS]], ROW_CHUNK a claim, at
    tolerance par[0] -- until none is left to claim (engine.collide.server.claim); the same
    arithmetic as query_rows_serial (fastmath off as there), whichever thread answers a chunk."""
    n_rows = ctl[N_ROWS]
    while True:
        c = claim(ctl, r)
        if c < 0:
            return
        hi = min(n_rows, (c + 1) * ROW_CHUNK)
        for i in range(c * ROW_CHUNK, hi):
            p = rows[i]
            query_point_into(points[p, 0], points[p, 1], points[p, 2], par[0], surf, vel, has_vel,
                             kind, side_src, geom, layout, zz, p, status, surface, penetration, normal,
                             velocity, map_index)
        chunk_done(ctl, tally, hi - c * ROW_CHUNK)


@serial_kernel(fastmath=False)
def _rows_help(ctl, wait, par, points, rows, surf, vel, has_vel, kind, side_src, geom, layout, zz,
               status, surface, penetration, normal, velocity, map_index):
    """The solver's thread: the chunks of the last request not yet claimed, then the wait for
    those the server holds; returns the ticks it waited, -1 when one was not finished within
    `wait` ticks."""
    _rows_work(ctl, atomic_load(ctl, REQ), SOLVER_CHUNKS, par, points, rows, surf, vel, has_vel, kind, side_src,
               geom, layout, zz, status, surface, penetration, normal, velocity, map_index)
    return wait_chunks(ctl, wait)


@serial_kernel(fastmath=False)
def _rows_serve(ctl, par, points, rows, surf, vel, has_vel, kind, side_src, geom, layout, zz,
                status, surface, penetration, normal, velocity, map_index):
    """The row query server's kernel (engine.collide.server): takes chunks of each request
    beside the solver's thread; returns on ctl[STOP], or after IDLE ticks without a request."""
    last = ctl[DONE]
    atomic_store(ctl, RUNNING, 2)
    while True:
        r = serve_wait(ctl, last)
        if r < 0:
            return
        last = r
        _rows_work(ctl, r, SERVER_CHUNKS, par, points, rows, surf, vel, has_vel, kind, side_src, geom, layout, zz,
                   status, surface, penetration, normal, velocity, map_index)
        atomic_store(ctl, DONE, r)


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
        its rows alone, so the answers are the same bit for bit whoever answers which chunk.
        Measured on the drape of default:female's dress (1.63 cm): a step asks all its contacts
        again every few steps (~1,000-2,000 rows), the others a few points alone."""
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
            self._served = (key, (sv.par, points, rows, *self.maps.kernel_args(), self.status, self.surface,
                                  self.depth, self.normal, self.velocity, self.map_index))
        args = self._served[1]
        if not sv.running_on(args):
            sv.start(_rows_serve, args)
        sv.par[0] = self.tol
        sv.ctl[N_ROWS] = n_rows
        sv.post_chunks(-(-n_rows // ROW_CHUNK))
        lost = after_help(_rows_help(sv.ctl, self.help_wait, *args), self.stalls)
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
