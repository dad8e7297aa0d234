"""Try-ons: queue one, follow it, cancel or delete it, download its results."""

from __future__ import annotations

from fastapi import APIRouter, Header, HTTPException, Query
from fastapi.responses import FileResponse

from app import crud
from app.api.deps import DBDep, JobView, KeysDep, Owner, OwnedJob, SettingsDep, job_opened
from app.models import TryOnIn
from app.queue.results import RESULT_FILES, result_dir
from app.services import tryons

router = APIRouter(prefix="/api/tryons", tags=["tryons"])


@router.post("", status_code=202)
def create_tryon(req: TryOnIn, who: Owner, s: SettingsDep, db: DBDep, show: JobView):
    return show(tryons.submit(req, s, db, who))


@router.get("")
def list_tryons(who: Owner, db: DBDep, show: JobView):
    return [show(r) for r in crud.list_owned(db, "jobs", who)]


@router.get("/{jid}")
def get_tryon(row: OwnedJob, show: JobView):
    return show(row)


@router.post("/{jid}/cancel", status_code=202)
def cancel_tryon(row: OwnedJob, db: DBDep, show: JobView):
    return show(tryons.cancel(row, db))


@router.delete("/{jid}", status_code=204)
def delete_tryon(row: OwnedJob, s: SettingsDep, db: DBDep):
    tryons.delete(row, s, db)


@router.get("/{jid}/files/{name}")
def result_file(jid: str, name: str, s: SettingsDep, db: DBDep, keys: KeysDep, key: str | None = Query(None),
                authorization: str | None = Header(None)):
    """A result, by the job's signed link (`files` of the try-on) or with the owner's token."""
    row = job_opened(db, keys, jid, key, authorization)
    if name not in RESULT_FILES:
        raise HTTPException(404, f"no result '{name}': results are {', '.join(RESULT_FILES)}")
    d = result_dir(s.data_dir, row)
    p = d / name if d else None
    if p is None or not p.is_file():
        raise HTTPException(404, f"'{name}' is not there (yet): the try-on is not done, or did not make it")
    return FileResponse(p)
