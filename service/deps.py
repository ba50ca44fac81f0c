"""FastAPI dependencies: settings, database, runner, the caller's identity (API key).

The app's settings come from ``create_app(settings)`` (default ``get_settings()``) and are
read here from ``app.state``; tests may still override :func:`app_settings` with
``app.dependency_overrides``. The cheap dependencies are ``async`` so they do not hop to
the thread pool; the API-key lookup is cached briefly in the process (a revoked key stops
working within ``OWNER_CACHE_S``).
"""

from __future__ import annotations

import time

from fastapi import Depends, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.security import APIKeyHeader, HTTPAuthorizationCredentials, HTTPBearer

from service import store
from service.config import Settings
from service.db import Database
from service.problems import Problem
from service.runners import Runner

OWNER_CACHE_S = 10.0
OWNER_CACHE_MAX = 10_000

api_key_header = APIKeyHeader(name="X-API-Key", auto_error=False, description="your API key")
bearer = HTTPBearer(auto_error=False, description="your API key as a bearer token")


async def app_settings(request: Request) -> Settings:
    return request.app.state.settings


async def get_db(request: Request) -> Database:
    return request.app.state.db


async def get_runner(request: Request) -> Runner:
    return request.app.state.runner


def _unauthorized(detail: str) -> Problem:
    return Problem(401, detail, headers={"WWW-Authenticate": "Bearer"})


async def get_owner(
    request: Request,
    api_key: str | None = Depends(api_key_header),
    credentials: HTTPAuthorizationCredentials | None = Depends(bearer),
    settings: Settings = Depends(app_settings),
    db: Database = Depends(get_db),
) -> str:
    """The owner id of the caller's API key; 401 without a valid key.

    Each motion and job belongs to the key that created it: another key gets 404.
    """
    key = api_key or (credentials.credentials if credentials else None)
    if not key:
        raise _unauthorized("an API key is required (header X-API-Key or Authorization: Bearer)")
    if len(key) > 512:
        raise _unauthorized("invalid API key")
    cache: dict = request.app.state.owner_cache
    hit = cache.get(key)
    now = time.monotonic()
    if hit is not None and hit[1] > now:
        return hit[0]

    def lookup() -> str | None:
        with db.read() as s:
            return store.owner_for_key(s, key=key, static_keys=settings.static_api_keys)

    owner = await run_in_threadpool(lookup)
    if owner is None:
        raise _unauthorized("invalid API key")
    if len(cache) >= OWNER_CACHE_MAX:
        cache.clear()
    cache[key] = (owner, now + OWNER_CACHE_S)
    return owner
