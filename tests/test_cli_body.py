"""`tryon body info`: measurements as JSON, and one-line errors without tracebacks."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from tests.samples import SAMPLE_BODY, SAMPLE_YAML, set_engine_env  # noqa: F401
from engine.cli import app

SAMPLE = SAMPLE_BODY
REF = yaml.safe_load(SAMPLE_YAML.read_text())["body"]
TRYON = Path(sys.executable).parent / "tryon"


def run_cli(*args, timeout=60):
    return subprocess.run([str(TRYON), *map(str, args)], capture_output=True, text=True, timeout=timeout)


def test_body_info_json_matches_reference():
    r = run_cli("body", "info", SAMPLE, "--json")
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["units"] == "cm"
    assert abs(d["height"] - REF["height"]) <= 1.0
    for key in ("bust", "waist", "hips"):
        assert abs(d[key] - REF[key]) <= 3.0, key
    assert "Traceback" not in r.stderr


def test_body_info_text():
    r = CliRunner().invoke(app, ["body", "info", str(SAMPLE)])
    assert r.exit_code == 0, r.output
    assert "Hip circumference" in r.stdout and "note: units: metres" in r.stderr


def _bad_files(tmp):
    import trimesh

    m = trimesh.load(SAMPLE, process=False)
    rng = np.random.default_rng(0)
    files = {}
    (tmp / "empty.obj").write_bytes(b"")
    files["empty"] = tmp / "empty.obj"
    for ext in ("obj", "ply", "stl"):
        (tmp / f"garbage.{ext}").write_bytes(rng.bytes(3000))
        files[f"garbage_{ext}"] = tmp / f"garbage.{ext}"
    trimesh.PointCloud(m.vertices).export(tmp / "pc.ply")
    files["points"] = tmp / "pc.ply"
    (tmp / "nan.obj").write_text("v 0 0 0\nv 1 nan 0\nv 0 1 0\nf 1 2 3\n")
    files["nan"] = tmp / "nan.obj"
    trimesh.Trimesh(m.vertices * 0.06, m.faces, process=False).export(tmp / "small.ply")
    files["small"] = tmp / "small.ply"
    trimesh.Trimesh(m.vertices * 18.0, m.faces, process=False).export(tmp / "big.ply")
    files["big"] = tmp / "big.ply"
    (tmp / "body.fbx").write_bytes(b"x")
    files["unsupported"] = tmp / "body.fbx"
    files["missing"] = tmp / "missing.obj"
    return files


def _one_line_error(exit_code, stderr):
    assert exit_code != 0
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    errors = [ln for ln in lines if ln.startswith("error:")]
    assert len(errors) == 1, stderr
    assert "Traceback" not in stderr


def test_refusals_through_cli(tmp_path, monkeypatch):
    runner = CliRunner()
    for name, path in _bad_files(tmp_path).items():
        r = runner.invoke(app, ["body", "info", str(path)])
        assert r.exception is None or isinstance(r.exception, SystemExit), (name, r.exception)
        _one_line_error(r.exit_code, r.stderr)
    for extra in (["--up", "q"], ["--front", "+y", "--up", "y"]):
        r = runner.invoke(app, ["body", "info", str(SAMPLE), *extra])
        _one_line_error(r.exit_code, r.stderr)
    set_engine_env(monkeypatch, TRYON_MAX_TRIANGLES="1000")
    r = runner.invoke(app, ["body", "info", str(SAMPLE)])
    _one_line_error(r.exit_code, r.stderr)
    assert "limit of 1,000" in r.stderr
    for name, value in (("TRYON_MAX_TRIANGLES", "many"), ("TRYON_GL", "vulkan")):  # read once, up front
        set_engine_env(monkeypatch, **{name: value})
        r = runner.invoke(app, ["body", "info", str(SAMPLE)])
        _one_line_error(r.exit_code, r.stderr)
        assert r.exit_code == 2 and f"{name}='{value}'" in r.stderr, r.stderr


@pytest.mark.parametrize("name", ["garbage_obj", "nan"])
def test_refusal_real_process(tmp_path, name):
    path = _bad_files(tmp_path)[name]
    r = run_cli("body", "info", path)
    assert r.returncode == 2
    _one_line_error(r.returncode, r.stderr)
