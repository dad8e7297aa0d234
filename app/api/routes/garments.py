"""Garments: the catalogue (names, sizes, fabrics) and uploaded patterns."""

from __future__ import annotations

from fastapi import APIRouter, File, Form, Query, UploadFile
from fastapi.responses import FileResponse

from app import crud
from app.api.deps import DBDep, GarmentView, OpenedGarment, Owner, OwnedGarment, UploadDep
from app.services import garments

router = APIRouter(prefix="/api/garments", tags=["garments"])
SVG_POLICY = {"Content-Security-Policy": "default-src 'none'; style-src 'unsafe-inline'"}  # a picture, no more


@router.get("")
def list_garments(who: Owner, db: DBDep, show: GarmentView):
    return {**garments.catalogue(), "uploaded": [show(r) for r in crud.list_owned(db, "garments", who)]}


@router.post("", status_code=201)
async def upload_garment(up: UploadDep, show: GarmentView,
                         file: UploadFile = File(..., description="a GarmentCode JSON specification, or a DXF "
                                                 "cutting pattern (ASTM D6673 / AAMA, or closed polylines): its "
                                                 "sizes, and its seams inferred"),
                         assembly: UploadFile | None = File(None, description="with a DXF, optional: its assembly "
                                                             "JSON, used instead of the inferred seams (the "
                                                             "inferred one, corrected: GET .../assembly.json)"),
                         units: str | None = Form(None, description="with a DXF that does not say: mm, cm, m or in")):
    """A pattern; a DXF's info lists its sizes (the file's order), pieces, the garment inferred
    and what the inference is unsure of, and links its seam picture (`pattern_svg`)."""
    return show(await garments.upload_pattern(file, assembly, units, up))


@router.get("/{gid}")
def get_garment(row: OwnedGarment, show: GarmentView):
    return show(row)


@router.get("/{gid}/pattern.svg")
async def garment_svg(opened: OpenedGarment,
                      size: str | None = Query(None, description="one of the pattern's sizes (default: the size "
                                                                 "it was read in: its sample size, else its middle one)")):
    """A DXF pattern's pieces in one size with its seams numbered and coloured, by the garment's
    signed link (`links` of the garment) or with the owner's token."""
    row, ctx = opened
    return FileResponse(await garments.pattern_svg(row, size, ctx), media_type="image/svg+xml", headers=SVG_POLICY)


@router.get("/{gid}/assembly.json")
def garment_assembly(row: OwnedGarment):
    """The assembly a DXF pattern is sewn by (the inferred one, or yours): to correct and upload
    with the DXF again."""
    return FileResponse(garments.assembly_file(row), media_type="application/json")


@router.delete("/{gid}", status_code=204)
def delete_garment(row: OwnedGarment, db: DBDep):
    garments.delete_garment(row, db)
