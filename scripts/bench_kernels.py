"""Benchmark: the cloth step's hot kernels compiled as engine.jit.serial_kernel against plain
@njit (the reason serial_kernel exists). Prints ns per spring for the velocity modification and
ns per point for a map query, both ways; results must be identical.

    .venv/bin/python scripts/bench_kernels.py
"""

from __future__ import annotations

import time
import warnings

import numpy as np
from numba import njit

from engine.body import resolve_body
from engine.cloth import kernels_strain as KS
from engine.collide.maps import render_body_maps
from engine.collide.query import query_batch_serial

warnings.simplefilter("ignore")


def _time(fn, reps=20):
    fn()
    t = time.perf_counter()
    for _ in range(reps):
        fn()
    return (time.perf_counter() - t) / reps


def main() -> None:
    rng = np.random.default_rng(0)
    n, s = 4000, 16000
    springs = rng.integers(0, n, (s, 2)).astype(np.int32)
    x = rng.normal(size=(n, 3))
    v0 = rng.normal(size=(n, 3))
    rest = np.linalg.norm(x[springs[:, 1]] - x[springs[:, 0]], axis=1) * 0.9
    args = (springs, rest, np.ones(s, np.bool_), 0.05, KS.VM_AVERAGE, np.array([0, -9.81, 0.0]), 1e-4,
            np.zeros((n, 3)), 12, np.zeros(s, np.int32), np.zeros((s, 4)), np.zeros((s, 2), np.int32), 0.002)
    print(f"{'kernel':<28}{'plain @njit':>14}{'serial_kernel':>16}{'speed-up':>10}")
    out = {}
    for name, fn in (("plain", njit(fastmath=True)(KS.modify_velocities.py_func)), ("serial", KS.modify_velocities)):
        v = v0.copy()
        out[name] = (_time(lambda: fn(x, v0.copy(), *args)), fn(x, v, *args), v)
    assert np.array_equal(out["plain"][2], out["serial"][2])
    per = 1e9 / (s * 12)
    print(f"{'velocity modification':<28}{out['plain'][0] * per:>11.1f} ns{out['serial'][0] * per:>13.1f} ns"
          f"{out['plain'][0] / out['serial'][0]:>9.1f}x   (per spring and pass)")

    body = resolve_body("default:female")
    maps = render_body_maps(body, texel=0.005, window=(0.0, 1.2), segments=["torso", "left_leg", "right_leg"])
    idx = rng.integers(0, len(body.vertices), 7000)
    pts = body.vertices[idx] + rng.normal(0, 0.01, (7000, 3))
    m = len(pts)
    res = [(np.zeros(m, np.int8), np.zeros((m, 3)), np.zeros(m), np.zeros((m, 3)), np.zeros((m, 3)),
            np.zeros(m, np.int32)) for _ in range(2)]
    plain = njit(query_batch_serial.py_func)
    t_plain = _time(lambda: plain(pts, 0.005, *maps.kernel_args(), *res[0]))
    t_serial = _time(lambda: query_batch_serial(pts, 0.005, *maps.kernel_args(), *res[1]))
    assert all(np.array_equal(a, b) for a, b in zip(*res))
    print(f"{'map query (3 segment maps)':<28}{t_plain / m * 1e9:>11.1f} ns{t_serial / m * 1e9:>13.1f} ns"
          f"{t_plain / t_serial:>9.1f}x   (per point near the body)")


if __name__ == "__main__":
    main()
