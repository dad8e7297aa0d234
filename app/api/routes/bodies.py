"""Bodies: uploaded scans and animations, default bodies by their parameters."""

from __future__ import annotations

from fastapi import APIRouter, File, Form, UploadFile

from app import crud
from app.api.deps import DBDep, Owner, OwnedBody, UploadDep
from app.models import DefaultBodyIn, body_public
from app.services import bodies

router = APIRouter(prefix="/api/bodies", tags=["bodies"])


@router.post("", status_code=201)
async def upload_body(up: UploadDep, file: UploadFile = File(...), fps: float = Form(30.0)):
    """A scan (a mesh file), or an animated body: a .zip of OBJ frames (one topology) played
    at `fps`, or a .glb with a morph-target or skinned animation sampled at `fps`. An
    animated body is dressed on its first frame and, with motion "walk", moves as uploaded."""
    return body_public(await bodies.upload_body(file, fps, up))


@router.post("/default", status_code=201)
def create_default_body(spec: DefaultBodyIn, who: Owner, db: DBDep):
    return body_public(bodies.default_body(spec, db, who))


@router.get("")
def list_bodies(who: Owner, db: DBDep):
    return [body_public(r) for r in crud.list_owned(db, "bodies", who)]


@router.get("/{bid}")
def get_body(row: OwnedBody):
    return body_public(row)


@router.delete("/{bid}", status_code=204)
def delete_body(row: OwnedBody, db: DBDep):
    bodies.delete_body(row, db)
