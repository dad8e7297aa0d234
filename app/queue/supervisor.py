"""The job supervisor (in the API process): worker processes (spawn), restart recovery, crash
handling.

- start(): jobs left 'running' by a previous run of the service are queued again (a new attempt)
  or, past `attempts`, failed with the reason; then the workers start.
- A monitor thread replaces a worker that died and fails the job it was running, with its exit
  code: the other jobs are not touched.
- stop(): the workers are stopped; their running jobs stay 'running' and are recovered at the
  next start.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import threading

from app import crud
from app.core.config import Settings
from app.core.db import DB


class JobManager:
    def __init__(self, settings: Settings, db: DB):
        self.settings, self.db = settings, db
        self.ctx = mp.get_context("spawn")
        self.procs: list = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def recover(self) -> None:
        crud.requeue_interrupted(self.db, self.settings.attempts)

    def worker_settings(self) -> Settings:
        """The settings handed to each worker: a try-on per core leaves no idle core for the
        solvers' query helper threads, so they are off then unless TRYON_QUERY_HELPER says."""
        s = self.settings
        if s.workers >= (os.cpu_count() or 1) and "query_helper" not in s.model_fields_set:
            return s.model_copy(update={"query_helper": False})
        return s

    def _spawn(self):
        from app.queue.worker import worker_main

        p = self.ctx.Process(target=worker_main, args=(self.worker_settings(),), daemon=True, name="tryon-worker")
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
            with self._lock:
                for i, p in enumerate(self.procs):
                    if p.is_alive() or self._stop.is_set():
                        continue
                    crud.fail_worker_jobs(self.db, p.pid, f"the worker process running this try-on stopped "
                                          f"unexpectedly (exit code {p.exitcode}); other try-ons are not "
                                          "affected, try again")
                    self.procs[i] = self._spawn()

    def worker_pids(self) -> list[int]:
        with self._lock:
            return [p.pid for p in self.procs]

    def stop(self) -> None:
        self._stop.set()
        with self._lock:
            for p in self.procs:
                p.kill()
            for p in self.procs:
                p.join(5)
            self.procs = []
