"""Dressing benchmark in the layout of seed 003's Tables 1 and 2 (a script that prints tables;
not a test).

For each product: cloth vertices, iterations, total time, ms per iteration split into cloth
simulation and collision detection + response (total = sewing + draping; like the seed, without
set-up: reading, meshing, maps), on default:female in size M, cotton -- at the
vertex counts the seed used (cloth resolution chosen to match) and at our default 1.5 cm. The
seed's figures (SGI R12000, 2001) are printed beside ours, with our per-iteration speed-up over
them at the same vertex count (issue 3's goal: >= 80x) and, as "whole s", the run from
placement to settled with the maps included (the goal for a dress: <= 1 s).

    .venv/bin/python scripts/bench_drape.py [--garments skirt,dress] [--body default:female]
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# seed 003: Table 1 (image-space rows) and Table 2
SEED = {
    "skirt": [(336, 66, 0.206, 3.1)],
    "trousers": [(560, 69, 0.334, 4.8)],
    "sleeveless-shirt": [(544, 55, 0.268, 4.8), (1800, 82, 1.3, 15.8)],
    "dress": [(1024, 88, 0.784, 8.9), (3840, 130, 4.3, 33.0)],
    "shirt": [],
}


def resolution_for(spec, place, target: int) -> float:
    """Cloth edge (m) giving about `target` vertices (vertex count ~ area / h^2)."""
    from engine.garment.garment import build_garment

    h = 0.03
    for _ in range(3):
        n = build_garment(spec, h=h, place=place).n_vertices
        h = h * math.sqrt(n / target)
    return max(h, 0.004)


def run(body, name: str, h: float) -> dict:
    from engine.scene.garments import resolve_garment
    from engine.scene.request import TryOnOptions
    from engine.scene.tryon import run_tryon

    spec, place, label = resolve_garment(name, body, "M")
    t = time.perf_counter()
    _, rep = run_tryon(body, spec, TryOnOptions(resolution_cm=100 * h), place=place, source=label)
    rep["wall"] = time.perf_counter() - t
    return rep


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--body", default="default:female")
    ap.add_argument("--garments", default="skirt,trousers,sleeveless-shirt,dress,shirt")
    ap.add_argument("--no-default", action="store_true", help="only the seed's vertex counts")
    args = ap.parse_args()
    from engine.body import resolve_body
    from engine.pattern.catalogue import CATALOGUE
    from engine.scene.garments import resolve_garment

    body = resolve_body(args.body)
    print("warming up: a coarse skirt, so that no row below includes compiling the kernels", file=sys.stderr)
    run(body, "skirt", 0.06)
    rows = []
    for name in args.garments.split(","):
        if name not in CATALOGUE:
            print(f"skip {name}: not in the catalogue", file=sys.stderr)
            continue
        spec, place, _ = resolve_garment(name, body, "M")
        runs = [(v, it, tt, ms) for v, it, tt, ms in SEED.get(name, [])]
        hs = [(resolution_for(spec, place, v), seed) for seed in runs for v in [seed[0]]]
        if not args.no_default:
            hs.append((0.015, None))
        for h, seed in hs:
            try:
                rep = run(body, name, h)
            except Exception as e:  # a failed run is a row, not a crash
                rows.append((name, h, None, seed, f"{type(e).__name__}: {e}"))
                continue
            rows.append((name, h, rep, seed, None))
            print(f"done {name} h={h * 100:.2f} cm", file=sys.stderr)

    print(f"\nbody {args.body}, size M, cotton; ours: this machine (2 cores), seed 003: SGI R12000\n")
    print("collision ms/it is that of an average step: the body is checked every k-th step (checks: sewing / "
          "draping), with the points predicted up to the next check\n")
    print("| product | edge cm | vertices | iterations | total s | ms/it | cloth ms/it | collision ms/it | checks "
          "| settled | pen. max mm | strain max % | whole s | seed 003: vertices, iterations, total s, ms/it "
          "| per-it speed-up |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for name, h, rep, seed, err in rows:
        s = "—" if seed is None else f"{seed[0]}, {seed[1]}, {seed[2]}, {seed[3]}"
        if rep is None:
            print(f"| {name} | {h * 100:.2f} | failed: {err} | | | | | | | | | | | {s} | |")
            continue
        ms = rep["ms_per_iteration"]
        ce = rep.get("collision_every_steps", {})
        speedup = "—" if seed is None else f"{seed[3] / max(ms['total'], 1e-9):.1f}x"
        print(f"| {name} | {h * 100:.2f} | {rep['cloth_vertices']} | {rep['iterations']} | "
              f"{rep['wall_seconds']['sewing'] + rep['wall_seconds']['draping']:.2f} | {ms['total']:.3f} | {ms['cloth']:.3f} | {ms['collision']:.3f} | "
              f"{ce.get('sewing', '-')} / {ce.get('draping', '-')} | "
              f"{rep['settled']} | {rep['penetration_mm']['max']:.1f} | {100 * rep['strain']['max']:.1f} | "
              f"{rep['wall_seconds']['total']:.2f} | {s} | "
              f"{speedup} |")


if __name__ == "__main__":
    main()
