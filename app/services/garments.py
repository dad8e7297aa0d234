"""Garments: the catalogue, and uploaded patterns -- GarmentCode JSON, read and checked by the
engine and stored as it is; or a DXF cutting pattern, alone (its garment inferred) or with its
assembly file (which then says how it is sewn), stored as uploaded in a folder of its own with
what the try-on and the page need: the assembly used, the seam picture of each size asked for."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

from fastapi import HTTPException, UploadFile

from app import crud
from app.core.db import DB
from app.services.readers import INFERRED, dxf_svg, read_dxf, read_pattern, svg_name
from app.services.uploads import Upload, kept_only_if_stored, save_upload

DXF_FILE, ASSEMBLY_FILE = "pattern.dxf", "assembly.json"  # a DXF garment's folder: as uploaded


def catalogue() -> dict:
    from engine.cloth.fabrics import FABRICS
    from engine.pattern.catalogue import AUTO, CATALOGUE, SIZES

    return {"catalogue": [{"name": n, "description": d} for n, (_, d) in CATALOGUE.items()],
            "sizes": [*SIZES, AUTO], "fabrics": list(FABRICS)}


def _check_pair(suffix: str, assembly: UploadFile | None) -> bool:
    """Whether an assembly file came with the pattern; 400 for what does not go together."""
    given = assembly is not None and bool(assembly.filename)
    if suffix not in (".json", ".dxf"):
        raise HTTPException(400, "a pattern is a GarmentCode JSON specification (.json) or a DXF cutting pattern "
                            "(.dxf; its seams are inferred, or upload its assembly file with it)")
    if suffix == ".json" and given:
        raise HTTPException(400, "an assembly file goes with a DXF; a GarmentCode pattern has its stitches "
                            "and placement already")
    return given


async def upload_pattern(file: UploadFile, assembly: UploadFile | None, units: str | None, ctx: Upload) -> dict:
    """Store and check an uploaded pattern (read in the fence); its row. 400 with the reason when it
    cannot be used; nothing is kept of a refused upload."""
    suffix = Path(file.filename or "").suffix.lower()
    given = _check_pair(suffix, assembly)
    gid = crud.new_id()
    source, cap = file.filename or "pattern", ctx.settings.max_upload_bytes
    name = Path(source).stem[:80]
    if suffix == ".dxf":
        folder = ctx.settings.data_dir / "uploads" / f"garment-{gid}"
        folder.mkdir(parents=True)
        with kept_only_if_stored(folder):
            await save_upload(file, folder / DXF_FILE, cap)
            asm = folder / ASSEMBLY_FILE if given else None
            if asm is not None:
                await save_upload(assembly, asm, cap)
            info = await ctx.read(read_dxf, folder / DXF_FILE, asm, units, folder,
                                  (Path(source).name, Path(assembly.filename).name if given else ""),
                                  what=source, ours=DXF_FILE)
            return crud.create_garment(ctx.db, gid, ctx.who, str(folder / DXF_FILE), name, info)
    dest = ctx.settings.data_dir / "uploads" / f"pattern-{gid}.json"
    with kept_only_if_stored(dest):
        await save_upload(file, dest, cap)
        info = await ctx.read(read_pattern, dest, source, what=source, ours=dest.name)
        return crud.create_garment(ctx.db, gid, ctx.who, str(dest), name, info)


def is_dxf(row: dict) -> bool:
    """Whether a stored garment is a DXF cutting pattern (its sizes, its inferred seams)."""
    return Path(row["file"]).name == DXF_FILE


def dxf_request(row: dict) -> dict:
    """What the worker needs to dress a stored DXF garment besides its file: the units and
    assembly given with it (engine.scene.request.TryOnRequest's `units`, `assembly`)."""
    asm = Path(row["file"]).with_name(ASSEMBLY_FILE)
    return {"units": json.loads(row["info"]).get("units_given"), "assembly": str(asm) if asm.is_file() else None}


async def pattern_svg(row: dict, size: str | None, ctx: Upload) -> Path:
    """The seam picture of a stored DXF garment in `size` (default: the size it was read in),
    made in the fence the first time it is asked for; 404 for a size it does not have."""
    if not is_dxf(row):
        raise HTTPException(404, "a seam picture is drawn for DXF patterns; this garment is a GarmentCode pattern")
    info = json.loads(row["info"])
    size = info["size"] if size is None else size
    if size not in info["sizes"]:
        raise HTTPException(404, f"no size '{size}' in this pattern: its sizes are {', '.join(info['sizes'])}")
    dxf = Path(row["file"])
    dest = dxf.with_name(svg_name(info["sizes"], size))
    if not dest.is_file():
        d = dxf_request(row)
        asm = Path(d["assembly"]) if d["assembly"] else None
        await ctx.read(dxf_svg, dxf, asm, d["units"], size, dest, info.get("file", row["name"]),
                       what=row["name"], ours=DXF_FILE)
    return dest


def assembly_file(row: dict) -> Path:
    """The assembly a stored DXF garment is sewn by: the one uploaded with it, or the inferred
    one (in the size it was read in; it serves every size), to correct and upload again."""
    folder = Path(row["file"]).parent
    for name in (ASSEMBLY_FILE, INFERRED):
        if is_dxf(row) and (folder / name).is_file():
            return folder / name
    raise HTTPException(404, "no assembly: this garment is a GarmentCode pattern, or no garment was inferred")


def delete_garment(row: dict, db: DB) -> None:
    if is_dxf(row):
        shutil.rmtree(Path(row["file"]).parent, ignore_errors=True)
    else:
        Path(row["file"]).unlink(missing_ok=True)
    crud.delete(db, "garments", row["id"])
