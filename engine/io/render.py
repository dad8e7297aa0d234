"""Shaded pictures of meshes (a body, later a body plus garments) with the process's headless
GL context: orthographic camera framing the meshes, Lambert + ambient light from the camera's
upper front, two-sided (open garment panels show their inside), light background, 4x MSAA.

    img = render_meshes([(body.vertices, body.faces, (0.8, 0.7, 0.6)),
                         (cloth_xyz, cloth_tris, (0.2, 0.4, 0.8))], size=800, view="three")
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from engine.body.types import Body
from engine.collide.gl import GL, compile_program, ensure_context, read_pixels
from engine.errors import InputError

# Rows: screen right, screen up, toward the camera -- for each view (world: Y up, body faces +Z).
VIEWS = {
    "front": np.array([[1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float64),     # camera at +Z
    "back": np.array([[-1, 0, 0], [0, 1, 0], [0, 0, -1]], np.float64),    # camera at -Z
    "side": np.array([[0, 0, 1], [0, 1, 0], [-1, 0, 0]], np.float64),     # camera at -X, faces right
}
BODY_RGB = (0.80, 0.68, 0.58)
BACKGROUND = (0.94, 0.94, 0.95)

_VERTEX = """#version 330 core
layout(location = 0) in vec3 a_pos;
layout(location = 1) in vec3 a_nrm;
uniform mat3 u_rot;     // world -> view (rows: right, up, toward camera)
uniform vec3 u_scale;   // view -> NDC scale
uniform vec3 u_shift;   // view -> NDC shift
out vec3 v_nrm;
void main() {
    vec3 p = u_rot * a_pos;
    v_nrm = u_rot * a_nrm;
    // NDC z grows away from the camera, so the toward-camera axis is negated.
    gl_Position = vec4(p * u_scale + u_shift, 1.0);
}
"""

_FRAGMENT = """#version 330 core
in vec3 v_nrm;
uniform vec3 u_rgb;
out vec4 o_rgb;
void main() {
    vec3 n = normalize(v_nrm);
    if (!gl_FrontFacing) n = -n;            // two-sided: garment insides are lit too
    vec3 l = normalize(vec3(-0.35, 0.55, 1.0));   // from the camera's upper front (left)
    float lambert = max(dot(n, l), 0.0);
    o_rgb = vec4(u_rgb * (0.28 + 0.72 * lambert), 1.0);
}
"""

_prog: dict = {}


def _program() -> int:
    if "id" not in _prog:
        _prog["id"] = compile_program(_VERTEX, _FRAGMENT)
        _prog["u"] = {n: GL.glGetUniformLocation(_prog["id"], n)
                      for n in ("u_rot", "u_scale", "u_shift", "u_rgb")}
    return _prog["id"]


def _vertex_normals(v: np.ndarray, f: np.ndarray) -> np.ndarray:
    return Body(v, f).vertex_normals()


def _render_view(meshes, rot, lo, hi, height, samples, background) -> np.ndarray:
    """One view -> (H, W, 3) uint8, top row first. lo/hi: (3,) view-space box to frame."""
    span = hi - lo
    width = max(1, int(round(height * span[0] / span[1])))
    ms_fbo, ms_rb = GL.glGenFramebuffers(1), GL.glGenRenderbuffers(2)
    fbo, rb = GL.glGenFramebuffers(1), GL.glGenRenderbuffers(1)
    vao = GL.glGenVertexArrays(1)
    vbos = GL.glGenBuffers(3)
    try:
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, ms_fbo)
        for r, fmt, att in ((ms_rb[0], GL.GL_RGBA8, GL.GL_COLOR_ATTACHMENT0),
                            (ms_rb[1], GL.GL_DEPTH_COMPONENT24, GL.GL_DEPTH_ATTACHMENT)):
            GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, r)
            GL.glRenderbufferStorageMultisample(GL.GL_RENDERBUFFER, samples, fmt, width, height)
            GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, att, GL.GL_RENDERBUFFER, r)
        if GL.glCheckFramebufferStatus(GL.GL_FRAMEBUFFER) != GL.GL_FRAMEBUFFER_COMPLETE:
            raise RuntimeError("picture framebuffer incomplete")
        GL.glDrawBuffers(1, [GL.GL_COLOR_ATTACHMENT0])
        GL.glViewport(0, 0, width, height)
        GL.glEnable(GL.GL_DEPTH_TEST)
        GL.glDepthFunc(GL.GL_LESS)
        GL.glDepthMask(GL.GL_TRUE)
        GL.glDisable(GL.GL_CULL_FACE)
        GL.glDisable(GL.GL_SCISSOR_TEST)
        GL.glEnable(GL.GL_MULTISAMPLE)
        GL.glClearColor(*background, 1.0)
        GL.glClearDepth(1.0)
        GL.glClear(GL.GL_COLOR_BUFFER_BIT | GL.GL_DEPTH_BUFFER_BIT)

        prog = _program()
        u = _prog["u"]
        GL.glUseProgram(prog)
        GL.glUniformMatrix3fv(u["u_rot"], 1, GL.GL_TRUE, rot.astype(np.float32))
        scale = np.array([2 / span[0], 2 / span[1], -2 / span[2]], np.float32)
        shift = np.array([-1 - lo[0] * scale[0], -1 - lo[1] * scale[1], 1 - lo[2] * scale[2]],
                         np.float32)
        GL.glUniform3fv(u["u_scale"], 1, scale)
        GL.glUniform3fv(u["u_shift"], 1, shift)
        GL.glBindVertexArray(vao)
        for v, f, rgb in meshes:
            n = _vertex_normals(v, f)
            for loc, a in ((0, v), (1, n)):
                GL.glBindBuffer(GL.GL_ARRAY_BUFFER, vbos[loc])
                GL.glBufferData(GL.GL_ARRAY_BUFFER, np.ascontiguousarray(a, np.float32), GL.GL_STREAM_DRAW)
                GL.glVertexAttribPointer(loc, 3, GL.GL_FLOAT, GL.GL_FALSE, 0, None)
                GL.glEnableVertexAttribArray(loc)
            idx = np.ascontiguousarray(f, np.uint32)
            GL.glBindBuffer(GL.GL_ELEMENT_ARRAY_BUFFER, vbos[2])
            GL.glBufferData(GL.GL_ELEMENT_ARRAY_BUFFER, idx, GL.GL_STREAM_DRAW)
            GL.glUniform3f(u["u_rgb"], *[float(c) for c in rgb])
            GL.glDrawElements(GL.GL_TRIANGLES, idx.size, GL.GL_UNSIGNED_INT, None)
        GL.glBindVertexArray(0)

        # Resolve the multisampled picture, then read it.
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, fbo)
        GL.glBindRenderbuffer(GL.GL_RENDERBUFFER, rb)
        GL.glRenderbufferStorage(GL.GL_RENDERBUFFER, GL.GL_RGBA8, width, height)
        GL.glFramebufferRenderbuffer(GL.GL_FRAMEBUFFER, GL.GL_COLOR_ATTACHMENT0, GL.GL_RENDERBUFFER, rb)
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, ms_fbo)
        GL.glBindFramebuffer(GL.GL_DRAW_FRAMEBUFFER, fbo)
        GL.glBlitFramebuffer(0, 0, width, height, 0, 0, width, height,
                             GL.GL_COLOR_BUFFER_BIT, GL.GL_NEAREST)
        GL.glBindFramebuffer(GL.GL_READ_FRAMEBUFFER, fbo)
        GL.glReadBuffer(GL.GL_COLOR_ATTACHMENT0)
        img = np.empty((height, width, 4), np.uint8)
        read_pixels(0, 0, img, GL.GL_RGBA, GL.GL_UNSIGNED_BYTE)
        return np.ascontiguousarray(img[::-1, :, :3])
    finally:
        GL.glBindFramebuffer(GL.GL_FRAMEBUFFER, 0)
        GL.glDeleteBuffers(3, vbos)
        GL.glDeleteVertexArrays(1, [vao])
        GL.glDeleteFramebuffers(1, [ms_fbo])
        GL.glDeleteFramebuffers(1, [fbo])
        GL.glDeleteRenderbuffers(2, ms_rb)
        GL.glDeleteRenderbuffers(1, [rb])


def render_meshes(meshes, size: int = 800, view: str = "front", samples: int = 4,
                  background=BACKGROUND, margin: float = 0.05) -> np.ndarray:
    """Picture of meshes: list of (vertices (N, 3), faces (F, 3), rgb 3 floats in 0..1).
    view: front, side, back, or three (the three side by side, same scale).
    Returns (size, W, 3) uint8, top row first; W follows the framed extent."""
    if view not in ("front", "side", "back", "three"):
        raise InputError(f"view '{view}': use front, side, back or three")
    if not 16 <= size <= 8192:
        raise InputError(f"picture size {size}: use 16..8192 pixels")
    meshes = [(np.asarray(v, np.float64), np.asarray(f), rgb) for v, f, rgb in meshes]
    if not meshes or any(len(f) == 0 for _, f, _ in meshes):
        raise InputError("nothing to render: give at least one mesh with faces")
    ensure_context()
    samples = min(samples, int(GL.glGetIntegerv(GL.GL_MAX_SAMPLES)))
    allv = np.concatenate([v for v, _, _ in meshes])
    names = ["front", "side", "back"] if view == "three" else [view]
    boxes = []
    for name in names:
        p = allv @ VIEWS[name].T
        lo, hi = p.min(axis=0), p.max(axis=0)
        boxes.append((lo, hi))
    # Same vertical framing (and so the same scale) in every panel of "three".
    ylo = min(b[0][1] for b in boxes)
    yhi = max(b[1][1] for b in boxes)
    pad = margin * (yhi - ylo)
    panels = []
    for name, (lo, hi) in zip(names, boxes):
        lo, hi = lo.copy(), hi.copy()
        lo[0], hi[0] = lo[0] - pad, hi[0] + pad
        lo[1], hi[1] = ylo - pad, yhi + pad
        dz = max(hi[2] - lo[2], 1e-6)
        lo[2], hi[2] = lo[2] - 0.01 * dz, hi[2] + 0.01 * dz
        panels.append(_render_view(meshes, VIEWS[name], lo, hi, size, samples, background))
    return np.concatenate(panels, axis=1)


def render_body_png(body: Body, path: str | Path, size: int = 800, view: str = "front",
                    rgb=BODY_RGB) -> Path:
    """Write a shaded picture of the body (size = picture height in pixels) to a PNG."""
    from PIL import Image

    img = render_meshes([(body.vertices, body.faces, rgb)], size=size, view=view)
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(img).save(path)
    return path
