"""The engine's numba decorators (every kernel file takes them from here), and atomic array reads
and writes for kernels that hand work between threads (imports numba only; the bottom of the engine).

`serial_kernel` compiles with numba's parallel pipeline switched on, although the kernels have
no prange and run on one thread: the same serial loop compiled this way runs several times
faster, bit for bit (docs/tuning.md, `serial_kernel`). A kernel so decorated must hold no array
expression or np.zeros/np.ones (numba would turn those into parallel loops on its thread pool,
which stall when another process holds a core): take buffers from the caller, or allocate with
np.empty and fill in a loop.

The on-disk cache of an engine kernel is keyed by the text of its file and of every kernel file
that file imports, directly or not (KernelCacheLocator): a kernel inlines helpers from other
files, and numba's own key (the defining file's time stamp) would let a kernel compiled against
an old helper run silently.
"""

from __future__ import annotations

import ast
import hashlib
import warnings
from functools import lru_cache
from pathlib import Path

import numba
from numba import njit, prange  # noqa: F401  (re-exported: kernel files take numba's decorators from here)
from numba.core.caching import CacheImpl, InTreeCacheLocator
from numba.core.errors import NumbaPerformanceWarning

# "parallel=True was specified but no transformation for parallel execution was possible":
# that is the point here
warnings.filterwarnings("ignore", category=NumbaPerformanceWarning, message=r"(?s).*parallel=True.*")

ENGINE = Path(__file__).resolve().parent


@lru_cache(maxsize=None)
def kernel_sources(root: Path = ENGINE) -> tuple[Path, ...]:
    """The engine's files that define numba kernels (they import their decorators from engine.jit)."""
    return tuple(sorted(p for p in root.rglob("*.py")
                        if p.name == "jit.py" or "from engine.jit import" in p.read_text(encoding="utf-8")))


def _imported_files(path: Path, root: Path) -> set[Path]:
    """The engine files that `path` imports (from engine.x import ..., import engine.x)."""
    out = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        names = [node.module] if isinstance(node, ast.ImportFrom) and node.module else \
            [a.name for a in node.names] if isinstance(node, ast.Import) else []
        for name in names:
            parts = name.split(".")
            if parts[0] != "engine":
                continue
            base = root.joinpath(*parts[1:])
            for f in (base.with_suffix(".py"), base / "__init__.py"):
                if f.is_file():
                    out.add(f.resolve())
    return out


@lru_cache(maxsize=None)
def kernel_stamp(path: Path, root: Path = ENGINE) -> str:
    """The cache key of the kernels in `path`: a hash of its text and of every kernel file it
    imports, directly or through other kernel files, with numba's version."""
    kernels = {p.resolve() for p in kernel_sources(root)}
    seen, todo = set(), [path.resolve()]
    while todo:
        f = todo.pop()
        if f in seen:
            continue
        seen.add(f)
        todo += [g for g in _imported_files(f, root) if g in kernels]
    h = hashlib.sha256(numba.__version__.encode())
    for f in sorted(seen):
        h.update(f.relative_to(root.resolve()).as_posix().encode() + b"\0" + f.read_bytes() + b"\0")
    return h.hexdigest()


class KernelCacheLocator(InTreeCacheLocator):
    """numba's in-tree cache (beside the source, in __pycache__) for the engine's kernels, stamped
    with kernel_stamp instead of the defining file's time stamp and size."""

    @classmethod
    def from_function(cls, py_func, py_file):
        try:
            Path(py_file).resolve().relative_to(ENGINE)
        except ValueError:
            return None
        return super().from_function(py_func, py_file)

    def get_source_stamp(self):
        return kernel_stamp(Path(self._py_file))


if KernelCacheLocator not in CacheImpl._locator_classes:
    CacheImpl._locator_classes.insert(0, KernelCacheLocator)


def serial_kernel(fn=None, *, fastmath: bool = True, error_model: str = "python"):
    """@serial_kernel or @serial_kernel(fastmath=False): njit(cache=True, parallel=True, nogil=True, ...)
    (nogil: another Python thread -- the walk's map renderer -- runs while a kernel does).
    error_model="numpy": a division by zero gives inf/nan instead of raising, which lets LLVM
    vectorize a loop that divides (the check is a branch in every iteration)."""
    def wrap(f):
        return njit(cache=True, fastmath=fastmath, parallel=True, error_model=error_model, nogil=True)(f)
    return wrap(fn) if fn is not None else wrap


from numba import types as _types  # noqa: E402
from numba.core import cgutils as _cgutils  # noqa: E402
from numba.extending import intrinsic as _intrinsic  # noqa: E402
from numba.extending import overload  # noqa: E402, F401  (re-exported)

nbtypes = _types  # (re-exported: numba's types, for overloads)


def _item_pointer(context, builder, signature, args):
    aryty = signature.args[0]
    ary = context.make_array(aryty)(context, builder, args[0])
    i = context.cast(builder, args[1], signature.args[1], _types.intp)
    return _cgutils.get_item_pointer(context, builder, aryty, ary, [i], wraparound=False)


@_intrinsic
def atomic_load(typingctx, arr, i):
    """atomic_load(a, i) inside a kernel: a[i] (a 1-D int64 array) read with acquire ordering --
    read from memory every time (a plain read in a loop may be read once), and what the thread
    that stored it wrote before is visible after. With atomic_store, two threads hand work to
    each other through an array without the GIL (engine.collide.moving's query server)."""
    sig = arr.dtype(arr, i)

    def codegen(context, builder, signature, args):
        return builder.load_atomic(_item_pointer(context, builder, signature, args), "acquire", 8)

    return sig, codegen


@_intrinsic
def atomic_store(typingctx, arr, i, value):
    """atomic_store(a, i, value) inside a kernel: a[i] = value with release ordering (everything
    this thread wrote before is visible to a thread that atomic_loads the value)."""
    sig = _types.void(arr, i, value)

    def codegen(context, builder, signature, args):
        value = context.cast(builder, args[2], signature.args[2], signature.args[0].dtype)
        builder.store_atomic(value, _item_pointer(context, builder, signature, args), "release", 8)
        return context.get_dummy_value()

    return sig, codegen


@_intrinsic
def atomic_add(typingctx, arr, i, value):
    """atomic_add(a, i, value) inside a kernel: a[i] += value as one indivisible step (acquire
    and release ordering); returns the value a[i] had before. Two threads counting into the
    same word lose no count (engine.collide.moving: chunks of a shared query finished)."""
    sig = arr.dtype(arr, i, value)

    def codegen(context, builder, signature, args):
        value = context.cast(builder, args[2], signature.args[2], signature.args[0].dtype)
        return builder.atomic_rmw("add", _item_pointer(context, builder, signature, args), value, "acq_rel")

    return sig, codegen


@_intrinsic
def atomic_cas(typingctx, arr, i, expected, value):
    """atomic_cas(a, i, expected, value) inside a kernel: if a[i] == expected, a[i] = value, as
    one indivisible step (acquire and release ordering); returns whether it did. Of two
    threads claiming the same word's next value, exactly one succeeds (engine.collide.moving:
    chunks of a shared query claimed)."""
    sig = _types.boolean(arr, i, expected, value)

    def codegen(context, builder, signature, args):
        ty = signature.args[0].dtype
        exp = context.cast(builder, args[2], signature.args[2], ty)
        value = context.cast(builder, args[3], signature.args[3], ty)
        pair = builder.cmpxchg(_item_pointer(context, builder, signature, args), exp, value, "acq_rel", "acquire")
        return builder.extract_value(pair, 1)

    return sig, codegen


@_intrinsic
def cycle_counter(typingctx):
    """cycle_counter() inside a kernel: the processor's time-stamp counter (int64 ticks at a fixed
    rate, ~3e9 a second here; LLVM's readcyclecounter) -- a clock for a spinning kernel to give
    up waiting after a while."""
    sig = _types.int64()

    def codegen(context, builder, signature, args):
        from llvmlite import ir

        fn = _cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.IntType(64), []),
                                             "llvm.readcyclecounter")
        return builder.call(fn, [])

    return sig, codegen


@_intrinsic
def spin_pause(typingctx):
    """spin_pause() inside a kernel's wait loop: the x86 PAUSE instruction (LLVM's
    llvm.x86.sse2.pause; nothing elsewhere) -- tells the processor this is a spin-wait, so it
    leaves more of the core to a thread sharing it and leaves the loop without a penalty."""
    sig = _types.void()

    def codegen(context, builder, signature, args):
        import platform

        from llvmlite import ir

        if platform.machine().lower() in ("x86_64", "amd64", "i386", "i686"):
            fn = _cgutils.get_or_insert_function(builder.module, ir.FunctionType(ir.VoidType(), []),
                                                 "llvm.x86.sse2.pause")
            builder.call(fn, [])
        return context.get_dummy_value()

    return sig, codegen
