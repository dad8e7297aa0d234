"""The live viewer (viser), relayed: the worker's viser server behind /viewer/{job}, and the
recording of a finished try-on played back. Opened by the job's signed key
(?key=, from the try-on's `viewer` link); the page keeps it in a cookie scoped to the job's path
so that the viser client's own requests (its websocket, the recording) carry it."""

from __future__ import annotations

import asyncio
from pathlib import Path

from fastapi import APIRouter, Cookie, Header, HTTPException, Query, Request, WebSocket
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse

from app import crud
from app.api.deps import DBDep, KeysDep, SettingsDep, get_db, get_keys, job_opened
from app.queue.results import result_dir

router = APIRouter(prefix="/viewer", include_in_schema=False)
VIEWER_COOKIE = "tryon_viewer"  # holds the job's key (never the API token), scoped to /viewer/<job>


@router.get("/{jid}")
def viewer_slash(jid: str, request: Request):
    q = f"?{request.url.query}" if request.url.query else ""
    return RedirectResponse(f"/viewer/{jid}/{q}")


@router.get("/{jid}/")
def viewer_page(jid: str, request: Request, s: SettingsDep, db: DBDep, keys: KeysDep, key: str | None = Query(None),
                playbackPath: str | None = Query(None), tryon_viewer: str | None = Cookie(None),
                authorization: str | None = Header(None)):
    """The viser client. While the try-on runs it connects back to ws://…/viewer/{jid} (relayed
    to the worker's viser server); once done it plays the try-on's recording."""
    import viser

    row = job_opened(db, keys, jid, key or tryon_viewer, authorization)
    d = result_dir(s.data_dir, row)
    if d is not None and (d / "recording.viser").exists() and playbackPath is None:
        resp = RedirectResponse(f"/viewer/{jid}/?playbackPath=/viewer/{jid}/recording.viser")
    elif row["status"] not in ("running", "done"):
        raise HTTPException(409, f"try-on '{jid}' is {row['status']}: nothing to show "
                                 + ("yet (it has not started)" if row["status"] == "queued" else ""))
    else:
        resp = HTMLResponse((Path(viser.__file__).parent / "client" / "build" / "index.html").read_text())
    resp.set_cookie(VIEWER_COOKIE, keys.link_key(jid), path=f"/viewer/{jid}", httponly=True, samesite="strict",
                    secure=request.url.scheme == "https", max_age=int(s.link_seconds))
    return resp


@router.get("/{jid}/recording.viser")
def viewer_recording(jid: str, s: SettingsDep, db: DBDep, keys: KeysDep, key: str | None = Query(None),
                     tryon_viewer: str | None = Cookie(None)):
    d = result_dir(s.data_dir, job_opened(db, keys, jid, key or tryon_viewer, None))
    if d is None or not (d / "recording.viser").is_file():
        raise HTTPException(404, "no recording (yet): the try-on is not done")
    return FileResponse(d / "recording.viser", media_type="application/octet-stream")


@router.websocket("/{jid}")
async def viewer_socket(ws: WebSocket, jid: str):
    """Relay the viser client's websocket to the worker's viser server, passing its
    subprotocol (viser-v<version>) through; both directions as they come."""
    from websockets.asyncio.client import connect

    key = ws.query_params.get("key") or ws.cookies.get(VIEWER_COOKIE)
    row = crud.get(get_db(ws), "jobs", jid) if get_keys(ws).opens(key, jid) else None
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
    await _relay(ws, upstream)


async def _relay(ws: WebSocket, upstream) -> None:
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
        for t in tasks:
            t.cancel()
        await upstream.close()
        try:
            await ws.close()
        except RuntimeError:
            pass
