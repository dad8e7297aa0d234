"""The job supervisor (in the API process): worker processes (spawn), restart recovery, crash
handling, graceful stop.

- start(): jobs left 'running' by a previous run of the service are queued again (a new attempt)
  or, past `attempts` starts, failed with the reason; then the workers start.
- A monitor thread replaces a worker that died and fails the job it was running, with its exit
  code (the other jobs are not touched), and requeues a job whose lease ran out (its runner
  stopped heartbeating). It survives its own errors (a full disk, a locked database).
- Workers die with the supervisor's process (app/queue/worker.py), and a job's attempt number
  fences its completion: a job has at most one live runner.
- stop() (SIGTERM to the service): each worker gives its running job back to the queue (not
  counted as an attempt) and exits; one that does not within `grace` s is killed, and its job
  is recovered at the next start.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import threading
import traceback

from app import crud
from app.core.config import Settings
from app.core.db import DB
from app.queue.results import drop_partials


class JobManager:
    def __init__(self, settings: Settings, db: DB):
        self.settings, self.db = settings, db
        self.ctx = mp.get_context("spawn")
        self.procs: list = []
        self._stop = threading.Event()
        self._stopping = False
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def recover(self) -> None:
        for jid in crud.requeue_stale(self.db, self.settings.attempts, expired_only=False):
            drop_partials(self.settings.data_dir, jid)

    def worker_settings(self) -> Settings:
        """The settings handed to each worker: a try-on per core leaves no idle core for the
        solvers' query helper threads, so they are off then unless TRYON_QUERY_HELPER says."""
        s = self.settings
        if s.workers >= (os.cpu_count() or 1) and "query_helper" not in s.model_fields_set:
            return s.model_copy(update={"query_helper": False})
        return s

    def _spawn(self):
        from app.queue.worker import worker_main

        p = self.ctx.Process(target=worker_main, args=(self.worker_settings(), os.getpid()), daemon=True,
                             name="tryon-worker")
        p.start()
        return p

    def start(self) -> None:
        self.recover()
        with self._lock:
            self.procs = [self._spawn() for _ in range(self.settings.workers)]
        self._thread = threading.Thread(target=self._monitor, daemon=True, name="tryon-monitor")
        self._thread.start()

    def _monitor(self) -> None:
        while not self._stop.wait(0.5):
            try:
                self._check()
            except Exception:  # noqa: BLE001 -- the monitor must outlive a full disk or a locked database
                traceback.print_exc()

    def _check(self) -> None:
        with self._lock:
            for i, p in enumerate(self.procs):
                if p.is_alive() or self._stopping:
                    continue
                for jid in crud.fail_worker_jobs(self.db, p.pid, f"the worker process running this try-on "
                                                 f"stopped unexpectedly (exit code {p.exitcode}); other try-ons "
                                                 "are not affected, try again"):
                    drop_partials(self.settings.data_dir, jid)
                self.procs[i] = self._spawn()
        for jid in crud.requeue_stale(self.db, self.settings.attempts):
            drop_partials(self.settings.data_dir, jid)

    def worker_pids(self) -> list[int]:
        with self._lock:
            return [p.pid for p in self.procs]

    def stop(self, grace: float = 10.0) -> None:
        with self._lock:
            self._stopping = True
            procs, self.procs = self.procs, []
        for p in procs:
            p.terminate()  # SIGTERM: the worker gives its job back and exits
        for p in procs:
            p.join(grace)
        for p in procs:
            if p.is_alive():
                p.kill()
                p.join(5)
        self._stop.set()
