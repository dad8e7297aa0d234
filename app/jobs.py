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
import time

from app.db import DB
from app.settings import Settings


class JobManager:
    def __init__(self, settings: Settings, db: DB):
        self.settings, self.db = settings, db
        self.ctx = mp.get_context("spawn")
        self.procs: list = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._lock = threading.Lock()

    def recover(self) -> None:
        n = self.settings.attempts
        self.db.run("UPDATE jobs SET status='queued', worker_pid=NULL, stage='', progress=0, "
                    "message='started again: the service stopped while it ran' "
                    "WHERE status='running' AND attempts < ? AND cancel = 0", n)
        self.db.run("UPDATE jobs SET status='failed', worker_pid=NULL, finished=?, "
                    "error='the service stopped while this try-on ran, ' || attempts || ' time(s); not retried again' "
                    "WHERE status='running'", time.time())

    def _spawn(self):
        from app.worker import worker_main

        p = self.ctx.Process(target=worker_main, args=(str(self.settings.db), str(self.settings.data_dir)),
                             daemon=True, name="tryon-worker")
        p.start()
        return p

    def start(self) -> None:
        self.recover()
        if self.settings.workers >= (os.cpu_count() or 1):
            # a try-on per core leaves no idle core for the solvers' query helper threads
            # (engine.collide.server.helper_default); the workers inherit this
            os.environ.setdefault("TRYON_QUERY_HELPER", "0")
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
                    self.db.run("UPDATE jobs SET status='failed', finished=?, worker_pid=NULL, "
                                "error=? WHERE status='running' AND worker_pid=?", time.time(),
                                f"the worker process running this try-on stopped unexpectedly (exit code "
                                f"{p.exitcode}); other try-ons are not affected, try again", p.pid)
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
