"""The try-on service: REST API (bodies, garments, try-ons, results) and the browser page.

    uvicorn --factory app.main:create_app      # settings from TRYON_* (app/core/config.py)

Every body, garment and try-on belongs to the API token that created it (header
`Authorization: Bearer <token>` only; tokens are stored hashed); any other token gets 404 for it.
Results and the viewer open with short-lived signed links (the try-on's `files` and `viewer`). Errors are JSON: {"error": "what is wrong and how to fix it"}.
Routes: app/api/routes/; auth and storage: app/api/deps.py, app/crud.py; jobs: app/queue/.
"""

from __future__ import annotations

from contextlib import asynccontextmanager
from pathlib import Path

from fastapi import FastAPI
from fastapi.responses import RedirectResponse
from fastapi.staticfiles import StaticFiles

from app.api import errors
from app.api.routes import bodies, garments, tokens, tryons, viewer
from app.core.config import Settings
from app import crud
from app.core.db import DB
from app.core.security import Keys, RateLimit, load_key
from app.core.limits import JSON_LIMIT, BodyLimit
from app.queue.supervisor import JobManager
from app.services.fence import Gate

WEB = Path(__file__).resolve().parents[1] / "web"


def create_app(settings: Settings | None = None, start_workers: bool = True) -> FastAPI:
    """The service; `settings` None reads them from the environment (TRYON_*)."""
    from engine.settings import read, use

    s = use(settings or read(Settings))
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
    app.state.gate = Gate(s.parse_slots, s.uploads_per_token)
    app.state.keys = Keys(load_key(s.secret, s.data_dir), s.tokens, s.link_seconds)
    app.state.token_rate = RateLimit(s.tokens_per_minute)
    crud.hash_plain_tokens(db, app.state.keys.token_hash)
    errors.install(app)
    app.add_middleware(BodyLimit, upload_limit=2 * s.max_upload_bytes + JSON_LIMIT)  # a DXF + its assembly
    for r in (tokens, bodies, garments, tryons, viewer):
        app.include_router(r.router)
    app.add_api_route("/", lambda: RedirectResponse("/web/index.html"), include_in_schema=False)
    if WEB.is_dir():
        app.mount("/web", StaticFiles(directory=WEB), name="web")
    return app
