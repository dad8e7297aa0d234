"""Summarise report.json files of `tryon drape` runs (e.g. out/catalogue/*/) as a markdown table
beside seed 003's Table 2 figures (SGI R12000, 2001).

    .venv/bin/python scripts/summarize_reports.py out/catalogue
"""

import json
import sys
from pathlib import Path

SEED = {"skirt": "336 v, 66 it, 0.206 s, 3.1 ms/it", "trousers": "560 v, 69 it, 0.334 s, 4.8 ms/it",
        "sleeveless-shirt": "544 v, 55 it, 0.268 s, 4.8 ms/it (1800 v: 82 it, 1.3 s, 15.8 ms/it)",
        "dress": "1024 v, 88 it, 0.784 s, 8.9 ms/it (3840 v: 130 it, 4.3 s, 33.0 ms/it)", "shirt": "—"}


def main() -> None:
    root = Path(sys.argv[1] if len(sys.argv) > 1 else "out/catalogue")
    print("| run | vertices | iterations | sew+drape s | ms/it | cloth ms/it | collision ms/it | pen. max / p99 mm "
          "| strain max % | settled | seed 003 (same product) |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for d in sorted(p for p in root.iterdir() if p.is_dir()):
        f = d / "report.json"
        if not f.exists():
            print(f"| {d.name} | failed (see {d / 'failed.png'}) | | | | | | | | | |")
            continue
        r = json.loads(f.read_text())
        ms, w = r["ms_per_iteration"], r["wall_seconds"]
        prod = d.name.split("_", 1)[-1]
        print(f"| {d.name} | {r['cloth_vertices']} | {r['iterations']} | {w['sewing'] + w['draping']:.1f} | "
              f"{ms['total']:.2f} | {ms['cloth']:.2f} | {ms['collision']:.2f} | "
              f"{r['penetration_mm']['max']:.1f} / {r['penetration_mm']['p99']:.1f} | "
              f"{100 * r['strain']['max']:.1f} | {r['settled']} | {SEED.get(prod, '—')} |")


if __name__ == "__main__":
    main()
