"""`tryon drape` refuses bad input with one "error:" line and a non-zero exit, before simulating."""

from __future__ import annotations

import pytest
from typer.testing import CliRunner

from engine.cli import app
from tests.samples import SAMPLE_SKIRT

BODY = "default:female"  # cached: loads in well under a second


@pytest.fixture(autouse=True)
def no_simulation(monkeypatch):
    """Any refusal here must come before the cloth is simulated: make a step fail loudly."""
    from engine.cloth.solver import ClothSolver

    def boom(*a, **k):
        raise AssertionError("a simulation step ran")

    monkeypatch.setattr(ClothSolver, "step", boom)


def drape(tmp_path, *args):
    r = CliRunner().invoke(app, ["drape", "--body", BODY, "--out", str(tmp_path / "out"), *map(str, args)])
    return r


def assert_refused(r, *words):
    assert r.exit_code == 2, (r.exit_code, r.output, r.exception)
    assert isinstance(r.exception, SystemExit)  # not an escaped exception
    assert "Traceback" not in r.output
    err = [ln for ln in r.stderr.splitlines() if ln.startswith("error:")]
    assert len(err) == 1, r.stderr
    assert "internal error" not in err[0]
    for w in words:
        assert w in err[0], err[0]
    other = [ln for ln in r.stderr.splitlines() if ln.strip() and not ln.startswith(("error:", "note:"))]
    assert other == [], r.stderr
    return err[0]


def test_unknown_garment(tmp_path):
    line = assert_refused(drape(tmp_path, "--garment", "ballgown"), "ballgown")
    assert "skirt" in line  # lists the catalogue


def test_missing_pattern_file(tmp_path):
    assert_refused(drape(tmp_path, "--garment", tmp_path / "nope.json"), "not found", "nope.json")


@pytest.mark.parametrize("content, words", [
    ("{this is not json", "not valid JSON"),
    ('{"panels": {}}', "no 'pattern'"),
    ('{"pattern": {"panels": {"a": {"vertices": [[0, 0], [10, 0], [0, 10], [10, 10]], '
     '"edges": [{"endpoints": [0, 1]}, {"endpoints": [1, 2]}, {"endpoints": [2, 7]}, {"endpoints": [7, 0]}]}}}}',
     "names vertex 7"),
])
def test_malformed_pattern_file(tmp_path, content, words):
    p = tmp_path / "bad.json"
    p.write_text(content)
    assert_refused(drape(tmp_path, "--garment", p), words, "bad.json")


def test_unknown_fabric(tmp_path):
    line = assert_refused(drape(tmp_path, "--garment", SAMPLE_SKIRT, "--fabric", "wool"), "wool")
    assert "cotton" in line and "denim" in line


def test_unknown_size(tmp_path):
    line = assert_refused(drape(tmp_path, "--garment", "skirt", "--size", "XXXL"), "XXXL")
    assert "XXL" in line


@pytest.mark.parametrize("cm", [0, 100])
def test_resolution_out_of_range(tmp_path, cm):
    assert_refused(drape(tmp_path, "--garment", SAMPLE_SKIRT, "--resolution", cm), "out of range")


def test_texel_zero(tmp_path):
    assert_refused(drape(tmp_path, "--garment", SAMPLE_SKIRT, "--texel", 0), "texel", "out of range")


def test_unknown_collision(tmp_path):
    assert_refused(drape(tmp_path, "--garment", SAMPLE_SKIRT, "--collision", "psychic"), "psychic")


def test_dt_above_the_bound(tmp_path):
    # object-space collision: no OpenGL needed; the refusal comes from the solver's eq. 4 check
    args = ["--garment", SAMPLE_SKIRT, "--dt", 50, "--resolution", 4, "--collision", "object"]
    assert_refused(drape(tmp_path, *args), "stability bound", "force")
    assert not (tmp_path / "out" / "report.json").exists()


@pytest.mark.parametrize("args, words", [
    (["--dt", 0], ["time step must be positive"]),
    (["--velocity-mode", "sideways"], ["sideways", "average"]),
])
def test_solver_refusals(tmp_path, args, words):
    base = ["--garment", SAMPLE_SKIRT, "--resolution", 4, "--collision", "object"]
    assert_refused(drape(tmp_path, *base, *args), *words)
