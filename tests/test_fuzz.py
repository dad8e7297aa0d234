"""The bounded fuzzing run of the default tests: every parser gets malformed inputs for four
seconds each (about a minute in all); `make fuzz` runs 10,000 per parser."""

from __future__ import annotations

import json
import time
from pathlib import Path

import pytest

from tests.fuzz.run import main
from tests.fuzz.targets import TARGETS

BOUNDED = list(TARGETS)


def test_bounded_fuzz_run(tmp_path):
    rc = main(["--inputs", "2000", "--seconds", "4", "--targets", ",".join(BOUNDED), "--out", str(tmp_path)])
    rows = json.loads((tmp_path / "summary.json").read_text())
    assert [r["target"] for r in rows] == BOUNDED
    for r in rows:
        assert r["inputs"] >= 30, r  # each target really ran
        assert r.get("accepted", 0) and r.get("refused", 0), r  # mutations both kept and broke inputs
    failures = [(r["target"], f) for r in rows for f in r["failures"]]
    assert rc == 0 and not failures, failures[:10]


REGRESSIONS = sorted((Path(__file__).parent / "fuzz" / "regressions").glob("*.bin"))


@pytest.mark.parametrize("path", REGRESSIONS, ids=[p.stem for p in REGRESSIONS])
def test_inputs_the_fuzzer_found(path):
    """Each input a fuzzing run failed on (its file name: target-sha1) is now refused in one line,
    in time and within memory."""
    from tests.fuzz.run import HANG_SECONDS, _classify

    target = path.name.split("-")[0]
    t0 = time.perf_counter()
    outcome, detail = _classify(TARGETS[target], path.read_bytes())
    assert outcome in ("refused", "accepted"), (outcome, detail)
    assert time.perf_counter() - t0 < HANG_SECONDS
