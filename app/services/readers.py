"""What runs in the fenced child (app/services/fence.py): an uploaded file read by the engine,
the result small and picklable. Raises the engine's TryonError for a file that cannot be used."""

from __future__ import annotations

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


def read_dxf(dxf: Path, asm: Path, units: str | None, dest: Path, names: tuple[str, str]) -> dict:
    """A DXF and its assembly converted to GarmentCode JSON at `dest` and checked; its info.
    names: the client's names of the two files (errors name those, not ours)."""
    from engine.errors import TryonError
    from engine.pattern.dxf import import_dxf, load_assembly
    from engine.pattern.io import save_pattern
    from engine.pattern.validate import check

    try:
        spec, notes = import_dxf(dxf, load_assembly(asm), units)
    except TryonError as e:
        msg = str(e).replace(dxf.name, names[0]).replace(asm.name, names[1])
        raise type(e)(msg.replace("--units", "the 'units' field")) from None
    problems = check(spec, source=names[0])
    save_pattern(spec, dest)
    return {**_info(spec, problems), "notes": notes, "from": "dxf"}


def _info(spec, problems) -> dict:
    return {"panels": len(spec.pattern.panels), "warnings": [str(p) for p in problems]}
