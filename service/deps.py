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

import asyncio
import collections
import hashlib
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


class GuessGuard:
    """Slows down wrong-key guesses, per client address: past ``FREE`` *distinct* wrong keys
    within ``WINDOW_S``, each further wrong key of that client is answered (401) only after a
    delay that doubles with each one (up to ``MAX_DELAY_S``), one at a time; more than
    ``MAX_WAITING`` waiting get 429. The same wrong key sent again (a misconfigured client, a
    contract test's probe) is not a new guess, and requests with a valid key are not affected."""

    FREE, WINDOW_S, BASE_DELAY_S, MAX_DELAY_S, MAX_WAITING = 10, 600.0, 0.05, 5.0, 16

    def __init__(self) -> None:
        self._seen: TTLCache[tuple[str, str], bool] = TTLCache(maxsize=100_000, ttl=self.WINDOW_S)
        self._wrong: TTLCache[str, int] = TTLCache(maxsize=10_000, ttl=self.WINDOW_S)
        self._locks: dict[str, asyncio.Lock] = {}
        self._waiting: collections.Counter[str] = collections.Counter()

    def delay(self, client: str) -> float:
        n = self._wrong.get(client, 0) - self.FREE
        return 0.0 if n <= 0 else min(self.MAX_DELAY_S, self.BASE_DELAY_S * 2.0 ** min(n, 20))

    async def wrong_key(self, client: str, key: str) -> Problem:
        """Count a wrong key of ``client``; wait its turn and its delay; the 401 (or 429) to raise."""
        seen = (client, hashlib.sha256(key.encode("utf-8", "replace")).hexdigest())
        if seen not in self._seen:
            self._seen[seen] = True
            self._wrong[client] = self._wrong.get(client, 0) + 1
        d = self.delay(client)
        if d <= 0:
            return _unauthorized("invalid API key")
        if self._waiting[client] >= self.MAX_WAITING:
            return Problem(429, "too many wrong API keys from this client; retry later",
                           headers={"Retry-After": str(int(self.MAX_DELAY_S))}, quota="wrong_keys")
        self._waiting[client] += 1
        try:
            async with self._locks.setdefault(client, asyncio.Lock()):
                await asyncio.sleep(d)
        finally:
            self._waiting[client] -= 1
            if self._waiting[client] <= 0:
                del self._waiting[client]
                self._locks.pop(client, None)
        return _unauthorized("invalid API key")


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
        raise await request.app.state.guess_guard.wrong_key(request.client.host if request.client else "", key)
    cache: OwnerCache = request.app.state.owner_cache
    hit = cache.get(key)
    if hit is not None:
        return hit

    def lookup() -> str | None:
        with db.read() as s:
            return store.owner_for_key(s, key=key, static_keys=settings.static_api_keys)

    owner = await run_in_threadpool(lookup)
    if owner is None:
        guard: GuessGuard = request.app.state.guess_guard
        raise await guard.wrong_key(request.client.host if request.client else "", key)
    cache.put(key, owner)
    return owner


OwnerDep = Annotated[str, Depends(get_owner)]

#: the OpenAPI responses of a route with per-key quotas, and of one that can meet an infrastructure fault
QUOTA_429 = {"description": "this API key is over one of its quotas (the body's `quota` names it): retry after "
                            "Retry-After seconds"}
UNAVAILABLE_503 = {"description": "a compute process restarted or the database is unavailable: retry after "
                                  "Retry-After seconds"}


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
