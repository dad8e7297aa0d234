"""A worker process: takes queued try-ons from the database, runs them with the engine, writes
their results and status. Started with multiprocessing's spawn (never fork after a GL context).

A try-on's request (JSON, resolved by the API): body {"spec": "default:female,..."},
{"file": path} or {"animation": path, "fps": rate} (dressed on its first frame; with motion
"walk" it moves as uploaded); garment {"name": catalogue name} or {"file": pattern path, "label":
its name, "dxf": {"units", "assembly"} for a DXF}; size, fabric, motion ("none" or "walk"),
seconds, resolution_cm. Results go to DATA/jobs/<id>/attempt-<n>/
(app/queue/results.py). The worker gets the service's settings from its supervisor and hands them
to the engine; it holds a job by a lease that its heartbeats extend, and dies with its supervisor.
"""

from __future__ import annotations

import ctypes
import errno
import json
import os
import shutil
import signal
import sqlite3
import threading
import time
import traceback
from pathlib import Path

from app import crud
from app.core.config import Settings
from app.core.db import DB
from app.queue.results import attempt_dir, job_dir


STOP = threading.Event()  # set by SIGTERM: finish the step, give the job back, exit


class Cancelled(Exception):
    pass


class Stopped(Exception):
    """The worker is stopping (SIGTERM): its job is given back to the queue."""


class LeaseLost(Exception):
    """The job is no longer this attempt's (requeued after a lost lease, or deleted)."""


def worker_main(settings: Settings, parent: int, poll: float = 0.2) -> None:
    from engine.settings import use

    _die_with(parent)
    os.nice(5)  # the API's answers first: a try-on is minutes of CPU, a request milliseconds
    signal.signal(signal.SIGTERM, lambda *_: STOP.set())
    use(settings)
    db = DB(settings.db)
    pid = os.getpid()
    warm = True  # warm up once, while no try-on waits (one that does is not kept waiting for it)
    while not STOP.is_set() and os.getppid() == parent:
        try:
            job = crud.claim(db, pid, settings.lease_seconds)
            if job is None:
                if warm:
                    warm = False
                    warm_up()
                    continue
                time.sleep(poll)
                continue
            warm = False
            run_job(db, job, settings.data_dir, settings.lease_seconds, settings.dress_seconds)
        except sqlite3.Error:  # a full disk or a locked database: the job's lease runs out and it is requeued
            traceback.print_exc()
            time.sleep(1.0)


def _die_with(parent: int) -> None:
    """Die when the supervisor's process does (Linux: PR_SET_PDEATHSIG), so that no orphan keeps
    running a job that a restarted service runs again; a parent already gone ends us now."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(1, signal.SIGKILL)  # 1: PR_SET_PDEATHSIG
    except (OSError, AttributeError):  # not Linux: the lease and the parent check below still hold
        pass
    if os.getppid() != parent:
        os._exit(0)


class Heartbeat:
    """A thread that extends the job's lease every sixth of it; `lost` once the attempt no longer
    holds it (or the database could not be written for a whole lease)."""

    def __init__(self, db: DB, jid: str, attempt: int, lease: float):
        self.lost, self._done = threading.Event(), threading.Event()
        self._args, self.lease = (db, jid, attempt), lease
        threading.Thread(target=self._run, daemon=True, name="tryon-heartbeat").start()

    def _run(self) -> None:
        last_ok = time.monotonic()
        while not self._done.wait(self.lease / 6):
            try:
                if not crud.heartbeat(*self._args, self.lease):
                    self.lost.set()
                    return
                last_ok = time.monotonic()
            except sqlite3.Error:
                if time.monotonic() - last_ok > self.lease:
                    self.lost.set()
                    return

    def stop(self) -> None:
        self._done.set()


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


def run_job(db: DB, job: dict, data_dir: Path, lease: float = 30.0, dress_seconds: float | None = None) -> None:
    """Run one claimed attempt: results written to its own folder, published by renaming it once
    done, recorded only if this attempt still holds the job (fenced by the attempt number).
    dress_seconds: the wall time its dressing may take (Settings.dress_seconds)."""
    jid, attempt = job["id"], job["attempts"]
    part = attempt_dir(data_dir, jid, attempt)
    beat = Heartbeat(db, jid, attempt, lease)
    last = [0.0]

    def progress(stage: str, fraction: float, message: str) -> None:
        if STOP.is_set():
            raise Stopped()
        now = time.monotonic()
        if now - last[0] < 0.3:
            return
        last[0] = now
        if crud.cancel_wanted(db, jid):
            raise Cancelled()
        if beat.lost.is_set():
            raise LeaseLost()
        crud.set_progress(db, jid, stage, fraction, message)

    def live(port: int) -> None:
        crud.set_viewer_port(db, jid, port)

    try:
        report = _run(json.loads(job["request"]), part, progress, live, dress_seconds)
        final = attempt_dir(data_dir, jid, attempt, partial=False)
        os.replace(part, final)
    except Exception as e:
        shutil.rmtree(part, ignore_errors=True)
        _record_failure(db, jid, attempt, e)
        _drop_if_deleted(db, data_dir, jid)
        return
    finally:
        beat.stop()
    if not crud.finish(db, jid, attempt, "done", None, report, final.name):
        shutil.rmtree(final, ignore_errors=True)  # cancelled, deleted or requeued meanwhile: not ours
        _drop_if_deleted(db, data_dir, jid)


def _drop_if_deleted(db: DB, data_dir: Path, jid: str) -> None:
    """A job deleted while it ran: the API removed its folder, but writing results after that
    made it again -- remove it, so nothing of a deleted job stays on disk."""
    if db.one("SELECT 1 FROM jobs WHERE id=?", jid) is None:
        shutil.rmtree(job_dir(data_dir, jid), ignore_errors=True)


def _record_failure(db: DB, jid: str, attempt: int, e: Exception) -> None:
    if isinstance(e, Stopped):
        crud.requeue(db, jid, attempt, "started again: the service was stopped while it ran")
    elif not isinstance(e, LeaseLost):  # a lost job is recorded by whoever holds it now
        crud.finish(db, jid, attempt, *_failure(e))


def _failure(e: Exception) -> tuple[str, str]:
    """(status, reason) of a try-on that stopped with `e`."""
    from engine.errors import TryonError

    if isinstance(e, Cancelled):
        return "cancelled", "cancelled on request"
    if isinstance(e, TryonError):
        return "failed", str(e)
    if isinstance(e, OSError) and e.errno in (errno.ENOSPC, errno.EDQUOT):
        return "failed", "the server's disk filled up while writing the results: nothing was kept; try again later"
    traceback.print_exc()  # a bug: the job fails with the reason, the worker goes on
    return "failed", f"internal error ({type(e).__name__}: {e})"


def _run(req: dict, out: Path, progress, live=None, dress_seconds: float | None = None) -> dict:
    from engine.body import resolve_body

    progress("body", 0.0, "loading the body")
    b = req["body"]
    track, posed = None, []
    if "animation" in b:
        from engine.body.animation import load_animation

        track = load_animation(b["animation"], float(b.get("fps", 30.0)))
        body = track.body
    else:
        from engine.scene.arms import clear_arms

        loaded = resolve_body(b["spec"] if "spec" in b else b["file"])
        body = clear_arms(loaded)
        # (the body is dressed and walked in another pose than uploaded: the report says so, as
        # the command line does)
        posed = [n for n in body.notes if n not in loaded.notes]
    g = req["garment"]
    walking = req.get("motion", "none") == "walk"
    from app.queue.live_view import LiveView

    view = LiveView(body.vertices, body.faces)
    try:
        if live is not None:
            live(view.port)
        return _simulate(req, body, g, walking, out, progress, view, track, posed, dress_seconds)
    finally:
        view.close()


def _simulate(req, body, g, walking, out, progress, view, track=None, posed=(), dress_seconds=None) -> dict:
    from engine.scene.drape import time_limited
    from engine.scene.request import TryOnOptions, TryOnRequest
    from engine.scene.tryon import dress_request, write_outputs

    retry = [""]  # while --size auto dresses a larger size, every progress message says why

    def note(size, why, other):
        retry[0] = f"size {size} did not fit, trying {other} -- "

    catalogue = "name" in g
    options = {k: req[k] for k in TryOnOptions.model_fields if k in req}  # (as posted: app/services/tryons.py)
    if track is not None:
        options["fps"] = track.fps  # an uploaded animation plays at its own rate
    # a catalogue garment in a chart size (M by default); a DXF in one of its sizes (its units and
    # assembly as uploaded); a GarmentCode pattern in its own
    size = (req.get("size") or "M") if catalogue else req.get("size")
    request = TryOnRequest(garment=g["name"] if catalogue else g["file"], size=size, **g.get("dxf", {}), **options)
    dressing = lambda stage, f, msg: progress(stage, f, retry[0] + msg)  # noqa: E731
    if dress_seconds is not None:  # (walking takes the time its length asks: only dressing is limited)
        dressing = time_limited(dressing, dress_seconds, "the service's limit for dressing one try-on, "
                                                         "TRYON_DRESS_SECONDS")
    res, report = dress_request(body, request, progress=dressing,
                                observer=view, note=note, label=None if catalogue else g.get("label"))
    report["warnings"][:0] = list(posed)
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
