"""Garments: the catalogue, and uploaded patterns (GarmentCode JSON, or a DXF with its assembly)
read and checked by the engine, stored as GarmentCode JSON."""

from __future__ import annotations

from pathlib import Path

from fastapi import HTTPException, UploadFile

from app import crud
from app.core.db import DB
from app.services.readers import read_dxf, read_pattern
from app.services.uploads import Upload, kept_only_if_stored, save_upload


def catalogue() -> dict:
    from engine.cloth.fabrics import FABRICS
    from engine.pattern.catalogue import AUTO, CATALOGUE, SIZES

    return {"catalogue": [{"name": n, "description": d} for n, (_, d) in CATALOGUE.items()],
            "sizes": [*SIZES, AUTO], "fabrics": list(FABRICS)}


def _check_pair(suffix: str, assembly: UploadFile | None) -> None:
    given = assembly is not None and bool(assembly.filename)
    if suffix not in (".json", ".dxf"):
        raise HTTPException(400, "a pattern is a GarmentCode JSON specification (.json) or a DXF of its pieces "
                            "(.dxf, with its assembly file)")
    if suffix == ".dxf" and not given:
        raise HTTPException(400, "a DXF holds the pieces but no seams or placement: upload its assembly file "
                            "with it (field 'assembly': stitches by panel and edge number, each panel's "
                            "translation and rotation -- `tryon pattern import PIECES.dxf` draws the pieces "
                            "with every edge numbered)")
    if suffix == ".json" and given:
        raise HTTPException(400, "an assembly file goes with a DXF; a GarmentCode pattern has its stitches "
                            "and placement already")


async def upload_pattern(file: UploadFile, assembly: UploadFile | None, units: str | None, ctx: Upload) -> dict:
    """Store and check an uploaded pattern (read in the fence); its row. 400 with the reason when it
    cannot be used; a DXF and its assembly are removed once converted."""
    suffix = Path(file.filename or "").suffix.lower()
    _check_pair(suffix, assembly)
    gid = crud.new_id()
    dest = ctx.settings.data_dir / "uploads" / f"pattern-{gid}.json"
    source, cap = file.filename or "pattern", ctx.settings.max_upload_bytes
    with kept_only_if_stored(dest):
        if suffix == ".dxf":
            dxf, asm = dest.with_suffix(".dxf"), dest.with_name(dest.stem + "-assembly.json")
            try:
                await save_upload(file, dxf, cap)
                await save_upload(assembly, asm, cap)
                info = await ctx.read(read_dxf, dxf, asm, units, dest, (source, assembly.filename),
                                      what=source, ours=dxf.name)
            finally:
                dxf.unlink(missing_ok=True)
                asm.unlink(missing_ok=True)
        else:
            await save_upload(file, dest, cap)
            info = await ctx.read(read_pattern, dest, source, what=source, ours=dest.name)
        return crud.create_garment(ctx.db, gid, ctx.who, str(dest), Path(source).stem[:80], info)


def delete_garment(row: dict, db: DB) -> None:
    Path(row["file"]).unlink(missing_ok=True)
    crud.delete(db, "garments", row["id"])
