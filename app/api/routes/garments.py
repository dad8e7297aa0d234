"""Garments: the catalogue (names, sizes, fabrics) and uploaded patterns."""

from __future__ import annotations

from fastapi import APIRouter, File, Form, UploadFile

from app import crud
from app.api.deps import DBDep, Owner, OwnedGarment, UploadDep
from app.models import garment_public
from app.services import garments

router = APIRouter(prefix="/api/garments", tags=["garments"])


@router.get("")
def list_garments(who: Owner, db: DBDep):
    return {**garments.catalogue(), "uploaded": [garment_public(r) for r in crud.list_owned(db, "garments", who)]}


@router.post("", status_code=201)
async def upload_garment(up: UploadDep,
                         file: UploadFile = File(..., description="a GarmentCode JSON specification, or a DXF "
                                                 "of the pattern pieces (ASTM D6673 / AAMA, or closed polylines)"),
                         assembly: UploadFile | None = File(None, description="with a DXF: its assembly JSON "
                                                             "(stitches by panel and edge number, placement; "
                                                             "see `tryon pattern import`)"),
                         units: str | None = Form(None, description="with a DXF that does not say: mm, cm, m or in")):
    return garment_public(await garments.upload_pattern(file, assembly, units, up))


@router.get("/{gid}")
def get_garment(row: OwnedGarment):
    return garment_public(row)


@router.delete("/{gid}", status_code=204)
def delete_garment(row: OwnedGarment, db: DBDep):
    garments.delete_garment(row, db)
