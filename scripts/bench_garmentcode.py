"""Conformance benchmark: patterns that GarmentCode's own generator writes, draped on a body.

Draws N designs with ../shared/garmentcode/sample_designs.py (seeded: the same --seed gives the same
designs), drapes each on the body, and prints a table: the designs, how many drape (settled; every
seam closed; penetration max <= 2 mm and p99 <= 0.5 mm; strain <= the fabric's threshold + 1 %; no
warning that it slid down the body, fell off the shoulders or bunched up),
the failures grouped by reason, the median and 90th-percentile wall time per garment, and the worst
penetration, strain and sharp folds. Writes results.json and contact_sheet.png (a front view of
every drape, its name and result under it) to --out.

    .venv/bin/python scripts/bench_garmentcode.py --body mean_female --n 100 --seed 1 --out out/gc
    .venv/bin/python scripts/bench_garmentcode.py --body f_smpl_average_A40 --n 100 --seed 2 --out out/gc2
    .venv/bin/python scripts/bench_garmentcode.py --patterns out/gc/patterns --out out/gc-again   # no drawing
"""

from __future__ import annotations

import argparse
import json
import re
import statistics
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parents[1]
GC = HERE.parent / "shared" / "garmentcode"
SAMPLES = HERE.parent / "shared" / "samples" / "garmentcode"
BODIES = {"mean_female": SAMPLES / "mean_female.obj",
          "f_smpl_average_A40": GC / "assets" / "bodies" / "f_smpl_average_A40.obj"}
PEN_MAX, PEN_P99, STRAIN_OVER = 2.0, 0.5, 0.01  # mm, mm, past the fabric's threshold


def draw(body: str, n: int, seed: int, out: Path) -> list[Path]:
    """N patterns from GarmentCode's sampler (its own programs; designs it cannot build are skipped)."""
    out.mkdir(parents=True, exist_ok=True)
    r = subprocess.run([sys.executable, str(GC / "sample_designs.py"), "--body", body, "--n", str(n), "--seed",
                        str(seed), "--out", str(out)], capture_output=True, text=True)
    if r.returncode != 0:
        sys.exit(f"GarmentCode's sampler failed: {r.stderr.strip()[-500:]}")
    return sorted(out.glob("*_specification.json"))


def verdict(rep: dict) -> str | None:
    """Why a finished drape does not meet the bars, or None."""
    if not rep["settled"]:
        return "did not settle"
    if rep["penetration_mm"]["max"] > PEN_MAX or rep["penetration_mm"]["p99"] > PEN_P99:
        return "penetration past the bars"
    if rep["strain"]["max"] > rep["strain"]["threshold"] + STRAIN_OVER:
        return "strain past threshold + 1 %"
    for w in rep["warnings"]:  # a drape that ends with good numbers but off where it was put looks wrong
        if w.startswith("the garment fell off the shoulders"):
            return "fell off the shoulders (a warning)"
        if w.startswith("the garment slid"):
            return "slid down the body (a warning)"
        if "bunched up" in w:
            return "bunched up (a warning)"
        if "it stands off the body" in w:
            return "stands off the body, held at its top (a warning)"
    return None


def reason(msg: str) -> str:
    """An error message grouped by its kind (the design's name, numbers and names taken out); seams
    that stalled beside a part stretched far past the fabric (a cuff or a band cut smaller round
    than the limb or body it closes round: the pattern's size, not the sewing) apart, and those
    beside a panel whose outline crosses itself (a neckline cut past the armholes)."""
    msg = re.sub(r"^\S+?(_specification\.json)?: (error: )?", "", msg)
    head = re.split(r"[;(]", msg)[0]
    kind = re.sub(r"'[^']*'|\d+(\.\d+)?", "#", head).strip()[:90]
    if "that part is too small for this body" in msg:
        kind += ", beside a part too small for the body"
    elif "hang from a point and cannot be held" in msg:
        kind += ", beside an outline that crosses itself"
    return kind


def drape_one(path: Path, body, request, limit: float | None = None) -> dict:
    """One design's row; limit: the wall time its try-on may take (as the service's TRYON_DRESS_SECONDS)."""
    from engine.errors import TryonError
    from engine.pattern.io import load_pattern
    from engine.scene.drape import time_limited
    from engine.scene.tryon import run_tryon

    t = time.perf_counter()
    row = {"design": path.name.removesuffix("_specification.json")}
    try:
        res, rep = run_tryon(body, load_pattern(path), request, source=row["design"],
                             progress=time_limited(None, limit, "the benchmark's --time-limit") if limit else None)
    except TryonError as e:
        row.update(ok=False, wall=time.perf_counter() - t, error=str(e), reason=reason(str(e)),
                   picture=(getattr(e, "positions", None), getattr(e, "triangles", None)))
        return row
    bad = verdict(rep)
    row.update(ok=bad is None, wall=time.perf_counter() - t, reason=bad, vertices=rep["cloth_vertices"],
               pen_max=rep["penetration_mm"]["max"], pen_p99=rep["penetration_mm"]["p99"],
               strain=rep["strain"]["max"], threshold=rep["strain"]["threshold"], folds=rep["sharp_folds"]["count"],
               snapped=rep["seam_gap_mm"]["snapped"], warnings=rep["warnings"], picture=(res.positions, res.triangles),
               # (the drape that stands: its fabric, its parts in a knit, its own wall -- the rest of
               # `wall` went on the fabric ladder's earlier drapes)
               fabric=rep["fabric"], parts=sorted(rep.get("panel_fabrics", {})),
               last_wall=rep["wall_seconds"]["total"])
    return row


def contact_sheet(rows: list[dict], body, path: Path, cell: int = 220, cols: int = 8) -> None:
    from PIL import Image, ImageDraw

    from engine.io.render import BODY_RGB, render_meshes

    n_rows = -(-len(rows) // cols)
    sheet = Image.new("RGB", (cols * cell, n_rows * (cell + 30)), (255, 255, 255))
    d = ImageDraw.Draw(sheet)
    for k, r in enumerate(rows):
        x, y = (k % cols) * cell, (k // cols) * (cell + 30)
        meshes = [(body.vertices, body.faces, BODY_RGB)]
        pos, tri = r["picture"]
        if pos is not None:
            meshes.append((pos, tri, (0.27, 0.43, 0.75) if r["ok"] else (0.8, 0.3, 0.3)))
        im = Image.fromarray(render_meshes(meshes, size=cell, view="front"))
        im.thumbnail((cell, cell))
        sheet.paste(im, (x, y))
        d.text((x + 4, y + cell + 2), r["design"][-24:], fill=(0, 0, 0))
        d.text((x + 4, y + cell + 15), "ok" if r["ok"] else (r["reason"] or "")[:34],
               fill=(30, 130, 50) if r["ok"] else (200, 40, 40))
    sheet.save(path)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--body", default="mean_female", help=f"one of {', '.join(BODIES)}, or a mesh file")
    ap.add_argument("--n", type=int, default=20)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--patterns", type=Path, help="drape these *_specification.json instead of drawing")
    ap.add_argument("--resolution", type=float, default=1.5, help="cloth edge, cm")
    ap.add_argument("--fabric", default=None, help="drape in this fabric (default: the try-on's default)")
    ap.add_argument("--out", type=Path, default=Path("out/bench_garmentcode"))
    ap.add_argument("--time-limit", type=float, default=300.0,
                    help="s a garment's try-on may take, then it fails (the service's TRYON_DRESS_SECONDS "
                         "default); 0: none")
    a = ap.parse_args()
    if not (1 <= a.n <= 1000):
        sys.exit("--n: 1 .. 1000 designs")
    from engine.body import resolve_body
    from engine.scene.request import TryOnOptions

    a.out.mkdir(parents=True, exist_ok=True)
    paths = sorted(a.patterns.glob("*_specification.json")) if a.patterns else \
        draw(a.body if a.body in BODIES else "mean_female", a.n, a.seed, a.out / "patterns")
    body = resolve_body(str(BODIES.get(a.body, a.body)))
    request = TryOnOptions(resolution_cm=a.resolution, **({"fabric": a.fabric} if a.fabric else {}))
    rows = []
    for p in paths:
        r = drape_one(p, body, request, a.time_limit or None)
        rows.append(r)
        extra = (f"{r['vertices']} v, pen {r['pen_max']:.1f}/{r['pen_p99']:.1f} mm, strain {100 * r['strain']:.1f} %, "
                 f"folds {r['folds']}, {r['fabric']}{' + parts' if r['parts'] else ''}, "
                 f"last drape {r['last_wall']:.1f} s" if "vertices" in r else r.get("error", "")[:160])
        print(f"{r['design']:32s} {'ok  ' if r['ok'] else 'FAIL'} {r['wall']:6.1f} s  {extra}"
              + ("" if r["ok"] or "vertices" not in r else f"  ({r['reason']})"), flush=True)
    ok = [r for r in rows if r["ok"]]
    walls = [r["wall"] for r in rows]
    reasons: dict[str, list[str]] = {}
    for r in rows:
        if not r["ok"]:
            reasons.setdefault(r["reason"], []).append(r["design"])
    done = [r for r in rows if "vertices" in r]
    print(f"\n{len(rows)} designs on {a.body}, {a.resolution:g} cm cloth: {len(ok)} drape ({100 * len(ok) / max(1, len(rows)):.0f} %)")
    print(f"wall time per garment: median {statistics.median(walls):.1f} s, p90 {np.percentile(walls, 90):.1f} s"
          + (f" (each stopped at {a.time_limit:g} s)" if a.time_limit else ""))
    if done:
        print(f"penetration max {max(r['pen_max'] for r in done):.2f} mm, p99 max {max(r['pen_p99'] for r in done):.2f} mm; "
              f"strain max {100 * max(r['strain'] for r in done):.1f} % (threshold {100 * done[0]['threshold']:.0f} %); "
              f"sharp folds max {max(r['folds'] for r in done)}")
    for why, names in sorted(reasons.items(), key=lambda kv: -len(kv[1])):
        print(f"  {len(names):3d} x {why}: {', '.join(names[:6])}{' ...' if len(names) > 6 else ''}")
    contact_sheet(rows, body, a.out / "contact_sheet.png")
    keep = [{k: v for k, v in r.items() if k != "picture"} for r in rows]
    (a.out / "results.json").write_text(json.dumps({"body": a.body, "rows": keep}, indent=1))
    print(f"wrote {a.out / 'contact_sheet.png'}, {a.out / 'results.json'}")


if __name__ == "__main__":
    main()
