"""What the routes depend on: the settings, the database, and who is asking (auth)."""

from __future__ import annotations

from typing import Annotated, Callable

from fastapi import Depends, Header, HTTPException, Path, Query
from starlette.requests import HTTPConnection

from app import crud
from app.core.config import Settings
from app.core.db import DB
from app.core.security import Keys
from app.services.uploads import Upload


def get_settings(conn: HTTPConnection) -> Settings:
    return conn.app.state.settings


def get_db(conn: HTTPConnection) -> DB:
    return conn.app.state.db


def get_keys(conn: HTTPConnection) -> Keys:
    return conn.app.state.keys


SettingsDep = Annotated[Settings, Depends(get_settings)]
DBDep = Annotated[DB, Depends(get_db)]
KeysDep = Annotated[Keys, Depends(get_keys)]


def bearer(authorization: str | None) -> str | None:
    """The token of an `Authorization: Bearer <token>` header."""
    if authorization and authorization.lower().startswith("bearer "):
        return authorization[7:].strip() or None
    return None


def current_owner(keys: KeysDep, db: DBDep, authorization: str | None = Header(None)) -> str:
    """Who asks: the keyed hash of the API token in the Authorization header (only there: never
    in a URL, where logs keep it). It owns what it makes."""
    t = bearer(authorization)
    if not t:
        raise HTTPException(401, "no API token: send 'Authorization: Bearer <token>' (POST /api/tokens gives one)")
    h = keys.token_hash(t)
    if not (keys.is_fixed(t) or crud.token_known(db, h)):
        raise HTTPException(401, "unknown API token: create one with POST /api/tokens")
    return h


Owner = Annotated[str, Depends(current_owner)]


def upload_context(settings: SettingsDep, db: DBDep, who: Owner, conn: HTTPConnection) -> Upload:
    return Upload(settings, db, who, conn.app.state.gate)


UploadDep = Annotated[Upload, Depends(upload_context)]


def garment_opened(settings: SettingsDep, db: DBDep, keys: KeysDep, conn: HTTPConnection,
                   gid: str = Path(), key: str | None = Query(None),
                   authorization: str | None = Header(None)) -> tuple[dict, Upload]:
    """A garment opened by its signed link or its owner's token, and the reading context of its
    owner (a picture drawn on demand is read in the fence, counted against the owner's uploads)."""
    row = job_opened(db, keys, gid, key, authorization, table="garments")
    return row, Upload(settings, db, row["owner"], conn.app.state.gate)


OpenedGarment = Annotated[tuple[dict, Upload], Depends(garment_opened)]

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


def job_view(s: SettingsDep, keys: KeysDep):
    """row -> the try-on's JSON, its links signed with a fresh job key."""
    from app.models import job_public

    return lambda row: job_public(row, s.data_dir, keys.link_key(row["id"]))


JobView = Annotated[Callable[[dict], dict], Depends(job_view)]


def job_opened(db: DBDep, keys: KeysDep, jid: str, key: str | None, authorization: str | None,
               table: str = "jobs") -> dict:
    """A job (or a garment: table "garments") opened by its signed key (links, the viewer) or by
    its owner's token; else 401/404."""
    kind = NAMES[table]
    if keys.opens(key, jid, kind):
        row = crud.get(db, table, jid)
    elif authorization:
        return owned(db, table, jid, current_owner(keys, db, authorization))
    else:
        what = "try-on" if kind == "job" else kind
        raise HTTPException(401, f"this link has expired or is not valid: open the {what} again for a fresh one")
    if row is None:
        raise HTTPException(404, f"no {'try-on' if kind == 'job' else kind} '{jid}'")
    return row


def garment_view(s: SettingsDep, keys: KeysDep):
    """row -> the garment's JSON, its picture links signed with a fresh garment key."""
    from app.models import garment_public

    return lambda row: garment_public(row, keys.link_key(row["id"], "garment"))


GarmentView = Annotated[Callable[[dict], dict], Depends(garment_view)]
