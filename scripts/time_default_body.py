"""Benchmark: how long the default body takes to build cold and to load from the cache.

    .venv/bin/python scripts/time_default_body.py            # cold build + cached load
    .venv/bin/python scripts/time_default_body.py --fully-cold   # also without body-models' cache

Each measurement runs in a fresh Python process with a temporary TRYON_CACHE, so nothing is
shared between them except what the measurement names. "--fully-cold" also points
XDG_CACHE_HOME at a temporary folder, so body-models has to preprocess the ANNY data again
(what the very first run on a new machine pays).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, time
t0 = time.perf_counter()
from engine.body.default import default_body
t1 = time.perf_counter()
body = default_body(PRESET)
t2 = time.perf_counter()
print(json.dumps({"import_s": t1 - t0, "call_s": t2 - t1, "height": body.height,
                  "vertices": len(body.vertices)}))
"""


def measure(preset: str, env_extra: dict[str, str]) -> dict:
    env = dict(os.environ, **env_extra)
    out = subprocess.run(
        [sys.executable, "-c", CHILD.replace("PRESET", repr(preset))],
        cwd=ROOT, env=env, capture_output=True, text=True, check=True,
    )
    return json.loads(out.stdout.strip().splitlines()[-1])


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--preset", default="female")
    ap.add_argument("--fully-cold", action="store_true", help="also rebuild body-models' ANNY cache")
    args = ap.parse_args()

    with tempfile.TemporaryDirectory() as cache:
        env = {"TRYON_CACHE": cache}
        if args.fully_cold:
            xdg = tempfile.mkdtemp()
            r = measure(args.preset, {**env, "XDG_CACHE_HOME": xdg})
            print(f"fully cold build (body-models cache empty): {r['call_s']:.2f} s "
                  f"(+ import {r['import_s']:.2f} s)")
            subprocess.run(["rm", "-rf", xdg], check=False)
            for p in Path(cache).glob("default_body/*"):
                p.unlink()
        r = measure(args.preset, env)
        print(f"cold build ({args.preset}, {r['vertices']} vertices, {r['height']:.3f} m): "
              f"{r['call_s']:.2f} s (+ import {r['import_s']:.2f} s)")
        loads = [measure(args.preset, env) for _ in range(3)]
        best = min(x["call_s"] for x in loads)
        print(f"cached load: {best * 1000:.1f} ms (best of 3 fresh processes; "
              f"+ import {min(x['import_s'] for x in loads):.2f} s)")


if __name__ == "__main__":
    main()
