"""Garments: the catalogue, and uploaded patterns (GarmentCode JSON, or a DXF with its assembly)
read and checked by the engine, stored as GarmentCode JSON."""

from __future__ import annotations

from pathlib import Path

from fastapi import HTTPException, UploadFile

from app import crud
from app.core.config import Settings
from app.core.db import DB
from app.services.uploads import save_upload


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


async def _from_dxf(file: UploadFile, assembly: UploadFile, units: str | None, dest: Path, cap: int):
    """(spec, notes) of an uploaded DXF and its assembly, written to `dest` as GarmentCode JSON;
    the uploads are removed once converted."""
    from engine.errors import TryonError
    from engine.pattern.dxf import import_dxf, load_assembly
    from engine.pattern.io import save_pattern

    dxf, asm = dest.with_suffix(".dxf"), dest.with_name(dest.stem + "-assembly.json")
    try:
        await save_upload(file, dxf, cap)
        await save_upload(assembly, asm, cap)
        try:
            spec, notes = import_dxf(dxf, load_assembly(asm), units)
        except TryonError as e:  # name the client's files, not ours
            msg = str(e).replace(dxf.name, file.filename or "pattern").replace(asm.name, assembly.filename)
            raise type(e)(msg.replace("--units", "the 'units' field")) from None
        save_pattern(spec, dest)
        return spec, notes
    finally:
        dxf.unlink(missing_ok=True)
        asm.unlink(missing_ok=True)


async def upload_pattern(file: UploadFile, assembly: UploadFile | None, units: str | None,
                         settings: Settings, db: DB, who: str) -> dict:
    """Store and check an uploaded pattern; its row. 400 with the reason when it cannot be used."""
    from engine.errors import TryonError
    from engine.pattern.io import parse_pattern
    from engine.pattern.validate import check

    suffix = Path(file.filename or "").suffix.lower()
    _check_pair(suffix, assembly)
    gid = crud.new_id()
    dest = settings.data_dir / "uploads" / f"pattern-{gid}.json"
    source = file.filename or "pattern"
    notes: list[str] = []
    try:
        if suffix == ".dxf":
            spec, notes = await _from_dxf(file, assembly, units, dest, settings.max_upload_bytes)
        else:
            await save_upload(file, dest, settings.max_upload_bytes)
            spec = parse_pattern(dest.read_bytes(), source=source)
        problems = check(spec, source=source)
    except TryonError as e:
        dest.unlink(missing_ok=True)
        raise HTTPException(400, str(e)) from None
    info = {"panels": len(spec.pattern.panels), "warnings": [str(p) for p in problems],
            **({"notes": notes, "from": "dxf"} if suffix == ".dxf" else {})}
    return crud.create_garment(db, gid, who, str(dest), Path(source).stem[:80], info)


def delete_garment(row: dict, db: DB) -> None:
    Path(row["file"]).unlink(missing_ok=True)
    crud.delete(db, "garments", row["id"])
