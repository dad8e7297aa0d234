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

Map reuse (DESIGN: a periodic walk renders one cycle): maps are kept per distinct track frame
(the ramp, then one cycle), rendered on first use; `stats` counts renders and reuses. Kept maps
hold their float arrays in float16 when `compact` is set (half the memory; the depth error at
2 m is 1 mm, under the 5 mm texel), expanded to float32 when their frame comes up.
"""

from __future__ import annotations

import time

import numpy as np

from engine.body.motion import BodyTrack
from engine.body.types import Body
from engine.collide.maps import CollisionMaps, MapRenderer
from engine.collide.query import query_batch_serial
from engine.jit import serial_kernel


@serial_kernel
def _retime(status, penetration, normal, velocity, root_v, widened, shift_t, tol):
    """Re-classify map answers for a surface moved by (velocity - root_v) * shift_t along its
    normal (the maps move with the root; its own travel is applied exactly)."""
    for i in range(status.shape[0]):
        if status[i] == 0:
            continue
        un = ((velocity[i, 0] - root_v[0]) * normal[i, 0] + (velocity[i, 1] - root_v[1]) * normal[i, 1]
              + (velocity[i, 2] - root_v[2]) * normal[i, 2])
        p = penetration[i] - widened + un * shift_t
        penetration[i] = p
        if p > tol:
            status[i] = 2
        elif p > 0.0:
            status[i] = 1
        else:
            status[i] = 0


class TrackCollider:
    """Cloth points against a BodyTrack, through per-frame collision maps."""

    def __init__(self, track: BodyTrack, renderer: MapRenderer, tol: float, keep: bool = True,
                 compact: bool = True):
        """keep: keep each frame's maps for reuse (a periodic track); compact: keep them as float16."""
        self.track, self.renderer, self.tol = track, renderer, float(tol)
        self.keep, self.compact = keep, compact and keep
        self.version = 0
        self._kept: dict[int, tuple] = {}  # distinct frame -> maps (arrays maybe float16)
        self._k = -1
        self.maps: CollisionMaps | None = None
        self._vmax = 0.0
        self._root_v = np.zeros(3)
        self._shift_t = 0.0
        self._offset = np.zeros(3)
        self._n = -1
        self.stats = {"renders": 0, "reuses": 0, "map_seconds": 0.0, "map_bytes": 0}
        self._normals_body = Body(track.body.vertices, track.body.faces)

    def _frame_maps(self, k: int) -> CollisionMaps:
        kept = self._kept.get(k)
        if kept is not None:
            self.stats["reuses"] += 1
            maps, surf, vel = kept
            if self.compact:
                maps.surf = surf.astype(np.float32)
                maps.vel = vel.astype(np.float32)
            return maps
        t0 = time.perf_counter()
        v = self.track.frames[k].astype(np.float64)
        self._normals_body.vertices = v
        maps = self.renderer.render(v, self._normals_body.vertex_normals(), self.track.vel[k].astype(np.float64))
        self.stats["renders"] += 1
        self.stats["map_seconds"] += time.perf_counter() - t0
        if self.keep:
            kept = (maps, maps.surf.astype(np.float16), maps.vel.astype(np.float16)) if self.compact else \
                (maps, maps.surf, maps.vel)
            self.stats["map_bytes"] += kept[1].nbytes + kept[2].nbytes + maps.kind.nbytes + maps.side_src.nbytes
            self._kept[k] = kept
        return maps

    def set_time(self, t: float) -> None:
        """Put the body at time t (s): the nearest frame's maps, the root offset at t."""
        tr = self.track
        i = int(round(max(t, 0.0) * tr.fps))
        k, _ = tr.index(i)
        if k != self._k:
            if self.maps is not None and self.compact:
                self.maps.surf = self.maps.vel = None  # the float16 copies are kept
            self.maps = self._frame_maps(k)
            self._k = k
            self._root_v = (tr.offset(i + 1) - tr.offset(i - 1)) * tr.fps / 2 if i > 0 else \
                (tr.offset(1) - tr.offset(0)) * tr.fps
            rel = tr.vel[k].astype(np.float64) - self._root_v
            self._vmax = float(np.sqrt(np.einsum("ij,ij->i", rel, rel).max()))
        self._shift_t = t - i / tr.fps
        self._offset = tr.offset_at(t)
        self.version += 1  # every step: the body moves

    def _alloc(self, n: int) -> None:
        self.status = np.zeros(n, np.int8)
        self.surface = np.zeros((n, 3))
        self.depth = np.zeros(n)
        self.normal = np.zeros((n, 3))
        self.velocity = np.zeros((n, 3))
        self.map_index = np.zeros(n, np.int32)
        self.local = np.zeros((n, 3))
        self._n = n

    def query(self, points: np.ndarray):
        if points.shape[0] != self._n:
            self._alloc(points.shape[0])
        np.subtract(points, self._offset, out=self.local)
        widened = self._vmax * abs(self._shift_t)
        query_batch_serial(self.local, self.tol + widened, *self.maps.kernel_args(), self.status, self.surface,
                           self.depth, self.normal, self.velocity, self.map_index)
        _retime(self.status, self.depth, self.normal, self.velocity, self._root_v, widened, self._shift_t,
                self.tol)
        return self.status, self.normal, self.velocity, self.depth

    def release(self) -> None:
        self._kept.clear()
        self.maps = None
