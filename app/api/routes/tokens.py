"""POST /api/tokens: a new API token (it owns what it creates). Open to anyone, or only with the
admin key (TRYON_TOKEN_ISSUE=admin); at most TRYON_TOKENS_PER_MINUTE per client address."""

from __future__ import annotations

import hmac
import secrets

from fastapi import APIRouter, Header, HTTPException, Request

from app import crud
from app.api.deps import DBDep, KeysDep, SettingsDep

router = APIRouter(prefix="/api/tokens", tags=["tokens"])


@router.post("", status_code=201)
def create_token(request: Request, s: SettingsDep, db: DBDep, keys: KeysDep,
                 x_admin_key: str | None = Header(None)):
    if s.token_issue == "admin" and not (s.admin_key and x_admin_key
                                         and hmac.compare_digest(x_admin_key.encode(), s.admin_key.encode())):
        raise HTTPException(403, "tokens are issued by the operator here: ask for one (header X-Admin-Key)")
    if not request.app.state.token_rate.allow(request.client.host if request.client else "?"):
        raise HTTPException(429, f"more than {s.tokens_per_minute} tokens a minute from your address: wait",
                            headers={"Retry-After": "60"})
    token = secrets.token_urlsafe(32)
    crud.add_token(db, keys.token_hash(token))
    return {"token": token}
