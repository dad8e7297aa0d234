"""Bodies: an uploaded scan or animation read by the engine, or a default body's spec checked."""

from __future__ import annotations

import math
from pathlib import Path

from fastapi import HTTPException, UploadFile
from starlette.concurrency import run_in_threadpool

from app import crud
from app.core.config import Settings
from app.core.db import DB
from app.models import DefaultBodyIn
from app.services.uploads import save_upload

BODY_EXT = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf", ".zip")  # .zip: OBJ frames (an animation)


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
    or a .glb/.gltf that has one). Raises the engine's TryonError."""
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


async def upload_body(file: UploadFile, fps: float, settings: Settings, db: DB, who: str) -> dict:
    """Store and read an uploaded body; its row. 400/413/422 with the reason when it cannot be used."""
    from engine.errors import TryonError

    ext = Path(file.filename or "").suffix.lower()
    if ext not in BODY_EXT:
        raise HTTPException(400, f"body file type '{ext or 'none'}' is not supported: give one of {' '.join(BODY_EXT)}")
    if not (math.isfinite(fps) and 5.0 <= fps <= 240.0):
        raise HTTPException(422, f"fps {fps:g}: give the animation's frame rate, 5 .. 240")
    bid = crud.new_id()
    dest = settings.data_dir / "uploads" / f"body-{bid}{ext}"  # our name, never the client's
    await save_upload(file, dest, settings.max_upload_bytes)
    try:
        kind, info = await run_in_threadpool(read_body, dest, fps)  # seconds for long ones: off the event loop
    except TryonError as e:
        dest.unlink(missing_ok=True)
        raise HTTPException(400, str(e).replace(dest.name, file.filename or dest.name)) from None
    name = Path(file.filename or "scan").stem[:80]
    return crud.create_body(db, bid, who, kind, str(dest), name, info)


def default_body(spec: DefaultBodyIn, db: DB, who: str) -> dict:
    """A default body's row, its parameters checked (422 with the range when out of it)."""
    from engine.body.default import check_params
    from engine.errors import InputError

    params = {k: v for k, v in spec.model_dump().items() if k != "preset" and v is not None}
    try:
        check_params(spec.preset, params)
    except InputError as e:
        raise HTTPException(422, str(e)) from None
    text = "default:" + ",".join([spec.preset] + [f"{k}={v:g}" for k, v in params.items()])
    return crud.create_body(db, crud.new_id(), who, "default", text, text, {"spec": text})


def delete_body(row: dict, db: DB) -> None:
    if row["kind"] in ("upload", "animation"):
        Path(row["spec"]).unlink(missing_ok=True)
    crud.delete(db, "bodies", row["id"])
