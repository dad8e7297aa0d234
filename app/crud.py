"""All the service's SQL: tokens, bodies, garments, jobs (the tables of app/core/db.py).

Rows come back as dicts. Bodies, garments and jobs are looked up only with their owner (the token
that made them), so another token's id reads as missing.
"""

from __future__ import annotations

import json
import secrets
import time
import uuid

from app.core.db import DB

ACTIVE = ("queued", "running")
OWNED = ("bodies", "garments", "jobs")  # the tables whose rows belong to a token


def new_id() -> str:
    return uuid.uuid4().hex[:16]


# --- tokens -----------------------------------------------------------------------------------
def issue_token(db: DB) -> str:
    token = secrets.token_urlsafe(24)
    db.run("INSERT INTO tokens (token, created) VALUES (?, ?)", token, time.time())
    return token


def token_known(db: DB, token: str) -> bool:
    return db.one("SELECT token FROM tokens WHERE token=?", token) is not None


# --- what a token owns ------------------------------------------------------------------------
def _table(table: str) -> str:
    if table not in OWNED:  # the name goes into the SQL text: only ours
        raise ValueError(f"not an owned table: {table}")
    return table


def get_owned(db: DB, table: str, rid: str, owner: str) -> dict | None:
    return db.one(f"SELECT * FROM {_table(table)} WHERE id=? AND owner=?", rid, owner)


def list_owned(db: DB, table: str, owner: str) -> list[dict]:
    return db.all(f"SELECT * FROM {_table(table)} WHERE owner=? ORDER BY created", owner)


def get(db: DB, table: str, rid: str) -> dict | None:
    return db.one(f"SELECT * FROM {_table(table)} WHERE id=?", rid)


def delete(db: DB, table: str, rid: str) -> None:
    db.run(f"DELETE FROM {_table(table)} WHERE id=?", rid)


def create_body(db: DB, bid: str, owner: str, kind: str, spec: str, name: str, info: dict) -> dict:
    """kind: default (spec: "default:..."), upload or animation (spec: the stored file)."""
    db.run("INSERT INTO bodies VALUES (?,?,?,?,?,?,?)", bid, owner, kind, spec, name, time.time(), json.dumps(info))
    return get(db, "bodies", bid)


def create_garment(db: DB, gid: str, owner: str, file: str, name: str, info: dict) -> dict:
    db.run("INSERT INTO garments VALUES (?,?,?,?,?,?)", gid, owner, file, name, time.time(), json.dumps(info))
    return get(db, "garments", gid)


# --- jobs -------------------------------------------------------------------------------------
def enqueue(db: DB, owner: str, request: dict, queue_max: int) -> str | None:
    """A new queued job, or None when `queue_max` jobs are already waiting (atomic)."""
    jid = new_id()
    with db.transaction() as c:
        if c.execute("SELECT COUNT(*) FROM jobs WHERE status='queued'").fetchone()[0] >= queue_max:
            return None
        c.execute("INSERT INTO jobs (id, owner, request, status, created) VALUES (?,?,?,?,?)",
                  (jid, owner, json.dumps(request), "queued", time.time()))
    return jid


def claim(db: DB, pid: int) -> dict | None:
    """The oldest queued job, marked running by worker `pid` (atomic)."""
    with db.transaction() as c:
        r = c.execute("SELECT * FROM jobs WHERE status='queued' ORDER BY created LIMIT 1").fetchone()
        if r is None:
            return None
        c.execute("UPDATE jobs SET status='running', attempts=attempts+1, worker_pid=?, started=?, "
                  "stage='starting', progress=0 WHERE id=?", (pid, time.time(), r["id"]))
        return dict(r)


def finish(db: DB, jid: str, status: str, error: str | None = None, report: dict | None = None) -> None:
    """A running job ends: done (with its report), failed or cancelled (with the reason)."""
    done = status == "done"
    db.run("UPDATE jobs SET status=?, error=?, report=?, finished=?, worker_pid=NULL, viewer_port=NULL, "
           "progress=CASE WHEN ? THEN 1 ELSE progress END, stage=CASE WHEN ? THEN 'done' ELSE stage END, "
           "message=CASE WHEN ? THEN '' ELSE message END WHERE id=? AND status='running'",
           status, error, json.dumps(report) if report is not None else None, time.time(), done, done, done, jid)


def cancel_wanted(db: DB, jid: str) -> bool:
    """Whether a running job should stop: cancelled, or deleted, on request."""
    row = db.one("SELECT cancel FROM jobs WHERE id=?", jid)
    return row is None or bool(row["cancel"])


def set_progress(db: DB, jid: str, stage: str, fraction: float, message: str) -> None:
    db.run("UPDATE jobs SET stage=?, progress=?, message=? WHERE id=?", stage, float(fraction), message, jid)


def set_viewer_port(db: DB, jid: str, port: int) -> None:
    db.run("UPDATE jobs SET viewer_port=? WHERE id=?", port, jid)


def cancel(db: DB, jid: str) -> None:
    """A queued job is cancelled at once; a running one is flagged (its worker stops and cleans up)."""
    db.run("UPDATE jobs SET cancel=1 WHERE id=?", jid)
    db.run("UPDATE jobs SET status='cancelled', finished=?, error='cancelled on request' "
           "WHERE id=? AND status='queued'", time.time(), jid)


def delete_job(db: DB, jid: str) -> None:
    db.run("UPDATE jobs SET cancel=1 WHERE id=?", jid)  # a running worker stops and cleans up
    delete(db, "jobs", jid)


def requeue_interrupted(db: DB, attempts: int) -> None:
    """At start: jobs left running by a previous run of the service are queued again, or failed
    once they have been started `attempts` times."""
    db.run("UPDATE jobs SET status='queued', worker_pid=NULL, stage='', progress=0, "
           "message='started again: the service stopped while it ran' "
           "WHERE status='running' AND attempts < ? AND cancel = 0", attempts)
    db.run("UPDATE jobs SET status='failed', worker_pid=NULL, finished=?, "
           "error='the service stopped while this try-on ran, ' || attempts || ' time(s); not retried again' "
           "WHERE status='running'", time.time())


def fail_worker_jobs(db: DB, pid: int, error: str) -> None:
    """The job a dead worker process was running fails with `error`."""
    db.run("UPDATE jobs SET status='failed', finished=?, worker_pid=NULL, error=? "
           "WHERE status='running' AND worker_pid=?", time.time(), error, pid)
