"""What the API takes (pydantic request models) and gives (a stored row turned into its JSON)."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Literal

from pydantic import BaseModel, Field

from engine.scene.request import TryOnRequest

from app.queue.results import RESULT_FILES, result_dir


class DefaultBodyIn(BaseModel):
    preset: Literal["female", "male"] = "female"
    height: float | None = Field(None, description="metres, 1.40 .. 2.10")
    weight: float | None = Field(None, description="0 thin .. 0.5 average .. 1 heavy")
    muscle: float | None = None
    proportions: float | None = None
    gender: float | None = None
    age: float | None = None


class TryOnIn(TryOnRequest):
    """A try-on: the engine's request (what `tryon drape`/`tryon walk` take) on a body of yours.
    (`assembly` and `units` go with a DXF upload, POST /api/garments, not here.)"""

    body_id: str | None = Field(None, description="a body you created; or give `body`")
    body: str | None = Field(None, description="a default body spec, e.g. default:female,height=1.7")


def body_public(row: dict) -> dict:
    return {"id": row["id"], "kind": row["kind"], "name": row["name"], "info": json.loads(row["info"] or "{}")}


def garment_public(row: dict, key: str) -> dict:
    """An uploaded pattern as the API shows it: its info and, for a DXF, links to its seam
    picture (`pattern_svg`, in its default size; add `&size=` for another of its sizes) signed with
    the garment's `key`, and to the assembly it is sewn by."""
    out = {"id": row["id"], "name": row["name"], "info": json.loads(row["info"] or "{}")}
    if Path(row["file"]).suffix.lower() == ".dxf":
        base = f"/api/garments/{row['id']}"
        out["links"] = {"pattern_svg": f"{base}/pattern.svg?key={key}", "assembly": f"{base}/assembly.json"}
    return out


def job_public(row: dict, data_dir: Path, key: str) -> dict:
    """A try-on as the API shows it: its state, request, and once done its report, files and viewer
    -- their links signed with the job's `key` (short-lived; app/core/security.py)."""
    out = {k: row[k] for k in ("id", "status", "progress", "stage", "message", "error", "attempts")}
    out["request"] = json.loads(row["request"])
    # the whole job's time, from its (last) start: every size --size auto dressed, and the walk
    out["seconds"] = row["finished"] - row["started"] if row["finished"] and row["started"] else None
    d = result_dir(data_dir, row)
    if row["status"] == "done":
        out["report"] = json.loads(row["report"] or "{}")
        out["files"] = {n: f"/api/tryons/{row['id']}/files/{n}?key={key}" for n in RESULT_FILES
                        if d and (d / n).exists()}
    live = row["status"] == "running" and row["viewer_port"]
    recorded = d is not None and (d / "recording.viser").exists()
    out["viewer"] = f"/viewer/{row['id']}/?key={key}" if live or recorded else None
    return out
