"""Storage: one SQLite file (WAL) holding tokens, bodies, garments and jobs. Each call opens its
own connection (threads and worker processes share the file, never a connection). The queries
are in app/crud.py."""

from __future__ import annotations

import sqlite3
from contextlib import contextmanager
from pathlib import Path

SCHEMA = """
CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT);
CREATE TABLE IF NOT EXISTS tokens (token TEXT PRIMARY KEY, created REAL);  -- token: its keyed hash
CREATE TABLE IF NOT EXISTS bodies (id TEXT PRIMARY KEY, owner TEXT, kind TEXT, spec TEXT, name TEXT,
    created REAL, info TEXT);
CREATE TABLE IF NOT EXISTS garments (id TEXT PRIMARY KEY, owner TEXT, file TEXT, name TEXT, created REAL,
    info TEXT);
CREATE TABLE IF NOT EXISTS jobs (id TEXT PRIMARY KEY, owner TEXT, request TEXT, status TEXT,
    progress REAL DEFAULT 0, stage TEXT DEFAULT '', message TEXT DEFAULT '', error TEXT,
    attempts INTEGER DEFAULT 0, worker_pid INTEGER, cancel INTEGER DEFAULT 0,
    created REAL, started REAL, finished REAL, report TEXT, viewer_port INTEGER,
    lease_until REAL, graceful INTEGER DEFAULT 0, result TEXT);
CREATE INDEX IF NOT EXISTS jobs_status ON jobs(status, created);
CREATE INDEX IF NOT EXISTS jobs_owner ON jobs(owner, status);
"""
# columns added since the first schema: a database made before gets them at start
ADDED = {"jobs": ("lease_until REAL", "graceful INTEGER DEFAULT 0", "result TEXT")}


class DB:
    def __init__(self, path: Path):
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        with self.conn() as c:
            c.execute("PRAGMA journal_mode=WAL")
            c.executescript(SCHEMA)
            for table, columns in ADDED.items():
                have = {r["name"] for r in c.execute(f"PRAGMA table_info({table})")}
                for col in columns:
                    if col.split()[0] not in have:
                        c.execute(f"ALTER TABLE {table} ADD COLUMN {col}")

    @contextmanager
    def conn(self):
        c = sqlite3.connect(self.path, timeout=30.0, isolation_level=None)
        c.row_factory = sqlite3.Row
        try:
            yield c
        finally:
            c.close()

    @contextmanager
    def transaction(self):
        """A connection inside BEGIN IMMEDIATE: committed on leaving, rolled back on an error."""
        with self.conn() as c:
            c.execute("BEGIN IMMEDIATE")
            try:
                yield c
            except BaseException:
                c.execute("ROLLBACK")
                raise
            c.execute("COMMIT")

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
