"""A moving body as a collider: one set of collision maps per body frame (with velocity maps),
the body between frames extrapolated along its surface velocity (seed 000 §4-5).

    collider = TrackCollider(track, renderer, tol=0.005)
    for each solver step:
        collider.set_time(t + dt)       # the body where the step's cloth will be
        solver.step(state)              # queries collider.query(points)

Between frames: the maps of the nearest frame k (time t_k) answer, and the surface is moved
along its normal by its velocity relative to the root (whose travel is applied exactly, below):
a point's penetration grows by ((v - v_root) . n) (t - t_k). The maps are
asked with the tolerance widened by the most the surface can move in that time, then each answer
is re-classified (clear / band / inside) with the corrected penetration. The root's horizontal
travel is exact: maps are rendered relative to it (track frames), and points are moved into
that frame before asking.

Asking the maps is the costliest part of a step, and most cloth points are far from the body or
move with it: each point keeps its last answer (in the root's frame) and asks again only when it
may be stale (_query_cached). A clear point is asked again at least every MAX_AGE: beside a limb,
outside every map, it has no distance to test.

Near the band: the maps are asked with the band widened by NEAR (1 mm) more, and a point they
find a surface for -- a contact, or a clear point close to the band -- keeps that answer and is
carried as contacts are (its penetration along the normal), so cloth resting just outside the
band is not asked again at every check.

The query server (`prefetch`): right after a collision check the solver predicts where its
points will be at the next check, and a helper thread answers them for that time while the cloth
steps on; the next check's query then finds most answers fresh. The thread
(engine.collide.server.SpinServer) runs one nogil kernel per frame's maps (engine.collide.server.serve) that spins
between requests, handed over through atomic control words -- no GIL, no sleeping (a thread
woken per request starts too late to pay).
Every request -- the prefetch, and the check's own query of the points where they are -- is
answered in chunks of CHUNK points that either thread claims (_work): the server starts on a
request at once, and the solver's thread, when it needs the answers, takes the chunks not yet
claimed instead of waiting (SpinServer.help), then waits only for the chunks the server holds. A point's
answer depends on its own rows alone, so the answers are the same bit for bit whoever answers
which chunk (tests/test_walk.py). The server starts on a frame's maps at the frame switch.

Rendered ahead (`ahead`): a helper thread with its own GL context (engine.collide.gl.thread_context)
renders frame k + 1's maps as soon as frame k's come into use; set_time waits for them only if
they are late.

Map reuse (DESIGN: a periodic walk renders one cycle): maps are kept per distinct track frame
(the ramp, then one cycle), rendered on first use; `stats` counts renders and reuses. Kept maps
hold their float arrays in float16 when `compact` is set (half the memory; the depth error at
2 m is 1 mm, under the 5 mm texel), expanded to float32 for their frame (into one of two buffer
sets: rendered ahead, the helper thread expands the next frame's, with its depth pairs, into
the set not in use while the solver works on this frame; the switch only waits for it, or
expands now after a jump). Both conversions are numba kernels (_compact_half, _expand_half),
bit for bit what numpy's astype gives, several times faster. `stats["map_seconds"]` counts the
conversions with the renders.
"""

from __future__ import annotations

import math
import time
from collections import namedtuple
from concurrent.futures import Future, ThreadPoolExecutor

import numpy as np

from engine.body.motion import BodyTrack
from engine.body.types import Body
from engine.collide.base import Collider
from engine.collide.collider import alloc_answers
from engine.collide.gl import drop_thread_context
from engine.collide.maps import CollisionMaps
from engine.collide.query import query_point_into
from engine.collide.server import (ASKED, HELP_WAIT, SERVER_CHUNKS, SOLVER_CHUNKS, SpinServer, StallWatch, after_help,
                                   chunk_done, claim, helper_default, register_job)
from engine.jit import njit, serial_kernel

REACH = 0.002  # m: a point that moved this far (in the root's frame) since its answer asks again
MAX_AGE = 0.002  # s: ... and so does an answer this old
SLACK = 0.0005  # m: a clear point may come this close to the band before it asks again
NEAR = 0.001  # m: a point this close outside the (widened) band is answered with the surface, and carried
MIN_NZ = 0.2  # a carried penetration changes at most 1 / MIN_NZ x the normal motion


@serial_kernel
def _query_cached(pts, off, lo, hi, t, frame, tol, widened, shift_t, root_v, vmax, reach, max_age, slack, near,
                  n_vertices, quads, tris, surf, vel, has_vel, kind, side_src, geom, layout, zz,
                  c_local, c_time, c_frame, c_pen, c_un, c_surf,
                  status, surface, penetration, normal, velocity, map_index):
    """Answer the points lo .. hi - 1 of pts (world; minus off: the root's frame) (each on its
    own: a point's answer and carried answer are its rows alone), asking the maps only where the
    last answer may be stale: the maps
    changed, the point moved `reach` (root frame), the answer is `max_age` old, or -- for a point
    the maps found no surface near (further than `near` outside the widened band) -- the point
    and the surface (at most vmax relative to the root) may together have closed its distance to
    the band. An answer is corrected for the surface's motion since the maps' frame (module doc);
    an answer with a surface (c_surf: a contact, or a point within `near` of the band) also for
    the time since: its penetration grows with the surface's normal speed and shrinks as the
    point moves out along the normal, and it is a contact again as soon as that penetration is
    positive. An answer may be for a later time than t (prefetched: TrackCollider.prefetch).
    The rows from n_vertices on are face points, written here first (_face_point; quads, tris:
    TrackCollider.fill_faces). Returns how many points were asked."""
    asked = 0
    for p in range(lo, hi):
        if p >= n_vertices:
            _face_point(pts, p, n_vertices, quads, tris)
        x, y, z = pts[p, 0] - off[0], pts[p, 1] - off[1], pts[p, 2] - off[2]
        dx, dy, dz = x - c_local[p, 0], y - c_local[p, 1], z - c_local[p, 2]
        moved = np.sqrt(dx * dx + dy * dy + dz * dz)
        age = t - c_time[p]
        fresh = c_frame[p] == frame and moved < reach and age < max_age
        if fresh and c_surf[p] != 0:
            # the maps' penetration is measured along z: it changes by the normal motion / |n_z|
            # (capped); a side-layer answer (n_z = 0) is a distance (as cloth.kernels_carry._depth_rate)
            nz = abs(normal[p, 2])
            rate = 1.0 if nz == 0.0 else 1.0 / max(nz, MIN_NZ)
            pen = c_pen[p] + (c_un[p] * age - (dx * normal[p, 0] + dy * normal[p, 1] + dz * normal[p, 2])) * rate
            penetration[p] = pen
            status[p] = 2 if pen > tol else (1 if pen > 0.0 else 0)
            continue
        if fresh and moved + vmax * abs(age) < -c_pen[p] - slack:
            continue
        asked += 1
        st = query_point_into(x, y, z, tol + widened + near, surf, vel, has_vel, kind, side_src, geom, layout, zz,
                              p, status, surface, penetration, normal, velocity, map_index)
        un = ((velocity[p, 0] - root_v[0]) * normal[p, 0] + (velocity[p, 1] - root_v[1]) * normal[p, 1]
              + (velocity[p, 2] - root_v[2]) * normal[p, 2])
        if st != 0:
            pen = penetration[p] - widened - near + un * shift_t
            penetration[p] = pen
            status[p] = 2 if pen > tol else (1 if pen > 0.0 else 0)
        c_surf[p] = st != 0
        c_local[p, 0], c_local[p, 1], c_local[p, 2] = x, y, z
        c_time[p] = t
        c_frame[p] = frame
        c_pen[p] = penetration[p]  # (a clear point far outside the widened band: pessimistic)
        c_un[p] = un
    return asked


@njit(fastmath=True, cache=True, inline="always")
def _face_point(pts, p, n_vertices, quads, tris):
    """Row p of pts (p >= n_vertices): its face's point from the vertex rows -- a quad's midpoint
    (quads first), else a triangle's centroid; as engine.cloth.kernels_contact.collision_points makes it,
    bit for bit."""
    f = p - n_vertices
    if f < quads.shape[0]:
        i0, i1, i2, i3 = quads[f, 0], quads[f, 1], quads[f, 2], quads[f, 3]
        for c in range(3):
            pts[p, c] = 0.25 * (pts[i0, c] + pts[i1, c] + pts[i2, c] + pts[i3, c])
    else:
        f -= quads.shape[0]
        third = 1.0 / 3.0
        i0, i1, i2 = tris[f, 0], tris[f, 1], tris[f, 2]
        for c in range(3):
            pts[p, c] = third * (pts[i0, c] + pts[i1, c] + pts[i2, c])


SERIAL, WHICH = 4, 9  # the walking query server's own words: the maps' serial, which points (0: predicted, 1: this step's)
CHUNK = 512  # points a claim takes

# A walking query shared with the query server: the world points pre_pts (predicted) or pts
# (ctl[WHICH]) with the face rows from n_vertices on made from quads and tris (fill_faces),
# against one frame's maps (the eight arrays of CollisionMaps.kernel_args; their serial
# ctl[SERIAL]) with par: t, tol, widened, shift_t, vmax, root_v, the root's offset; the carried
# answers (c_local, c_time, c_frame, c_pen, c_un, c_surf) and the answers (status, surface,
# penetration, normal, velocity, map_index)
TrackJob = namedtuple("TrackJob", "par pre_pts pts n_vertices quads tris maps carried answers")


@serial_kernel
def _work(ctl, r, tally, job):
    """Answer chunks of request r of a TrackJob (_query_cached) until none is left to claim (the
    solver's thread claims from the end: engine.collide.server.claim); returns the points this
    thread asked. (Each chunk takes its points into the root's frame itself.)"""
    asked = 0
    root_v = np.empty(3)
    off = np.empty(3)
    par = job.par
    n = job.carried[1].shape[0]
    while True:
        c = claim(ctl, r, tally == SOLVER_CHUNKS)
        if c < 0:
            return asked
        for k in range(3):
            root_v[k] = par[5 + k]
            off[k] = par[8 + k]
        points = job.pts if ctl[WHICH] != 0 else job.pre_pts
        k = _query_cached(points, off, c * CHUNK, min(n, (c + 1) * CHUNK), par[0], ctl[SERIAL], par[1], par[2], par[3],
                          root_v, par[4], REACH, MAX_AGE, SLACK, NEAR, job.n_vertices, job.quads, job.tris,
                          *job.maps, *job.carried, *job.answers)
        asked += k
        chunk_done(ctl, tally, k)


register_job(TrackJob, _work)


@serial_kernel
def _expand_half(bits, table, out):
    """out[i] = table[bits[i]]: float16 values (as their uint16 bits) to float32 through the
    65,536-entry table of every half's value (_HALF_TABLE) -- exact, as numpy's astype, which
    converts each element in software."""
    for i in range(bits.shape[0]):
        out[i] = table[bits[i]]


_HALF_TABLE = np.arange(2 ** 16, dtype=np.uint16).view(np.float16).astype(np.float32)


@serial_kernel
def _compact_half(bits, out):
    """out[i] = the float16 bits of the float32 whose bits are bits[i] (uint32), rounded to
    nearest, ties to even; overflow to infinity, NaN stays NaN, underflow to subnormals and
    zero -- IEEE 754's conversion, as numpy's astype does it (tests/test_walk.py checks them
    equal)."""
    for i in range(bits.shape[0]):
        f = bits[i]
        sgn = np.uint16((f & 0x80000000) >> 16)
        f_exp = f & 0x7F800000
        if f_exp >= 0x47800000:  # too large for a half: infinity (or NaN)
            sig = f & 0x007FFFFF
            if f_exp == 0x7F800000 and sig != 0:
                h = np.uint16(0x7C00 + (sig >> 13))
                if h == 0x7C00:
                    h = np.uint16(0x7C01)
                out[i] = sgn | h
            else:
                out[i] = sgn | np.uint16(0x7C00)
        elif f_exp <= 0x38000000:  # a subnormal half, or zero
            if f_exp < 0x33000000:
                out[i] = sgn
            else:
                e = f_exp >> 23
                sig = (0x00800000 + (f & 0x007FFFFF)) >> (113 - e)
                if (sig & 0x00003FFF) != 0x00001000 or (f & 0x000007FF) != 0:
                    sig += 0x00001000
                out[i] = sgn + np.uint16(sig >> 13)
        else:
            sig = f & 0x007FFFFF
            if (sig & 0x00003FFF) != 0x00001000:
                sig += 0x00001000
            out[i] = sgn + np.uint16((sig >> 13) + ((f_exp - 0x38000000) >> 13))


def _compacted(a: np.ndarray) -> np.ndarray:
    """A float16 copy of the array `a` (as a.astype(np.float16); via float32)."""
    a = np.ascontiguousarray(a, dtype=np.float32)  # the kernel reads 4-byte words
    out = np.empty(a.shape, np.float16)
    _compact_half(a.reshape(-1).view(np.uint32), out.reshape(-1).view(np.uint16))
    return out


def _expanded(half: np.ndarray, out: np.ndarray | None) -> np.ndarray:
    """A float32 copy of the float16 array `half`, written into `out` when it has the shape."""
    half = np.ascontiguousarray(half, dtype=np.float16)  # the kernel reads 2-byte words
    if out is None or out.shape != half.shape:
        out = np.empty(half.shape, np.float32)
    _expand_half(half.reshape(-1).view(np.uint16), _HALF_TABLE, out.reshape(-1))
    return out


class TrackCollider(Collider):
    """Cloth points against a BodyTrack, through per-frame collision maps."""

    solver_carries = False  # the body moves every step; it carries answers itself (_query_cached)
    prefetches = True
    makes_face_points = True

    def __init__(self, track: BodyTrack, renderer, tol: float, keep: bool = True,
                 compact: bool = True, ahead: bool = False, helper: bool | None = None):
        """keep: keep each frame's maps for reuse (a periodic track); compact: keep them as float16.
        ahead: render each frame's maps one frame ahead in a helper thread while the solver works
        (the body's motion does not depend on the cloth); `renderer` is then a function that makes
        the MapRenderer, called in that thread (with own_context=True: GL objects belong to the
        context they were made in). release() ends the thread.
        helper: the query server's thread takes part in the queries (module doc); False: this
        thread answers them alone (the same answers); None: unless the environment says not to
        (engine.collide.server.helper_default)."""
        self.track, self.renderer, self.tol = track, (None if ahead else renderer), float(tol)
        self._make_renderer = renderer if ahead else None
        self._pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="maps") if ahead else None
        self._pending: dict[int, Future] = {}  # distinct frame -> its maps being rendered ahead
        self.last_frame = math.inf  # frames past this one are not rendered ahead (the walk's end)
        self.keep, self.compact = keep, compact and keep
        self.version = 0
        self._kept: dict[int, tuple] = {}  # distinct frame -> maps (arrays maybe float16)
        self._k = -1
        self.maps: CollisionMaps | None = None
        self._vmax = 0.0
        self._vmax_of: dict[tuple, float] = {}  # (distinct frame, root velocity) -> the body's fastest point relative to the root
        self._root_v = np.zeros(3)
        self._k_serial = 0
        self._t = 0.0
        self._shift_t = 0.0
        self._offset = np.zeros(3)
        self._n = -1
        self.stats = {"renders": 0, "reuses": 0, "map_seconds": 0.0, "map_bytes": 0, "asked": 0, "points": 0,
                      "render_seconds": 0.0}
        self._normals_body = Body(track.body.vertices, track.body.faces)
        # A kept frame's maps are expanded into one of two buffer sets (float32 surf, vel, and
        # their depth pairs): the set of the frame in use (_use), and the other, into which the
        # helper thread expands the next frame's while the solver works on this one (_prepared:
        # (frame, future)) -- the frame switch then only waits for it (_frame_maps)
        self._sets: list[list] = [[None, None, None], [None, None, None]]
        self._use = 0
        self._prepared: tuple[int, Future] | None = None
        self._zz32 = None  # a rendered frame's depth pairs (CollisionMaps.depth_pairs)
        # the query server (prefetch), and the arguments of its kernel while it serves a frame's maps
        self.server = SpinServer("query-server")
        self.helper = helper_default() if helper is None else helper
        self.help_wait = HELP_WAIT
        self.stalls = StallWatch()
        self.last_asked = 0
        self._served = None
        self._pts = self._pre_pts = np.zeros((0, 3))  # the points asked for (the caller's arrays)
        self._posted = False  # a query request posted and not yet known to be answered (_finish)
        # the rows of the points asked that are face points, made here (fill_faces); none by default
        self._n_vertices = np.int64(2 ** 62)
        self._quads, self._tris = np.zeros((0, 4), np.int32), np.zeros((0, 3), np.int32)

    def _frame_maps(self, k: int) -> CollisionMaps:
        kept = self._kept.get(k)
        t0 = time.perf_counter()
        if kept is not None:
            self.stats["reuses"] += 1
            maps = kept[0]
            if self.compact:  # into the buffer set not in use (expanded ahead, or now)
                spare = 1 - self._use
                prep, self._prepared = self._prepared, None
                if prep is not None:
                    prep[1].result()  # (it writes into the spare set: wait for it either way)
                    if prep[0] != k:  # expanded for another frame (the track jumped)
                        self._let_go(self._kept[prep[0]][0])
                        prep = None
                if prep is None:
                    self._fill(k, spare)
                self._use = spare
                self.stats["map_seconds"] += time.perf_counter() - t0
                return maps
            return self._with_depth_pairs(maps)
        if self._pool is not None:  # rendered ahead (or now, in the helper thread)
            fut = self._pending.pop(k, None) or self._pool.submit(self._render, k)
            maps, kept, took = fut.result()
        else:
            maps, kept, took = self._render(k)
        self._count_render(k, maps, kept, took)
        # (the float16 copies included; rendered ahead: only the wait for them)
        self.stats["map_seconds"] += time.perf_counter() - t0
        return self._with_depth_pairs(maps)

    def _count_render(self, k: int, maps: CollisionMaps, kept, took: float) -> None:
        self.stats["renders"] += 1
        self.stats["render_seconds"] += took
        if kept is not None:
            self.stats["map_bytes"] += kept[1].nbytes + kept[2].nbytes + maps.kind.nbytes + maps.side_src.nbytes
            self._kept[k] = kept

    def prerender(self, last: int, progress=None) -> float:
        """Render now the maps of every distinct track frame of frames 0 .. last and keep them
        (float16 when compact) -- a periodic walk's ramp and one cycle -- so that the walk
        itself only expands kept copies (`keep` must be set). Rendered ahead, in the helper
        thread (its GL context), else in this one; progress(done, total) after each. Returns
        the seconds it took."""
        if not self.keep:
            raise ValueError("prerender: maps that are not kept would be rendered again")
        t0 = time.perf_counter()
        todo = []
        for i in range(last + 1):
            k = self.track.index(i)[0]
            if k not in self._kept and k not in todo:
                todo.append(k)
        for n, k in enumerate(todo):
            if self._pool is not None:
                maps, kept, took = (self._pending.pop(k, None) or self._pool.submit(self._render, k)).result()
            else:
                maps, kept, took = self._render(k)
            self._count_render(k, maps, kept, took)
            if self.compact and k != self._k:  # keep the float16 copies only (expanded when used)
                self._let_go(maps)
            if progress is not None:
                progress(n + 1, len(todo))
        return time.perf_counter() - t0

    def _render(self, k: int):
        """Frame k's maps (and their kept copy): (maps, kept or None, seconds it took)."""
        t0 = time.perf_counter()
        if self.renderer is None:
            self.renderer = self._make_renderer()
        v = self.track.frames[k].astype(np.float64)
        self._normals_body.vertices = v
        maps = self.renderer.render(v, self._normals_body.vertex_normals(), self.track.vel[k].astype(np.float64))
        kept = None
        if self.keep:
            kept = (maps, _compacted(maps.surf), _compacted(maps.vel)) if self.compact else \
                (maps, maps.surf, maps.vel)
        else:  # (dropped with the maps; rendered ahead, they are made in the helper thread)
            maps.depth_pairs  # noqa: B018
        return maps, kept, time.perf_counter() - t0

    def _fill(self, k: int, j: int) -> None:
        """Frame k's kept float16 maps expanded into buffer set j, with their depth pairs (in
        the helper thread ahead of time, or in this one at the frame switch)."""
        maps, surf, vel = self._kept[k]
        b = self._sets[j]
        maps.surf = b[0] = _expanded(surf, b[0])
        maps.vel = b[1] = _expanded(vel, b[1])
        maps.surf_changed(b[2])
        b[2] = maps.depth_pairs  # made now (into b[2] when it has the shape)

    @staticmethod
    def _let_go(maps: CollisionMaps) -> None:
        """Kept (compact) maps let go of their float32 buffers (they keep the float16 copies)."""
        maps.surf_changed()
        maps.surf = maps.vel = None

    def _prepare_ahead(self, i: int) -> None:
        """Start expanding the maps of frame i, if kept, into the spare buffer set."""
        k, _ = self.track.index(i)
        if self.compact and k != self._k and k in self._kept and i <= self.last_frame:
            self._prepared = (k, self._pool.submit(self._fill, k, 1 - self._use))

    def _render_ahead(self, i: int) -> None:
        """Start rendering the maps of frame i (if neither kept nor on their way)."""
        k, _ = self.track.index(i)
        if k != self._k and k not in self._kept and k not in self._pending and i <= self.last_frame:
            self._pending[k] = self._pool.submit(self._render, k)

    def _with_depth_pairs(self, maps: CollisionMaps) -> CollisionMaps:
        """The frame's depth pairs go into one buffer for all frames (one frame's maps are in use;
        kept frames keep none) -- unless made with the maps (_render, maps not kept)."""
        if maps.depth_pairs_ready:
            return maps
        if self._zz32 is None or self._zz32.shape[:2] != maps.surf.shape[:2]:
            self._zz32 = np.zeros(maps.surf.shape[:2] + (2,), np.float32)
        maps.surf_changed(self._zz32)
        return maps

    def set_time(self, t: float) -> None:
        """Put the body at time t (s): the nearest frame's maps, the root offset at t."""
        tr = self.track
        i = int(round(max(t, 0.0) * tr.fps))
        k, _ = tr.index(i)
        if k != self._k:
            self._stop_server()  # (it reads this frame's maps)
            if self.maps is not None:  # (its depth-pair buffer goes to another frame)
                if self.compact:
                    self._let_go(self.maps)
                else:
                    self.maps.surf_changed()
            self.maps = self._frame_maps(k)
            self._k = k
            if self._pool is not None:
                self._render_ahead(i + 1)
                self._prepare_ahead(i + 1)
            self._root_v = tr.root_velocity(i)
            key = (k, *self._root_v.tolist())  # (a periodic walk comes back to the same pairs)
            self._vmax = self._vmax_of.get(key)
            if self._vmax is None:  # (~0.2 ms over the default body's 13k vertices: once per pair)
                rel = tr.vel[k].astype(np.float64) - self._root_v
                self._vmax = self._vmax_of[key] = float(np.sqrt(np.einsum("ij,ij->i", rel, rel).max()))
            self._k_serial += 1  # answers from other maps are not carried over
            if self.helper and self._n > 0:  # the server starts on these maps now, not at the first query
                self._served = self._job()
                self.server.start(self._served)
        self._shift_t = t - i / tr.fps
        self._t = t
        self._offset = tr.offset_at(t)
        self.version += 1  # every step: the body moves

    def _alloc(self, n: int) -> None:
        self._stop_server()
        alloc_answers(self, n)
        # each point's last map answer: where (root frame), when, from which maps, penetration
        # then and the surface's normal speed relative to the root
        self.c_local = np.zeros((n, 3))
        self.c_time = np.zeros(n)
        self.c_frame = np.full(n, -1, np.int64)
        self.c_pen = np.zeros(n)
        self.c_un = np.zeros(n)
        self.c_surf = np.zeros(n, np.uint8)

    def fill_faces(self, n_vertices: int, quads: np.ndarray, tris: np.ndarray) -> None:
        """From now on the rows of the points asked (query, prefetch) from n_vertices on are the
        faces' points -- each quad's midpoint, then each triangle's centroid, of the vertex rows
        (engine.cloth.kernels_contact.collision_points) -- and this collider makes them: the caller
        writes the vertex rows only. Each query's chunk makes its own face points (_face_point),
        so on the query server's thread for the chunks it answers, instead of on the solver's
        before every query (the solver asks for this: engine.cloth.solver). The same frames bit
        for bit."""
        self._stop_server()
        self._n_vertices = np.int64(n_vertices)
        self._quads = np.ascontiguousarray(quads, dtype=np.int32)
        self._tris = np.ascontiguousarray(tris, dtype=np.int32)

    def prefetch(self, points: np.ndarray, later: float) -> bool:
        """Have `points` -- where the cloth's points are predicted to be `later` seconds from now,
        at the next collision check -- answered by the query server (module doc) while the
        solver steps on: the answers go into each point's carried answer (_query_cached), so the
        query at that check asks the maps itself only for the points that ended up elsewhere.
        The server serves one frame's maps and is stopped when the frame changes (set_time).
        Skipped (False) when that time falls in another frame or the points are not the
        queried ones. `points` is read while the caller steps on: it must stay unchanged until
        the next query or prefetch (the solver writes its predicted points only then)."""
        if self.maps is None or points.shape[0] != self._n:
            return False
        tr = self.track
        t = self._t + later
        i = int(round(max(t, 0.0) * tr.fps))
        if tr.index(i)[0] != self._k:
            return False
        self._finish()  # (the last request's answers)
        self._pre_pts = self._served_points(points, self._pre_pts)
        self._post(0, t, t - i / tr.fps, tr.offset_at(t))
        return True

    def _post(self, which: int, t: float, shift_t: float, offset: np.ndarray) -> None:
        """Post a query of the points (which 0: the prefetched ones, 1: the queried ones; world,
        `offset` the root's) at time t, shift_t from this frame's maps, in chunks that the query
        server's thread and this one claim (_work): the server starts on it at once; _finish
        answers the rest and waits."""
        sv = self.server
        if self._served is None:  # (None at every change of maps, set_time, and of arrays, _alloc)
            self._served = self._job()
        if self.helper and not sv.running_on(self._served):
            sv.start(self._served)
        ctl, par = sv.ctl, sv.par
        ctl[WHICH] = which
        ctl[SERIAL] = self._k_serial
        par[0], par[1], par[2], par[3], par[4] = t, self.tol, self._vmax * abs(shift_t), shift_t, self._vmax
        par[5:8] = self._root_v
        par[8:11] = offset
        sv.post_chunks(-(-self._n // CHUNK), launch=self.helper)
        self._posted = True

    def _finish(self) -> None:
        """Answer what the server's thread has not claimed of the last request, and wait for
        the chunks it holds."""
        if not self._posted:
            return
        lost = after_help(self.server.help(self._served, self.help_wait), self.stalls if self.helper else None)
        self._posted = False
        if lost:  # the machine has no core for it: answer alone from now on
            self.helper = False
            self.stats["helper_let_go_at"] = self._t
            self.server.stop()
        self.last_asked = int(self.server.ctl[ASKED])  # (points the request asked the maps for)
        self.stats["asked"] += self.last_asked

    def _served_points(self, points: np.ndarray, current: np.ndarray) -> np.ndarray:
        """The array the server is to read the caller's points from: the caller's own (float64,
        C order; else a copy), and when it is not the one the server reads, the server stops (it
        starts again on the new one)."""
        if points is not current or not (points.flags.c_contiguous and points.dtype == np.float64):
            self._stop_server()
            return np.ascontiguousarray(points, dtype=np.float64)
        return current

    def _job(self) -> TrackJob:
        """The query server's job on this frame's maps: the prefetched and the queried points, the
        maps, the carried answers and the answers."""
        return TrackJob(self.server.par, self._pre_pts, self._pts, self._n_vertices, self._quads, self._tris,
                        self.maps.kernel_args(),
                        (self.c_local, self.c_time, self.c_frame, self.c_pen, self.c_un, self.c_surf),
                        (self.status, self.surface, self.depth, self.normal, self.velocity, self.map_index))

    def _stop_server(self) -> None:
        """Stop serving this frame's maps (its answers are in the carried arrays)."""
        self._finish()
        self.server.stop()
        self._served = None

    def query(self, points: np.ndarray):
        self._finish()
        if points.shape[0] != self._n:
            self._alloc(points.shape[0])
        self._pts = self._served_points(points, self._pts)
        self._post(1, self._t, self._shift_t, self._offset)
        self._finish()
        self.stats["points"] += points.shape[0]
        return self.status, self.normal, self.velocity, self.depth

    def release(self) -> None:
        """Let go of the kept maps; end the query server's thread; with ahead, end the helper
        thread (its renderer and context)."""
        self._stop_server()
        self.server.close()
        self.stats["query_chunks"] = {"server": int(self.server.ctl[SERVER_CHUNKS]),
                                      "solver": int(self.server.ctl[SOLVER_CHUNKS])}
        if self._pool is not None:
            for fut in self._pending.values():
                fut.cancel()
            self._pending.clear()
            if self._prepared is not None:
                self._prepared[1].cancel()
                self._prepared = None
            self._pool.submit(self._end_thread).result()
            self._pool.shutdown(wait=True)
            self._pool = None
        self._kept.clear()
        self.maps = None

    def _end_thread(self) -> None:
        if self.renderer is not None:
            self.renderer.release()
            self.renderer = None
        drop_thread_context()


@serial_kernel
def _shift_answers(status, depth, normal, velocity, root_v, shift_t, tol):
    """Object-space answers for a surface moved by (velocity - root_v) * shift_t along its normal
    (depth = tol - signed distance, exact for every point)."""
    for i in range(status.shape[0]):
        un = ((velocity[i, 0] - root_v[0]) * normal[i, 0] + (velocity[i, 1] - root_v[1]) * normal[i, 1]
              + (velocity[i, 2] - root_v[2]) * normal[i, 2])
        d = depth[i] + un * shift_t
        depth[i] = d
        status[i] = 2 if d > tol else (1 if d > 0.0 else 0)


class TrackObjectCollider(Collider):
    """The object-space baseline on a moving body: the BVH over the body triangles is refitted
    to the nearest frame (relative to the root, like the maps), points move into the root's
    frame, and the surface between frames moves along its velocity as in TrackCollider."""

    solver_carries = False  # the body moves every step

    def __init__(self, track: BodyTrack, tol: float):
        from engine.collide.bvh import ObjectSpaceCollider

        self.track, self.tol = track, float(tol)
        self.inner = ObjectSpaceCollider(track.frames[0].astype(np.float64), track.body.faces, tolerance=tol,
                                         vertex_velocities=track.vel[0].astype(np.float64))
        self._k = 0
        self._shift_t = 0.0
        self._offset = np.zeros(3)
        self._root_v = np.zeros(3)
        self.version = 0
        self.stats = {"renders": 0, "reuses": 0, "map_seconds": 0.0, "map_bytes": 0, "asked": 0, "points": 0}

    def set_time(self, t: float) -> None:
        tr = self.track
        i = int(round(max(t, 0.0) * tr.fps))
        k, _ = tr.index(i)
        if k != self._k:
            t0 = time.perf_counter()
            self.inner.update(tr.frames[k].astype(np.float64), tr.vel[k].astype(np.float64))
            self.stats["map_seconds"] += time.perf_counter() - t0  # (the refit stands in for maps)
            self.stats["renders"] += 1
            self._k = k
            self._root_v = tr.root_velocity(i)
        self._shift_t = t - i / tr.fps
        self._offset = tr.offset_at(t)
        self.version += 1

    def query(self, points: np.ndarray):
        local = points - self._offset
        status, normal, velocity, depth = self.inner.query(local)
        _shift_answers(status, depth, normal, velocity, self._root_v, self._shift_t, self.tol)
        self.stats["asked"] += points.shape[0]
        self.stats["points"] += points.shape[0]
        return status, normal, velocity, depth
