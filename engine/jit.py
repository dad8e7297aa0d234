"""The decorator for serial numba kernels (imports numba only; the bottom of the engine).

`serial_kernel` compiles with numba's parallel pipeline switched on, although the kernels have
no prange and run on one thread: measured on numba 0.68 (scripts/bench_kernels.py), the same
serial loop compiled this way runs 3-9x faster (the velocity modification: ~58 -> ~14 ns a
spring and pass; a map query near the body: ~430 -> ~50 ns a point) with bit-identical results. A kernel so
decorated must hold no array expression or np.zeros/np.ones (numba would turn those into
parallel loops on its thread pool, which stall when another process holds a core): take
buffers from the caller, or allocate with np.empty and fill in a loop.
"""

from __future__ import annotations

import warnings

from numba import njit
from numba.core.errors import NumbaPerformanceWarning

# "parallel=True was specified but no transformation for parallel execution was possible":
# that is the point here
warnings.filterwarnings("ignore", category=NumbaPerformanceWarning, message=r"(?s).*parallel=True.*")


def serial_kernel(fn=None, *, fastmath: bool = True, error_model: str = "python"):
    """@serial_kernel or @serial_kernel(fastmath=False): njit(cache=True, parallel=True, nogil=True, ...)
    (nogil: another Python thread -- the walk's map renderer -- runs while a kernel does).
    error_model="numpy": a division by zero gives inf/nan instead of raising, which lets LLVM
    vectorize a loop that divides (the check is a branch in every iteration)."""
    def wrap(f):
        return njit(cache=True, fastmath=fastmath, parallel=True, error_model=error_model, nogil=True)(f)
    return wrap(fn) if fn is not None else wrap
