"""FastAPI dependencies: settings, database, runner, the caller's identity (API key).

The app's settings come from ``create_app(settings)`` (default ``get_settings()``) and are
read here from ``app.state``; tests may still override :func:`app_settings` with
``app.dependency_overrides``. The cheap dependencies are ``async`` so they do not hop to
the thread pool; the API-key lookup is cached briefly in the process (a revoked key stops
working within ``OWNER_CACHE_S``).

Routes take them as ``Annotated`` aliases (``SettingsDep``, ``DatabaseDep``, ``RunnerDep``,
``OwnerDep``), and a list's page as ``OffsetPageDep`` or ``CursorPageDep``, whose ``answer``
builds the page (items, total, limit, the next page's link).
"""

from __future__ import annotations

import threading
from dataclasses import dataclass
from typing import Annotated

from cachetools import TTLCache
from fastapi import Depends, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse
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


SettingsDep = Annotated[Settings, Depends(app_settings)]
DatabaseDep = Annotated[Database, Depends(get_db)]
RunnerDep = Annotated[Runner, Depends(get_runner)]


class OwnerCache:
    """API key -> owner id, each for ``OWNER_CACHE_S`` seconds, at most ``OWNER_CACHE_MAX``."""

    def __init__(self) -> None:
        self._items: TTLCache[str, str] = TTLCache(maxsize=OWNER_CACHE_MAX, ttl=OWNER_CACHE_S)
        self._lock = threading.Lock()

    def get(self, key: str) -> str | None:
        with self._lock:
            return self._items.get(key)

    def put(self, key: str, owner: str) -> None:
        with self._lock:
            self._items[key] = owner


def _unauthorized(detail: str) -> Problem:
    return Problem(401, detail, headers={"WWW-Authenticate": "Bearer"})


async def get_owner(
    request: Request,
    api_key: Annotated[str | None, Depends(api_key_header)],
    credentials: Annotated[HTTPAuthorizationCredentials | None, Depends(bearer)],
    settings: SettingsDep,
    db: DatabaseDep,
) -> str:
    """The owner id of the caller's API key; 401 without a valid key.

    Each motion and job belongs to the key that created it: another key gets 404.
    """
    key = api_key or (credentials.credentials if credentials else None)
    if not key:
        raise _unauthorized("an API key is required (header X-API-Key or Authorization: Bearer)")
    if len(key) > 512:
        raise _unauthorized("invalid API key")
    cache: OwnerCache = request.app.state.owner_cache
    hit = cache.get(key)
    if hit is not None:
        return hit

    def lookup() -> str | None:
        with db.read() as s:
            return store.owner_for_key(s, key=key, static_keys=settings.static_api_keys)

    owner = await run_in_threadpool(lookup)
    if owner is None:
        raise _unauthorized("invalid API key")
    cache.put(key, owner)
    return owner


OwnerDep = Annotated[str, Depends(get_owner)]


# --- pages of a list --------------------------------------------------------------------


@dataclass(frozen=True)
class OffsetPage:
    """``?offset=&limit=`` of a list, oldest first (``limit`` defaults to the settings' page size)."""

    offset: int
    limit: int

    def answer(self, path: str, items: list, total: int) -> dict:
        """The page: its items, the total, the limit, and the next page's path (None on the last)."""
        nxt = (f"{path}?offset={self.offset + self.limit}&limit={self.limit}"
               if self.offset + self.limit < total else None)
        return dict(items=items, total=total, limit=self.limit, next=nxt)


async def offset_page(
    settings: SettingsDep,
    offset: Annotated[int, Query(ge=0, le=10**9)] = 0,
    limit: Annotated[int | None, Query(ge=1, le=1000)] = None,
) -> OffsetPage:
    return OffsetPage(offset=offset, limit=limit or settings.page_size)


@dataclass(frozen=True)
class CursorPage:
    """``?after=&limit=`` of a list ordered by an integer key: the items after ``after``. Read
    ``limit + 1`` rows (``fetch``) so that ``answer`` knows whether a next page exists."""

    after: int
    limit: int

    @property
    def fetch(self) -> int:
        return self.limit + 1

    def answer(self, path: str, items: list[dict], total: int, key: str) -> JSONResponse:
        """The page (and a ``Link: <next>; rel="next"`` header unless it is the last); ``items``
        are the rows read with ``fetch``, ``key`` the field the cursor runs on."""
        page = items[:self.limit]
        nxt = f"{path}?after={page[-1][key]}&limit={self.limit}" if len(items) > self.limit else None
        headers = {"Link": f'<{nxt}>; rel="next"'} if nxt else {}
        return JSONResponse(dict(items=page, total=total, limit=self.limit, next=nxt), headers=headers)


async def cursor_page(
    settings: SettingsDep,
    after: Annotated[int, Query(ge=-1, le=10**9, description="cursor: return steps after this one")] = -1,
    limit: Annotated[int | None, Query(ge=1, le=1000)] = None,
) -> CursorPage:
    return CursorPage(after=after, limit=limit or settings.page_size)


OffsetPageDep = Annotated[OffsetPage, Depends(offset_page)]
CursorPageDep = Annotated[CursorPage, Depends(cursor_page)]
