"""Errors are JSON: {"error": "what is wrong and how to fix it"}, never a traceback."""

from __future__ import annotations

import errno
import sqlite3

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from starlette.exceptions import HTTPException  # FastAPI's and Starlette's own (a body that is not UTF-8, 404, 405)

from app.services.uploads import DISK_FULL


async def http_error(request: Request, exc: HTTPException):
    return JSONResponse({"error": exc.detail}, status_code=exc.status_code, headers=exc.headers)


async def storage_error(request: Request, exc: Exception):
    """A full disk or a database that cannot be written: 507/503 with the reason, never a 500."""
    full = isinstance(exc, OSError) and exc.errno in (errno.ENOSPC, errno.EDQUOT) or "full" in str(exc)
    why = DISK_FULL if full else f"storage is unavailable ({exc}): try again later"
    return JSONResponse({"error": why}, status_code=507 if full else 503, headers={"Retry-After": "30"})


async def validation_error(request: Request, exc: RequestValidationError):
    parts = []
    for e in exc.errors():
        where = ".".join(str(x) for x in e.get("loc", ()) if x != "body")
        parts.append(f"{where}: {e.get('msg')}" if where else str(e.get("msg")))
    return JSONResponse({"error": "; ".join(parts)}, status_code=422)


def install(app: FastAPI) -> None:
    app.add_exception_handler(HTTPException, http_error)
    app.add_exception_handler(RequestValidationError, validation_error)
    app.add_exception_handler(sqlite3.Error, storage_error)
    app.add_exception_handler(OSError, storage_error)
