"""A/B benchmark of the dressing step: this checkout against another one (a git worktree of an
older commit, say), the two run in turns in the same minutes -- on a shared machine whose speed
drifts by tens of percent within minutes, only runs interleaved like this compare (a script that
prints a table; not a test).

Each run is a fresh process: a coarse skirt first (numba compiles or loads its kernels), then
the garment timed. Printed per run and as medians: ms per iteration (cloth, collision),
iterations, wall seconds, strain max, and a hash of the final vertices (equal hashes: the two
checkouts computed the same drape bit for bit).

    git worktree add /tmp/base <commit> && ln -s "$PWD/.venv" /tmp/base/.venv
    .venv/bin/python scripts/bench_ab.py /tmp/base [--garment dress] [--edge-cm 1.5] [--rounds 3]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parents[1]

CHILD = r"""
import hashlib, json, sys, time
sys.path.insert(0, sys.argv[1])
from engine.body import resolve_body
from engine.scene.garments import resolve_garment
from engine.scene.tryon import run_tryon
body = resolve_body(sys.argv[2])
spec, place, label = resolve_garment("skirt", body, "M")
run_tryon(body, spec, h=0.06, place=place, source=label)
spec, place, label = resolve_garment(sys.argv[3], body, sys.argv[4])
t = time.perf_counter()
res, rep = run_tryon(body, spec, h=float(sys.argv[5]), place=place, source=label)
ms = rep["ms_per_iteration"]
print(json.dumps({"ms_it": ms["total"], "cloth": ms["cloth"], "collision": ms["collision"],
                  "iterations": rep["iterations"], "wall": time.perf_counter() - t,
                  "strain": rep["strain"]["max"], "hash": hashlib.md5(res.positions.tobytes()).hexdigest()[:8]}))
"""


def run_one(root: Path, args) -> dict:
    out = subprocess.run([sys.executable, "-c", CHILD, str(root), args.body, args.garment, args.size,
                          str(args.edge_cm / 100)], capture_output=True, text=True)
    if out.returncode != 0:
        sys.exit(f"{root}: the try-on failed:\n{out.stderr.strip().splitlines()[-1] if out.stderr else ''}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("other", type=Path, help="the other checkout's root (it must hold engine/)")
    ap.add_argument("--body", default="default:female")
    ap.add_argument("--garment", default="dress")
    ap.add_argument("--size", default="M")
    ap.add_argument("--edge-cm", type=float, default=1.5)
    ap.add_argument("--rounds", type=int, default=3)
    args = ap.parse_args()
    if not (args.other / "engine").is_dir():
        sys.exit(f"{args.other} holds no engine/: give the root of another checkout of this project")
    if not (1 <= args.rounds <= 50):
        sys.exit("--rounds: use 1 .. 50")
    roots = {"this": HERE, "other": args.other.resolve()}
    rows: dict[str, list[dict]] = {k: [] for k in roots}
    print(f"{args.garment} ({args.size}) on {args.body}, {args.edge_cm:g} cm cloth; this = {HERE}, other = {roots['other']}")
    print("| run | checkout | ms/it | cloth | collision | iterations | wall s | strain % | hash |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in range(args.rounds):
        for name, root in roots.items():
            res = run_one(root, args)
            rows[name].append(res)
            print(f"| {r + 1} | {name} | {res['ms_it']:.3f} | {res['cloth']:.3f} | {res['collision']:.3f} | "
                  f"{res['iterations']} | {res['wall']:.2f} | {100 * res['strain']:.2f} | {res['hash']} |", flush=True)
    print()
    for name, rs in rows.items():
        med = {k: statistics.median(x[k] for x in rs) for k in ("ms_it", "cloth", "collision", "wall")}
        print(f"median {name}: {med['ms_it']:.3f} ms/it (cloth {med['cloth']:.3f}, collision {med['collision']:.3f}), "
              f"wall {med['wall']:.2f} s")
    a, b = (statistics.median(x["ms_it"] for x in rows[k]) for k in ("this", "other"))
    print(f"this / other, ms per iteration: {a / b:.2f}")


if __name__ == "__main__":
    main()
