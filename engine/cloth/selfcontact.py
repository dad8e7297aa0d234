"""Cloth-cloth contact within one cloth (a cuff over its sleeve, a skirt level over the next, a
collar on the neckline): every few steps the vertex-triangle pairs closer than the cloth's
thickness -- now, or at the next check with the points predicted ahead as the body check predicts
them -- are found and pushed apart by proximity impulses (engine.cloth.kernels_self). They are
found among the pairs a spatial hash listed within the thickness and a slack, listed again only
once the cloth has moved half that slack. Pairs that lie near each other on the flat pattern (within
REST_RINGS cloth edges along the mesh: a fold's two sides next to its crease) are never pushed
apart, nor, while sewing, the two sides of a stitch and their neighbours.

    contact = SelfContact(model, thickness=0.003, every=2)
    contact.step(state, iteration, dt, push_rate=50.0, friction=0.3)   # in the solver's step
    self_intersections(state.x, triangles)                               # the check
"""

from __future__ import annotations

import numpy as np

from engine.cloth import kernels_self as K
from engine.cloth.model import FLEXION, ClothModel, ClothState
from engine.cloth.schedule import CheckSchedule
from engine.errors import InputError

REST_RINGS = 1.5  # cloth edges: vertices this near on the pattern (its own ring of 8 on the grid) may lie as near as folds put them
PASSES = 3  # Gauss-Seidel passes of the response over the pairs found
MAX_THICKNESS = 3.0  # cloth edges: a thicker layer would make every vertex's rest neighbourhood (and its cost) balloon
PAIRS_PER_VERTEX = 32  # candidate pairs kept, per vertex; past that (a crumpled heap) the rest are left out
SLACK = 0.5  # cloth edges: pairs within thickness + this are listed, and the list kept while no vertex moves half this


def all_triangles(quads: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """(F, 3) int32: the triangles, then each quad as two (split along 0-2)."""
    return np.concatenate([tris, quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]]).astype(np.int32)


class _Hash:
    """A hashed grid of triangle boxes, its buffers kept from call to call."""

    def __init__(self, n_boxes: int, cell: float):
        size = 1 << max(4, int(np.ceil(np.log2(2 * n_boxes + 1))))
        self.inv_c = 1.0 / cell
        self.start = np.zeros(size + 1, dtype=np.int64)
        self.entries = np.zeros(8 * n_boxes + 16, dtype=np.int32)
        self.packed = np.zeros((len(self.entries), 6), dtype=np.float32)
        self.lo = np.zeros((n_boxes, 3))
        self.hi = np.zeros((n_boxes, 3))

    def fill(self) -> None:
        need = K.fill_hash(self.lo, self.hi, self.inv_c, self.start, self.entries, self.packed)
        if need > len(self.entries):
            self.entries = np.zeros(2 * need, dtype=np.int32)
            self.packed = np.zeros((len(self.entries), 6), dtype=np.float32)
            K.fill_hash(self.lo, self.hi, self.inv_c, self.start, self.entries, self.packed)


def rest_radius(edge: float, thickness: float) -> float:
    """The distance along the pattern within which two vertices are never pushed apart: REST_RINGS
    edges, or more for a layer thick against the edges -- on the flat pattern, every triangle of
    vertices farther along it than this lies farther than `thickness` (the grid's distance along
    its springs is at most 1.09 x the straight one; a triangle's edge is at most sqrt(2) edges)."""
    return max(REST_RINGS * edge, 1.1 * (thickness + edge))


def rest_neighbours(n: int, pairs: np.ndarray, lengths: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """(ptr (n + 1,) int64, near (K,) int32): for each vertex, the vertices within `radius` of it
    along the graph of `pairs` (P, 2) with edge `lengths` (P,) -- CSR, by vertex."""
    a, b = pairs[:, 0].astype(np.int64), pairs[:, 1].astype(np.int64)
    ends, other = np.concatenate([a, b]), np.concatenate([b, a])
    order = np.argsort(ends, kind="stable")
    ptr = np.zeros(n + 1, dtype=np.int64)
    np.add.at(ptr, ends + 1, 1)
    ptr = np.cumsum(ptr)
    other, length = other[order].astype(np.int32), np.concatenate([lengths, lengths])[order].astype(np.float64)
    out_ptr = np.zeros(n + 1, dtype=np.int64)
    dist, seen = np.full(n, np.inf), np.zeros(n, dtype=np.int32)
    K.rest_neighbours(ptr, other, length, radius, out_ptr, np.zeros(0, dtype=np.int32), dist, seen)
    near = np.zeros(int(out_ptr[-1]), dtype=np.int32)
    if len(near):
        K.rest_neighbours(ptr, other, length, radius, out_ptr, near, dist, seen)
    return out_ptr, near


class SelfContact:
    """The self-collision pass of one cloth model (module doc): `thickness` m kept between layers,
    checked every `every` steps. The hash is searched only when the cloth has moved: it lists
    every vertex-triangle pair within thickness + SLACK edges (a Verlet list), and each check
    looks at those pairs alone until a vertex, now or predicted, is half the slack from where it
    was when they were listed."""

    def __init__(self, model: ClothModel, thickness: float, every: int):
        self.model, self.thickness, self.every = model, float(thickness), int(every)
        h = model.edge_length
        if not (0.0 < self.thickness <= MAX_THICKNESS * h):
            raise InputError(f"self-collision thickness {1000 * self.thickness:g} mm: use more than 0 and at most "
                             f"{MAX_THICKNESS:g} cloth edges ({1000 * MAX_THICKNESS * h:g} mm at this cloth's "
                             f"{1000 * h:g} mm edges), or a coarser cloth")
        self.tris = all_triangles(model.quads, model.tris)
        self.radius = rest_radius(h, self.thickness)
        self.slack = SLACK * h
        planar = model.kind != FLEXION  # (along the cloth: a flexion spring spans two edges)
        self._springs, self._rest = model.springs[planar], model.rest[planar]
        self.near = rest_neighbours(model.n, self._springs, self._rest, self.radius)
        self._sewing = (None, self.near)  # (the stitch pairs, the rest neighbours with them)
        # a cell holds a triangle's box grown by the reach (at most two cells a side)
        self.grid = _Hash(len(self.tris), h + 2.0 * (self.thickness + self.slack))
        self.xp, self.x0 = np.zeros((model.n, 3)), np.zeros((model.n, 3))
        self.mark, self.tmark = np.zeros(model.n, dtype=np.int32), np.zeros(len(self.tris), dtype=np.int32)
        self.cap = PAIRS_PER_VERTEX * model.n + 16
        self._grow(4 * model.n + 16)
        self.n_cand = 0
        self._listed = None  # the rest neighbours the pairs were listed with (None: not listed yet)
        self.schedule = CheckSchedule()
        self.found = 0  # pairs found at the last check
        self.listings = 0  # searches of the hash
        self.dropped = 0  # candidate pairs past the cap (PAIRS_PER_VERTEX) at the last listing, left out
        self.pushed = 0  # pairs whose velocity the last check changed

    def _grow(self, m: int) -> None:
        self.cand_v, self.cand_t = np.zeros(m, dtype=np.int32), np.zeros((m, 3), dtype=np.int32)
        self.c_v, self.c_t = np.zeros(m, dtype=np.int32), np.zeros((m, 3), dtype=np.int32)
        self.c_w, self.c_n, self.c_d = np.zeros((m, 3)), np.zeros((m, 3)), np.zeros(m)

    def _neighbours(self, stitches: np.ndarray | None) -> tuple[np.ndarray, np.ndarray]:
        """The rest neighbours; while sewing, the stitch pairs counted as joined (zero apart)."""
        if stitches is None:
            return self.near
        if self._sewing[0] is not stitches:
            pairs = np.concatenate([self._springs, stitches]).astype(np.int64)
            lengths = np.concatenate([self._rest, np.zeros(len(stitches))])
            self._sewing = (stitches, rest_neighbours(self.model.n, pairs, lengths, self.radius))
        return self._sewing[1]

    def _list(self, x: np.ndarray, near: tuple[np.ndarray, np.ndarray]) -> None:
        """The candidate pairs of x: within thickness + slack, from the hash."""
        h, reach = self.grid, self.thickness + self.slack
        K.triangle_boxes(x, x, self.tris, reach, h.lo, h.hi)
        h.fill()
        args = (x, self.tris, h.packed, h.inv_c, h.start, h.entries, near[0], near[1], reach)
        m = K.find_near(*args, self.cand_v, self.cand_t, self.mark, self.tmark)
        if m > len(self.cand_v) < self.cap:
            self._grow(min(2 * m, self.cap))
            m = K.find_near(*args, self.cand_v, self.cand_t, self.mark, self.tmark)
        self.dropped = max(0, m - len(self.cand_v))  # (past the cap: the first pairs, by vertex, kept)
        self.n_cand = m - self.dropped
        self.x0[:] = x
        self._listed = near
        self.listings += 1

    def step(self, state: ClothState, iteration: int, dt: float, push_rate: float, friction: float,
             stitches: np.ndarray | None = None) -> bool:
        """The pass, if `iteration` checks (every `every` steps): pairs found with the points
        predicted to the next check, their velocities changed in place. stitches (P, 2): the
        pairs being sewn (never pushed apart). Returns whether it checked."""
        ahead = self.schedule.now(self.every, iteration)
        if not ahead:
            return False
        x, v = state.x, state.v
        np.multiply(v, dt * ahead, out=self.xp)
        self.xp += x
        if not np.isfinite(self.xp).all():  # (the scene's own check names the failure)
            return True
        near = self._neighbours(stitches)
        # a pair not listed was farther than thickness + slack; neither end has moved half the
        # slack since, so it is still farther than the thickness, now and predicted
        if near is not self._listed or K.moved_past(x, self.xp, self.x0, 0.5 * self.slack):
            self._list(x, near)
        m = K.find_contacts(x, self.xp, self.cand_v, self.cand_t, self.n_cand, self.thickness,
                            self.c_v, self.c_t, self.c_w, self.c_n, self.c_d)
        self.found = m
        self.pushed = K.respond_contacts(v, self.model.inv_mass, self.c_v, self.c_t, self.c_w, self.c_n, self.c_d,
                                         m, self.thickness, dt * ahead, push_rate, friction, PASSES)
        return True


def self_intersections(x: np.ndarray, triangles: np.ndarray) -> dict:
    """How much a cloth passes through itself: the triangles that cross another triangle (one
    sharing no corner with it), and the crossing pairs."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    tris = np.asarray(triangles, dtype=np.int32)
    tris = np.ascontiguousarray(tris[np.isfinite(x[tris]).all(axis=(1, 2))])  # (a torn cloth's too)
    if len(tris) == 0:
        return {"triangles": 0, "pairs": 0}
    ext = x[tris].max(axis=1) - x[tris].min(axis=1)
    h = _Hash(len(tris), max(float(np.median(ext.max(axis=1))), 1e-6))
    K.triangle_boxes(x, x, tris, 0.0, h.lo, h.hi)
    h.fill()
    hit = np.zeros(len(tris), dtype=np.uint8)
    pairs = K.mark_crossings(x, tris, h.lo, h.hi, h.inv_c, h.start, h.entries, h.packed, hit)
    return {"triangles": int(hit.sum()), "pairs": int(pairs)}
