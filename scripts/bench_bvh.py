"""Benchmark engine.collide.bvh on the sample body: build, refit, and ns per query point.

    .venv/bin/python scripts/bench_bvh.py [--body PATH] [--n 10000] [--repeat 5]

Points: (a) near the surface, surface samples pushed up to 5 cm along +-normal (what cloth
asks), (b) uniform in the body's bounding box. Each is timed single-thread (numba threads = 1)
and parallel (all numba threads), exact and with a 5 cm search radius. Times are the minimum
of --repeat runs after one warm-up call (numba compile / cache load excluded; the minimum,
not the median, because the machine may be shared: other load only ever adds time).
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numba  # noqa: E402
import trimesh  # noqa: E402

from engine.collide.bvh import MeshBVH, ObjectSpaceCollider  # noqa: E402

DEFAULT_BODY = str(Path(__file__).resolve().parents[2] / "shared/samples/garmentcode/mean_female.obj")


def _median_time(fn, repeat):
    fn()                                          # warm-up: compile / cache load
    ts = []
    for _ in range(repeat):
        t = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t)
    return float(np.min(ts))


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--body", default=DEFAULT_BODY)
    ap.add_argument("--n", type=int, default=10000)
    ap.add_argument("--repeat", type=int, default=5)
    args = ap.parse_args()

    m = trimesh.load(args.body, process=False)
    v = np.asarray(m.vertices, np.float64)
    f = np.asarray(m.faces, np.int32)
    rng = np.random.default_rng(0)
    s, fi = trimesh.sample.sample_surface(m, args.n, seed=0)
    near = s + m.face_normals[fi] * rng.uniform(-0.05, 0.05, (args.n, 1))
    unif = rng.uniform(v.min(0), v.max(0), (args.n, 3))

    t_build = _median_time(lambda: MeshBVH(v, f), args.repeat)
    bvh = MeshBVH(v, f)
    R = np.array([[np.cos(0.1), 0, np.sin(0.1)], [0, 1, 0], [-np.sin(0.1), 0, np.cos(0.1)]])
    v2 = v @ R.T + 0.01
    vel = rng.normal(size=v.shape)
    t_refit = _median_time(lambda: bvh.update(v2, vel), args.repeat)
    col = ObjectSpaceCollider(v, f, tolerance=0.005, vertex_velocities=vel)

    threads = numba.config.NUMBA_NUM_THREADS
    print(f"body {Path(args.body).name}: {len(v)} vertices, {len(f)} triangles, "
          f"{bvh.n_nodes} BVH nodes; {threads} numba threads, {os.cpu_count()} CPUs")
    print(f"build  {t_build * 1e3:8.1f} ms")
    print(f"refit  {t_refit * 1e3:8.1f} ms   (update(): boxes + normals + velocities)")
    print()
    print(f"{'query (ns / point, N=%d)' % args.n:34s} {'1 thread':>10s} {f'{threads} threads':>10s}")
    rows = [
        ("signed_distance, near (<5 cm)", lambda: bvh.signed_distance(near)),
        ("signed_distance, uniform bbox", lambda: bvh.signed_distance(unif)),
        ("  ... radius 5 cm, near", lambda: bvh.signed_distance(near, max_distance=0.05)),
        ("  ... radius 5 cm, uniform", lambda: bvh.signed_distance(unif, max_distance=0.05)),
        ("closest (all outputs), near", lambda: bvh.closest(near)),
        ("closest (all outputs), uniform", lambda: bvh.closest(unif)),
        ("collider.query, near", lambda: col.query(near)),
        ("collider.query, uniform", lambda: col.query(unif)),
    ]
    for name, fn in rows:
        numba.set_num_threads(1)
        t1 = _median_time(fn, args.repeat)
        numba.set_num_threads(threads)
        tp = _median_time(fn, args.repeat)
        print(f"{name:34s} {t1 / args.n * 1e9:10.0f} {tp / args.n * 1e9:10.0f}")


if __name__ == "__main__":
    main()
