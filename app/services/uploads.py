"""Receiving an uploaded file: streamed to our own name under DATA/uploads, size-capped, then read
in the fence (app/services/fence.py); nothing is left of a refused or failed upload."""

from __future__ import annotations

import errno
import shutil
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path

from fastapi import HTTPException, UploadFile

from app.core.config import Settings
from app.core.db import DB
from app.services.fence import Gate

DISK_FULL = "the server's disk is full: nothing was kept; try again later"


@dataclass
class Upload:
    """Who uploads, and where to: what the upload services need from the request."""
    settings: Settings
    db: DB
    who: str
    gate: Gate

    async def read(self, fn, *args, what: str, ours: str):
        """fn(*args) in the fence; errors name the client's file `what`, not our name `ours`."""
        try:
            return await self.gate.run(self.who, fn, *args, settings=self.settings,
                                       limits=self.settings.parse_limits, what=what)
        except HTTPException as e:
            raise HTTPException(e.status_code, str(e.detail).replace(ours, what), e.headers) from None


@contextmanager
def kept_only_if_stored(*paths: Path):
    """The files (or folders) are removed if anything inside fails (a refusal, a full disk, a bug)."""
    try:
        yield
    except BaseException:
        for p in paths:
            if p.is_dir():
                shutil.rmtree(p, ignore_errors=True)
            else:
                p.unlink(missing_ok=True)
        raise


async def save_upload(f: UploadFile, dest: Path, cap: int) -> None:
    """Write `f` to `dest`; 413 past `cap` bytes, 400 when empty, 507 when the disk is full."""
    n = 0
    dest.parent.mkdir(parents=True, exist_ok=True)
    try:
        with open(dest, "wb") as out:
            while chunk := await f.read(1 << 20):
                n += len(chunk)
                if n > cap:
                    raise HTTPException(413, f"upload larger than {cap / 2 ** 20:.0f} MB: decimate the mesh "
                                             "or raise TRYON_MAX_UPLOAD_MB")
                out.write(chunk)
    except OSError as e:
        dest.unlink(missing_ok=True)
        if e.errno in (errno.ENOSPC, errno.EDQUOT):
            raise HTTPException(507, DISK_FULL) from None
        raise
    except HTTPException:
        dest.unlink(missing_ok=True)
        raise
    if n == 0:
        dest.unlink(missing_ok=True)
        raise HTTPException(400, "the uploaded file is empty")
