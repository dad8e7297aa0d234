"""Request bodies limited while they stream in: a declared Content-Length past the limit is
refused before a byte is read, and a body that grows past it (chunked, or lying) is cut off
with 413 -- a 300 MB upload is not spooled to disk first, a 200 MB JSON not parsed."""

from __future__ import annotations

from fastapi import HTTPException

JSON_LIMIT = 1 << 20  # bytes of a request that is not a file upload


class TooLarge(HTTPException):
    def __init__(self, limit: int):
        super().__init__(413, f"request body larger than {limit / 2 ** 20:.1f} MB: send a smaller file "
                              "or raise TRYON_MAX_UPLOAD_MB")


class BodyLimit:
    """ASGI middleware. upload_limit: bytes of a multipart request (its files and fields)."""

    def __init__(self, app, upload_limit: int):
        self.app, self.upload_limit = app, upload_limit

    async def __call__(self, scope, receive, send):
        if scope["type"] != "http":
            return await self.app(scope, receive, send)
        headers = dict(scope.get("headers") or [])
        multipart = headers.get(b"content-type", b"").startswith(b"multipart/")
        limit = self.upload_limit if multipart else JSON_LIMIT
        declared = headers.get(b"content-length", b"")
        if declared.isdigit() and int(declared) > limit:
            return await _refuse(send, limit)
        seen = 0

        async def counted():
            nonlocal seen
            msg = await receive()
            seen += len(msg.get("body", b""))
            if seen > limit:
                raise TooLarge(limit)  # FastAPI passes an HTTPException from the body parse through
            return msg

        await self.app(scope, counted, send)


async def _refuse(send, limit: int) -> None:
    import json

    body = json.dumps({"error": TooLarge(limit).detail}).encode()
    await send({"type": "http.response.start", "status": 413,
                "headers": [(b"content-type", b"application/json"), (b"content-length", str(len(body)).encode()),
                            (b"connection", b"close")]})
    await send({"type": "http.response.body", "body": body})
