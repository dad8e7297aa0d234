"""A worker process: takes queued try-ons from the database, runs them with the engine, writes
their results and status. Started with multiprocessing's spawn (never fork after a GL context).

A try-on's request (JSON, resolved by the API): body {"spec": "default:female,..."},
{"file": path} or {"animation": path, "fps": rate} (dressed on its first frame; with motion
"walk" it moves as uploaded); garment {"name": catalogue name} or {"file": pattern path}; size, fabric,
motion ("none" or "walk"), seconds, resolution_cm. Results go to DATA/jobs/<id>/.
"""

from __future__ import annotations

import json
import os
import shutil
import time
import traceback
from pathlib import Path

from app.db import DB


class Cancelled(Exception):
    pass


def job_dir(data_dir: Path, jid: str) -> Path:
    return Path(data_dir) / "jobs" / jid


def worker_main(db_path: str, data_dir: str, poll: float = 0.2) -> None:
    db = DB(Path(db_path))
    pid = os.getpid()
    warm = True  # warm up once, while no try-on waits (one that does is not kept waiting for it)
    while True:
        job = db.claim(pid)
        if job is None:
            if warm:
                warm = False
                warm_up()
                continue
            time.sleep(poll)
            continue
        warm = False
        run_job(db, job, Path(data_dir))


def warm_up() -> dict:
    """Load what every try-on needs before the first one comes: the engine's modules, its
    compiled kernels (numba's cache), the default body and the OpenGL context with its
    shaders -- by dressing a coarse skirt (4 cm cloth, ~160 steps). Measured (dress, M, on
    default:female): in a fresh process the engine imported in 0.9 s and the first dress took
    5.4 s (maps 0.45 s: the GL context), after this warm-up (3 s of idle time, imports
    included) 3.6-3.9 s (maps 0.04 s). Walking is not warmed (a 0.1 s walk added 3 s,
    mostly the gait's planning, to a try-on that walks for 20 s and more).
    It is only a speed-up: whatever fails here is logged and the worker goes on (the try-on
    that meets the same failure reports it). Returns {"seconds": ..., "ok": bool}."""
    t0 = time.perf_counter()
    try:
        from engine.body import resolve_body
        from engine.scene.garments import resolve_garment
        from engine.scene.request import TryOnOptions
        from engine.scene.tryon import run_tryon
        from engine.scene.tuning import DrapeTuning, SewTuning, Tuning

        body = resolve_body("default:female")
        spec, place, label = resolve_garment("skirt", body, "M")
        run_tryon(body, spec, TryOnOptions(resolution_cm=4.0), Tuning(sew=SewTuning(budget=0.05),
                                                                      drape=DrapeTuning(budget=0.05)),
                  place=place, source=label)
        ok = True
    except Exception:  # noqa: BLE001 -- an optimisation only: never stop the worker
        traceback.print_exc()
        ok = False
    return {"seconds": time.perf_counter() - t0, "ok": ok}


def run_job(db: DB, job: dict, data_dir: Path) -> None:
    from engine.errors import TryonError

    jid = job["id"]
    out = job_dir(data_dir, jid)
    last = [0.0]

    def progress(stage: str, fraction: float, message: str) -> None:
        now = time.monotonic()
        if now - last[0] < 0.3:
            return
        last[0] = now
        row = db.one("SELECT cancel FROM jobs WHERE id=?", jid)
        if row is None or row["cancel"]:
            raise Cancelled()
        db.run("UPDATE jobs SET stage=?, progress=?, message=? WHERE id=?", stage, float(fraction), message, jid)

    def live(port: int) -> None:
        db.run("UPDATE jobs SET viewer_port=? WHERE id=?", port, jid)

    try:
        report = _run(json.loads(job["request"]), out, progress, live)
    except Cancelled:
        shutil.rmtree(out, ignore_errors=True)
        db.finish(jid, "cancelled", "cancelled on request")
        return
    except TryonError as e:
        shutil.rmtree(out, ignore_errors=True)
        db.finish(jid, "failed", str(e))
        return
    except Exception as e:  # a bug: the job fails with the reason, the worker goes on
        shutil.rmtree(out, ignore_errors=True)
        db.finish(jid, "failed", f"internal error ({type(e).__name__}: {e})")
        traceback.print_exc()
        return
    if db.one("SELECT id FROM jobs WHERE id=?", jid) is None:  # deleted while it ran
        shutil.rmtree(out, ignore_errors=True)
        return
    db.run("UPDATE jobs SET progress=1, stage='done', message='' WHERE id=?", jid)
    db.finish(jid, "done", None, report)


def _run(req: dict, out: Path, progress, live=None) -> dict:
    from engine.body import resolve_body

    progress("body", 0.0, "loading the body")
    b = req["body"]
    track = None
    if "animation" in b:
        from engine.body.animation import load_animation

        track = load_animation(b["animation"], float(b.get("fps", 30.0)))
        body = track.body
    else:
        from engine.scene.arms import clear_hands

        body = clear_hands(resolve_body(b["spec"] if "spec" in b else b["file"]))
    g = req["garment"]
    fabric = req.get("fabric", "cotton")
    walking = req.get("motion", "none") == "walk"
    from app.viewer import LiveView

    view = LiveView(body.vertices, body.faces)
    try:
        if live is not None:
            live(view.port)
        return _simulate(req, body, g, fabric, walking, out, progress, view, track)
    finally:
        view.close()


def _simulate(req, body, g, fabric, walking, out, progress, view, track=None) -> dict:
    from engine.scene.request import TryOnRequest
    from engine.scene.tryon import dress_request, write_outputs

    retry = [""]  # while --size auto dresses a larger size, every progress message says why

    def note(size, why, other):
        retry[0] = f"size {size} did not fit, trying {other} -- "

    catalogue = "name" in g
    request = TryOnRequest(garment=g["name"] if catalogue else g["file"],
                           size=(req.get("size") or "M") if catalogue else None, fabric=fabric,
                           resolution_cm=req.get("resolution_cm", 1.5), motion=req.get("motion", "none"),
                           seconds=req.get("seconds", 4.0), fps=track.fps if track is not None else 30.0)
    res, report = dress_request(body, request, progress=lambda stage, f, msg: progress(stage, f, retry[0] + msg),
                                observer=view, note=note if catalogue else None,
                                label=None if catalogue else g.get("label"))
    out.mkdir(parents=True, exist_ok=True)
    write_outputs(out, body, res, report, size=500)
    if walking:
        from engine.scene.walk import walk_cloth, walk_report, walking_body, write_walk_outputs

        # an uploaded animation moves as uploaded; a scan walks with the default skeleton fitted to it
        walker = body if track is not None else walking_body(body)
        w = walk_cloth(walker, res, request, progress=progress, observer=view, track=track)
        report = walk_report(report, w.report)
        write_walk_outputs(out, walker, w, report)
    view.save(out / "recording.viser")
    return report
