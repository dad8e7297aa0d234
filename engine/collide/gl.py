"""One headless OpenGL context per process (and one per helper thread that asks for its own):
EGL surfaceless first, OSMesa as the fallback.

PyOpenGL binds its function loader to a platform (PYOPENGL_PLATFORM) the first time
`OpenGL.platform` is imported, and that cannot change afterwards. So this module decides the
backend and sets PYOPENGL_PLATFORM *before* it imports OpenGL; every engine module that draws
imports GL from here (`from engine.collide.gl import GL, ensure_context`). Consequences:
  - the backend is fixed per process; to use the other one, start a process with TRYON_GL set
    (engine.settings: read once)
    (tests and the benchmark do this with subprocess.run);
  - never fork a process after a context exists (use spawn) -- Mesa's threads do not survive it.

Choice, in order: an already-set PYOPENGL_PLATFORM (egl or osmesa), else TRYON_GL=egl|osmesa,
else a ctypes probe of EGL's surfaceless platform (no PyOpenGL involved, so a failed probe
still leaves OSMesa open), else OSMesa.

The context is created lazily by `ensure_context()` and reused. It renders only into our own
framebuffer objects (no window surface). Use it from one thread at a time. A helper thread that
renders while another keeps that context (the walk's maps rendered ahead) makes its own with
`thread_context()` and ends it with `drop_thread_context()`; GL objects stay with the context
they were made in.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import os
import sys
import threading
from dataclasses import dataclass

from engine.errors import GLUnavailableError, InputError
from engine.settings import current

_APT_HINT = ("install Mesa's headless drivers: apt-get install libegl1 libegl-mesa0 libgl1-mesa-dri "
             "libgbm1 libopengl0 (EGL) or libosmesa6 (OSMesa)")
_EGL_PLATFORM_SURFACELESS_MESA = 0x31DD
_BACKENDS = ("egl", "osmesa")


def _probe_egl() -> str | None:
    """Return None when an EGL surfaceless display initialises, else why not (one line)."""
    name = ctypes.util.find_library("EGL") or "libEGL.so.1"
    try:
        egl = ctypes.CDLL(name)
    except OSError as e:
        return f"libEGL not loadable ({e})"
    egl.eglGetProcAddress.restype = ctypes.c_void_p
    egl.eglGetProcAddress.argtypes = [ctypes.c_char_p]
    addr = egl.eglGetProcAddress(b"eglGetPlatformDisplayEXT")
    if not addr:
        return "EGL has no eglGetPlatformDisplayEXT"
    get_display = ctypes.CFUNCTYPE(ctypes.c_void_p, ctypes.c_uint, ctypes.c_void_p,
                                   ctypes.c_void_p)(addr)
    dpy = get_display(_EGL_PLATFORM_SURFACELESS_MESA, None, None)
    if not dpy:
        return "EGL_MESA_platform_surfaceless display not available"
    egl.eglInitialize.argtypes = [ctypes.c_void_p, ctypes.c_void_p, ctypes.c_void_p]
    major, minor = ctypes.c_int(), ctypes.c_int()
    if not egl.eglInitialize(ctypes.c_void_p(dpy), ctypes.byref(major), ctypes.byref(minor)):
        return "eglInitialize failed on the surfaceless display"
    # Left initialised on purpose: the display is a per-process singleton that the real
    # context creation below initialises again (a no-op on an initialised display).
    return None


def _decide_backend() -> tuple[str, list[str]]:
    """(backend, notes on what was tried)."""
    notes: list[str] = []
    preset = os.environ.get("PYOPENGL_PLATFORM", "").strip().lower()
    forced = current().gl or ""
    if forced and forced not in _BACKENDS:
        raise GLUnavailableError(f"TRYON_GL={forced!r}: use egl or osmesa")
    if preset:
        if preset not in _BACKENDS:
            raise GLUnavailableError(
                f"PYOPENGL_PLATFORM={preset!r} is set, but headless rendering needs egl or osmesa; "
                "unset it or set TRYON_GL")
        if forced and forced != preset:
            raise GLUnavailableError(f"PYOPENGL_PLATFORM={preset} conflicts with TRYON_GL={forced}")
        return preset, [f"PYOPENGL_PLATFORM={preset} was already set"]
    if forced:
        return forced, [f"TRYON_GL={forced}"]
    why = _probe_egl()
    if why is None:
        return "egl", ["EGL surfaceless probe ok"]
    notes.append(f"EGL: {why}")
    return "osmesa", notes


if "OpenGL.platform" in sys.modules and "PYOPENGL_PLATFORM" not in os.environ:
    # Someone imported PyOpenGL before us with its default (windowed) platform.
    _DECISION_ERROR: GLUnavailableError | None = GLUnavailableError(
        "PyOpenGL was imported before engine.collide.gl with no PYOPENGL_PLATFORM; import "
        "engine.collide.gl first or set PYOPENGL_PLATFORM=egl|osmesa")
    BACKEND, _NOTES = "none", []
else:
    try:
        BACKEND, _NOTES = _decide_backend()
        os.environ["PYOPENGL_PLATFORM"] = BACKEND
        _DECISION_ERROR = None
    except (GLUnavailableError, InputError) as e:  # InputError: a bad TRYON_* setting
        BACKEND, _NOTES, _DECISION_ERROR = "none", [], e

from OpenGL import GL  # noqa: E402  (must follow the platform decision above)


@dataclass
class ContextInfo:
    backend: str        # "egl" or "osmesa"
    version: str        # GL_VERSION string
    renderer: str       # GL_RENDERER string, e.g. "llvmpipe (LLVM 15.0.6, 256 bits)"


_lock = threading.Lock()
_ctx: dict = {}          # the one context: {"handle":..., "info": ContextInfo, "keep": [...]}


def _create_egl() -> dict:
    from OpenGL import EGL
    from OpenGL.EGL.EXT.platform_base import eglGetPlatformDisplayEXT

    dpy = eglGetPlatformDisplayEXT(_EGL_PLATFORM_SURFACELESS_MESA, EGL.EGL_DEFAULT_DISPLAY, None)
    major, minor = EGL.EGLint(), EGL.EGLint()
    if not dpy or not EGL.eglInitialize(dpy, ctypes.pointer(major), ctypes.pointer(minor)):
        raise RuntimeError("eglInitialize failed")
    if not EGL.eglBindAPI(EGL.EGL_OPENGL_API):
        raise RuntimeError("eglBindAPI(EGL_OPENGL_API) failed")
    attrs = (EGL.EGLint * 5)(EGL.EGL_RENDERABLE_TYPE, EGL.EGL_OPENGL_BIT,
                             EGL.EGL_SURFACE_TYPE, 0, EGL.EGL_NONE)
    cfg, n = EGL.EGLConfig(), EGL.EGLint()
    if not EGL.eglChooseConfig(dpy, attrs, ctypes.pointer(cfg), 1, ctypes.pointer(n)) or n.value < 1:
        raise RuntimeError("no EGL config with EGL_OPENGL_BIT")
    ctx = EGL.EGL_NO_CONTEXT
    for ver in ((4, 5), (3, 3)):   # core profile: the newest Mesa offers, at least 3.3
        cattrs = (EGL.EGLint * 7)(EGL.EGL_CONTEXT_MAJOR_VERSION, ver[0],
                                  EGL.EGL_CONTEXT_MINOR_VERSION, ver[1],
                                  EGL.EGL_CONTEXT_OPENGL_PROFILE_MASK,
                                  EGL.EGL_CONTEXT_OPENGL_CORE_PROFILE_BIT, EGL.EGL_NONE)
        try:
            ctx = EGL.eglCreateContext(dpy, cfg, EGL.EGL_NO_CONTEXT, cattrs)
        except Exception:  # PyOpenGL raises EGLError on failure
            ctx = EGL.EGL_NO_CONTEXT
        if ctx:
            break
    if not ctx:
        raise RuntimeError("eglCreateContext (OpenGL 3.3+ core) failed")
    if not EGL.eglMakeCurrent(dpy, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, ctx):
        raise RuntimeError("eglMakeCurrent (surfaceless) failed")

    def make_current():
        return EGL.eglMakeCurrent(dpy, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, ctx)

    def destroy():
        EGL.eglMakeCurrent(dpy, EGL.EGL_NO_SURFACE, EGL.EGL_NO_SURFACE, EGL.EGL_NO_CONTEXT)
        EGL.eglDestroyContext(dpy, ctx)

    return {"handle": ctx, "make_current": make_current, "destroy": destroy, "keep": [dpy, cfg]}


def _create_osmesa() -> dict:
    import numpy as np
    from OpenGL import osmesa

    ctx = None
    for ver in ((4, 5), (3, 3)):
        attrs = (ctypes.c_int * 11)(osmesa.OSMESA_FORMAT, osmesa.OSMESA_RGBA,
                                    osmesa.OSMESA_DEPTH_BITS, 24,
                                    osmesa.OSMESA_PROFILE, osmesa.OSMESA_CORE_PROFILE,
                                    osmesa.OSMESA_CONTEXT_MAJOR_VERSION, ver[0],
                                    osmesa.OSMESA_CONTEXT_MINOR_VERSION, ver[1], 0)
        ctx = osmesa.OSMesaCreateContextAttribs(attrs, None)
        if ctx:
            break
    if not ctx:
        raise RuntimeError("OSMesaCreateContextAttribs (OpenGL 3.3+ core) failed")
    # OSMesa needs a default framebuffer to make current; we draw into FBOs, so 4x4 suffices.
    buf = np.zeros((4, 4, 4), np.uint8)
    if not osmesa.OSMesaMakeCurrent(ctx, buf, GL.GL_UNSIGNED_BYTE, 4, 4):
        raise RuntimeError("OSMesaMakeCurrent failed")

    def make_current():
        return osmesa.OSMesaMakeCurrent(ctx, buf, GL.GL_UNSIGNED_BYTE, 4, 4)

    def destroy():
        osmesa.OSMesaDestroyContext(ctx)

    return {"handle": ctx, "make_current": make_current, "destroy": destroy, "keep": [buf]}


def _current_info() -> ContextInfo:
    """What the context current in this thread is."""
    return ContextInfo(BACKEND, GL.glGetString(GL.GL_VERSION).decode(), GL.glGetString(GL.GL_RENDERER).decode())


def ensure_context() -> ContextInfo:
    """Create the process's GL context on first use (later calls reuse it) and make it current
    in the calling thread. Raises GLUnavailableError naming what was tried."""
    if _DECISION_ERROR is not None:
        raise _DECISION_ERROR
    with _lock:
        if _ctx:
            if _ctx["thread"] != threading.get_ident():
                if not _ctx["make_current"]():
                    raise GLUnavailableError("the GL context is current in another thread; "
                                             "use GL from one thread at a time")
                _ctx["thread"] = threading.get_ident()
            return _ctx["info"]
        create = _create_egl if BACKEND == "egl" else _create_osmesa
        try:
            made = create()
        except Exception as e:
            tried = "; ".join(_NOTES + [f"{BACKEND}: {e}"])
            other = "osmesa" if BACKEND == "egl" else "egl"
            raise GLUnavailableError(
                f"no headless OpenGL context (tried {tried}). Try TRYON_GL={other} in a fresh "
                f"process, or {_APT_HINT}") from e
        info = _current_info()
        _ctx.update(made, info=info, thread=threading.get_ident())
        return info


_own = threading.local()  # a thread's private context (thread_context)


def thread_context() -> ContextInfo:
    """A context of the calling thread's own, made on its first call and current in it from then
    on: for a helper thread that renders while the main thread keeps the process's context
    (ensure_context) -- the walk's maps rendered a frame ahead (engine.collide.moving). GL
    objects made in it are that thread's alone. drop_thread_context() ends it."""
    if _DECISION_ERROR is not None:
        raise _DECISION_ERROR
    own = getattr(_own, "ctx", None)
    if own is not None:
        return own["info"]
    with _lock:  # (one creation at a time: EGL and OSMesa set-up is not thread safe)
        create = _create_egl if BACKEND == "egl" else _create_osmesa
        try:
            made = create()
        except Exception as e:
            raise GLUnavailableError(f"no second headless OpenGL context for a render thread ({BACKEND}: {e})") from e
    made["info"] = _current_info()
    _own.ctx = made
    return made["info"]


def drop_thread_context() -> None:
    """Destroy the calling thread's private context (thread_context), if it has one."""
    own = getattr(_own, "ctx", None)
    if own is not None:
        _own.ctx = None
        with _lock:
            own["destroy"]()


def backend() -> str:
    """The backend this process uses ("egl", "osmesa"; "none" when no choice was possible)."""
    return BACKEND


# --- small GL helpers shared by the map renderer and the picture renderer -----------------

def compile_program(vertex_src: str, fragment_src: str) -> int:
    """Compile and link a GLSL program; raises RuntimeError with the driver's log."""
    def stage(kind, src):
        s = GL.glCreateShader(kind)
        GL.glShaderSource(s, src)
        GL.glCompileShader(s)
        if not GL.glGetShaderiv(s, GL.GL_COMPILE_STATUS):
            raise RuntimeError(GL.glGetShaderInfoLog(s).decode())
        return s

    vs, fs = stage(GL.GL_VERTEX_SHADER, vertex_src), stage(GL.GL_FRAGMENT_SHADER, fragment_src)
    prog = GL.glCreateProgram()
    GL.glAttachShader(prog, vs)
    GL.glAttachShader(prog, fs)
    GL.glLinkProgram(prog)
    if not GL.glGetProgramiv(prog, GL.GL_LINK_STATUS):
        raise RuntimeError(GL.glGetProgramInfoLog(prog).decode())
    GL.glDeleteShader(vs)
    GL.glDeleteShader(fs)
    return prog


def read_pixels(x: int, y: int, out, fmt, gl_type) -> None:
    """glReadPixels straight into a preallocated C-contiguous NumPy array `out` (rows, cols,
    channels); rows come bottom-up as GL stores them. Uses the raw entry point to skip
    PyOpenGL's array wrapping (a copy per call)."""
    from OpenGL.raw.GL.VERSION.GL_1_0 import glReadPixels as raw_read

    assert out.flags.c_contiguous
    GL.glPixelStorei(GL.GL_PACK_ALIGNMENT, 1)
    raw_read(x, y, out.shape[1], out.shape[0], fmt, gl_type, ctypes.c_void_p(out.ctypes.data))
