"""FastAPI dependencies: settings, database, runner, the caller's identity (API key)."""

from __future__ import annotations

from fastapi import Depends, Request
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer

from service import store
from service.config import Settings, get_settings
from service.db import Database
from service.problems import Problem
from service.runners import Runner

api_key_header = APIKeyHeader(name="X-API-Key", auto_error=False, description="your API key")
bearer = HTTPBearer(auto_error=False, description="your API key as a bearer token")


def get_db(request: Request) -> Database:
    return request.app.state.db


def get_runner(request: Request) -> Runner:
    return request.app.state.runner


def get_owner(
    api_key: str | None = Depends(api_key_header),
    credentials: HTTPAuthorizationCredentials | None = Depends(bearer),
    settings: Settings = Depends(get_settings),
    db: Database = Depends(get_db),
) -> str:
    """The owner id of the caller's API key; 401 without a valid key.

    Each motion and job belongs to the key that created it: another key gets 404.
    """
    key = api_key or (credentials.credentials if credentials else None)
    if not key:
        raise Problem(401, "an API key is required (header X-API-Key or Authorization: Bearer)",
                      headers={"WWW-Authenticate": "Bearer"})
    if len(key) > 512:
        raise Problem(401, "invalid API key", headers={"WWW-Authenticate": "Bearer"})
    with db.read() as s:
        owner = store.owner_for_key(s, key=key, static_keys=settings.static_api_keys)
    if owner is None:
        raise Problem(401, "invalid API key", headers={"WWW-Authenticate": "Bearer"})
    return owner
