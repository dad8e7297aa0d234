"""Where a try-on's results are. Each attempt writes DATA/jobs/<id>/attempt-<n>.partial/ and, once
it has finished, renames it to attempt-<n>/ (atomic) and records that name as the job's result:
only a done job's recorded folder is ever served, so a half-written or failed attempt never is."""

from __future__ import annotations

import shutil
from pathlib import Path

RESULT_FILES = ("scene.glb", "garment.obj", "front.png", "side.png", "back.png", "report.json", "anim.glb",
                "strip.png", "recording.viser", "pattern.json", "pattern.svg")


def job_dir(data_dir: Path, jid: str) -> Path:
    return Path(data_dir) / "jobs" / jid


def attempt_dir(data_dir: Path, jid: str, attempt: int, partial: bool = True) -> Path:
    return job_dir(data_dir, jid) / (f"attempt-{attempt}" + (".partial" if partial else ""))


def result_dir(data_dir: Path, row: dict) -> Path | None:
    """The published results of a done job, else None."""
    if row.get("status") != "done" or not row.get("result"):
        return None
    return job_dir(data_dir, row["id"]) / row["result"]


def drop_partials(data_dir: Path, jid: str) -> None:
    """Remove the unfinished attempts of a job that no runner holds."""
    for d in job_dir(data_dir, jid).glob("attempt-*.partial"):
        shutil.rmtree(d, ignore_errors=True)
