"""The figures of issue 49 for the DXF samples (a script that prints tables; not a test).

1. Every file in ../shared/samples/dxf/: its pieces x sizes, units, and the largest difference
   between a panel's area and the shoelace area of its piece's chained layer-1 cut line (twice
   that for a piece cut on the fold and unfolded), over every size.
2. --drape: each whole garment there, in its middle size, on a default body (the men's body for
   men's garments -- the file's sizes say men's chest sizes 42-70 -- else the women's), with the
   seams inferred and nothing else: iterations, settled, seam gap, penetration, strain, and
   front.png / side.png / back.png under OUT/<file>/. The leggings are cut 16-18 % under their
   wearer's hips, for a stretch knit: in the stretchiest fabric of engine.cloth.fabrics (jersey,
   15 % strain threshold) their middle size is refused on default:female (42 % over the seat)
   and draped on a petite default body whose hips it fits within jersey's limits.
3. --grading FILE: that garment in its smallest, middle and largest sizes on one body (--body:
   default:female, whose 85 cm bust the smallest men's tee, 91 cm, goes round), side by side in
   OUT/grading.png, with each size's chest (or hip) girth and its drape's strain.

    .venv/bin/python scripts/dxf_figures.py [--drape] [--grading MEN_CLASSIC_TEE.DXF] [--out out/dxf]
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))
SAMPLES = ROOT.parent / "shared" / "samples" / "dxf"
# the whole garments of the samples, and the default body each is draped on
PETITE = "default:female,height=1.52,weight=0.05"
GARMENTS = {"MEN_CLASSIC_TEE.DXF": ("default:male", "cotton"), "WM_SLIM_TANK.DXF": ("default:female", "cotton"),
            "GMX1016S18_AAMA.DXF": ("default:male", "cotton"), "GMX1016S18_ASTM.DXF": ("default:male", "cotton"),
            "GMH1006F18_AAMA.DXF": ("default:male", "cotton"), "drill-holes.DXF": ("default:male", "cotton"),
            "GLX4802S19_AAMA.DXF": (PETITE, "jersey"), "ORILEGWB_AAMA.DXF": (PETITE, "jersey")}


def table() -> None:
    from engine.pattern.dxf import import_pattern, piece_areas
    from engine.pattern.dxf_read import read_pattern

    print("area diff: |panel area / shoelace area of the chained layer-1 cut line - 1|, largest over every size: "
          "of every piece (its edges between its corners), and of the garment's panels (unfolded, as inferred)")
    print(f"{'file':24s} {'units':5s} {'pieces x sizes':>14s} {'pieces %':>9s} {'garment':8s} {'panels':>6s} "
          f"{'panels %':>9s}  worst panel")
    for path in sorted(SAMPLES.iterdir()):
        t = time.perf_counter()
        pattern = read_pattern(path)
        worst, where, kind, panels = 0.0, "", "", 0
        for size in pattern.sizes:
            imp = import_pattern(path, size, pattern=pattern)
            kind, panels = imp.kind, len(imp.spec.pattern.panels)
            for name, (a, f) in imp.areas.items():
                d = 100 * abs(a / f - 1)
                if d > worst:
                    worst, where = d, f"{name} in {size}"
        n = f"{len(pattern.pieces)} x {len(pattern.sizes)}"
        pieces = max(100 * abs(a / f - 1) for a, f in piece_areas(pattern).values())
        print(f"{path.name:24s} {pattern.units:5s} {n:>14s} {pieces:9.3f} {kind:8s} {panels:6d} {worst:9.3f}  "
              f"{where} ({time.perf_counter() - t:.1f} s)")


def drape_one(path: Path, body_name: str, size: str, out: Path, fabric: str = "cotton") -> dict:
    from engine.body import resolve_body
    from engine.scene.request import TryOnRequest
    from engine.scene.tryon import dress_request, write_outputs

    body = resolve_body(body_name)
    res, rep = dress_request(body, TryOnRequest(garment=str(path), size=size, fabric=fabric))
    write_outputs(out, body, res, rep)
    return rep


def drape_all(out: Path) -> None:
    from engine.errors import TryonError
    from engine.pattern.dxf_read import read_pattern

    print(f"\n{'file':24s} {'body':15s} {'fabric':7s} {'size':5s} {'vertices':>8s} {'iters':>6s} {'settled':7s} "
          f"{'seam gap mm':>11s} {'pen. max/p99 mm':>15s} {'strain %':>8s} {'s':>5s}")
    for fname, (body, fabric) in GARMENTS.items():
        pattern = read_pattern(SAMPLES / fname)
        size = pattern.sizes[len(pattern.sizes) // 2]
        t = time.perf_counter()
        try:
            r = drape_one(SAMPLES / fname, body, size, out / Path(fname).stem, fabric)
        except TryonError as e:
            print(f"{fname:24s} {body:15s} {fabric:7s} {size:5s} FAILED: {e}")
            continue
        body = "petite female" if body == PETITE else body
        print(f"{fname:24s} {body:15s} {fabric:7s} {size:5s} {r['cloth_vertices']:8d} {r['iterations']:6d} "
              f"{str(r['settled']):7s} {r['seam_gap_mm']['max']:11.1f} "
              f"{r['penetration_mm']['max']:7.1f}/{r['penetration_mm']['p99']:<7.1f} "
              f"{100 * r['strain']['max']:8.1f} {time.perf_counter() - t:5.0f}")


def grading(fname: str, out: Path, body: str) -> None:
    from PIL import Image

    from engine.pattern.dxf_read import read_pattern
    from engine.pattern.dxf_size import garment_girth

    pattern = read_pattern(SAMPLES / fname)
    fabric = GARMENTS.get(fname, ("", "cotton"))[1]
    sizes = [pattern.sizes[0], pattern.sizes[len(pattern.sizes) // 2], pattern.sizes[-1]]
    imgs = []
    print(f"\n{fname} on {body}:")
    for s in sizes:
        sub = out / f"grading_{s}"
        r = drape_one(SAMPLES / fname, body, s, sub, fabric)
        where, g = garment_girth(pattern, s)
        print(f"  size {s}: {where} {g:.1f} cm; strain max {100 * r['strain']['max']:.1f} %, settled {r['settled']}, "
              f"shift top {r['shift_mm']['top']:.0f} mm")
        imgs.append(np.asarray(Image.open(sub / "front.png").convert("RGB")))
    h = min(i.shape[0] for i in imgs)
    Image.fromarray(np.concatenate([i[:h] for i in imgs], axis=1)).save(out / "grading.png")
    print(f"  {out / 'grading.png'} (sizes {', '.join(sizes)}, left to right)")


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--drape", action="store_true")
    ap.add_argument("--grading", default=None)
    ap.add_argument("--out", default="out/dxf")
    ap.add_argument("--body", default="default:female", help="the body of --grading")
    a = ap.parse_args()
    out = Path(a.out)
    table()
    if a.drape:
        drape_all(out)
    if a.grading:
        grading(a.grading, out, a.body)


if __name__ == "__main__":
    main()
