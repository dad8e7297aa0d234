"""What the routes depend on: the settings, the database, and who is asking (auth)."""

from __future__ import annotations

from typing import Annotated

from fastapi import Depends, Header, HTTPException, Path, Query
from starlette.requests import HTTPConnection

from app import crud
from app.core.config import Settings
from app.core.db import DB
from app.services.uploads import Upload


def get_settings(conn: HTTPConnection) -> Settings:
    return conn.app.state.settings


def get_db(conn: HTTPConnection) -> DB:
    return conn.app.state.db


SettingsDep = Annotated[Settings, Depends(get_settings)]
DBDep = Annotated[DB, Depends(get_db)]


def bearer(authorization: str | None) -> str | None:
    """The token of an `Authorization: Bearer <token>` header."""
    if authorization and authorization.lower().startswith("bearer "):
        return authorization[7:].strip() or None
    return None


def known(settings: Settings, db: DB, token: str | None) -> bool:
    return bool(token) and (token in settings.tokens or crud.token_known(db, token))


def current_owner(settings: SettingsDep, db: DBDep, authorization: str | None = Header(None),
                  token: str | None = Query(None)) -> str:
    """The API token asking (header, or ?token= for downloads and the page): it owns what it makes."""
    t = bearer(authorization) or token
    if not t:
        raise HTTPException(401, "no API token: send 'Authorization: Bearer <token>' (POST /api/tokens gives one)")
    if not known(settings, db, t):
        raise HTTPException(401, "unknown API token: create one with POST /api/tokens")
    return t


Owner = Annotated[str, Depends(current_owner)]


def upload_context(settings: SettingsDep, db: DBDep, who: Owner, conn: HTTPConnection) -> Upload:
    return Upload(settings, db, who, conn.app.state.gate)


UploadDep = Annotated[Upload, Depends(upload_context)]

NAMES = {"bodies": "body", "garments": "garment", "jobs": "job"}


def owned(db: DB, table: str, rid: str, who: str) -> dict:
    """The row `rid` of `table` if `who` owns it, else 404 (another token's ids read as missing)."""
    row = crud.get_owned(db, table, rid, who)
    if row is None:
        raise HTTPException(404, f"no {NAMES[table]} '{rid}' for this token")
    return row


def _owned_row(table: str, param: str):
    """A dependency: the row of `table` named by the path parameter `param`, owned by the caller."""
    def dep(db: DBDep, who: Owner, rid: str = Path(alias=param)) -> dict:
        return owned(db, table, rid, who)
    return Annotated[dict, Depends(dep)]


OwnedBody = _owned_row("bodies", "bid")
OwnedGarment = _owned_row("garments", "gid")
OwnedJob = _owned_row("jobs", "jid")
