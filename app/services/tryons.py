"""A try-on request checked and resolved into the worker's request (app/queue/worker.py), then
queued; cancel and delete."""

from __future__ import annotations

import json
import shutil

from fastapi import HTTPException

from app import crud
from app.api.deps import owned
from app.core.config import Settings
from app.core.db import DB
from app.models import TryOnIn
from app.queue.results import job_dir
from app.services import garments


def _body(req: TryOnIn, db: DB, who: str) -> dict:
    if (req.body_id is None) == (req.body is None):
        raise HTTPException(422, "give either body_id (a body you created) or body (e.g. default:female)")
    if req.body_id is None:
        if not req.body.startswith("default:"):
            raise HTTPException(422, "body: only default bodies by name (default:female, default:male); "
                                     "upload a scan with POST /api/bodies and give its body_id")
        _check_default(req.body)
        return {"spec": req.body}
    row = owned(db, "bodies", req.body_id, who)
    if row["kind"] == "default":
        return {"spec": row["spec"]}
    if row["kind"] == "animation":
        return {"animation": row["spec"], "fps": json.loads(row["info"])["fps"]}
    return {"file": row["spec"]}


def _check_default(spec: str) -> None:
    """A default body's spec checked now (preset, names, ranges), not first in the worker."""
    from engine.body import parse_default_spec
    from engine.body.default import check_params
    from engine.errors import InputError

    try:
        check_params(*parse_default_spec(spec))
    except InputError as e:
        raise HTTPException(422, f"body: {e}") from None


def _garment(req: TryOnIn, db: DB, who: str) -> tuple[dict, str | None]:
    """The worker's garment and size for `req`: a catalogue garment in a chart size or auto; an
    uploaded DXF in one of its own sizes or auto; a GarmentCode pattern in its one size."""
    from engine.pattern.catalogue import AUTO, CATALOGUE, SIZES

    if req.assembly is not None or req.units is not None:
        raise HTTPException(422, "assembly and units go with the DXF they belong to: upload them with it "
                                 "(POST /api/garments, fields 'assembly' and 'units')")
    auto = req.size is not None and req.size.lower() == AUTO
    if req.garment in CATALOGUE:
        if req.size is not None and req.size.upper() not in SIZES and not auto:
            raise HTTPException(422, f"size '{req.size}': choose one of {', '.join(SIZES)} or {AUTO}")
        return {"name": req.garment}, None if req.size is None else (AUTO if auto else req.size.upper())
    g = crud.get_owned(db, "garments", req.garment, who)
    if g is None:
        raise HTTPException(404, f"garment '{req.garment}' is neither in the catalogue "
                                 f"({', '.join(CATALOGUE)}) nor one of your patterns")
    out = {"file": g["file"], "label": g["name"]}
    if garments.is_dxf(g):
        sizes = json.loads(g["info"])["sizes"]
        if req.size is not None and req.size not in sizes and not auto:
            raise HTTPException(422, f"size '{req.size}': this pattern's sizes are {', '.join(sizes)} (or {AUTO})")
        return {**out, "dxf": garments.dxf_request(g)}, AUTO if auto else req.size
    if req.size is not None:
        raise HTTPException(422, "size applies to catalogue garments and DXF patterns; a GarmentCode pattern has "
                                 "its own size")
    return out, None


def resolve(req: TryOnIn, db: DB, who: str) -> dict:
    """The worker's request for `req` (bodies and patterns by their stored files), or 4xx."""
    from engine.scene.request import TryOnOptions

    body, (garment, size) = _body(req, db, who), _garment(req, db, who)
    # the service's own bounds, inside the engine's (a shared server: no 0.2 cm cloth, no minute-long walks)
    if not (0.75 <= req.resolution_cm <= 4.0):
        raise HTTPException(422, "resolution_cm: use 0.75 .. 4 cm")
    if req.seconds > 20.0:
        raise HTTPException(422, "seconds: walk 0.1 .. 20 s")
    return {"body": body, "garment": garment, "size": size, **req.model_dump(include=set(TryOnOptions.model_fields))}


def submit(req: TryOnIn, settings: Settings, db: DB, who: str) -> dict:
    """Queue a try-on; its row. 429 (with Retry-After) when the queue is full."""
    jid, full = crud.enqueue(db, who, resolve(req, db, who), settings.queue_max, settings.queue_per_token)
    if full:
        wait = 30 * max(1, settings.queue_max // settings.workers)
        why = (f"the queue is full ({settings.queue_max} try-ons waiting)" if full == "all" else
               f"you have {settings.queue_per_token} try-ons waiting or running (TRYON_QUEUE_PER_TOKEN)")
        raise HTTPException(429, f"{why}: try again later", headers={"Retry-After": str(wait)})
    return crud.get(db, "jobs", jid)


def cancel(row: dict, db: DB) -> dict:
    if row["status"] not in crud.ACTIVE:
        raise HTTPException(409, f"try-on '{row['id']}' is already {row['status']}")
    crud.cancel(db, row["id"])
    return crud.get(db, "jobs", row["id"])


def delete(row: dict, settings: Settings, db: DB) -> None:
    crud.delete_job(db, row["id"])
    shutil.rmtree(job_dir(settings.data_dir, row["id"]), ignore_errors=True)
