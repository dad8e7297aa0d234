"""Storage: one SQLite file (WAL) holding tokens, bodies, garments and jobs. Each call opens its
own connection (threads and worker processes share the file, never a connection)."""

from __future__ import annotations

import json
import sqlite3
import time
import uuid
from contextlib import contextmanager
from pathlib import Path

SCHEMA = """
CREATE TABLE IF NOT EXISTS tokens (token TEXT PRIMARY KEY, created REAL);
CREATE TABLE IF NOT EXISTS bodies (id TEXT PRIMARY KEY, owner TEXT, kind TEXT, spec TEXT, name TEXT,
    created REAL, info TEXT);
CREATE TABLE IF NOT EXISTS garments (id TEXT PRIMARY KEY, owner TEXT, file TEXT, name TEXT, created REAL,
    info TEXT);
CREATE TABLE IF NOT EXISTS jobs (id TEXT PRIMARY KEY, owner TEXT, request TEXT, status TEXT,
    progress REAL DEFAULT 0, stage TEXT DEFAULT '', message TEXT DEFAULT '', error TEXT,
    attempts INTEGER DEFAULT 0, worker_pid INTEGER, cancel INTEGER DEFAULT 0,
    created REAL, started REAL, finished REAL, report TEXT, viewer_port INTEGER);
CREATE INDEX IF NOT EXISTS jobs_status ON jobs(status, created);
"""

ACTIVE = ("queued", "running")


def new_id() -> str:
    return uuid.uuid4().hex[:16]


class DB:
    def __init__(self, path: Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.conn() as c:
            c.execute("PRAGMA journal_mode=WAL")
            c.executescript(SCHEMA)

    @contextmanager
    def conn(self):
        c = sqlite3.connect(self.path, timeout=30.0, isolation_level=None)
        c.row_factory = sqlite3.Row
        try:
            yield c
        finally:
            c.close()

    def one(self, sql: str, *args) -> dict | None:
        with self.conn() as c:
            r = c.execute(sql, args).fetchone()
            return dict(r) if r else None

    def all(self, sql: str, *args) -> list[dict]:
        with self.conn() as c:
            return [dict(r) for r in c.execute(sql, args).fetchall()]

    def run(self, sql: str, *args) -> int:
        with self.conn() as c:
            return c.execute(sql, args).rowcount

    # --- jobs ---
    def enqueue(self, owner: str, request: dict, queue_max: int) -> str | None:
        """A new queued job, or None when `queue_max` jobs are already waiting (atomic)."""
        jid = new_id()
        with self.conn() as c:
            c.execute("BEGIN IMMEDIATE")
            n = c.execute("SELECT COUNT(*) FROM jobs WHERE status='queued'").fetchone()[0]
            if n >= queue_max:
                c.execute("ROLLBACK")
                return None
            c.execute("INSERT INTO jobs (id, owner, request, status, created) VALUES (?,?,?,?,?)",
                      (jid, owner, json.dumps(request), "queued", time.time()))
            c.execute("COMMIT")
        return jid

    def claim(self, pid: int) -> dict | None:
        """The oldest queued job, marked running by worker `pid` (atomic)."""
        with self.conn() as c:
            c.execute("BEGIN IMMEDIATE")
            r = c.execute("SELECT * FROM jobs WHERE status='queued' ORDER BY created LIMIT 1").fetchone()
            if r is None:
                c.execute("ROLLBACK")
                return None
            c.execute("UPDATE jobs SET status='running', attempts=attempts+1, worker_pid=?, started=?, "
                      "stage='starting', progress=0 WHERE id=?", (pid, time.time(), r["id"]))
            c.execute("COMMIT")
            return dict(r)

    def finish(self, jid: str, status: str, error: str | None = None, report: dict | None = None) -> None:
        self.run("UPDATE jobs SET status=?, error=?, report=?, finished=?, worker_pid=NULL, viewer_port=NULL "
                 "WHERE id=? AND status='running'", status, error, json.dumps(report) if report is not None else None,
                 time.time(), jid)
