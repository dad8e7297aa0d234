"""The bounded fuzzing run of the default tests: every parser but the DXF pair gets malformed inputs
for a few seconds each (about a minute in all); `make fuzz` runs 10,000 per parser. The DXF reader
and its assembly loader (engine/pattern/dxf.py) are being rewritten (issue 49): their targets run in
`make fuzz` and join this list once the new reader is in."""

from __future__ import annotations

import json

from tests.fuzz.run import main
from tests.fuzz.targets import TARGETS

BOUNDED = [t for t in TARGETS if t not in ("dxf", "assembly")]


def test_bounded_fuzz_run(tmp_path):
    rc = main(["--inputs", "2000", "--seconds", "6", "--targets", ",".join(BOUNDED), "--out", str(tmp_path)])
    rows = json.loads((tmp_path / "summary.json").read_text())
    assert [r["target"] for r in rows] == BOUNDED
    for r in rows:
        assert r["inputs"] >= 30, r  # each target really ran
        assert r.get("accepted", 0) and r.get("refused", 0), r  # mutations both kept and broke inputs
    failures = [(r["target"], f) for r in rows for f in r["failures"]]
    assert rc == 0 and not failures, failures[:10]
