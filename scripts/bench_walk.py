"""Walking benchmark in the layout of seed 000's Table 2 (a script that prints a table; not a test).

For each product, dressed on default:female (size M, cotton) and then walked (1.2 m/s, 30 fps):
cloth vertices, seconds per frame, frames per second, the realtime factor (simulated seconds per
wall second of the walking stage) and ms per frame split into maps, cloth and collision -- once
with one walk cycle of maps rendered (before the walking stage: its time printed beside, and a
realtime factor that counts it in) and reused, once with maps rendered every frame. The seed's
figures (1 GHz PC + GeForce2, 2001; their frame included reading the body and drawing) are
printed beside ours at about the seed's vertex counts; the dress also runs at the goal's ~4,000
vertices; every product at our default 1.5 cm cloth. Issue 4's
goal: realtime factor >= 1.0 for a ~4,000-vertex dress with reused maps, >= 0.3 with maps every
frame.

    .venv/bin/python scripts/bench_walk.py [--seconds 2] [--garments skirt,dress,shirt]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

# seed 000, Table 2: product -> (vertices, seconds per frame)
SEED = {"skirt": (672, 0.244), "shirt": (2300, 0.294)}  # "dress with sleeves": our shirt has sleeves
GOAL = {"dress": 4000}  # issue 4's goal is stated for a ~4,000-vertex dress (our 1.5 cm dress has ~4,400)
LABEL = {"skirt": "skirt", "dress": "dress", "shirt": "shirt (seed: dress with sleeves)"}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--body", default="default:female")
    ap.add_argument("--garments", default="skirt,dress,shirt")
    ap.add_argument("--seconds", type=float, default=2.0, help="walk length after the 0.5 s start")
    ap.add_argument("--no-seed-size", action="store_true", help="skip the runs at the seed's vertex counts")
    ap.add_argument("--no-goal-size", action="store_true",
                    help="skip the run at the goal's vertex count (the dress at ~4,000 vertices)")
    a = ap.parse_args()

    from bench_drape import resolution_for

    from engine.body import resolve_body
    from engine.body.motion import walk_track
    from engine.scene.garments import resolve_garment
    from engine.scene.request import TryOnOptions
    from engine.scene.tryon import run_tryon
    from engine.scene.walk import walk_cloth

    body = resolve_body(a.body)
    opts = TryOnOptions(seconds=a.seconds)
    track = walk_track(body, opts.walk, opts.fps)
    rows = []
    for g in a.garments.split(","):
        spec, place, label = resolve_garment(g, body, "M")
        sizes = [0.015]
        if g in GOAL and not a.no_goal_size:
            sizes.insert(0, resolution_for(spec, place, GOAL[g]))
        if g in SEED and not a.no_seed_size:
            sizes.insert(0, resolution_for(spec, place, SEED[g][0]))
        for h in sizes:
            t0 = time.perf_counter()
            res, rep = run_tryon(body, spec, TryOnOptions(resolution_cm=100 * h), place=place, source=label)
            t_dress = time.perf_counter() - t0
            if not rows:  # compile the walking kernels first (a cold numba cache), outside the figures
                walk_cloth(body, res, TryOnOptions(seconds=0.1), track=track)
            for reuse in (True, False):
                w = walk_cloth(body, res, TryOnOptions(seconds=a.seconds, reuse_maps=reuse), track=track)
                r = w.report
                rows.append((g, h, rep["cloth_vertices"], reuse, r, t_dress))
                print(f"{g:6s} h={h * 100:.2f} cm  {rep['cloth_vertices']:5d} v  maps {'reused' if reuse else 'every frame'}: "
                      f"{r['ms_per_frame']['total']:.0f} ms/frame, realtime {r['realtime_factor']:.3f}, "
                      f"pen max {r['penetration_mm']['max']:.1f} mm p99 {r['penetration_mm']['p99']:.1f} mm, "
                      f"strain max {100 * r['strain_max']:.1f} %, springs x{r['stiffness']['start']:g}"
                      + (f" -> x{r['stiffness']['end']:g}" if r["stiffness"]["stiffened"] else "")
                      + f" of the drape's, step {r['dt_ms']:.3f} ms"
                      + (f", maps of the ramp and a cycle rendered before in {r['map_prerender_seconds']:.2f} s"
                         if r["map_prerender_seconds"] else ""), flush=True)
    print()
    print(f"Walking {a.seconds:g} s at 30 fps, 1.2 m/s ({track.notes[0]}); default:female, size M, cotton; "
          f"walking springs x{opts.stiffness:g} of the drape's (stiffer where a frame's strain passed the fabric's "
          f"threshold + {opts.stiffen_at:g}); ms per frame of the walking stage (maps: the wait for maps "
          "rendered one frame ahead in a helper thread, and the float16 expansions). Reused maps: the ramp's and "
          "one cycle's maps are rendered before the walking stage (WalkTuning.prerender; 'maps before s', not in "
          "the walking stage's realtime factor; 'with maps' counts them in)")
    print("| product | vertices | maps | s/frame | frames/s | realtime | with maps | maps before s | maps ms | cloth ms "
          "| collision ms | seed vertices | seed s/frame | seed frames/s |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|---|---|")
    for g, h, nv, reuse, r, _ in rows:
        m = r["ms_per_frame"]
        sv = SEED.get(g)
        seed = f"{sv[0]} | {sv[1]:.3f} | {1 / sv[1]:.1f}" if sv and abs(nv - sv[0]) < 0.3 * sv[0] else "| |"
        goal = ""
        if g in GOAL and abs(nv - GOAL[g]) < 0.05 * GOAL[g]:
            goal = f" (goal >= {1.0 if reuse else 0.3:.1f})"
        before = r["map_prerender_seconds"]
        with_maps = r["seconds"] / (r["wall_seconds"]["walking"] + before)
        print(f"| {LABEL.get(g, g)} | {nv} | {'one cycle, reused' if reuse else 'every frame'} | "
              f"{m['total'] / 1000:.3f} | {1000 / m['total']:.2f} | {r['realtime_factor']:.3f}{goal} | {with_maps:.3f} | "
              f"{before:.2f} | {m['maps']:.1f} | {m['cloth']:.0f} | {m['collision']:.0f} | {seed} |")


if __name__ == "__main__":
    main()
