"""The live viewer (viser), relayed: the worker's viser server behind /viewer/{job}, and the
recording of a finished try-on played back. The page sets a cookie scoped to the job's path so
that the viser client's own requests (its websocket, the recording) carry the token."""

from __future__ import annotations

import asyncio
from pathlib import Path

from fastapi import APIRouter, Cookie, Header, HTTPException, Query, Request, WebSocket
from fastapi.responses import FileResponse, HTMLResponse, RedirectResponse

from app import crud
from app.api.deps import DBDep, SettingsDep, bearer, get_db, known
from app.queue.results import result_dir

router = APIRouter(prefix="/viewer", include_in_schema=False)
VIEWER_COOKIE = "tryon_viewer"


def viewer_job(s, db, jid: str, token: str | None) -> dict:
    """The job `jid` of `token` (from ?token=, the cookie or the header), else 401/404."""
    if not known(s, db, token):
        raise HTTPException(401, "open the viewer with ?token=<your API token>")
    row = crud.get_owned(db, "jobs", jid, token)
    if row is None:
        raise HTTPException(404, f"no try-on '{jid}' for this token")
    return row


@router.get("/{jid}")
def viewer_slash(jid: str, request: Request):
    q = f"?{request.url.query}" if request.url.query else ""
    return RedirectResponse(f"/viewer/{jid}/{q}")


@router.get("/{jid}/")
def viewer_page(jid: str, s: SettingsDep, db: DBDep, token: str | None = Query(None),
                playbackPath: str | None = Query(None), tryon_viewer: str | None = Cookie(None),
                authorization: str | None = Header(None)):
    """The viser client. While the try-on runs it connects back to ws://…/viewer/{jid} (relayed
    to the worker's viser server); once done it plays the try-on's recording."""
    import viser

    t = token or tryon_viewer or bearer(authorization)
    row = viewer_job(s, db, jid, t)
    d = result_dir(s.data_dir, row)
    if d is not None and (d / "recording.viser").exists() and playbackPath is None:
        resp = RedirectResponse(f"/viewer/{jid}/?playbackPath=/viewer/{jid}/recording.viser")
    elif row["status"] not in ("running", "done"):
        raise HTTPException(409, f"try-on '{jid}' is {row['status']}: nothing to show "
                                 + ("yet (it has not started)" if row["status"] == "queued" else ""))
    else:
        resp = HTMLResponse((Path(viser.__file__).parent / "client" / "build" / "index.html").read_text())
    resp.set_cookie(VIEWER_COOKIE, t, path=f"/viewer/{jid}", httponly=True, samesite="strict")
    return resp


@router.get("/{jid}/recording.viser")
def viewer_recording(jid: str, s: SettingsDep, db: DBDep, token: str | None = Query(None),
                     tryon_viewer: str | None = Cookie(None)):
    d = result_dir(s.data_dir, viewer_job(s, db, jid, token or tryon_viewer))
    if d is None or not (d / "recording.viser").is_file():
        raise HTTPException(404, "no recording (yet): the try-on is not done")
    return FileResponse(d / "recording.viser", media_type="application/octet-stream")


@router.websocket("/{jid}")
async def viewer_socket(ws: WebSocket, jid: str):
    """Relay the viser client's websocket to the worker's viser server, passing its
    subprotocol (viser-v<version>) through; both directions as they come."""
    from websockets.asyncio.client import connect

    t = ws.query_params.get("token") or ws.cookies.get(VIEWER_COOKIE)
    row = crud.get_owned(get_db(ws), "jobs", jid, t) if t else None
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
