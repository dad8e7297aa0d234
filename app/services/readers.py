"""What runs in the fenced child (app/services/fence.py): an uploaded file read by the engine,
the result small and picklable. Raises the engine's TryonError for a file that cannot be used."""

from __future__ import annotations

import json
from pathlib import Path


def measure_notes(b) -> list[str]:
    """What the measurements say about a scan before it is dressed (arms held too close for
    tops, armpits not found...), or why they cannot be taken."""
    from engine.body.measure import measure
    from engine.errors import TryonError

    try:
        return list(measure(b).notes)
    except TryonError as e:
        return [f"the body could not be measured, so catalogue garments cannot be sized for it: {e}"]


def read_body(path: Path, fps: float) -> tuple[str, dict]:
    """(kind, info) of a stored body file: a scan ("upload") or an animation (a .zip of frames,
    or a .glb/.gltf that has one)."""
    from engine.body.gltf_anim import has_animation

    ext = path.suffix.lower()
    if ext == ".zip" or (ext in (".glb", ".gltf") and has_animation(path)):
        from engine.body.animation import load_animation

        track = load_animation(path, fps)
        n = int(track.frames.shape[0])
        b, kind, notes = track.body, "animation", list(track.notes)
        extra = {"frames": n, "fps": fps, "seconds": round((n - 1) / fps, 3)}
    else:
        from engine.body.load import load_body_file

        b = load_body_file(path)
        kind, notes, extra = "upload", list(b.notes) + measure_notes(b), {}
    return kind, {"height_m": round(b.height, 4), "vertices": int(len(b.vertices)), **extra, "notes": notes}


def read_pattern(path: Path, source: str) -> dict:
    """The info of a GarmentCode JSON pattern, parsed and checked."""
    from engine.pattern.io import parse_pattern
    from engine.pattern.validate import check

    spec = parse_pattern(path.read_bytes(), source=source)
    return _info(spec, check(spec, source=source))


def read_dxf(dxf: Path, asm: Path | None, units: str | None, folder: Path, names: tuple[str, str]) -> dict:
    """A DXF cutting pattern (and its assembly, if given) read, its garment inferred (or
    assembled) and checked in its default size; its seam picture (`svg_name`) and the assembly
    used written to `folder`; its info: units, sizes (the file's order), pieces, the garment and
    what the inference is unsure of. names: the client's names of the two files (errors name
    those, not ours)."""
    from engine.pattern.dxf import load_assembly, summary
    from engine.pattern.dxf_read import read_pattern

    with _client_names(names, dxf, asm):
        pattern = read_pattern(dxf, units)
        pattern.source = names[0]
        assembly = load_assembly(asm) if asm is not None else None
        imp, problems = _import(pattern, dxf, None, assembly, names[0])
    (folder / svg_name(pattern.sizes, imp.size)).write_text(imp.svg())
    if imp.assembly is not None:
        (folder / INFERRED).write_text(json.dumps(imp.assembly, indent=1))
    s = summary(pattern, imp)
    pieces = [{k: p[k] for k in ("name", "quantity", "cut", "category", "annotation")} for p in s["pieces"]]
    g = s["garment"]
    return {**_info(imp.spec, problems), "from": "dxf", "file": names[0], "units": s["units"], "units_note": s["units_note"],
            "units_given": units, "sizes": s["sizes"], "size": imp.size, "pieces": pieces,
            "garment": {k: g[k] for k in ("kind", "panels", "seams", "unsure", "left_out")},
            "notes": s["notes"] + g["notes"], "fabric": g["fabric"],
            "assembly": "yours" if assembly is not None else "inferred"}


def dxf_svg(dxf: Path, asm: Path | None, units: str | None, size: str, dest: Path, source: str) -> None:
    """pattern.svg of a stored DXF pattern (read at its upload) in another of its sizes, written to
    `dest`; source: the client's name of the file."""
    from engine.pattern.dxf import load_assembly
    from engine.pattern.dxf_read import read_pattern

    pattern = read_pattern(dxf, units)
    pattern.source = source
    imp, _ = _import(pattern, dxf, size, load_assembly(asm) if asm is not None else None, source)
    tmp = dest.with_suffix(".part")
    tmp.write_text(imp.svg())
    tmp.replace(dest)  # (two requests for one picture: each writes its own, the last one stays)


INFERRED = "inferred-assembly.json"


def svg_name(sizes: list[str], size: str) -> str:
    """The stored picture of a size (by its place in the file's sizes: a size name may hold any
    character)."""
    return f"pattern-{sizes.index(size)}.svg"


def _import(pattern, dxf: Path, size: str | None, assembly, source: str):
    """(Imported, its problems) of the pattern in `size`; InputError when no garment can be made."""
    from engine.errors import InputError
    from engine.pattern.dxf import import_pattern
    from engine.pattern.validate import check

    imp = import_pattern(dxf, size, assembly=assembly, pattern=pattern)
    if imp.kind == "pieces" and assembly is None:
        raise InputError(f"{source}: {'; '.join(imp.unsure)} (upload its assembly file with it: field 'assembly'; "
                         "`tryon pattern import` draws the pieces with every corner and edge numbered)")
    return imp, check(imp.spec, source=source)


class _client_names:
    """Errors inside name the client's files (and their 'units' field), not our stored names."""

    def __init__(self, names: tuple[str, str], dxf: Path, asm: Path | None):
        self.pairs = [(dxf.name, names[0])] + ([(asm.name, names[1])] if asm is not None else [])

    def __enter__(self):
        return self

    def __exit__(self, kind, e, tb):
        from engine.errors import TryonError

        if not isinstance(e, TryonError):
            return False
        msg = str(e)
        for ours, theirs in self.pairs:
            msg = msg.replace(ours, theirs)
        raise type(e)(msg.replace("--units", "the 'units' field")) from None


def _info(spec, problems) -> dict:
    return {"panels": len(spec.pattern.panels), "warnings": [str(p) for p in problems]}
