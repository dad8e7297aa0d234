"""Bodies: an uploaded scan or animation read by the engine, or a default body's spec checked."""

from __future__ import annotations

import math
from pathlib import Path

from fastapi import HTTPException, UploadFile

from app import crud
from app.core.db import DB
from app.models import DefaultBodyIn
from app.services.readers import read_body
from app.services.uploads import Upload, kept_only_if_stored, save_upload

BODY_EXT = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf", ".zip")  # .zip: OBJ frames (an animation)


async def upload_body(file: UploadFile, fps: float, ctx: Upload) -> dict:
    """Store and read an uploaded body (fenced: app/services/fence.py); its row. 400/413/422 with
    the reason when it cannot be used; nothing is kept of a refused one."""
    ext = Path(file.filename or "").suffix.lower()
    if ext not in BODY_EXT:
        raise HTTPException(400, f"body file type '{ext or 'none'}' is not supported: give one of {' '.join(BODY_EXT)}")
    if not (math.isfinite(fps) and 5.0 <= fps <= 240.0):
        raise HTTPException(422, f"fps {fps:g}: give the animation's frame rate, 5 .. 240")
    bid = crud.new_id()
    dest = ctx.settings.data_dir / "uploads" / f"body-{bid}{ext}"  # our name, never the client's
    client = file.filename or dest.name
    with kept_only_if_stored(dest):
        await save_upload(file, dest, ctx.settings.max_upload_bytes)
        kind, info = await ctx.read(read_body, dest, fps, what=client, ours=dest.name)
        return crud.create_body(ctx.db, bid, ctx.who, kind, str(dest), Path(file.filename or "scan").stem[:80], info)


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
