"""The service's settings, in one place: every TRYON_* variable (the engine's too), read once.

    TRYON_DATA            data directory: the job database, uploads, results   (./data)
    TRYON_DB              the SQLite file of the jobs                           (DATA/jobs.sqlite)
    TRYON_MAX_UPLOAD_MB   largest accepted upload                               (50)
    TRYON_QUEUE_MAX       try-ons waiting at most; more get 429                 (20)
    TRYON_QUEUE_PER_TOKEN one token's try-ons waiting or running; more get 429  (5)
    TRYON_WORKERS         worker processes (each runs one try-on at a time)     (1)
    TRYON_ATTEMPTS        how often a try-on cut off by a restart is started    (2)
    TRYON_LEASE_SECONDS   a running try-on whose worker is silent this long is started again (30)
    TRYON_DRESS_SECONDS   wall time dressing one try-on may take (sewing, draping, every fabric
                          tried); past it the try-on fails and says so             (300)
    TRYON_TOKENS          comma-separated API tokens accepted besides issued ones
    TRYON_SECRET          key the API tokens are stored hashed with        (random, DATA/secret.key)
    TRYON_LINK_SECONDS    how long a try-on's result and viewer links work      (3600)
    TRYON_TOKEN_ISSUE     who may get a token: open, or admin (X-Admin-Key)     (open)
    TRYON_ADMIN_KEY       the admin key for TRYON_TOKEN_ISSUE=admin
    TRYON_TOKENS_PER_MINUTE  tokens issued to one client address a minute     (10)
    TRYON_PARSE_SECONDS   time an upload's read may take                        (60)
    TRYON_PARSE_MB        memory an upload's read may take                      (2048)
    TRYON_PARSE_SLOTS     uploads read at once; more wait                       (2)
    TRYON_UPLOADS_PER_TOKEN  one token's uploads being read or waiting; more 429 (2)
    and the engine's (engine/settings.py): TRYON_GL, TRYON_CACHE, TRYON_MAX_TRIANGLES,
    TRYON_QUERY_HELPER, TRYON_DEBUG.

`create_app` reads them (or takes a Settings) and passes them down: to the engine in this process
(engine.settings.use) and to each worker process it starts.
"""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, field_validator
from pydantic_settings import NoDecode, SettingsConfigDict

from engine.settings import EngineSettings


class Settings(EngineSettings):
    model_config = SettingsConfigDict(populate_by_name=True)

    data_dir: Path = Field(Path("data"), validation_alias="tryon_data")
    db_path: Path | None = Field(None, validation_alias="tryon_db")
    max_upload_mb: float = Field(50.0, gt=0)
    queue_max: int = Field(20, ge=1)
    queue_per_token: int = Field(5, ge=1)                # one token's try-ons waiting or running
    workers: int = Field(1, ge=1, le=16)
    attempts: int = Field(2, ge=1, le=10)
    lease_seconds: float = Field(30.0, ge=2, le=3600)   # a job stays a worker's this long without a heartbeat
    dress_seconds: float = Field(300.0, ge=5, le=86400)  # one try-on's dressing, wall time (then it fails)
    tokens: Annotated[list[str], NoDecode] = []
    secret: str | None = Field(None, repr=False)         # the key tokens are hashed with (else DATA/secret.key)
    link_seconds: float = Field(3600.0, gt=0)            # how long a job's result/viewer links work
    token_issue: Literal["open", "admin"] = "open"       # who may POST /api/tokens
    admin_key: str | None = Field(None, repr=False)      # with token_issue admin: the X-Admin-Key header
    tokens_per_minute: int = Field(10, ge=1)             # tokens one client address may be issued
    parse_seconds: float = Field(60.0, gt=0, le=3600)   # one upload's read, wall and CPU time
    parse_mb: int = Field(2048, ge=256)                  # memory one upload's read may take
    parse_slots: int = Field(2, ge=1, le=64)             # uploads read at once (more wait)
    uploads_per_token: int = Field(2, ge=1)              # one token's uploads being read or waiting

    @field_validator("tokens", mode="before")
    @classmethod
    def _comma_separated(cls, v):
        return [t.strip() for t in v.split(",") if t.strip()] if isinstance(v, str) else v

    @property
    def db(self) -> Path:
        return self.db_path or self.data_dir / "jobs.sqlite"

    @property
    def max_upload_bytes(self) -> int:
        return int(self.max_upload_mb * 2 ** 20)

    @property
    def parse_limits(self):
        from app.services.fence import Limits

        return Limits(seconds=self.parse_seconds, memory_mb=self.parse_mb)
