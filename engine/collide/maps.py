"""Collision maps of a body frame (seed 003 §5, seed 000 §4), rendered with OpenGL.

Two orthographic cameras look at the body's bounding box: the front camera from +Z toward -Z,
the back camera from -Z toward +Z. Each sees depth (as world z), the interpolated surface
normal and (for a moving body) the interpolated surface velocity. Where the papers encode
normals into 8-bit colours (eqs. 7-10), we render into float32 colour targets, both at once
(multiple render targets), so no encoding is needed.

Layout. Every map pair lives in one float atlas so a frame costs one draw per camera per map
and ONE read-back per target. Map s is an H x W grid of square texels of size `texel`:
row i covers world y in [y0 + i*texel, y0 + (i+1)*texel) -- row 0 at the BOTTOM, as GL reads
it -- and column j covers x in [x0 + j*texel, ...). Its front block sits at atlas rows
[r0, r0+H), columns [cf, cf+W); its back block at columns [cb, cb+W) with cb = cf + W, on the
SAME grid (not mirrored: atlas[r0+i, cf+j] and atlas[r0+i, cb+j] cover the same world (x, y)
square), so one index serves both.

Side layer (seed 003 §5.4). The two cameras say nothing about points beside the silhouette,
so a ring of ceil(tol/texel) (>= 1) pixels around it is filled from the nearest body pixel:
its depths, velocity, and an outward in-plane normal (the in-plane part of the body's own
normals there, or the pixel-offset direction where that vanishes). The query kernel treats such a pixel as
the body's rim (see query.py).

Per-segment maps (DESIGN "Known weakness of two maps"): with segments, each chosen segment is
drawn alone into its own window (its bounding box + margin), same texel; a face belongs to
every segment one of its vertices belongs to, so segment seams have no holes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from engine.body.types import SEGMENT_ID, SEGMENTS, Body
from engine.collide.gl import GL, compile_program, ensure_context, read_pixels, thread_context
from engine.errors import InputError
from engine.jit import njit, serial_kernel

KIND_EMPTY, KIND_BODY, KIND_SIDE = 0, 1, 2
SEGMENT_GROWTH_RINGS = 0  # rings a segment map reaches into its neighbours; 3 closed the armpit
# crease (7.7 mm penetration) but let the arm maps push shoulder straps off while sewing: off


@njit(cache=True, nogil=True)
def _depth_pairs(surf, layout, zz):
    """zz[r, c] = (front z, back z) for every front-block pixel (CollisionMaps.depth_pairs)."""
    for m in range(layout.shape[0]):
        h, w, r0, cf, cb = layout[m, 0], layout[m, 1], layout[m, 2], layout[m, 3], layout[m, 4]
        for i in range(r0, r0 + h):
            for j in range(w):
                zz[i, cf + j, 0] = surf[i, cf + j, 3]
                zz[i, cf + j, 1] = surf[i, cb + j, 3]


@dataclass
class CollisionMaps:
    """Front/back depth, normal and velocity maps of one body frame, packed for numba.

    surf:       (Ha, Wa, 4) float32 atlas; channels nx, ny, nz, z (world z of the surface the
                camera sees). Empty pixels: normal 0, z = -inf in front blocks, +inf in back blocks.
    vel:        (Ha, Wa, 4) float32 atlas; vx, vy, vz (m/s), unused. Shape (1, 1, 4) zeros when
                has_velocity is False. Atlas pixels outside every map block are undefined.
    kind:       (Ha, Wa) int8, indexed at FRONT-block positions: 0 empty, 1 body, 2 side layer.
    side_src:   (Ha, Wa) int32, at front-block positions: flat atlas index r*Wa + c of the
                nearest body pixel of a side-layer pixel, else -1.
    geom:       (S, 3) float64 per map: x0, y0, texel (world position of the grid's corner).
    layout:     (S, 5) int32 per map: H, W, r0, cf, cb (see module doc).
    segment_ids:(S,) int32 index into SEGMENTS, -1 for a whole-body map.
    zrange:     (S, 2) float64 per map: z of the back and front camera planes (bbox + margin).
    texel, tol: metres. window: (y_min, y_max) height range or None (whole body).
    """

    surf: np.ndarray
    vel: np.ndarray
    kind: np.ndarray
    side_src: np.ndarray
    geom: np.ndarray
    layout: np.ndarray
    segment_ids: np.ndarray
    zrange: np.ndarray
    texel: float
    tol: float
    has_velocity: bool
    window: tuple[float, float] | None = None
    backend: str = ""
    notes: list[str] = field(default_factory=list)

    @property
    def count(self) -> int:
        return int(self.layout.shape[0])

    @property
    def names(self) -> list[str]:
        return ["body" if s < 0 else SEGMENTS[s] for s in self.segment_ids]

    def kernel_args(self) -> tuple:
        """The eight map arrays, in order, of query.query_point_into / query_batch."""
        return (self.surf, self.vel, self.has_velocity, self.kind, self.side_src,
                self.geom, self.layout, self.depth_pairs)

    @property
    def depth_pairs(self) -> np.ndarray:
        """(Ha, Wa, 2) float32 at front-block positions: the front and the back depth (surf's z
        of the front block and of the back block) side by side, made from `surf` when first
        asked after surf changed. The query reads depths for every point it asks and the rest
        of surf only for contacts: two depths in one cache line instead of two 16-byte texels
        a block apart (the maps' cache footprint for the depth tests is an eighth)."""
        zz = self.__dict__.get("_zz")
        if zz is None or self.__dict__.get("_zz_of") is not self.surf:  # (surf_changed: rewritten in place)
            if zz is None or zz.shape[:2] != self.surf.shape[:2]:
                zz = np.zeros(self.surf.shape[:2] + (2,), np.float32)
            _depth_pairs(self.surf, self.layout, zz)
            self.__dict__["_zz"], self.__dict__["_zz_of"] = zz, self.surf
        return zz

    @property
    def depth_pairs_ready(self) -> bool:
        """Whether depth_pairs are made for the present surf (asking for them costs nothing)."""
        return self.__dict__.get("_zz") is not None and self.__dict__.get("_zz_of") is self.surf

    def surf_changed(self, buffer: np.ndarray | None = None) -> None:
        """Say that surf was rewritten in place (or dropped): depth_pairs are made again when
        next asked, into `buffer` when it has the shape, else into a new array (None also lets
        go of the old one: a kept frame's maps keep no depth pairs)."""
        self.__dict__["_zz"], self.__dict__["_zz_of"] = buffer, None

    # Views of one map (no copies); all (H, W[, C]) with row 0 at the bottom.
    def _block(self, a, s, back):
        h, w, r0, cf, cb = self.layout[s]
        c = cb if back else cf
        return a[r0:r0 + h, c:c + w]

    def front_depth(self, s: int = 0) -> np.ndarray:
        return self._block(self.surf, s, False)[..., 3]

    def back_depth(self, s: int = 0) -> np.ndarray:
        return self._block(self.surf, s, True)[..., 3]

    def front_normal(self, s: int = 0) -> np.ndarray:
        return self._block(self.surf, s, False)[..., :3]

    def back_normal(self, s: int = 0) -> np.ndarray:
        return self._block(self.surf, s, True)[..., :3]

    def front_velocity(self, s: int = 0) -> np.ndarray | None:
        return self._block(self.vel, s, False)[..., :3] if self.has_velocity else None

    def back_velocity(self, s: int = 0) -> np.ndarray | None:
        return self._block(self.vel, s, True)[..., :3] if self.has_velocity else None

    def kind_map(self, s: int = 0) -> np.ndarray:
        return self._block(self.kind, s, False)

    def pixel_centres(self, s: int = 0) -> tuple[np.ndarray, np.ndarray]:
        """(X, Y): (H, W) float64 world x and y of the pixel centres of map s."""
        x0, y0, t = self.geom[s]
        h, w = self.layout[s, :2]
        return np.meshgrid(x0 + (np.arange(w) + 0.5) * t, y0 + (np.arange(h) + 0.5) * t)


_VERTEX = """#version 330 core
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec3 a_nrm;
layout(location = 2) in vec3 a_vel;
uniform vec4 u_xy;   // ndc.xy = pos.xy * u_xy.xy + u_xy.zw  (the map's window)
uniform vec2 u_z;    // ndc.z  = pos.z * u_z.x + u_z.y       (front or back camera)
out vec3 v_nrm;
out vec3 v_vel;
out float v_z;
void main() {
    v_nrm = a_nrm;
    v_vel = a_vel;
    v_z = a_pos.z;
    gl_Position = vec4(a_pos.xy * u_xy.xy + u_xy.zw, a_pos.z * u_z.x + u_z.y, 1.0);
}
"""

_FRAGMENT = """#version 330 core
in vec3 v_nrm;
in vec3 v_vel;
in float v_z;
layout(location = 0) out vec4 o_surf;
layout(location = 1) out vec4 o_vel;
void main() {
    float l = length(v_nrm);
    // World z goes into the float target directly: the same value the depth buffer holds,
    // already in metres, and it saves reading the depth buffer back.
    o_surf = vec4(l > 0.0 ? v_nrm / l : vec3(0.0), v_z);
    o_vel = vec4(v_vel, 0.0);
}
"""


def _ring_width(tol: float, texel: float) -> int:
    return max(1, int(math.ceil(tol / texel - 1e-9)))


class MapRenderer:
    """Keeps the GL objects (program, VAO, buffers, FBO) of one body's maps alive between
    frames, so a frame costs upload + draw + one read-back per target.

        r = MapRenderer(body.faces, texel=0.005, with_velocity=True)
        for verts, vels in frames:                       # (N, 3) arrays per body frame
            maps = r.render(verts, normals_of(verts), vels)
            result = query_points(maps, cloth_points)
        r.release()

    faces: (F, 3) int; segments: (N,) uint8 labels into SEGMENTS (needed when segment_names
    is given); segment_names: segments to render each into its own map pair, or None for one
    whole-body pair; window: (y_min, y_max) height range or None; tol: collision tolerance (m)
    that sets the side-layer width; extent: the vertices whose bounding box the whole-body map
    covers (default: those of its faces) -- the maps of a body less some parts on the same texel
    grid as the whole body's answer a point away from those parts exactly as they do.
    """

    def __init__(self, faces: np.ndarray, *, segments: np.ndarray | None = None,
                 segment_names: list[str] | None = None, texel: float = 0.005,
                 tol: float = 0.005, window: tuple[float, float] | None = None,
                 with_velocity: bool = False, own_context: bool = False, extent: np.ndarray | None = None):
        if not texel > 0 or not tol >= 0:
            raise InputError(f"texel ({texel}) must be > 0 and tol ({tol}) >= 0")
        if window is not None and not window[1] > window[0]:
            raise InputError(f"window {window}: need y_min < y_max")
        self.texel, self.tol, self.window = float(texel), float(tol), window
        self.with_velocity = with_velocity
        self.ring = _ring_width(tol, texel)
        faces = np.ascontiguousarray(faces, dtype=np.uint32)
        self.n_vertices = int(faces.max()) + 1 if len(faces) else 0

        # Face subsets, one per map: the whole body, or each chosen segment.
        if segment_names is None:
            subsets, seg_ids = [faces], [-1]
        else:
            if segments is None:
                raise InputError("segment maps need per-vertex segment labels and this body has none (scans are not segmented yet): leave out --segments to map the whole body")
            subsets, seg_ids = [], []
            for name in segment_names:
                if name not in SEGMENT_ID:
                    raise InputError(f"unknown segment '{name}'; choose from {', '.join(SEGMENTS)}")
                sid = SEGMENT_ID[name]
                # grow the segment a few rings into its neighbours: at a joint (the armpit
                # crease) each segment's open cut would otherwise leave cloth between two slabs
                mask = np.asarray(segments) == sid
                for _ in range(SEGMENT_GROWTH_RINGS):
                    touch = mask[faces].any(axis=1)
                    mask[faces[touch].ravel()] = True
                sel = mask[faces].any(axis=1)
                if not sel.any():
                    raise InputError(f"segment '{name}' has no faces on this body")
                subsets.append(faces[sel])
                seg_ids.append(sid)
        self.segment_ids = np.array(seg_ids, np.int32)
        self._subset_vertices = [np.unique(f).astype(np.int64) for f in subsets]
        if extent is not None and segment_names is None:  # (the whole-body map's window: see the doc)
            self._subset_vertices = [np.asarray(extent, np.int64)]
        self._ranges = []                       # (byte offset, index count) in the index buffer
        off = 0
        for f in subsets:
            self._ranges.append((off * 4, f.size))
            off += f.size
        indices = np.concatenate([f.ravel() for f in subsets])

        # own_context: the calling thread's private context (gl.thread_context), for a renderer
        # made and used in a helper thread only
        self._context = thread_context if own_context else ensure_context
        self.info = self._context()
        self._prog = compile_program(_VERTEX, _FRAGMENT)
        self._u_xy = GL.glGetUniformLocation(self._prog, "u_xy")
        self._u_z = GL.glGetUniformLocation(self._prog, "u_z")
        self._vao = GL.glGenVertexArrays(1)
        GL.glBindVertexArray(self._vao)
        self._vbo = GL.glGenBuffers(3)
        for loc in range(3 if with_velocity else 2):
            GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self._vbo[loc])
            GL.glBufferData(GL.GL_ARRAY_BUFFER, self.n_vertices * 12, None, GL.GL_STREAM_DRAW)
            GL.glVertexAttribPointer(loc, 3, GL.GL_FLOAT, GL.GL_FALSE, 0, None)
            GL.glEnableVertexAttribArray(loc)
        if not with_velocity:
            GL.glVertexAttrib3f(2, 0.0, 0.0, 0.0)
        self._ebo = GL.glGenBuffers(1)
        GL.glBindBuffer(GL.GL_ELEMENT_ARRAY_BUFFER, self._ebo)   # recorded in the VAO
        GL.glBufferData(GL.GL_ELEMENT_ARRAY_BUFFER, indices.nbytes, indices, GL.GL_STATIC_DRAW)
        GL.glBindVertexArray(0)
        self._fbo = None
        self._cap = (0, 0)
        self._one = np.ones(1, np.float32)
        self._last_depth = None
        self._max_size = int(GL.glGetIntegerv(GL.GL_MAX_RENDERBUFFER_SIZE))

    # --- layout -------------------------------------------------------------------------
    def _layout(self, vertices: np.ndarray):
        """Per map: window geometry and atlas position, from this frame's bounding boxes."""
        t, margin = self.texel, (self.ring + 1) * self.texel
        geom, lay, zr, keep = [], [], [], []
        x_cursor = y_cursor = shelf_h = 0
        for s, vidx in enumerate(self._subset_vertices):
            lo, hi = _bbox(vertices, vidx)
            x0, x1 = lo[0] - margin, hi[0] + margin
            y0, y1 = lo[1] - margin, hi[1] + margin
            if self.window is not None:
                y0, y1 = max(y0, self.window[0]), min(y1, self.window[1])
                if self.segment_ids[s] < 0:     # whole body: exactly the asked range
                    y0, y1 = self.window
                if y1 <= y0:
                    continue                     # this segment lies outside the height range
            w = max(1, int(math.ceil((x1 - x0) / t - 1e-6)))   # no extra texel from rounding
            h = max(1, int(math.ceil((y1 - y0) / t - 1e-6)))
            if 2 * w > self._max_size or h > self._max_size:
                raise InputError(f"map of {h}x{w} texels exceeds the GL limit {self._max_size}; "
                                 f"use a larger texel than {t} m")
            if x_cursor + 2 * w > self._max_size:        # next shelf of the atlas
                x_cursor, y_cursor, shelf_h = 0, y_cursor + shelf_h, 0
            geom.append((x0, y0, t))
            lay.append((h, w, y_cursor, x_cursor, x_cursor + w))
            dz = max(hi[2] - lo[2], t)
            zr.append((lo[2] - 0.01 * dz - t, hi[2] + 0.01 * dz + t))
            keep.append(s)
            x_cursor += 2 * w
            shelf_h = max(shelf_h, h)
        if not keep:
            raise InputError(f"nothing of the body lies in the height window {self.window}")
        lay = np.array(lay, np.int32)
        size = (int((lay[:, 2] + lay[:, 0]).max()), int((lay[:, 3] + 2 * lay[:, 1]).max()))
        return (np.array(geom, np.float64), lay, np.array(zr, np.float64), keep, size)

    def _ensure_fbo(self, h: int, w: int) -> None:
        if h <= self._cap[0] and w <= self._cap[1]:
            return
        # Grow with slack so a walking body's changing bounding box rarely reallocates.
        ch, cw = min(self._max_size, int(h * 1.1) + 8), min(self._max_size, int(w * 1.1) + 8)
        self._free_fbo()
        self._fbo = GL.glGenFramebuffers(1)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self._fbo)
        self._rbo = GL.glGenRenderbuffers(3)
        fmts = (GL.GL_RGBA32F, GL.GL_RGBA32F, GL.GL_DEPTH_COMPONENT32F)
        atts = (GL.GL_COLOR_ATTACHMENT0, GL.GL_COLOR_ATTACHMENT1, GL.GL_DEPTH_ATTACHMENT)
        for rb, fmt, att in zip(self._rbo, fmts, atts):
            GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, rb)
            GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, fmt, cw, ch)
            GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, att, GL.GL_RENDERBUFFER, rb)
        st = GL.glCheckFramebufferStatus(GL.GL_FRAMEBUFFER)
        if st != GL.GL_FRAMEBUFFER_COMPLETE:
            raise RuntimeError(f"collision-map framebuffer incomplete (status 0x{st:x})")
        self._cap = (ch, cw)

    def _free_fbo(self) -> None:
        if self._fbo is not None:
            GL.glDeleteFramebuffers(1, [self._fbo])
            GL.glDeleteRenderbuffers(3, self._rbo)
            self._fbo = None
            self._cap = (0, 0)

    # --- one frame ------------------------------------------------------------------------
    def render(self, vertices: np.ndarray, normals: np.ndarray,
               velocities: np.ndarray | None = None) -> CollisionMaps:
        """Maps of one body frame. vertices, normals, velocities: (N, 3) float (world frame;
        normals unit; velocities m/s, required iff the renderer was made with_velocity)."""
        if (velocities is not None) != self.with_velocity:
            raise InputError("velocities must be given exactly when the renderer has velocity maps")
        vertices = np.asarray(vertices, np.float64)
        if vertices.shape[0] < self.n_vertices:
            raise InputError(f"{vertices.shape[0]} vertices, but faces index {self.n_vertices}")
        self._context()
        geom, lay, zr, keep, (ha, wa) = self._layout(vertices)
        self._ensure_fbo(ha, wa)

        GL.glBindVertexArray(self._vao)
        arrays = [vertices, normals] + ([velocities] if self.with_velocity else [])
        for loc, a in enumerate(arrays):
            a32 = np.ascontiguousarray(a, dtype=np.float32)
            GL.glBindBuffer(GL.GL_ARRAY_BUFFER, self._vbo[loc])
            # Re-specify (orphan) instead of sub-updating: the driver needs no sync with the
            # previous frame's draw.
            GL.glBufferData(GL.GL_ARRAY_BUFFER, a32.nbytes, a32, GL.GL_STREAM_DRAW)

        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, self._fbo)
        n_targets = 2 if self.with_velocity else 1
        GL.glDrawBuffers(n_targets, [GL.GL_COLOR_ATTACHMENT0, GL.GL_COLOR_ATTACHMENT1][:n_targets])
        # Each camera needs only the faces turned toward it: on a closed, outward-wound body the
        # nearest surface always faces the camera, and through the open cut of a segment mesh a
        # camera must not see that segment's inside. The back camera keeps the front's x, y (its
        # image is mirrored), so faces turned toward it wind clockwise on screen: cull GL_FRONT.
        GL.glEnable(GL.GL_CULL_FACE)
        GL.glFrontFace(GL.GL_CCW)
        GL.glDisable(GL.GL_BLEND)
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glDepthFunc(GL.GL_LESS)            # both cameras map their near plane to depth 0
        GL.glDepthMask(GL.GL_TRUE)
        GL.glColorMask(True, True, True, True)
        # Only depth is cleared (to 1 = far; coverage is read from it): _finish_maps
        # overwrites every uncovered colour pixel, and clearing two float targets would
        # cost llvmpipe more than the draws. The scissor keeps the clear to the used atlas.
        GL.glEnable(GL.GL_SCISSOR_TEST)
        GL.glScissor(0, 0, wa, ha)
        GL.glClearBufferfv(GL.GL_DEPTH, 0, self._one)
        GL.glDisable(GL.GL_SCISSOR_TEST)
        GL.glUseProgram(self._prog)
        for m, s in enumerate(keep):
            h, w, r0, cf, cb = (int(v) for v in lay[m])
            x0, y0, t = geom[m]
            sx, sy = 2.0 / (w * t), 2.0 / (h * t)
            GL.glUniform4f(self._u_xy, sx, sy, -1.0 - x0 * sx, -1.0 - y0 * sy)
            zb, zf = zr[m]
            d = zf - zb
            offset, count = self._ranges[s]
            # front camera at z = zf looking toward -z: depth = (zf - z) / d
            GL.glViewport(cf, r0, w, h)
            GL.glCullFace(GL.GL_BACK)
            GL.glUniform2f(self._u_z, -2.0 / d, 2.0 * zf / d - 1.0)
            GL.glDrawElements(GL.GL_TRIANGLES, count, GL.GL_UNSIGNED_INT, GL.GLvoidp(offset))
            # back camera at z = zb looking toward +z: depth = (z - zb) / d; same x, y mapping,
            # so the back block is on the front's grid (un-mirrored)
            GL.glViewport(cb, r0, w, h)
            GL.glCullFace(GL.GL_FRONT)
            GL.glUniform2f(self._u_z, 2.0 / d, -2.0 * zb / d - 1.0)
            GL.glDrawElements(GL.GL_TRIANGLES, count, GL.GL_UNSIGNED_INT, GL.GLvoidp(offset))

        surf = np.empty((ha, wa, 4), np.float32)
        GL.glReadBuffer(GL.GL_COLOR_ATTACHMENT0)
        read_pixels(0, 0, surf, GL.GL_RGBA, GL.GL_FLOAT)
        if self.with_velocity:
            vel = np.empty((ha, wa, 4), np.float32)
            GL.glReadBuffer(GL.GL_COLOR_ATTACHMENT1)
            read_pixels(0, 0, vel, GL.GL_RGBA, GL.GL_FLOAT)
        else:
            vel = np.zeros((1, 1, 4), np.float32)
        depth = np.empty((ha, wa, 1), np.float32)
        read_pixels(0, 0, depth, GL.GL_DEPTH_COMPONENT, GL.GL_FLOAT)
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        GL.glBindVertexArray(0)
        self._last_depth = depth

        kind = np.empty((ha, wa), np.int8)
        side_src = np.empty((ha, wa), np.int32)
        if len(keep) > 1:  # segment maps: pixels where a segment's open mesh has one side only
            _complete_one_sided(surf, vel, self.with_velocity, depth, depth.copy(), lay, geom)
        _finish_maps(surf, vel, self.with_velocity, depth, lay, self.ring, kind, side_src)
        return CollisionMaps(surf=surf, vel=vel, kind=kind, side_src=side_src, geom=geom,
                             layout=lay, segment_ids=self.segment_ids[keep].copy(), zrange=zr,
                             texel=self.texel, tol=self.tol, has_velocity=self.with_velocity,
                             window=self.window, backend=self.info.backend)

    def read_depth_z(self, maps: CollisionMaps) -> np.ndarray:
        """World z from the DEPTH buffer of the last frame, (Ha, Wa) float32, NaN where empty:
        a check that the z written to the colour target matches seed 003's eq. for z-buffer
        depth (tests use it; the hot path reads depth only for coverage)."""
        ha, wa = maps.kind.shape
        depth = self._last_depth
        out = np.full((ha, wa), np.nan, np.float32)
        for m in range(maps.count):
            h, w, r0, cf, cb = maps.layout[m]
            zb, zf = maps.zrange[m]
            d = depth[r0:r0 + h, :, 0]
            f, b = d[:, cf:cf + w], d[:, cb:cb + w]
            out[r0:r0 + h, cf:cf + w] = np.where(f < 1.0, zf - f * (zf - zb), np.nan)
            out[r0:r0 + h, cb:cb + w] = np.where(b < 1.0, zb + b * (zf - zb), np.nan)
        return out

    def release(self) -> None:
        """Delete the GL objects (the context itself stays for the process)."""
        if self._prog:
            self._free_fbo()
            GL.glDeleteBuffers(3, self._vbo)
            GL.glDeleteBuffers(1, [self._ebo])
            GL.glDeleteVertexArrays(1, [self._vao])
            GL.glDeleteProgram(self._prog)
            self._prog = 0


@njit(cache=True)
def _bbox(vertices, idx):
    """(lo, hi) (3,) float64 bounding box of vertices[idx] without the fancy-index copy."""
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for k in range(idx.shape[0]):
        for c in range(3):
            x = vertices[idx[k], c]
            lo[c] = min(lo[c], x)
            hi[c] = max(hi[c], x)
    return lo, hi


@njit(cache=True, nogil=True)
def _complete_one_sided(surf, vel, has_vel, depth, depth0, layout, geom):
    """Segment maps render each segment's own triangles, and each camera only the triangles
    turned toward it, so where the segments' open meshes meet (the shoulder: the deltoid's front
    belongs to the arm, the upper back to the torso) a pixel can be covered by one camera only.
    Such a pixel borrows the missing side from another segment map that has it at the same
    world (x, y) -- the body there spans the torso's back face to the arm's front face -- and
    is dropped (left empty) when none has it. depth0 is an unmodified copy of depth."""
    nm = layout.shape[0]
    for m in range(nm):
        h, w, r0, cf, cb = layout[m, 0], layout[m, 1], layout[m, 2], layout[m, 3], layout[m, 4]
        x0, y0, t = geom[m, 0], geom[m, 1], geom[m, 2]
        for i in range(h):
            r = r0 + i
            for j in range(w):
                cov_f = depth0[r, cf + j, 0] < 1.0
                cov_b = depth0[r, cb + j, 0] < 1.0
                if cov_f == cov_b:
                    continue
                miss = cb if cov_f else cf  # column base of the missing side in map m
                x = x0 + (j + 0.5) * t
                y = y0 + (i + 0.5) * t
                found = False
                for m2 in range(nm):
                    if m2 == m:
                        continue
                    h2, w2, r2, cf2, cb2 = (layout[m2, 0], layout[m2, 1], layout[m2, 2], layout[m2, 3],
                                            layout[m2, 4])
                    u = (x - geom[m2, 0]) / geom[m2, 2]
                    v = (y - geom[m2, 1]) / geom[m2, 2]
                    if not (u >= 0.0 and v >= 0.0 and u < w2 and v < h2):
                        continue
                    rr = r2 + int(v)
                    cc = (cb2 if cov_f else cf2) + int(u)
                    if depth0[rr, cc, 0] < 1.0:
                        for k in range(4):
                            surf[r, miss + j, k] = surf[rr, cc, k]
                        if has_vel:
                            for k in range(4):
                                vel[r, miss + j, k] = vel[rr, cc, k]
                        depth[r, miss + j, 0] = 0.5
                        found = True
                        break
                if not found:
                    depth[r, cf + j, 0] = 1.0
                    depth[r, cb + j, 0] = 1.0


@serial_kernel(fastmath=False)  # (the maps as before bit for bit)
def _finish_maps(surf, vel, has_vel, depth, layout, ring, kind, side_src):
    """Classify pixels, build the side layer, and define every non-body pixel of every block.

    Coverage comes from the depth buffer (< 1 where a triangle was drawn; front and back
    blocks cover the same pixels: same triangles, same x-y projection), so the colour targets
    need no clear: every empty pixel is overwritten here. The nearest body pixel within `ring`
    (Euclidean, pixel centres) is found separably: nearest body column per row first, then
    the best row -- exact, and (2*ring+1) reads per pixel instead of (2*ring+1)^2.
    One thread: in parallel over rows, each parallel region waits for the other core's thread."""
    wa = surf.shape[1]
    for m in range(layout.shape[0]):
        h, w, r0, cf, cb = layout[m, 0], layout[m, 1], layout[m, 2], layout[m, 3], layout[m, 4]
        near = np.empty((h, w), np.int32)           # nearest body column in the row, or -1
        for i in range(h):
            for j in range(w):
                near[i, j] = -1
        for i in range(h):
            r = r0 + i
            last = -(1 << 30)
            for j in range(w):
                body = depth[r, cf + j, 0] < 1.0
                kind[r, cf + j] = 1 if body else 0
                side_src[r, cf + j] = -1
                if body:
                    last = j
                if j - last <= ring:
                    near[i, j] = last
            nxt = 1 << 30
            for j in range(w - 1, -1, -1):
                if kind[r, cf + j] == 1:
                    nxt = j
                if nxt - j <= ring and (near[i, j] < 0 or nxt - j < j - near[i, j]):
                    near[i, j] = nxt
        for i in range(h):
            r = r0 + i
            for j in range(w):
                if kind[r, cf + j] == 1:
                    continue
                best, bi, bj = ring * ring + 1, -1, -1
                for ii in range(max(0, i - ring), min(h, i + ring + 1)):
                    jj = near[ii, j]
                    if jj >= 0:
                        d2 = (ii - i) * (ii - i) + (jj - j) * (jj - j)
                        if d2 < best:
                            best, bi, bj = d2, ii, jj
                if bi < 0:
                    for c, zempty in ((cf, -np.inf), (cb, np.inf)):
                        surf[r, c + j, 0] = 0.0
                        surf[r, c + j, 1] = 0.0
                        surf[r, c + j, 2] = 0.0
                        surf[r, c + j, 3] = zempty
                        if has_vel:
                            vel[r, c + j, 0] = 0.0
                            vel[r, c + j, 1] = 0.0
                            vel[r, c + j, 2] = 0.0
                    continue
                kind[r, cf + j] = 2
                side_src[r, cf + j] = (r0 + bi) * wa + cf + bj
                # Outward in-plane normal: at a smooth rim the body's own normals already
                # point outward, so use the in-plane part of front + back normal of the
                # source pixel (accurate for round limbs); where that vanishes (a face
                # parallel to the cameras, e.g. a box) use the pixel offset direction.
                sx = surf[r0 + bi, cf + bj, 0] + surf[r0 + bi, cb + bj, 0]
                sy = surf[r0 + bi, cf + bj, 1] + surf[r0 + bi, cb + bj, 1]
                ls = math.sqrt(sx * sx + sy * sy)
                ox, oy = float(j - bj), float(i - bi)
                lo = math.sqrt(ox * ox + oy * oy)
                if ls > 0.3 and (sx * ox + sy * oy) > 0.0:
                    nx, ny = sx / ls, sy / ls
                else:
                    nx, ny = ox / lo, oy / lo
                for c in (cf, cb):          # same pixel in the front and the back block
                    surf[r, c + j, 0] = nx
                    surf[r, c + j, 1] = ny
                    surf[r, c + j, 2] = 0.0
                    surf[r, c + j, 3] = surf[r0 + bi, c + bj, 3]
                    if has_vel:
                        for k in range(3):
                            vel[r, c + j, k] = vel[r0 + bi, c + bj, k]


def render_body_maps(body: Body, texel: float = 0.005, window: tuple[float, float] | None = None,
                     segments: list[str] | None = None, velocities: np.ndarray | None = None,
                     tol: float = 0.005, vertices: np.ndarray | None = None,
                     extent: np.ndarray | None = None) -> CollisionMaps:
    """One-off maps of a body (a renderer made, used once and released).

    vertices: (N, 3) positions of this frame (default: the body's rest vertices);
    velocities: (N, 3) m/s or None (no velocity maps); segments: names from SEGMENTS to map
    each separately, or None for the whole body; window: (y_min, y_max) or None; extent: see
    MapRenderer."""
    verts = body.vertices if vertices is None else np.asarray(vertices, np.float64)
    normals = Body(verts, body.faces).vertex_normals()
    r = MapRenderer(body.faces, segments=body.segments, segment_names=segments, texel=texel,
                    tol=tol, window=window, with_velocity=velocities is not None, extent=extent)
    try:
        return r.render(verts, normals, velocities)
    finally:
        r.release()
