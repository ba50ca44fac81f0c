"""The FastAPI application: ``create_app(settings)`` (a factory; nothing at import time).

Run it with ``motionx serve`` (uvicorn) — or ``uvicorn --factory service.app:create_app``.
"""

from __future__ import annotations

import asyncio
import copy
import logging
from contextlib import asynccontextmanager

from fastapi import FastAPI
from fastapi.concurrency import run_in_threadpool
from fastapi.openapi.utils import get_openapi

from service import problems
from service.cache import BytesLRU
from service.config import Settings, get_settings
from service.db import get_database, upgrade
from service.middleware import BodyLimitMiddleware
from service.runners import make_runner

log = logging.getLogger(__name__)

DESCRIPTION = """\
Extrapolate one captured human walk into a continuum of physically plausible walks
(slopes, curves, other friction or gravity).

Upload a motion (`POST /motions`), start an extrapolation (`POST /motions/{id}/extrapolate`,
202 + `Location: /jobs/{id}`), follow the job (`GET /jobs/{id}`, `GET /jobs/{id}/events`),
fetch every λ optimum (`GET /jobs/{id}/motions`, `GET /motions/{id}?format=json|gltf|glb|bvh|motion`).

Every request needs an API key (`X-API-Key` or `Authorization: Bearer`); errors are
RFC 9457 problem details (`application/problem+json`).
"""


async def _sweeper(app: FastAPI, interval: float) -> None:
    while True:
        await asyncio.sleep(interval)
        try:
            await run_in_threadpool(app.state.runner.sweep)
        except Exception:  # keep sweeping: a DB or broker outage is temporary
            log.warning("sweep failed", exc_info=True)


def create_app(settings: Settings | None = None) -> FastAPI:
    app_settings = settings if settings is not None else get_settings()

    @asynccontextmanager
    async def lifespan(app: FastAPI):
        s: Settings = app.state.settings
        if s.auto_migrate:
            await run_in_threadpool(upgrade, s.sqlalchemy_url)
        app.state.db = get_database(s.sqlalchemy_url)
        app.state.runner = make_runner(s, app.state.db)
        await run_in_threadpool(app.state.runner.start)
        task = asyncio.create_task(_sweeper(app, s.sweep_interval_s))
        try:
            yield
        finally:
            task.cancel()
            app.state.runner.close()

    app = FastAPI(
        title="motionx",
        version="1.0.0",
        description=DESCRIPTION,
        lifespan=lifespan,
        responses={
            400: {"model": _problem_model(), "description": "malformed request (e.g. an unparsable body)"},
            401: {"model": _problem_model(), "description": "missing or invalid API key"},
            422: {"model": _problem_model(), "description": "invalid request"},
        },
    )
    app.state.settings = app_settings
    app.state.owner_cache = {}
    app.state.export_cache = BytesLRU()
    problems.install(app)
    app.add_middleware(BodyLimitMiddleware, max_bytes=app_settings.max_body_bytes)

    from service.routes import health, jobs, motions, plots, web

    app.include_router(health.router)
    app.include_router(motions.router)
    app.include_router(jobs.router)
    app.include_router(plots.router)
    app.include_router(web.router)  # the page at /ui/: public files, its API calls carry the key
    app.openapi = lambda: _openapi(app)
    return app


def _problem_model():
    from service.schemas import Problem

    return Problem


def _openapi(app: FastAPI) -> dict:
    """OpenAPI 3.1 with the motion file v1 JSON Schema inlined for uploads, and every
    error response typed as application/problem+json."""
    if app.openapi_schema:
        return app.openapi_schema
    schema = get_openapi(title=app.title, version=app.version, description=app.description, routes=app.routes)
    comps = schema.setdefault("components", {}).setdefault("schemas", {})
    from solver.motion import schema as motion_schema

    ms = copy.deepcopy(motion_schema())
    defs = ms.pop("$defs", {})

    def rewrite(x):
        if isinstance(x, dict):
            return {k: (f"#/components/schemas/MotionV1_{v.split('/')[-1]}" if k == "$ref" and isinstance(v, str)
                        and v.startswith("#/$defs/") else rewrite(v)) for k, v in x.items()}
        if isinstance(x, list):
            return [rewrite(v) for v in x]
        return x

    for k, v in defs.items():
        comps[f"MotionV1_{k}"] = rewrite(v)
    for key in ("$schema", "$id"):
        ms.pop(key, None)
    comps["MotionFileV1"] = rewrite(ms)
    for path in schema.get("paths", {}).values():
        for op in path.values():
            for code, resp in op.get("responses", {}).items():
                if code.startswith(("4", "5")) and "application/json" in resp.get("content", {}):
                    resp["content"] = {problems.MEDIA_TYPE: resp["content"]["application/json"]}
    app.openapi_schema = schema
    return schema
