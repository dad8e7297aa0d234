"""Body robustness benchmark (issue 48): bodies x catalogue garments in --size auto, each dressed
standing and walked for 2 s, as `tryon walk` does.

    .venv/bin/python scripts/bench_bodies.py --quick                 # a small subset (~30 min)
    .venv/bin/python scripts/bench_bodies.py                         # the whole matrix (hours)
    .venv/bin/python scripts/bench_bodies.py --bodies sample@arms20,default:male --garments trousers
    .venv/bin/python scripts/bench_bodies.py --list                  # the bodies and garments, no runs

Bodies: the default bodies across their parameters (both sexes; height 1.50 and 2.00 m, weight
0 and 1, muscle 0 and 1, 18 and 70 years) and four bases made scan-like: default:female and
default:male saved as mesh files ("@plain": the default body as a scan, without its skeleton),
the sample scan (`sample`) and GarmentCode's SMPL average woman (`smpl`), each also in every
variant of engine.body.scanlike (mm, inches, Z up, facing -Z or +X, off the origin, a floor
plate, decimated to 10k triangles, subdivided to ~500k, holes, 1 mm noise, arms lowered to 20
degrees, down to the thighs, T-pose). A variant is written to a file and loaded as a user's
upload is (engine.body.load). Where loading gives back exactly the base's body (units, axes,
offset and floor undone: the same vertices to 1 um) its cells are the base's, marked "= base"
(--no-reuse runs them anyway).

Per cell it prints: dressed and walked or the error, the size chosen (and those tried), the
warnings, penetration (mm: drape max, walk max), strain (%: drape, walk max), the walk's
stiffening, the realtime factor of the walk. Writes to --out: results.json, results.md (the
table and the rates: cells that dress and walk, and clean ones -- no "too large", "tight" or
"slid" warning), contact_sheet_N.png (a row per body, the garment as it stands after the walk,
framed green: clean, amber: warnings, red: failed) and strips/BODY__GARMENT.png (the walk).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import traceback
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from engine.body.scanlike import VARIANTS  # noqa: E402

GARMENTS = ("skirt", "trousers", "sleeveless-shirt", "shirt", "dress")
SAMPLE = ROOT.parent / "shared" / "samples" / "garmentcode" / "mean_female.obj"
SMPL = ROOT.parent / "shared" / "garmentcode" / "assets" / "bodies" / "f_smpl_average_A40.obj"
BASES = {"default:female": None, "default:male": None, "sample": SAMPLE, "smpl": SMPL}
AGE_18, AGE_70 = 0.77, 0.852  # ANNY's age control (engine.body.default)
DEFAULT_RANGE = [f"default:{sex}{extra}" for sex in ("female", "male")
                 for extra in ("", ",height=1.5", ",height=2.0", ",weight=0.0", ",weight=1.0", ",muscle=0.0",
                               ",muscle=1.0", f",age={AGE_18}", f",age={AGE_70}")]
QUICK_BODIES = ("default:male,weight=1.0", "default:male@arms-thighs", "smpl@plain", "sample@t-pose")
QUICK_GARMENTS = ("trousers", "shirt", "dress")
CLEAN_BREAKERS = ("too large", "tight", "slid")  # warnings that make a cell not clean (issue 48)


def all_bodies() -> list[str]:
    return DEFAULT_RANGE + [f"{b}@{v}" for b in BASES for v in ("plain",) + tuple(VARIANTS)]


# --------------------------------------------------------------------------- bodies


def load_body(name: str, tmp: Path):
    """The Body a name stands for: a default body's spec as such; BASE@VARIANT written to a mesh
    file and loaded as an upload is."""
    from engine.body import resolve_body
    from engine.body.load import load_body_file
    from engine.body.scanlike import write_scan

    if "@" not in name:
        return resolve_body(name)
    base, variant = name.split("@")
    source = resolve_body(str(BASES[base]) if BASES[base] is not None else base)
    if variant == "plain" and BASES[base] is not None:
        return source
    path = tmp / f"{base.replace(':', '_')}_{variant}.{'obj' if variant == 'inches' else 'ply'}"
    if variant == "plain":
        import trimesh

        trimesh.Trimesh(source.vertices, source.faces, process=False).export(path)
    else:
        write_scan(path, source, variant)
    body = load_body_file(path)
    body.name = name.replace("default:", "")  # (a body named default:... takes that body's size chart)
    return body


def same_body(a, b) -> bool:
    return a.vertices.shape == b.vertices.shape and np.array_equal(a.faces, b.faces) and \
        float(np.abs(a.vertices - b.vertices).max()) < 1e-6


# --------------------------------------------------------------------------- one cell


def run_cell(body, walker, garment: str, seconds: float) -> tuple[dict, object]:
    """Dress `body` in `garment` (--size auto) and walk it (`walker`: its rigged self) for
    `seconds`: (the cell's figures, the WalkResult or None)."""
    from engine.errors import TryonError
    from engine.scene.request import TryOnRequest
    from engine.scene.tryon import dress_request
    from engine.scene.walk import walk_cloth

    cell = {"garment": garment, "ok": False}
    t0 = time.perf_counter()
    request = TryOnRequest.of(garment=garment, size="auto", motion="walk", seconds=seconds)
    try:
        res, report = dress_request(body, request)
        cell.update(size=report["garment"], cloth_vertices=report["cloth_vertices"], sizes_tried=report.get("sizes_tried", []),
                    warnings=list(report["warnings"]), drape_pen_mm=report["penetration_mm"]["max"],
                    drape_strain=report["strain"]["max"], dress_s=report["wall_seconds"]["total"])
        w = walk_cloth(walker, res, request)
    except TryonError as e:
        cell.update(error=str(e), seconds=time.perf_counter() - t0)
        return cell, None
    r = w.report
    cell.update(ok=True, walk_pen_mm=r["penetration_mm"]["max"], walk_pen_p99_mm=r["penetration_mm"]["p99"],
                walk_strain=r["strain_max"], realtime=r["realtime_factor"],
                stiffened=[(s["frame"], round(100 * s["strain"], 1)) for s in r["stiffness"]["stiffened"]],
                walk_s=r["wall_seconds"]["walking"], seconds=time.perf_counter() - t0)
    cell["clean"] = not any(k in w_ for w_ in cell["warnings"] for k in CLEAN_BREAKERS)
    return cell, w


def cell_line(body: str, c: dict) -> str:
    if c.get("same_as"):
        head = f"= {c['same_as']}"
    elif not c["ok"]:
        return f"{body:34s} {c['garment']:16s} FAILED  {c.get('error', '')}"
    else:
        head = (f"{'clean' if c['clean'] else 'warn':5s} {_size(c):28s} pen {c['drape_pen_mm']:4.1f}/"
                f"{c['walk_pen_mm']:4.1f} mm  strain {100 * c['drape_strain']:4.1f}/{100 * c['walk_strain']:4.1f} %"
                f"  rt {c['realtime']:.2f} ({c['cloth_vertices']} v)"
                + (f"  stiffened {c['stiffened']}" if c["stiffened"] else ""))
    warn = "; ".join(c.get("warnings", []))
    return f"{body:34s} {c['garment']:16s} {head}" + (f"  [{warn}]" if warn else "")


def _size(c: dict) -> str:
    label = c.get("size") or ""
    size = label.split("(")[1].split(",")[0] if "(" in label else "?"
    tried = ",".join(t["size"] for t in c.get("sizes_tried", []))
    return size + (f" (tried {tried})" if tried else "")


# --------------------------------------------------------------------------- pictures


def thumbnail(walker, w, size: int = 200) -> np.ndarray:
    """Front view of the body and garment at the walk's last frame (centred on the walker)."""
    from engine.io.render import BODY_RGB, render_meshes

    tr, gf = w.track, w.garment_frames
    i = len(gf) - 1
    off = np.array([0.0, 0.0, tr.offset(i)[2]])
    return render_meshes([(tr.vertices(i) - off, walker.faces, BODY_RGB), (gf[i] - off, w.triangles, (0.27, 0.43, 0.75))],
                         size=size, view="front")


FRAME = {"clean": (40, 160, 60), "warn": (230, 160, 20), "failed": (210, 40, 40), "same": (150, 150, 150)}


def contact_sheets(rows: list[tuple[str, list[dict]]], thumbs: dict, out: Path, per_page: int = 12) -> list[Path]:
    """Pages of a row per body, a column per garment, each thumbnail framed by its result."""
    from PIL import Image, ImageDraw

    cw, ch, label_w = 130, 210, 230
    paths = []
    for page in range(0, len(rows), per_page):
        part = rows[page:page + per_page]
        ncol = max(len(cells) for _, cells in part)
        sheet = Image.new("RGB", (label_w + ncol * cw, 24 + len(part) * ch), (255, 255, 255))
        draw = ImageDraw.Draw(sheet)
        for r, (body, cells) in enumerate(part):
            y = 24 + r * ch
            draw.text((6, y + ch // 2 - 6), body, fill=(0, 0, 0))
            for k, c in enumerate(cells):
                x = label_w + k * cw
                if r == 0:
                    draw.text((x + 4, 6), c["garment"], fill=(0, 0, 0))
                state = "same" if c.get("same_as") else ("failed" if not c["ok"] else ("clean" if c["clean"] else "warn"))
                draw.rectangle([x + 1, y + 1, x + cw - 2, y + ch - 2], outline=FRAME[state], width=4)
                img = thumbs.get((c.get("same_as") or body, c["garment"]))
                if img is not None:
                    im = Image.fromarray(img)
                    im.thumbnail((cw - 12, ch - 26))
                    sheet.paste(im, (x + 6, y + 6))
                draw.text((x + 6, y + ch - 18), _size(c).split(" ")[0] if c["ok"] else "failed", fill=FRAME[state])
        p = out / f"contact_sheet_{page // per_page + 1}.png"
        sheet.save(p)
        paths.append(p)
    return paths


# --------------------------------------------------------------------------- the matrix


def rates(rows: list[tuple[str, list[dict]]]) -> dict:
    cells = [c for _, cs in rows for c in cs]
    n = len(cells)
    ok = sum(1 for c in cells if c["ok"])
    clean = sum(1 for c in cells if c["ok"] and c["clean"])
    return {"cells": n, "dress_and_walk": ok, "clean": clean, "dress_and_walk_rate": ok / max(n, 1),
            "clean_rate": clean / max(n, 1)}


def write_table(rows, out: Path, r: dict) -> Path:
    lines = ["# Body robustness benchmark", "",
             f"{r['cells']} cells: {r['dress_and_walk']} dress and walk ({100 * r['dress_and_walk_rate']:.1f} %), "
             f"{r['clean']} clean ({100 * r['clean_rate']:.1f} %)", "", "```"]
    lines += [cell_line(body, c) for body, cells in rows for c in cells]
    lines += ["```", "", "Realtime factor of the walk, median over the runs of each body (`--repeat`):", "", "```"]
    rt: dict = {}
    for body, cells in rows:
        for c in cells:
            if c.get("realtime") is not None and not c.get("same_as"):
                rt.setdefault((body, c["garment"]), []).append(c["realtime"])
    lines += [f"{b:34s} {g:16s} {np.median(v):.3f}  ({', '.join(f'{x:.3f}' for x in v)})" for (b, g), v in rt.items()]
    lines += ["```", ""]
    p = out / "results.md"
    p.write_text("\n".join(lines))
    return p


def run_body(name: str, garments, args, tmp: Path, done: dict, thumbs: dict, out: Path) -> list[dict]:
    """Every garment on one body; cells of a body that loads back as one already run are its."""
    from engine.errors import TryonError
    from engine.scene.arms import clear_arms
    from engine.scene.walk import walk_strip, walking_body

    try:
        loaded = load_body(name, tmp)
        twin = next((k for k, (b, _) in done.items() if not args.no_reuse and same_body(b, loaded)), None)
        if twin is not None:
            return [dict(c, same_as=twin) for c in done[twin][1] if c["garment"] in garments]
        body = clear_arms(loaded)  # as `tryon walk` does
        walker = walking_body(body)
    except TryonError as e:
        return [{"garment": g, "ok": False, "error": f"the body: {e}"} for g in garments]
    cells = []
    for g in garments:
        try:
            c, w = run_cell(body, walker, g, args.seconds)
        except Exception as e:  # noqa: BLE001 -- a bug, not a body's fault: recorded, the bench goes on
            c, w = {"garment": g, "ok": False, "error": f"internal error: {type(e).__name__}: {e}",
                    "trace": traceback.format_exc()}, None
        if w is not None:
            thumbs[(name, g)] = thumbnail(walker, w)
            from PIL import Image

            Image.fromarray(walk_strip(walker, w, panels=8, size=240)).save(
                out / "strips" / f"{name.replace(':', '_').replace(',', '_')}__{g}.png")
        c["body_notes"] = [n for n in walker.notes if any(k in n for k in ("fitted", "sex", "turned"))]
        cells.append(c)
        print(cell_line(name, c), flush=True)
    done[name] = (loaded, cells)
    return cells


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0], formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help=f"bodies {', '.join(QUICK_BODIES)} x {', '.join(QUICK_GARMENTS)}")
    ap.add_argument("--bodies", help="comma-separated body names (see --list); a default body spec may use ';' for ','")
    ap.add_argument("--garments", help=f"comma-separated, of {', '.join(GARMENTS)}")
    ap.add_argument("--seconds", type=float, default=2.0, help="walking time per cell (s)")
    ap.add_argument("--no-reuse", action="store_true", help="run bodies that load back as an earlier one")
    ap.add_argument("--repeat", type=int, default=1, help="run the body list this many times in turn (interleaved "
                    "timings: a scan's realtime factor against the default body's, side by side)")
    ap.add_argument("--out", type=Path, default=ROOT / "out" / "bench_bodies")
    ap.add_argument("--list", action="store_true", help="print the bodies and garments and stop")
    args = ap.parse_args(argv)
    bodies = list(QUICK_BODIES) if args.quick else all_bodies()
    if args.bodies:
        bodies = [b.strip().replace(";", ",") for b in args.bodies.split(",") if b.strip()]
    if args.repeat > 1:
        args.no_reuse = True
        bodies = bodies * args.repeat
    garments = list(QUICK_GARMENTS if args.quick and not args.garments else
                    (args.garments.split(",") if args.garments else GARMENTS))
    bad = [g for g in garments if g not in GARMENTS]
    if bad:
        ap.error(f"unknown garment(s) {', '.join(bad)}: choose from {', '.join(GARMENTS)}")
    if args.list:
        print("\n".join(bodies))
        print("garments:", ", ".join(garments))
        return 0
    out = args.out
    (out / "strips").mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    done, thumbs, rows = {}, {}, []
    with tempfile.TemporaryDirectory() as tmp:
        for name in bodies:
            rows.append((name, run_body(name, garments, args, Path(tmp), done, thumbs, out)))
            r = rates(rows)
            (out / "results.json").write_text(json.dumps({"rates": r, "rows": rows}, indent=1, default=str))
    r = rates(rows)
    write_table(rows, out, r)
    sheets = contact_sheets(rows, thumbs, out)
    print(f"\n{r['cells']} cells in {time.perf_counter() - t0:.0f} s: dress and walk {r['dress_and_walk']} "
          f"({100 * r['dress_and_walk_rate']:.1f} %), clean {r['clean']} ({100 * r['clean_rate']:.1f} %)")
    print("wrote", out / "results.md", *sheets)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
