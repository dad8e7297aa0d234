"""All the service's SQL: tokens, bodies, garments, jobs (the tables of app/core/db.py).

Rows come back as dicts. Bodies, garments and jobs are looked up only with their owner (the token
that made them), so another token's id reads as missing.
"""

from __future__ import annotations

import json
import time
import uuid

from app.core.db import DB

ACTIVE = ("queued", "running")
OWNED = ("bodies", "garments", "jobs")  # the tables whose rows belong to a token


def new_id() -> str:
    return uuid.uuid4().hex[:16]


# --- tokens (kept as their keyed hashes: app/core/security.py) ----------------------------------
def add_token(db: DB, token_hash: str) -> None:
    db.run("INSERT INTO tokens (token, created) VALUES (?, ?)", token_hash, time.time())


def token_known(db: DB, token_hash: str) -> bool:
    return db.one("SELECT token FROM tokens WHERE token=?", token_hash) is not None


def hash_plain_tokens(db: DB, token_hash) -> None:
    """Once: a database from before tokens were hashed gets every token and owner column hashed."""
    with db.transaction() as c:
        if c.execute("SELECT value FROM meta WHERE key='tokens'").fetchone():
            return
        for (t,) in c.execute("SELECT token FROM tokens").fetchall():
            c.execute("UPDATE tokens SET token=? WHERE token=?", (token_hash(t), t))
        for table in OWNED:
            for (o,) in c.execute(f"SELECT DISTINCT owner FROM {table}").fetchall():
                c.execute(f"UPDATE {table} SET owner=? WHERE owner=?", (token_hash(o), o))
        c.execute("INSERT INTO meta (key, value) VALUES ('tokens', 'hmac-sha256')")


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
def enqueue(db: DB, owner: str, request: dict, queue_max: int, per_owner: int) -> tuple[str | None, str]:
    """(id, "") of a new queued job, or (None, "all") when `queue_max` jobs are already waiting,
    (None, "owner") when `owner` has `per_owner` waiting or running (atomic)."""
    jid = new_id()
    with db.transaction() as c:
        if c.execute("SELECT COUNT(*) FROM jobs WHERE status='queued'").fetchone()[0] >= queue_max:
            return None, "all"
        if c.execute("SELECT COUNT(*) FROM jobs WHERE owner=? AND status IN ('queued', 'running')",
                     (owner,)).fetchone()[0] >= per_owner:
            return None, "owner"
        c.execute("INSERT INTO jobs (id, owner, request, status, created) VALUES (?,?,?,?,?)",
                  (jid, owner, json.dumps(request), "queued", time.time()))
    return jid, ""


def claim(db: DB, pid: int, lease: float) -> dict | None:
    """The oldest queued job, marked running by worker `pid` with a new attempt number (its fence)
    and a lease of `lease` seconds that the worker's heartbeats extend (atomic)."""
    now = time.time()
    with db.transaction() as c:
        r = c.execute("SELECT * FROM jobs WHERE status='queued' ORDER BY created LIMIT 1").fetchone()
        if r is None:
            return None
        c.execute("UPDATE jobs SET status='running', attempts=attempts+1, worker_pid=?, started=?, lease_until=?, "
                  "stage='starting', progress=0 WHERE id=?", (pid, now, now + lease, r["id"]))
        return dict(c.execute("SELECT * FROM jobs WHERE id=?", (r["id"],)).fetchone())


FENCE = "id=? AND attempts=? AND status='running'"  # only the job's current attempt may change it


def heartbeat(db: DB, jid: str, attempt: int, lease: float) -> bool:
    """Extend the lease; False when this attempt no longer holds the job (requeued, cancelled, deleted)."""
    return db.run(f"UPDATE jobs SET lease_until=? WHERE {FENCE}", time.time() + lease, jid, attempt) == 1


def finish(db: DB, jid: str, attempt: int, status: str, error: str | None = None,
           report: dict | None = None, result: str | None = None) -> bool:
    """Attempt `attempt` of a running job ends: done (its report and published result folder),
    failed or cancelled (the reason). False when that attempt no longer holds the job."""
    done = status == "done"
    return db.run("UPDATE jobs SET status=?, error=?, report=?, result=?, finished=?, worker_pid=NULL, "
                  "viewer_port=NULL, lease_until=NULL, progress=CASE WHEN ? THEN 1 ELSE progress END, "
                  "stage=CASE WHEN ? THEN 'done' ELSE stage END, message=CASE WHEN ? THEN '' ELSE message END "
                  f"WHERE {FENCE}", status, error, json.dumps(report) if report is not None else None, result,
                  time.time(), done, done, done, jid, attempt) == 1


def requeue(db: DB, jid: str, attempt: int, message: str) -> bool:
    """A worker stopping gracefully gives its job back (not counted against TRYON_ATTEMPTS)."""
    return db.run("UPDATE jobs SET status='queued', worker_pid=NULL, lease_until=NULL, viewer_port=NULL, "
                  f"stage='', progress=0, message=?, graceful=graceful+1 WHERE {FENCE}", message, jid, attempt) == 1


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


def requeue_stale(db: DB, attempts: int, expired_only: bool = True) -> list[str]:
    """Running jobs whose runner is gone -- their lease ran out, or (at start, expired_only False)
    all of them -- are queued again, or failed once started `attempts` times (graceful stops
    not counted). Their ids."""
    now = time.time()
    cond = "status='running'" + (" AND lease_until < ?" if expired_only else "")
    args = (now,) if expired_only else ()
    if db.one(f"SELECT id FROM jobs WHERE {cond} LIMIT 1", *args) is None:  # the usual case: no write lock taken
        return []
    with db.transaction() as c:
        ids = [r[0] for r in c.execute(f"SELECT id FROM jobs WHERE {cond}", args)]
        c.execute("UPDATE jobs SET status='queued', worker_pid=NULL, lease_until=NULL, viewer_port=NULL, stage='', "
                  "progress=0, message='started again: the service or its worker stopped while it ran' "
                  f"WHERE {cond} AND attempts - graceful < ? AND cancel = 0", (*args, attempts))
        c.execute("UPDATE jobs SET status=CASE WHEN cancel THEN 'cancelled' ELSE 'failed' END, worker_pid=NULL, "
                  "lease_until=NULL, viewer_port=NULL, finished=?, error=CASE WHEN cancel THEN 'cancelled on request' "
                  "ELSE 'the service stopped while this try-on ran, ' || (attempts - graceful) || ' time(s); not "
                  f"retried again' END WHERE {cond}", (now, *args))
    return ids


def fail_worker_jobs(db: DB, pid: int, error: str) -> list[str]:
    """The job a dead worker process was running fails with `error`; its id(s)."""
    with db.transaction() as c:
        ids = [r[0] for r in c.execute("SELECT id FROM jobs WHERE status='running' AND worker_pid=?", (pid,))]
        c.execute("UPDATE jobs SET status='failed', finished=?, worker_pid=NULL, lease_until=NULL, viewer_port=NULL, "
                  "error=? WHERE status='running' AND worker_pid=?", (time.time(), error, pid))
    return ids
