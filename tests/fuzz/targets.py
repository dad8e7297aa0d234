"""What the fuzzers feed: each parser's public entry point, valid seed files to mutate, and what
an accepted result must satisfy (finite numbers).

A target takes the bytes of one input and returns the parsed result; it may raise only the
project's TryonError. Seeds are small (a capsule-shaped "body" of a few hundred triangles, the
sample skirt) so that thousands of inputs run in minutes.
"""

from __future__ import annotations

import io
import json
import tempfile
import zipfile
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Callable

import numpy as np

from tests.samples import GC_SHIRT, SAMPLE_SKIRT


@dataclass(frozen=True)
class Target:
    name: str
    kind: str                     # how inputs mutate: "text", "binary", "json", "glb", "zip"
    seeds: Callable[[], list[bytes]]
    parse: Callable[[bytes], object]
    finite: Callable[[object], bool]
    # one-time costs some inputs reach and the seeds do not (loaded before timing: not a hang)
    warm: Callable[[], None] | None = None


def _warm_body_model() -> None:
    """Loads the default body model (ANNY): an animated body without a rig is fitted with it (a
    first load takes 1-1.5 s; a mutant that reached it under load went past the hang bar)."""
    from engine.body.default import _anny_model

    _anny_model()


def _capsule(frame: int = 0):
    """A 1.7 m capsule standing on y = 0 (a body-sized closed mesh), moved a little per frame."""
    import trimesh

    m = trimesh.creation.capsule(height=1.3, radius=0.2, count=[12, 12])
    v = m.vertices[:, [0, 2, 1]] + [0.01 * frame, 0.85, 0.0]
    return v, m.faces


@lru_cache(maxsize=None)
def _mesh_seeds(fmt: str) -> tuple[bytes, ...]:
    import trimesh

    v, f = _capsule()
    m = trimesh.Trimesh(v, f, process=False)
    if fmt in ("ply", "stl"):
        return (m.export(file_type=fmt), m.export(file_type=fmt, encoding="ascii") if fmt == "ply"
                else trimesh.exchange.stl.export_stl_ascii(m).encode())
    out = m.export(file_type=fmt)
    return (out.encode() if isinstance(out, str) else out,)


def _in_file(data: bytes, suffix: str, fn):
    with tempfile.TemporaryDirectory() as d:
        p = Path(d) / f"input{suffix}"
        p.write_bytes(data)
        return fn(p)


def _mesh_target(fmt: str) -> Target:
    def parse(data: bytes):
        from engine.body.load import load_body_file

        return _in_file(data, f".{fmt}", load_body_file)

    kind = "text" if fmt in ("obj", "off") else ("glb" if fmt == "glb" else "binary")
    return Target(fmt, kind, lambda: list(_mesh_seeds(fmt)), parse, lambda b: bool(np.isfinite(b.vertices).all()))


def _anim_glb_seeds() -> list[bytes]:
    from tests.test_gltf_anim import _skinned_bar

    return [_skinned_bar()[0], _skinned_bar("CUBICSPLINE")[0] if False else _skinned_bar("STEP")[0]]


def _zip_seeds() -> list[bytes]:
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
        for k in range(3):
            v, f = _capsule(k)
            text = "".join(f"v {x:.5f} {y:.5f} {z:.5f}\n" for x, y, z in v) + \
                "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in f)
            z.writestr(f"frame_{k:03d}.obj", text)
    return [buf.getvalue()]


def _animation_target(name: str, suffix: str, seeds) -> Target:
    def parse(data: bytes):
        from engine.body.animation import load_animation

        return _in_file(data, suffix, lambda p: load_animation(p, 30.0))

    return Target(name, "glb" if suffix == ".glb" else "zip", seeds, parse,
                  lambda t: bool(np.isfinite(t.frames).all() and np.isfinite(t.vel).all()), warm=_warm_body_model)


def _numbers_finite(obj) -> bool:
    if isinstance(obj, float):
        return bool(np.isfinite(obj))
    if isinstance(obj, dict):
        return all(_numbers_finite(v) for v in obj.values())
    if isinstance(obj, (list, tuple)):
        return all(_numbers_finite(v) for v in obj)
    return True


def _pattern_finite(spec) -> bool:
    from engine.pattern.io import pattern_to_dict

    return _numbers_finite(pattern_to_dict(spec))


def _garmentcode(data: bytes):
    from engine.pattern.io import parse_pattern
    from engine.pattern.validate import check

    spec = parse_pattern(data, source="input.json")
    check(spec, source="input.json")
    return spec


@lru_cache(maxsize=None)
def _dxf_pair() -> tuple[bytes, bytes]:
    from engine.pattern.dxf import assembly_of, write_dxf
    from engine.pattern.io import load_pattern

    spec = load_pattern(SAMPLE_SKIRT)
    with tempfile.TemporaryDirectory() as d:
        write_dxf(spec, Path(d) / "p.dxf")
        return (Path(d) / "p.dxf").read_bytes(), json.dumps(assembly_of(spec)).encode()


def _dxf_with(dxf: bytes, asm: bytes):
    from engine.pattern.dxf import import_dxf, load_assembly
    from engine.pattern.validate import check

    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "p.dxf").write_bytes(dxf)
        (Path(d) / "a.json").write_bytes(asm)
        spec, _ = import_dxf(Path(d) / "p.dxf", load_assembly(Path(d) / "a.json"))
        check(spec, source="p.dxf")
        return spec


def _named_pieces_dxf(pieces: list[tuple[str, list]]) -> bytes:
    """A small pattern-CAD-like DXF (mm): a block per piece with its cut line (layer 1), turn
    points (2), grain line (7) and name, inserted side by side."""
    import ezdxf

    doc = ezdxf.new("R12")
    for k, (name, pts) in enumerate(pieces):
        blk = doc.blocks.new(f"P{k}")
        blk.add_polyline2d(pts, close=True, dxfattribs={"layer": "1"})
        for q in pts:
            blk.add_point(q, dxfattribs={"layer": "2"})
        blk.add_text(f"Piece Name: {name}", dxfattribs={"layer": "1"})
        blk.add_line((0, 100), (0, 500), dxfattribs={"layer": "7"})
        doc.modelspace().add_blockref(f"P{k}", (k * 700, 0))
    doc.modelspace().add_text("Units: METRIC")
    out = io.StringIO()
    doc.write(out)
    return out.getvalue().encode()


@lru_cache(maxsize=None)
def _alone_seeds() -> tuple[bytes, ...]:
    """A tee's front and back, and a one-piece leg with its waistband: garments the inference
    builds (shoulders, sides; rises, inseams, a band round the waist)."""
    half = [(250, 0), (250, 480), (220, 560), (185, 680), (80, 710)]
    mirror = [(-x, y) for x, y in reversed(half)]
    tee = [("FRONT", mirror + [(0, 640)] + half), ("BACK", mirror + [(0, 690)] + half)]
    legs = [("LEG", [(-100, 0), (100, 0), (230, 700), (170, 930), (-180, 960), (-270, 690)]),
            ("WAISTBAND", [(-350, 0), (350, 0), (350, 60), (-350, 60)])]
    return _named_pieces_dxf(tee), _named_pieces_dxf(legs)


def _dxf_alone(data: bytes):
    """A DXF alone, as the service reads an upload: every size read, the garment inferred in the
    default size (refused when none can be), checked, its seam picture drawn."""
    from engine.errors import InputError
    from engine.pattern.dxf import import_pattern
    from engine.pattern.dxf_read import read_pattern
    from engine.pattern.validate import check

    with tempfile.TemporaryDirectory() as d:
        (Path(d) / "p.dxf").write_bytes(data)
        imp = import_pattern(Path(d) / "p.dxf", pattern=read_pattern(Path(d) / "p.dxf"))
    if imp.kind == "pieces":
        raise InputError("; ".join(imp.unsure))
    check(imp.spec, source="p.dxf")
    imp.svg()
    return imp.spec


TARGETS = {t.name: t for t in [
    *(_mesh_target(f) for f in ("obj", "ply", "stl", "off", "glb")),
    _animation_target("glb_anim", ".glb", _anim_glb_seeds),
    _animation_target("zip", ".zip", _zip_seeds),
    Target("garmentcode", "json", lambda: [SAMPLE_SKIRT.read_bytes(), GC_SHIRT.read_bytes()], _garmentcode,
           _pattern_finite),
    Target("dxf", "text", lambda: [_dxf_pair()[0]], lambda b: _dxf_with(b, _dxf_pair()[1]), _pattern_finite),
    Target("assembly", "json", lambda: [_dxf_pair()[1]], lambda b: _dxf_with(_dxf_pair()[0], b), _pattern_finite),
    Target("dxf_alone", "text", lambda: list(_alone_seeds()), _dxf_alone, _pattern_finite),
]}


_API: dict = {}


def _api_client():
    """One service (workers not started) per fuzzing process, with one token."""
    if not _API:
        from fastapi.testclient import TestClient

        from app.core.config import Settings
        from app.main import create_app

        c = TestClient(create_app(Settings(data_dir=Path(tempfile.mkdtemp()) / "data", queue_max=10 ** 9,
                                           queue_per_token=10 ** 9), start_workers=False))
        c.__enter__()
        _API.update(client=c, headers={"Authorization": "Bearer " + c.post("/api/tokens").json()["token"],
                                       "Content-Type": "application/json"})
    return _API["client"], _API["headers"]


def _api_bodies(data: bytes):
    """The bytes as the JSON body of POST /api/tryons and POST /api/bodies/default: a 4xx is the
    project's refusal, a 5xx a failure."""
    from engine.errors import InputError

    c, h = _api_client()
    out = []
    for path in ("/api/tryons", "/api/bodies/default"):
        r = c.post(path, content=data, headers=h)
        if r.status_code >= 500:
            raise RuntimeError(f"{path}: {r.status_code} {r.text[:200]}")
        if r.status_code >= 400 and not isinstance(r.json().get("error"), str):
            raise RuntimeError(f"{path}: {r.status_code} without an error message")
        out.append(r.status_code)
    if all(s >= 400 for s in out):
        raise InputError(f"refused: {out}")
    return out


TARGETS["api"] = Target("api", "json", lambda: [
    json.dumps({"body": "default:female,height=1.7", "garment": "skirt", "size": "M", "fabric": "silk",
                "motion": "walk", "seconds": 2.0, "resolution_cm": 2.0, "preset": "male", "weight": 0.6}).encode(),
    json.dumps({"preset": "female", "height": 1.6, "garment": "dress", "body": "default:male"}).encode()],
    _api_bodies, lambda r: True)
