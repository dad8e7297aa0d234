"""The service's settings, in one place, from the environment (TRYON_* variables).

    TRYON_DATA            data directory: the job database, uploads, results   (./data)
    TRYON_DB              the SQLite file of the jobs                           (DATA/jobs.sqlite)
    TRYON_MAX_UPLOAD_MB   largest accepted upload                               (50)
    TRYON_QUEUE_MAX       try-ons waiting at most; more get 429                 (20)
    TRYON_WORKERS         worker processes (each runs one try-on at a time)     (1)
    TRYON_ATTEMPTS        how often a try-on cut off by a restart is started    (2)
    TRYON_TOKENS          comma-separated API tokens accepted besides issued ones
"""

from __future__ import annotations

import os
from pathlib import Path

from pydantic import BaseModel, Field


class Settings(BaseModel):
    data_dir: Path = Path("data")
    db_path: Path | None = None
    max_upload_bytes: int = Field(50 * 2 ** 20, gt=0)
    queue_max: int = Field(20, ge=1)
    workers: int = Field(1, ge=1, le=16)
    attempts: int = Field(2, ge=1, le=10)
    tokens: list[str] = []

    @property
    def db(self) -> Path:
        return self.db_path or self.data_dir / "jobs.sqlite"

    @classmethod
    def from_env(cls, **over) -> "Settings":
        e = os.environ
        kw: dict = {}
        if "TRYON_DATA" in e:
            kw["data_dir"] = Path(e["TRYON_DATA"])
        if "TRYON_DB" in e:
            kw["db_path"] = Path(e["TRYON_DB"])
        if "TRYON_MAX_UPLOAD_MB" in e:
            kw["max_upload_bytes"] = int(float(e["TRYON_MAX_UPLOAD_MB"]) * 2 ** 20)
        for key, name in (("queue_max", "TRYON_QUEUE_MAX"), ("workers", "TRYON_WORKERS"),
                          ("attempts", "TRYON_ATTEMPTS")):
            if name in e:
                kw[key] = int(e[name])
        if e.get("TRYON_TOKENS"):
            kw["tokens"] = [t.strip() for t in e["TRYON_TOKENS"].split(",") if t.strip()]
        kw.update(over)
        return cls(**kw)
