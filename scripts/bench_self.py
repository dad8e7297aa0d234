"""Cloth-cloth contact within a garment (engine.cloth.selfcontact): what it costs, what it changes.

For each garment (a catalogue name or a pattern file), interleaved A/B drapes on the same body --
self-collision off, on, off, on, ... (the machine is shared: a ratio of neighbours in time) -- and
per garment: ms per solver iteration off and on and their ratio; the pass's own cost, timed on the
final drape (ms per listing of the pairs from the hash, ms per check of the listed pairs); the cloth
triangles crossing other cloth triangles at the end (off / on; of a failed drape, its cloth as it
stopped, seams not yet closed crossing too); penetration, strain, settled, or the error.

    .venv/bin/python scripts/bench_self.py --body default:female dress skirt
    .venv/bin/python scripts/bench_self.py --body ../shared/samples/garmentcode/mean_female.obj --repeat 1 \\
        /tmp/gc/s1/mean_female_1_009_specification.json
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from dataclasses import replace
from pathlib import Path


sys.path.insert(0, str(Path(__file__).resolve().parents[1]))


def tuning_with(on: bool, thickness: float | None, every: int | None):
    from engine.scene.tuning import Tuning

    t = Tuning()
    step = t.drape.step
    if thickness is not None:
        step = replace(step, self_thickness=thickness)
    if every is not None:
        step = replace(step, self_every=every)
    return replace(t, drape=replace(t.drape, step=step, self_contact="on" if on else "off"))


def drape(body, garment: str, tuning) -> dict:
    """One drape: its figures, the final cloth (or the failed one's, for the crossing count)."""
    from engine.cloth.selfcontact import self_intersections
    from engine.errors import TryonError
    from engine.scene.request import TryOnRequest
    from engine.scene.tryon import dress_request

    t0 = time.perf_counter()
    try:
        res, rep = dress_request(body, TryOnRequest(garment=garment), tuning)
    except TryonError as e:
        row = {"error": str(e)[:110], "wall": time.perf_counter() - t0}
        x, tri = getattr(e, "positions", None), getattr(e, "triangles", None)
        row["crossing"] = self_intersections(x, tri)["triangles"] if x is not None else None
        return row
    return {"wall": time.perf_counter() - t0, "ms_it": rep["ms_per_iteration"]["total"],
            "iterations": rep["iterations"], "crossing": self_intersections(res.positions, res.triangles)["triangles"],
            "pen": rep["penetration_mm"]["max"], "strain": rep["strain"]["max"], "settled": rep["settled"],
            "vertices": rep["cloth_vertices"], "result": res}


def pass_cost(res, thickness: float, every: int, calls: int = 40) -> tuple[float, float, int, int]:
    """(ms per listing, ms per check of the list, pairs listed, pairs found) of the pass alone on
    the final drape."""
    from engine.cloth.model import ClothState
    from engine.cloth.selfcontact import SelfContact

    sc = SelfContact(res.model, thickness, every)
    st = ClothState(res.state.x.copy(), res.state.v.copy())
    sc.step(st, 0, res.dt, 50.0, 0.3)
    lists, checks = [], []
    for i in range(1, calls + 1):
        t = time.perf_counter()
        sc._list(st.x, sc.near)
        lists.append(time.perf_counter() - t)
        t = time.perf_counter()
        sc.step(st, i * every, res.dt, 50.0, 0.3)
        checks.append(time.perf_counter() - t)
    return 1000 * statistics.median(lists), 1000 * statistics.median(checks), sc.n_cand, sc.found


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("garments", nargs="+", help="catalogue names or pattern files")
    ap.add_argument("--body", default="default:female")
    ap.add_argument("--repeat", type=int, default=2, help="A/B pairs per garment")
    ap.add_argument("--thickness", type=float, default=None, help="m (default: StepConfig's)")
    ap.add_argument("--every", type=int, default=None, help="steps between checks (default: StepConfig's)")
    a = ap.parse_args()
    from engine.body import resolve_body
    from engine.cloth.config import StepConfig

    body = resolve_body(a.body)
    thickness = a.thickness or StepConfig.self_thickness
    every = a.every or StepConfig.self_every
    print(f"body {a.body}; thickness {1000 * thickness:.1f} mm, checked every {every} steps; "
          f"{a.repeat} interleaved off/on pairs per garment")
    for g in a.garments:
        runs = {False: [], True: []}
        for _ in range(a.repeat):
            for on in (False, True):
                runs[on].append(drape(body, g, tuning_with(on, a.thickness, a.every)))
        name = Path(g).name.removesuffix("_specification.json")
        for on in (False, True):
            for r in runs[on]:
                fig = (f"{r['vertices']} v, {r['iterations']} it, {r['ms_it']:.2f} ms/it, wall {r['wall']:.1f} s, "
                       f"pen {r['pen']:.1f} mm, strain {100 * r['strain']:.1f} %, settled {r['settled']}"
                       if "error" not in r else f"FAIL {r['wall']:.1f} s: {r['error']}")
                print(f"{name:24s} {'on ' if on else 'off'} crossing triangles {r['crossing']}  {fig}")
        ok = [(x, y) for x, y in zip(runs[False], runs[True]) if "error" not in x and "error" not in y]
        if ok:
            ratio = statistics.median(y["ms_it"] / x["ms_it"] for x, y in ok)
            ms_list, ms_check, listed, found = pass_cost(ok[-1][1]["result"], thickness, every)
            off_ms = statistics.median(x["ms_it"] for x, _ in ok)
            print(f"{name:24s} on/off ms per iteration x{ratio:.3f} ({off_ms:.2f} ms off); the pass alone on the "
                  f"final drape: {ms_list:.3f} ms per listing ({listed} pairs), {ms_check:.3f} ms per check "
                  f"({found} in contact)")


if __name__ == "__main__":
    main()
