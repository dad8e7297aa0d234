"""Receiving an uploaded file: streamed to our own name under DATA/uploads, size-capped."""

from __future__ import annotations

from pathlib import Path

from fastapi import HTTPException, UploadFile


async def save_upload(f: UploadFile, dest: Path, cap: int) -> None:
    """Write `f` to `dest`; 413 past `cap` bytes, 400 when empty (nothing is left behind)."""
    n = 0
    dest.parent.mkdir(parents=True, exist_ok=True)
    with open(dest, "wb") as out:
        while chunk := await f.read(1 << 20):
            n += len(chunk)
            if n > cap:
                out.close()
                dest.unlink(missing_ok=True)
                raise HTTPException(413, f"upload larger than {cap / 2 ** 20:.0f} MB: decimate the mesh "
                                         "or raise TRYON_MAX_UPLOAD_MB")
            out.write(chunk)
    if n == 0:
        dest.unlink(missing_ok=True)
        raise HTTPException(400, "the uploaded file is empty")
