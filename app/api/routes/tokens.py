"""POST /api/tokens: a new API token (it owns what it creates)."""

from __future__ import annotations

from fastapi import APIRouter

from app import crud
from app.api.deps import DBDep

router = APIRouter(prefix="/api/tokens", tags=["tokens"])


@router.post("", status_code=201)
def create_token(db: DBDep):
    return {"token": crud.issue_token(db)}
