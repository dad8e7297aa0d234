"""Benchmark: collision-map generation per body frame and the map query kernel.

    .venv/bin/python scripts/bench_maps.py [--sizes 256,512,1024] [--frames 30] [--backends egl,osmesa]

Per backend (each in its own subprocess: the GL backend is fixed per process) and map size N
(texel = larger side of the body's x-y bounding box / N): median time of one frame =
upload positions + normals + velocities, draw front and back cameras into depth + normal +
velocity targets, read back, finish (side layer). Then the query kernel: ns per point for
10k points in the body's bounding box (after JIT warm-up, median of many runs).
Goals (DESIGN / brief, 2-core machine): <= 15 ms per frame at 512^2, <= 30 ns per point.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SAMPLE = Path(__file__).resolve().parents[2] / "shared/samples/garmentcode/mean_female.obj"


def load_body():
    """(vertices, faces, where from): the default body if it resolves, else the sample scan."""
    try:
        from engine.body import resolve_body

        b = resolve_body("default:female")
        return b.vertices, b.faces, "engine.body.resolve_body('default:female')"
    except Exception as e:  # the default body may not exist yet
        import trimesh

        m = trimesh.load(SAMPLE, process=False)
        return (np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int32),
                f"{SAMPLE} (default body unavailable: {type(e).__name__})")


def _normals(v, f):
    from engine.body.types import Body

    return Body(v, f).vertex_normals()


def worker(sizes: list[int], frames: int) -> dict:
    from engine.collide.gl import ensure_context
    from engine.collide.maps import MapRenderer
    from engine.collide.query import query_batch

    info = ensure_context()
    v, f, source = load_body()
    n = _normals(v, f)
    rng = np.random.default_rng(0)
    vel = rng.normal(scale=0.3, size=v.shape)
    ext = v.max(0) - v.min(0)
    out = {"backend": info.backend, "renderer": info.renderer, "body": source,
           "vertices": len(v), "faces": len(f), "maps": []}
    for size in sizes:
        texel = max(ext[0], ext[1]) / size
        r = MapRenderer(f, texel=texel, tol=0.005, with_velocity=True)
        times = []
        for k in range(frames + 5):
            vk = v + 0.001 * np.sin(k)          # a moving body: new positions every frame
            t0 = time.perf_counter()
            maps = r.render(vk, n, vel)
            dt = time.perf_counter() - t0
            if k >= 5:
                times.append(dt)
        h, w = maps.layout[0, :2]
        r.release()
        # query kernel, on the last maps
        pts = rng.uniform(v.min(0), v.max(0), (10_000, 3))
        m = len(pts)
        res = (np.zeros(m, np.int8), np.zeros((m, 3)), np.zeros(m), np.zeros((m, 3)),
               np.zeros((m, 3)), np.zeros(m, np.int32))
        args = maps.kernel_args()
        query_batch(pts, 0.005, *args, *res)         # JIT / cache load
        q = []
        for _ in range(300):
            t0 = time.perf_counter()
            query_batch(pts, 0.005, *args, *res)
            q.append(time.perf_counter() - t0)
        out["maps"].append({"N": size, "H": int(h), "W": int(w), "texel_mm": texel * 1000,
                            "frame_ms": float(np.median(times)) * 1000,
                            "frame_min_ms": float(np.min(times)) * 1000,
                            "query_ns": float(np.median(q)) / m * 1e9,
                            "query_min_ns": float(np.min(q)) / m * 1e9,
                            "contacts": int((res[0] > 0).sum())})
    return out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--sizes", default="256,512,1024")
    ap.add_argument("--frames", type=int, default=30)
    ap.add_argument("--backends", default="egl,osmesa")
    ap.add_argument("--worker", action="store_true", help=argparse.SUPPRESS)
    a = ap.parse_args()
    sizes = [int(s) for s in a.sizes.split(",")]
    if a.worker:
        print(json.dumps(worker(sizes, a.frames)))
        return
    results = []
    for backend in a.backends.split(","):
        env = {k: v for k, v in os.environ.items() if k != "PYOPENGL_PLATFORM"}
        env["TRYON_GL"] = backend
        p = subprocess.run([sys.executable, __file__, "--worker", "--sizes", a.sizes,
                            "--frames", str(a.frames)], env=env, capture_output=True, text=True)
        if p.returncode != 0:
            print(f"{backend}: unavailable or failed: {(p.stderr.strip().splitlines() or ['?'])[-1]}")
            continue
        results.append(json.loads(p.stdout.strip().splitlines()[-1]))
    if not results:
        sys.exit(1)
    r0 = results[0]
    print(f"body: {r0['body']}  ({r0['vertices']} vertices, {r0['faces']} faces)")
    print(f"renderer: {r0['renderer']}; CPUs: {os.cpu_count()}; "
          f"LP_NUM_THREADS={os.environ.get('LP_NUM_THREADS', 'default')}")
    print(f"load average before: {os.getloadavg()[0]:.2f} (other processes distort these times)")
    print(f"{'backend':8} {'N':>5} {'H x W':>11} {'texel mm':>8} {'frame ms':>9} {'min ms':>7} "
          f"{'query ns/pt':>11} {'min':>6}")
    for r in results:
        for m in r["maps"]:
            print(f"{r['backend']:8} {m['N']:5d} {m['H']:5d}x{m['W']:<5d} {m['texel_mm']:8.2f} "
                  f"{m['frame_ms']:9.2f} {m['frame_min_ms']:7.2f} {m['query_ns']:11.1f} "
                  f"{m['query_min_ns']:6.1f}")
    print("frame = median (and min) of the timed frames; query = median (and min) over 300 "
          "batches of 10k points, 2 threads; on a busy machine the min is the uncontended cost")
    print("goals: <= 15 ms per frame at N = 512, <= 30 ns per query point")


if __name__ == "__main__":
    main()
