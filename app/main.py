"""The try-on service: REST API (bodies, garments, try-ons, results) and the browser page.

    uvicorn --factory app.main:create_app      # settings from TRYON_* (app/settings.py)

Every body, garment and try-on belongs to the API token that created it (header
`Authorization: Bearer <token>`; `?token=` also works for downloads and the page); any other
token gets 404 for it. Errors are JSON: {"error": "what is wrong and how to fix it"}.
"""

from __future__ import annotations

import json
import math
import secrets
import shutil
import time
from contextlib import asynccontextmanager
from pathlib import Path
from typing import Literal

from fastapi import Cookie, Depends, FastAPI, File, Form, Header, HTTPException, Query, Request, UploadFile, WebSocket
from fastapi.exceptions import RequestValidationError
from fastapi.responses import FileResponse, HTMLResponse, JSONResponse, RedirectResponse
from fastapi.staticfiles import StaticFiles
from starlette.concurrency import run_in_threadpool
from pydantic import BaseModel, Field

from app.db import ACTIVE, DB, new_id
from app.jobs import JobManager
from app.settings import Settings
from app.worker import job_dir

WEB = Path(__file__).resolve().parents[1] / "web"
BODY_EXT = (".obj", ".ply", ".stl", ".off", ".glb", ".gltf", ".zip")  # .zip: OBJ frames (an animation)
RESULT_FILES = ("scene.glb", "garment.obj", "front.png", "side.png", "back.png", "report.json", "anim.glb",
                "strip.png", "recording.viser", "pattern.json", "pattern.svg")
VIEWER_COOKIE = "tryon_viewer"


class DefaultBodyIn(BaseModel):
    preset: Literal["female", "male"] = "female"
    height: float | None = Field(None, description="metres, 1.40 .. 2.10")
    weight: float | None = Field(None, description="0 thin .. 0.5 average .. 1 heavy")
    muscle: float | None = None
    proportions: float | None = None
    gender: float | None = None
    age: float | None = None


class TryOnIn(BaseModel):
    body_id: str | None = Field(None, description="a body you created; or give `body`")
    body: str | None = Field(None, description="a default body spec, e.g. default:female,height=1.7")
    garment: str = Field(..., description="a catalogue name (GET /api/garments) or the id of your pattern")
    size: str | None = Field(None, description="catalogue size XS..XXL, or auto: the smallest that covers "
                                                "the body's girths (default M); not for patterns")
    fabric: str = "cotton"
    motion: Literal["none", "walk"] = "none"
    seconds: float = Field(4.0, description="walking time (motion=walk)")
    resolution_cm: float = Field(1.5, description="cloth edge length, 0.75 .. 4 cm")


def create_app(settings: Settings | None = None, start_workers: bool = True) -> FastAPI:
    s = settings or Settings.from_env()
    s.data_dir.mkdir(parents=True, exist_ok=True)
    db = DB(s.db)
    manager = JobManager(s, db)

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        if start_workers:
            manager.start()
        yield
        manager.stop()

    app = FastAPI(title="tryon", description="Virtual try-on: dress a body in a garment, walk it.",
                  lifespan=lifespan)
    app.state.settings, app.state.db, app.state.jobs = s, db, manager

    @app.exception_handler(HTTPException)
    async def http_error(request: Request, exc: HTTPException):
        return JSONResponse({"error": exc.detail}, status_code=exc.status_code, headers=exc.headers)

    @app.exception_handler(RequestValidationError)
    async def validation_error(request: Request, exc: RequestValidationError):
        parts = []
        for e in exc.errors():
            where = ".".join(str(x) for x in e.get("loc", ()) if x != "body")
            parts.append(f"{where}: {e.get('msg')}" if where else str(e.get("msg")))
        return JSONResponse({"error": "; ".join(parts)}, status_code=422)

    # --- access -------------------------------------------------------------------------
    def bearer(authorization: str | None) -> str | None:
        if authorization and authorization.lower().startswith("bearer "):
            return authorization[7:].strip() or None
        return None

    def known(t: str) -> bool:
        return t in s.tokens or db.one("SELECT token FROM tokens WHERE token=?", t) is not None

    def owner(authorization: str | None = Header(None), token: str | None = Query(None)) -> str:
        t = bearer(authorization) or token
        if not t:
            raise HTTPException(401, "no API token: send 'Authorization: Bearer <token>' (POST /api/tokens gives one)")
        if not known(t):
            raise HTTPException(401, "unknown API token: create one with POST /api/tokens")
        return t

    @app.post("/api/tokens", status_code=201)
    def create_token():
        t = secrets.token_urlsafe(24)
        db.run("INSERT INTO tokens (token, created) VALUES (?, ?)", t, time.time())
        return {"token": t}

    def owned(table: str, rid: str, who: str) -> dict:
        row = db.one(f"SELECT * FROM {table} WHERE id=? AND owner=?", rid, who)
        if row is None:
            raise HTTPException(404, f"no {table[:-1] if table != 'bodies' else 'body'} '{rid}' for this token")
        return row

    async def save_upload(f: UploadFile, dest: Path) -> None:
        cap = s.max_upload_bytes
        n = 0
        dest.parent.mkdir(parents=True, exist_ok=True)
        with open(dest, "wb") as out:
            while chunk := await f.read(1 << 20):
                n += len(chunk)
                if n > cap:
                    out.close()
                    dest.unlink(missing_ok=True)
                    raise HTTPException(413, f"upload larger than {cap / 2 ** 20:.0f} MB: decimate the mesh "
                                             "or raise TRYON_MAX_UPLOAD_MB")
                out.write(chunk)
        if n == 0:
            dest.unlink(missing_ok=True)
            raise HTTPException(400, "the uploaded file is empty")

    # --- bodies -------------------------------------------------------------------------
    def body_out(row: dict) -> dict:
        return {"id": row["id"], "kind": row["kind"], "name": row["name"], "info": json.loads(row["info"] or "{}")}

    def measure_notes(b) -> list[str]:
        """What the measurements say about a scan before it is dressed (arms held too close for
        tops, armpits not found...), or why they cannot be taken."""
        from engine.body.measure import measure
        from engine.errors import TryonError

        try:
            return list(measure(b).notes)
        except TryonError as e:
            return [f"the body could not be measured, so catalogue garments cannot be sized for it: {e}"]

    @app.post("/api/bodies", status_code=201)
    async def upload_body(file: UploadFile = File(...), fps: float = Form(30.0), who: str = Depends(owner)):
        """A scan (a mesh file), or an animated body: a .zip of OBJ frames (one topology) played
        at `fps`, or a .glb with a morph-target or skinned animation sampled at `fps`. An
        animated body is dressed on its first frame and, with motion "walk", moves as uploaded."""
        from engine.errors import TryonError

        ext = Path(file.filename or "").suffix.lower()
        if ext not in BODY_EXT:
            raise HTTPException(400, f"body file type '{ext or 'none'}' is not supported: give one of {' '.join(BODY_EXT)}")
        if not (math.isfinite(fps) and 5.0 <= fps <= 240.0):
            raise HTTPException(422, f"fps {fps:g}: give the animation's frame rate, 5 .. 240")
        bid = new_id()
        dest = s.data_dir / "uploads" / f"body-{bid}{ext}"  # our name, never the client's
        await save_upload(file, dest)
        try:
            from engine.body.gltf_anim import has_animation

            if ext == ".zip" or (ext in (".glb", ".gltf") and has_animation(dest)):
                from engine.body.animation import load_animation

                track = await run_in_threadpool(load_animation, dest, fps)  # seconds for long ones: off the event loop
                b, kind, notes = track.body, "animation", list(track.notes)
                n = int(track.frames.shape[0])
                extra = {"frames": n, "fps": fps, "seconds": round((n - 1) / fps, 3)}
            else:
                from engine.body.load import load_body_file

                b = await run_in_threadpool(load_body_file, dest)
                kind, notes, extra = "upload", list(b.notes) + await run_in_threadpool(measure_notes, b), {}
        except TryonError as e:
            dest.unlink(missing_ok=True)
            raise HTTPException(400, str(e).replace(dest.name, file.filename or dest.name)) from None
        info = {"height_m": round(b.height, 4), "vertices": int(len(b.vertices)), **extra, "notes": notes}
        name = Path(file.filename or "scan").stem[:80]
        db.run("INSERT INTO bodies VALUES (?,?,?,?,?,?,?)", bid, who, kind, str(dest), name, time.time(),
               json.dumps(info))
        return body_out(db.one("SELECT * FROM bodies WHERE id=?", bid))

    @app.post("/api/bodies/default", status_code=201)
    def default_body_create(spec: DefaultBodyIn, who: str = Depends(owner)):
        from engine.body.default import _check_value
        from engine.errors import InputError

        params = {k: v for k, v in spec.model_dump().items() if k != "preset" and v is not None}
        try:
            for k, v in params.items():
                _check_value(k, v)
        except InputError as e:
            raise HTTPException(422, str(e)) from None
        text = "default:" + ",".join([spec.preset] + [f"{k}={v:g}" for k, v in params.items()])
        bid = new_id()
        db.run("INSERT INTO bodies VALUES (?,?,?,?,?,?,?)", bid, who, "default", text, text, time.time(),
               json.dumps({"spec": text}))
        return body_out(db.one("SELECT * FROM bodies WHERE id=?", bid))

    @app.get("/api/bodies")
    def list_bodies(who: str = Depends(owner)):
        return [body_out(r) for r in db.all("SELECT * FROM bodies WHERE owner=? ORDER BY created", who)]

    @app.get("/api/bodies/{bid}")
    def get_body(bid: str, who: str = Depends(owner)):
        return body_out(owned("bodies", bid, who))

    @app.delete("/api/bodies/{bid}", status_code=204)
    def delete_body(bid: str, who: str = Depends(owner)):
        row = owned("bodies", bid, who)
        if row["kind"] in ("upload", "animation"):
            Path(row["spec"]).unlink(missing_ok=True)
        db.run("DELETE FROM bodies WHERE id=?", bid)

    # --- garments -----------------------------------------------------------------------
    @app.get("/api/garments")
    def garments(who: str = Depends(owner)):
        from engine.cloth.fabrics import FABRICS
        from engine.pattern.catalogue import AUTO, CATALOGUE, SIZES

        return {"catalogue": [{"name": n, "description": d} for n, (_, d) in CATALOGUE.items()],
                "sizes": [*SIZES, AUTO], "fabrics": list(FABRICS),
                "uploaded": [garment_out(r) for r in db.all("SELECT * FROM garments WHERE owner=? ORDER BY created", who)]}

    def garment_out(row: dict) -> dict:
        return {"id": row["id"], "name": row["name"], "info": json.loads(row["info"] or "{}")}

    @app.post("/api/garments", status_code=201)
    async def upload_garment(file: UploadFile = File(..., description="a GarmentCode JSON specification, or a DXF "
                                                     "of the pattern pieces (ASTM D6673 / AAMA, or closed polylines)"),
                             assembly: UploadFile | None = File(None, description="with a DXF: its assembly "
                                                                   "JSON (stitches by panel and edge number, "
                                                                   "placement; see `tryon pattern import`)"),
                             units: str | None = Form(None, description="with a DXF that does not say: mm, cm, "
                                                         "m or in"),
                             who: str = Depends(owner)):
        from engine.errors import TryonError
        from engine.pattern.io import parse_pattern, save_pattern
        from engine.pattern.validate import check

        suffix = Path(file.filename or "").suffix.lower()
        if suffix not in (".json", ".dxf"):
            raise HTTPException(400, "a pattern is a GarmentCode JSON specification (.json) or a DXF of its pieces "
                                "(.dxf, with its assembly file)")
        if suffix == ".dxf" and (assembly is None or not assembly.filename):
            raise HTTPException(400, "a DXF holds the pieces but no seams or placement: upload its assembly file "
                                "with it (field 'assembly': stitches by panel and edge number, each panel's "
                                "translation and rotation -- `tryon pattern import PIECES.dxf` draws the pieces "
                                "with every edge numbered)")
        if suffix == ".json" and assembly is not None and assembly.filename:
            raise HTTPException(400, "an assembly file goes with a DXF; a GarmentCode pattern has its stitches "
                                "and placement already")
        gid = new_id()
        dest = s.data_dir / "uploads" / f"pattern-{gid}.json"
        source = file.filename or "pattern"
        notes: list[str] = []
        sources = []  # the uploaded DXF and its assembly, removed once converted
        try:
            if suffix == ".dxf":
                from engine.pattern.dxf import import_dxf, load_assembly

                dxf = s.data_dir / "uploads" / f"pattern-{gid}.dxf"
                asm = s.data_dir / "uploads" / f"pattern-{gid}-assembly.json"
                sources = [dxf, asm]
                await save_upload(file, dxf)
                await save_upload(assembly, asm)
                try:
                    spec, notes = import_dxf(dxf, load_assembly(asm), units)
                except TryonError as e:  # name the client's files, not ours
                    msg = str(e).replace(dxf.name, source).replace(asm.name, assembly.filename)
                    raise type(e)(msg.replace("--units", "the 'units' field")) from None
                problems = check(spec, source=source)
                save_pattern(spec, dest)
            else:
                await save_upload(file, dest)
                spec = parse_pattern(dest.read_bytes(), source=source)
                problems = check(spec, source=source)
        except TryonError as e:
            dest.unlink(missing_ok=True)
            raise HTTPException(400, str(e)) from None
        finally:
            for f in sources:
                f.unlink(missing_ok=True)
        name = Path(source).stem[:80]
        info = {"panels": len(spec.pattern.panels), "warnings": [str(p) for p in problems],
                **({"notes": notes, "from": "dxf"} if suffix == ".dxf" else {})}
        db.run("INSERT INTO garments VALUES (?,?,?,?,?,?)", gid, who, str(dest), name, time.time(), json.dumps(info))
        return garment_out(db.one("SELECT * FROM garments WHERE id=?", gid))

    @app.get("/api/garments/{gid}")
    def get_garment(gid: str, who: str = Depends(owner)):
        return garment_out(owned("garments", gid, who))

    @app.delete("/api/garments/{gid}", status_code=204)
    def delete_garment(gid: str, who: str = Depends(owner)):
        row = owned("garments", gid, who)
        Path(row["file"]).unlink(missing_ok=True)
        db.run("DELETE FROM garments WHERE id=?", gid)

    # --- try-ons ------------------------------------------------------------------------
    def job_out(row: dict) -> dict:
        out = {k: row[k] for k in ("id", "status", "progress", "stage", "message", "error", "attempts")}
        out["request"] = json.loads(row["request"])
        if row["status"] == "done":
            out["report"] = json.loads(row["report"] or "{}")
            d = job_dir(s.data_dir, row["id"])
            out["files"] = {n: f"/api/tryons/{row['id']}/files/{n}" for n in RESULT_FILES if (d / n).exists()}
        live = row["status"] == "running" and row["viewer_port"]
        recorded = row["status"] == "done" and (job_dir(s.data_dir, row["id"]) / "recording.viser").exists()
        out["viewer"] = f"/viewer/{row['id']}/" if live or recorded else None
        return out

    @app.post("/api/tryons", status_code=202)
    def create_tryon(req: TryOnIn, who: str = Depends(owner)):
        from engine.cloth.fabrics import FABRICS
        from engine.pattern.catalogue import AUTO, CATALOGUE, SIZES

        if (req.body_id is None) == (req.body is None):
            raise HTTPException(422, "give either body_id (a body you created) or body (e.g. default:female)")
        if req.body_id is not None:
            row = owned("bodies", req.body_id, who)
            if row["kind"] == "default":
                body = {"spec": row["spec"]}
            elif row["kind"] == "animation":
                body = {"animation": row["spec"], "fps": json.loads(row["info"])["fps"]}
            else:
                body = {"file": row["spec"]}
        else:
            if not req.body.startswith("default:"):
                raise HTTPException(422, "body: only default bodies by name (default:female, default:male); "
                                         "upload a scan with POST /api/bodies and give its body_id")
            body = {"spec": req.body}
        if req.garment in CATALOGUE:
            garment = {"name": req.garment}
            if req.size is not None and req.size.upper() not in SIZES and req.size.lower() != AUTO:
                raise HTTPException(422, f"size '{req.size}': choose one of {', '.join(SIZES)} or {AUTO}")
        else:
            g = db.one("SELECT * FROM garments WHERE id=? AND owner=?", req.garment, who)
            if g is None:
                raise HTTPException(404, f"garment '{req.garment}' is neither in the catalogue "
                                         f"({', '.join(CATALOGUE)}) nor one of your patterns")
            if req.size is not None:
                raise HTTPException(422, "size applies to catalogue garments; a pattern has its own size")
            garment = {"file": g["file"], "label": g["name"]}
        if req.fabric not in FABRICS:
            raise HTTPException(422, f"fabric '{req.fabric}': choose one of {', '.join(FABRICS)}")
        if not (0.75 <= req.resolution_cm <= 4.0):
            raise HTTPException(422, "resolution_cm: use 0.75 .. 4 cm")
        if not (0.1 <= req.seconds <= 20.0) or not math.isfinite(req.seconds):
            raise HTTPException(422, "seconds: walk 0.1 .. 20 s")
        size = None if req.size is None else (AUTO if req.size.lower() == AUTO else req.size.upper())
        request = {"body": body, "garment": garment, "size": size,
                   "fabric": req.fabric, "motion": req.motion, "seconds": req.seconds,
                   "resolution_cm": req.resolution_cm}
        jid = db.enqueue(who, request, s.queue_max)
        if jid is None:
            wait = 30 * max(1, s.queue_max // s.workers)
            raise HTTPException(429, f"the queue is full ({s.queue_max} try-ons waiting): try again later",
                                headers={"Retry-After": str(wait)})
        return job_out(db.one("SELECT * FROM jobs WHERE id=?", jid))

    @app.get("/api/tryons")
    def list_tryons(who: str = Depends(owner)):
        return [job_out(r) for r in db.all("SELECT * FROM jobs WHERE owner=? ORDER BY created", who)]

    @app.get("/api/tryons/{jid}")
    def get_tryon(jid: str, who: str = Depends(owner)):
        return job_out(owned("jobs", jid, who))

    @app.post("/api/tryons/{jid}/cancel", status_code=202)
    def cancel_tryon(jid: str, who: str = Depends(owner)):
        row = owned("jobs", jid, who)
        if row["status"] not in ACTIVE:
            raise HTTPException(409, f"try-on '{jid}' is already {row['status']}")
        db.run("UPDATE jobs SET cancel=1 WHERE id=?", jid)
        db.run("UPDATE jobs SET status='cancelled', finished=?, error='cancelled on request' "
               "WHERE id=? AND status='queued'", time.time(), jid)
        return job_out(db.one("SELECT * FROM jobs WHERE id=?", jid))

    @app.delete("/api/tryons/{jid}", status_code=204)
    def delete_tryon(jid: str, who: str = Depends(owner)):
        owned("jobs", jid, who)
        db.run("UPDATE jobs SET cancel=1 WHERE id=?", jid)  # a running worker stops and cleans up
        db.run("DELETE FROM jobs WHERE id=?", jid)
        shutil.rmtree(job_dir(s.data_dir, jid), ignore_errors=True)

    @app.get("/api/tryons/{jid}/files/{name}")
    def result_file(jid: str, name: str, who: str = Depends(owner)):
        owned("jobs", jid, who)
        if name not in RESULT_FILES:
            raise HTTPException(404, f"no result '{name}': results are {', '.join(RESULT_FILES)}")
        p = job_dir(s.data_dir, jid) / name
        if not p.is_file():
            raise HTTPException(404, f"'{name}' is not there (yet): the try-on is not done, or did not make it")
        return FileResponse(p)

    # --- the live viewer (viser), relayed ------------------------------------------------
    def viewer_owner(jid: str, token: str | None, cookie: str | None, authorization: str | None = None) -> dict:
        t = token or cookie or bearer(authorization)
        if not t or not known(t):
            raise HTTPException(401, "open the viewer with ?token=<your API token>")
        row = db.one("SELECT * FROM jobs WHERE id=? AND owner=?", jid, t)
        if row is None:
            raise HTTPException(404, f"no try-on '{jid}' for this token")
        return {**row, "_token": t}

    @app.get("/viewer/{jid}", include_in_schema=False)
    def viewer_slash(jid: str, request: Request):
        q = f"?{request.url.query}" if request.url.query else ""
        return RedirectResponse(f"/viewer/{jid}/{q}")

    @app.get("/viewer/{jid}/", include_in_schema=False)
    def viewer_page(jid: str, token: str | None = Query(None), playbackPath: str | None = Query(None),
                    tryon_viewer: str | None = Cookie(None), authorization: str | None = Header(None)):
        """The viser client. While the try-on runs it connects back to ws://…/viewer/{jid} (relayed
        to the worker's viser server); once done it plays the try-on's recording."""
        import viser

        row = viewer_owner(jid, token, tryon_viewer, authorization)
        rec = job_dir(s.data_dir, jid) / "recording.viser"
        if row["status"] == "done" and rec.exists() and playbackPath is None:
            resp = RedirectResponse(f"/viewer/{jid}/?playbackPath=/viewer/{jid}/recording.viser")
        elif row["status"] not in ("running", "done"):
            raise HTTPException(409, f"try-on '{jid}' is {row['status']}: nothing to show "
                                     + ("yet (it has not started)" if row["status"] == "queued" else ""))
        else:
            html = (Path(viser.__file__).parent / "client" / "build" / "index.html").read_text()
            resp = HTMLResponse(html)
        resp.set_cookie(VIEWER_COOKIE, row["_token"], path=f"/viewer/{jid}", httponly=True, samesite="strict")
        return resp

    @app.get("/viewer/{jid}/recording.viser", include_in_schema=False)
    def viewer_recording(jid: str, token: str | None = Query(None), tryon_viewer: str | None = Cookie(None)):
        viewer_owner(jid, token, tryon_viewer)
        p = job_dir(s.data_dir, jid) / "recording.viser"
        if not p.is_file():
            raise HTTPException(404, "no recording (yet): the try-on is not done")
        return FileResponse(p, media_type="application/octet-stream")

    @app.websocket("/viewer/{jid}")
    async def viewer_socket(ws: WebSocket, jid: str):
        """Relay the viser client's websocket to the worker's viser server, passing its
        subprotocol (viser-v<version>) through; both directions as they come."""
        import asyncio

        from websockets.asyncio.client import connect

        t = ws.query_params.get("token") or ws.cookies.get(VIEWER_COOKIE)
        row = db.one("SELECT * FROM jobs WHERE id=? AND owner=?", jid, t) if t else None
        if row is None or not row["viewer_port"] or row["status"] != "running":
            await ws.close(code=4404, reason="no live viewer for this try-on (not running, or not yours)")
            return
        protos = ws.scope.get("subprotocols") or []
        try:
            upstream = await connect(f"ws://127.0.0.1:{row['viewer_port']}", subprotocols=protos or None,
                                     max_size=None, open_timeout=5)
        except Exception:
            await ws.close(code=1011, reason="the try-on's viewer is not reachable")
            return
        await ws.accept(subprotocol=upstream.subprotocol)

        async def down():
            async for m in upstream:
                if isinstance(m, bytes):
                    await ws.send_bytes(m)
                else:
                    await ws.send_text(m)

        async def up():
            while True:
                msg = await ws.receive()
                if msg["type"] == "websocket.disconnect":
                    return
                if msg.get("bytes") is not None:
                    await upstream.send(msg["bytes"])
                elif msg.get("text") is not None:
                    await upstream.send(msg["text"])

        tasks = [asyncio.create_task(down()), asyncio.create_task(up())]
        try:
            await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
        finally:
            for t_ in tasks:
                t_.cancel()
            await upstream.close()
            try:
                await ws.close()
            except RuntimeError:
                pass

    # --- the page -----------------------------------------------------------------------
    @app.get("/", include_in_schema=False)
    def index():
        return RedirectResponse("/web/index.html")

    if WEB.is_dir():
        app.mount("/web", StaticFiles(directory=WEB), name="web")
    return app



