"""Where a try-on's results are: DATA/jobs/<id>/, the files the API serves from it."""

from __future__ import annotations

from pathlib import Path

RESULT_FILES = ("scene.glb", "garment.obj", "front.png", "side.png", "back.png", "report.json", "anim.glb",
                "strip.png", "recording.viser", "pattern.json", "pattern.svg")


def job_dir(data_dir: Path, jid: str) -> Path:
    return Path(data_dir) / "jobs" / jid

