"""The fuzzing run: every parser fed `--inputs` malformed inputs grown from its seeds (hypothesis
strategies, tests/fuzz/mutate.py), each target in its own process whose address space is capped
at what it had loaded + 1 GiB. Per input: accepted (its numbers must be finite), refused with the
project's one-line error, or a failure -- another exception ("uncaught"), a multi-line message,
NaN/inf accepted, more than HANG_SECONDS, or more than the memory cap. Failing inputs are saved
under --out for regression tests.

    python -m tests.fuzz.run --inputs 10000 --out out/fuzz            # all targets (make fuzz)
    python -m tests.fuzz.run --inputs 200 --targets obj,zip --seconds 60
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import signal
import subprocess
import sys
import time
import traceback
from collections import Counter
from pathlib import Path

HANG_SECONDS = 5.0
MEMORY_CAP = 2 ** 30


class Hang(Exception):
    pass


class TimeUp(Exception):
    """--seconds ran out: ends the run (hypothesis would otherwise go on drawing inputs unused)."""


def _hang(*_):
    raise Hang()


def _vm_size() -> int:
    with open("/proc/self/status") as f:
        return next(int(ln.split()[1]) * 1024 for ln in f if ln.startswith("VmSize:"))


def _classify(target, raw: bytes) -> tuple[str, str]:
    """(outcome, detail) of one input."""
    from engine.errors import TryonError

    signal.signal(signal.SIGALRM, _hang)
    signal.setitimer(signal.ITIMER_REAL, HANG_SECONDS * 2)
    try:
        result = target.parse(raw)
        return ("accepted", "") if target.finite(result) else ("nonfinite", "NaN or inf accepted")
    except Hang:
        return "hang", f"over {HANG_SECONDS * 2:g} s (interrupted)"
    except TryonError as e:
        msg = str(e)
        if "needs more memory" in msg:
            return "memory", msg
        return ("refused", "") if "\n" not in msg and msg else ("multiline", msg[:300])
    except BaseException as e:  # noqa: BLE001 -- what the fuzzer is looking for
        tb = traceback.extract_tb(e.__traceback__)
        site = f"{tb[-1].filename.split('site-packages/')[-1]}:{tb[-1].lineno}" if tb else "?"
        return "uncaught", f"{type(e).__name__} at {site}: {str(e)[:120]}"
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)


def run_target(name: str, n: int, seconds: float, out: Path) -> dict:
    """In this process: `n` inputs (or `seconds` of them) through target `name`."""
    from hypothesis import HealthCheck, Phase, given, settings
    from hypothesis import strategies as st

    from tests.fuzz.mutate import inputs
    from tests.fuzz.targets import TARGETS

    target = TARGETS[name]
    seeds = target.seeds()
    for s in seeds:  # warm: imports, caches, compiled kernels are not the inputs' cost
        _classify(target, s)
    if target.warm is not None:
        target.warm()
    cap = _vm_size() + MEMORY_CAP
    resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    counts, worst, failures, t_end = Counter(), [0.0, ""], [], time.monotonic() + seconds

    @settings(max_examples=n, deadline=None, database=None, phases=[Phase.generate],
              suppress_health_check=list(HealthCheck))
    @given(st.one_of([inputs(target.kind, s) for s in seeds]))
    def one(raw: bytes) -> None:
        if time.monotonic() > t_end:
            raise TimeUp()
        t0 = time.perf_counter()
        outcome, detail = _classify(target, raw)
        dt = time.perf_counter() - t0
        if dt > HANG_SECONDS and outcome != "hang":
            outcome, detail = "hang", f"{dt:.1f} s"
        counts[outcome] += 1
        if dt > worst[0]:
            worst[:] = [dt, outcome]
        if outcome not in ("accepted", "refused"):
            key = hashlib.sha1(raw).hexdigest()[:12]
            out.mkdir(parents=True, exist_ok=True)
            (out / f"{name}-{key}.bin").write_bytes(raw)
            failures.append({"file": f"{name}-{key}.bin", "outcome": outcome, "detail": detail})

    try:
        one()
    except TimeUp:
        pass
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"target": name, "inputs": sum(counts.values()), **dict(counts), "slowest_s": round(worst[0], 3),
            "peak_rss_mb": round(peak), "failures": failures[:50], "failed": len(failures)}


def main(argv=None) -> int:
    from tests.fuzz.targets import TARGETS

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--inputs", type=int, default=10_000, help="inputs per target")
    ap.add_argument("--seconds", type=float, default=1e9, help="at most this long per target")
    ap.add_argument("--targets", default="all", help="comma-separated, of: " + ", ".join(TARGETS))
    ap.add_argument("--out", type=Path, default=Path("out/fuzz"))
    ap.add_argument("--one", help=argparse.SUPPRESS)  # internal: run one target in this process
    a = ap.parse_args(argv)
    if a.one:
        print(json.dumps(run_target(a.one, a.inputs, a.seconds, a.out)))
        return 0
    names = list(TARGETS) if a.targets == "all" else a.targets.split(",")
    rows, bad = [], 0
    for name in names:
        cmd = [sys.executable, "-m", "tests.fuzz.run", "--one", name, "--inputs", str(a.inputs),
               "--seconds", str(a.seconds), "--out", str(a.out)]
        t0 = time.perf_counter()
        try:  # a target that stalls in native code is stopped here (inputs are timed inside)
            p = subprocess.run(cmd, capture_output=True, text=True, env={**os.environ, "PYTHONHASHSEED": "0"},
                               timeout=min(a.seconds + 120, 60 + a.inputs * HANG_SECONDS))
            row = json.loads(p.stdout.strip().splitlines()[-1])
        except (IndexError, json.JSONDecodeError, subprocess.TimeoutExpired) as e:
            why = "timed out" if isinstance(e, subprocess.TimeoutExpired) else f"exit {p.returncode}: {p.stderr[-500:]}"
            row = {"target": name, "inputs": 0, "failed": 1, "failures": [{"outcome": "died", "detail": why}]}
        row["wall_s"] = round(time.perf_counter() - t0, 1)
        rows.append(row)
        bad += row["failed"]
        print(f"{name:12s} inputs {row['inputs']:6d}  accepted {row.get('accepted', 0):6d}  refused "
              f"{row.get('refused', 0):6d}  failed {row['failed']:4d}  slowest {row.get('slowest_s', 0):6.2f} s  "
              f"peak {row.get('peak_rss_mb', 0):5d} MB  ({row['wall_s']} s)", flush=True)
        for f in row["failures"][:5]:
            print(f"    {f['outcome']}: {f['detail']}", flush=True)
    a.out.mkdir(parents=True, exist_ok=True)
    (a.out / "summary.json").write_text(json.dumps(rows, indent=1))
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
