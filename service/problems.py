"""Errors as RFC 9457 problem details (``application/problem+json``).

Raise :class:`Problem` anywhere in a route; validation errors, HTTP errors and unexpected
exceptions are all rendered the same way (an unexpected one as a plain 500 without
internals — the traceback goes to the log).
"""

from __future__ import annotations

import logging
import re
from typing import Any

from fastapi import FastAPI, Request
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse, Response
from sqlalchemy.exc import DBAPIError, DisconnectionError, InterfaceError, OperationalError, SQLAlchemyError
from sqlalchemy.exc import TimeoutError as PoolTimeout
from starlette.exceptions import HTTPException as StarletteHTTPException

from service.limits import plain

log = logging.getLogger(__name__)

MEDIA_TYPE = "application/problem+json"
TYPE_BASE = "https://motionx.dev/problems/"

TITLES = {
    400: "Bad Request",
    401: "Unauthorized",
    403: "Forbidden",
    404: "Not Found",
    405: "Method Not Allowed",
    406: "Not Acceptable",
    409: "Conflict",
    413: "Content Too Large",
    415: "Unsupported Media Type",
    422: "Unprocessable Content",
    429: "Too Many Requests",
    500: "Internal Server Error",
    501: "Not Implemented",
    503: "Service Unavailable",
}


class ClientGone(Exception):
    """The client of a heavy request closed its connection: its work was cancelled (raised by
    ``service.work``, answered 499 here)."""


class Problem(Exception):
    def __init__(
        self,
        status: int,
        detail: str,
        *,
        type: str | None = None,
        title: str | None = None,
        headers: dict[str, str] | None = None,
        **extra: Any,
    ) -> None:
        super().__init__(detail)
        self.status, self.detail = status, detail
        self.type = type or "about:blank"
        self.title = title or TITLES.get(status, "Error")
        self.headers = headers or {}
        self.extra = extra


def problem_response(
    status: int, detail: str, *, instance: str | None = None, type: str = "about:blank", title: str | None = None,
    headers: dict[str, str] | None = None, **extra: Any,
) -> JSONResponse:
    detail = plain(detail)
    if len(detail) > MAX_DETAIL:
        detail = detail[: MAX_DETAIL - 1] + "…"
    body: dict[str, Any] = {"type": type, "title": title or TITLES.get(status, "Error"), "status": status,
                            "detail": detail}
    if instance:
        body["instance"] = _short(instance, MAX_ECHO)
    body.update(extra)
    return JSONResponse(body, status_code=status, media_type=MEDIA_TYPE, headers=headers)


#: the longest ``detail`` sent: a message never repeats a large input
MAX_DETAIL = 2000
#: the longest excerpt of the client's own input (a request path, a value) an answer repeats
MAX_ECHO = 200
_IDS = {"motion": re.compile(r"m_[0-9a-f]{32}"), "job": re.compile(r"j_[0-9a-f]{32}"),
        "library": re.compile(r"l_[0-9a-f]{32}")}


def _short(ident: str, n: int = 80) -> str:
    return ident if len(ident) <= n else ident[: n - 1] + "…"


def not_found(what: str, ident: str) -> Problem:
    return Problem(404, f"no {what} {_short(ident)!r} (or it belongs to another API key)",
                   type=TYPE_BASE + "not-found")


def known_id(what: str, ident: str) -> str:
    """``ident`` if it has the form of a ``what`` id (m_…, j_…), else 404: malformed ids (NUL
    bytes, 10 kB strings...) never reach the database."""
    if not _IDS[what].fullmatch(ident):
        raise not_found(what, ident)
    return ident


def _loc(loc: tuple | list) -> str:
    parts = [_short(str(p), 60) for p in loc if p not in ("body",)] or [_short(str(p), 60) for p in loc]
    return _short(".".join(parts), 200)


def allowed_methods(request: Request) -> list[str]:
    """The methods of all routes matching the request's path (Starlette answers a 405 with the
    first route's only: ``OPTIONS /motions`` said ``Allow: POST`` although GET exists).
    ``app.state.route_methods`` lists (path regex, methods) of every route (``create_app``)."""
    path = request.url.path
    methods: set[str] = set()
    for regex, ms in getattr(request.app.state, "route_methods", ()):
        if regex.match(path):
            methods |= set(ms or ())
    methods.discard("HEAD")  # implied by GET
    order = ["GET", "POST", "PUT", "PATCH", "DELETE"]
    return sorted(methods, key=lambda m: (order.index(m) if m in order else len(order), m))


def install(app: FastAPI) -> None:
    @app.exception_handler(Problem)
    async def _problem(request: Request, exc: Problem):
        return problem_response(exc.status, exc.detail, instance=request.url.path, type=exc.type, title=exc.title,
                                headers=exc.headers, **exc.extra)

    @app.exception_handler(RequestValidationError)
    async def _validation(request: Request, exc: RequestValidationError):
        errors = [
            {"loc": _loc(e.get("loc", ())), "msg": _short(str(e.get("msg", "")), 300), "type": e.get("type", "")}
            for e in exc.errors()[:20]
        ]
        detail = "; ".join(f"{e['loc']}: {e['msg']}" if e["loc"] else e["msg"] for e in errors[:5]) or "invalid request"
        return problem_response(422, detail, instance=request.url.path, type=TYPE_BASE + "validation",
                                errors=errors)

    @app.exception_handler(StarletteHTTPException)
    async def _http(request: Request, exc: StarletteHTTPException):
        detail = exc.detail if isinstance(exc.detail, str) else TITLES.get(exc.status_code, "Error")
        headers = dict(getattr(exc, "headers", None) or {})
        if exc.status_code == 405:  # the path exists: Allow lists every method of every route on it
            allow = ", ".join(allowed_methods(request))
            if request.method == "OPTIONS":
                return Response(status_code=204, headers={"Allow": allow})
            headers["Allow"] = allow
            detail = f"{_short(request.method, 20)} is not allowed here; allowed: {allow}"
        return problem_response(exc.status_code, detail, instance=request.url.path, headers=headers or None)

    @app.exception_handler(ClientGone)
    async def _gone(request: Request, exc: ClientGone):  # nobody reads it: the client has closed its connection
        return problem_response(499, "the client closed the request; its work was cancelled",
                                instance=request.url.path, title="Client Closed Request")

    @app.exception_handler(SQLAlchemyError)
    async def _database(request: Request, exc: SQLAlchemyError):
        return _database_problem(request, exc)

    @app.exception_handler(Exception)
    async def _unexpected(request: Request, exc: Exception):
        if database_unavailable(exc):
            return _database_problem(request, exc)
        log.exception("unhandled error on %s %s", request.method, request.url.path)
        return problem_response(500, "internal error (logged on the server)", instance=request.url.path)


#: Retry-After of a 503 while the database is out of reach (a restart takes seconds)
DATABASE_RETRY_S = 3


def database_unavailable(exc: BaseException) -> bool:
    """An error that means the database cannot be reached or used right now (a restart, a
    connection lost, the pool exhausted, SQLite busy), anywhere in the exception's chain."""
    seen = 0
    e: BaseException | None = exc
    while e is not None and seen < 10:
        if isinstance(e, (OperationalError, InterfaceError, DisconnectionError, PoolTimeout)):
            return True
        if isinstance(e, DBAPIError) and e.connection_invalidated:
            return True
        e = e.__cause__ or e.__context__
        seen += 1
    return False


def _database_problem(request: Request, exc: BaseException) -> JSONResponse:
    if database_unavailable(exc):
        log.warning("database unavailable on %s %s: %s", request.method, request.url.path,
                    str(exc).splitlines()[0][:300] if str(exc) else type(exc).__name__)
        return problem_response(503, "the database is unavailable right now; retry in a few seconds",
                                instance=request.url.path, headers={"Retry-After": str(DATABASE_RETRY_S)})
    log.error("database error on %s %s", request.method, request.url.path, exc_info=exc)
    return problem_response(500, "internal error (logged on the server)", instance=request.url.path)
