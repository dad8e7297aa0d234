"""`tryon bench --quick`: every section runs, the report and plots are written, and the stability
grid has no unstable cell (issue 6)."""

from __future__ import annotations

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from engine.cli import app


@pytest.mark.slow
def test_bench_quick(tmp_path):
    r = CliRunner().invoke(app, ["bench", "--quick", "--out", str(tmp_path)])
    assert r.exit_code == 0, (r.output, r.stderr)
    names = sorted(p.name for p in tmp_path.iterdir())
    assert names == ["pareto.png", "report.md", "results.json", "scaling.png", "stability.png"]
    res = json.loads((tmp_path / "results.json").read_text())
    assert res["total_seconds"] < 180  # "under two minutes" is the goal; CI machines vary
    st = res["stability"]
    assert st["unstable"] == 0, [c for c in st["cells"] if c["outcome"] == "unstable"]
    assert {c["outcome"] for c in st["cells"]} <= {"stable", "refused"}
    assert any(c["outcome"] == "refused" for c in st["cells"])  # dt above the eq. 4 bound is refused
    t1 = {(row["product"], row["collision"]) for row in res["table1"]}
    assert ("shirt", "image") in t1 and ("shirt", "object") in t1
    assert len(res["sweeps"]["runs"]) >= 5 and all(r["distance_mean_mm"] >= 0 for r in res["sweeps"]["runs"])
    # the scaling's fit is there; how straight its line is (r2) is a timing, the benchmark's to
    # report, not this test's (in the slow suite, beside the other test process, it was 0.78 once
    # where it is > 0.95 alone); that 16 x the vertices take longer an iteration is not
    fit = res["scaling"]["fits"]["image"]
    assert np.isfinite(fit["r2"]) and fit["ms_per_1000_vertices"] > 0
    image = sorted((r["vertices"], r["ms_per_iteration"]) for r in res["scaling"]["cloth"] if r["collision"] == "image")
    assert len(image) == 3 and image[-1][0] > 10 * image[0][0] and image[-1][1] > image[0][1], image
    md = (tmp_path / "report.md").read_text()
    for heading in ("Table 1", "Error against run time", "Scaling", "Stability map", "peer"):
        assert heading in md, heading


def test_decimate_keeps_a_body():
    """The scaling sweep's coarser bodies: vertex clustering keeps a usable mesh."""
    import numpy as np

    from engine.body.default import default_body
    from engine.scene.bench import _decimate

    b = default_body("female")
    v, f, seg = _decimate(b.vertices, b.faces, 0.03, b.segments)
    assert 1000 < len(f) < len(b.faces) // 3
    assert f.max() < len(v) and np.all(f[:, 0] != f[:, 1])
    assert abs(v[:, 1].max() - b.vertices[:, 1].max()) < 0.03 and len(seg) == len(v)
