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
from service.config import Settings, find_check_modules, get_settings
from service.db import get_database, upgrade
from service.deps import GuessGuard, OwnerCache
from service.middleware import BodyLimitMiddleware, SecurityHeadersMiddleware, page_csp
from service.runners import make_runner
from service.work import Compute

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
        find_check_modules(s)
        if s.auto_migrate:
            await run_in_threadpool(upgrade, s.sqlalchemy_url)
        app.state.db = get_database(s.sqlalchemy_url)
        app.state.compute = Compute(s)
        app.state.runner = make_runner(s, app.state.db)
        # the process pools' supervisor threads live until shutdown (see service.procpool)
        app.state.compute.start()
        await run_in_threadpool(app.state.runner.start)
        task = asyncio.create_task(_sweeper(app, s.sweep_interval_s))
        try:
            yield
        finally:
            task.cancel()
            await run_in_threadpool(app.state.runner.close)
            await run_in_threadpool(app.state.compute.close)

    app = FastAPI(
        title="motionx",
        version="1.0.0",
        description=DESCRIPTION,
        lifespan=lifespan,
        docs_url=None,  # /docs is served from local files (service/routes/docs.py), no CDN
        redoc_url=None,
        responses={
            400: {"model": _problem_model(), "description": "malformed request (e.g. an unparsable body)"},
            401: {"model": _problem_model(), "description": "missing or invalid API key"},
            422: {"model": _problem_model(), "description": "invalid request"},
            429: {"model": _problem_model(), "description": "this API key is over one of its quotas, or this client "
                  "sent too many wrong keys: retry after Retry-After seconds (`quota` names it)"},
            503: {"model": _problem_model(), "description": "the database is unavailable or a compute process "
                  "restarted: retry after Retry-After seconds"},
        },
    )
    app.state.settings = app_settings
    app.state.owner_cache = OwnerCache()
    app.state.guess_guard = GuessGuard()
    problems.install(app)
    app.add_middleware(BodyLimitMiddleware, max_bytes=app_settings.max_body_bytes)

    # lazy: loaded when an app is made, not on import (importing service creates nothing)
    from service.routes import axes, docs, health, jobs, libraries, motions, plots, simulations, web

    index = web.STATIC_DIR / "index.html"
    app.add_middleware(SecurityHeadersMiddleware, page_policy=page_csp(index.read_text() if index.is_file() else ""))
    app.include_router(health.router)
    app.include_router(axes.router)
    app.include_router(motions.router)
    app.include_router(jobs.router)
    app.include_router(simulations.router)
    app.include_router(libraries.router)
    app.include_router(plots.router)
    app.include_router(docs.router)  # /docs: Swagger UI from local files
    app.include_router(web.router)  # the page at /ui/: public files, its API calls carry the key
    app.state.route_methods = [(r.path_regex, frozenset(r.methods or ())) for router in
                               (health.router, axes.router, motions.router, jobs.router, simulations.router,
                                              libraries.router, plots.router, docs.router, web.router)
                               for r in router.routes if hasattr(r, "path_regex")]
    app.openapi = lambda: _openapi(app)
    return app


def _problem_model():
    # lazy: loaded when an app is made, not on import (importing service creates nothing)
    from service.schemas import Problem

    return Problem


def _openapi(app: FastAPI) -> dict:
    """OpenAPI 3.1 with the motion file v2 JSON Schema inlined for uploads, and every
    error response typed as application/problem+json."""
    if app.openapi_schema:
        return app.openapi_schema
    schema = get_openapi(title=app.title, version=app.version, description=app.description, routes=app.routes)
    comps = schema.setdefault("components", {}).setdefault("schemas", {})
    # lazy: loaded when an app is made, not on import (importing service creates nothing)
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
    _add_links(schema)
    body = schema["paths"].get("/motions", {}).get("post", {}).get("requestBody", {}).get("content", {})
    if "application/json" in body:
        body["application/json"]["example"] = _example_motion()
    app.openapi_schema = schema
    return schema


def _example_motion() -> dict:
    """A small valid upload for the documentation (a HalfBoy standing still for 1 s at 15 fps)."""
    import numpy as np  # lazy: loaded when an app is made, not on import (importing service creates nothing)

    # lazy: loaded when an app is made, not on import (importing service creates nothing)
    from solver.character import reference
    from solver.motion import Motion

    ch = reference("halfboy")
    q = np.zeros((ch.n, 16))
    q[ch.index("root_tz")] = 0.9
    d = Motion(character=ch, fps=15.0, q=q, reference_name="halfboy", provenance={"step": "capture"}).to_dict()
    d["provenance"].pop("created", None)
    return d


#: OpenAPI links: where the id of a created motion or job can be used next (clients, and
#: schemathesis' stateful phase, follow them)
LINKS = {
    ("/motions", "post", "201"): {
        "GetMotion": ("/motions/{motion_id}", "get", "motion_id"),
        "GetValidation": ("/motions/{motion_id}/validation", "get", "motion_id"),
        "Extrapolate": ("/motions/{motion_id}/extrapolate", "post", "motion_id"),
        "GrfPlot": ("/motions/{motion_id}/plots/grf.png", "get", "motion_id"),
        "ResidualsPlot": ("/motions/{motion_id}/plots/residuals.png", "get", "motion_id"),
        "FilmstripPlot": ("/motions/{motion_id}/plots/filmstrip.png", "get", "motion_id"),
        "Simulate": ("/motions/{motion_id}/simulation", "post", "motion_id"),
        "DeleteSimulations": ("/motions/{motion_id}/simulation", "delete", "motion_id"),
        "DeleteMotion": ("/motions/{motion_id}", "delete", "motion_id"),
    },
    ("/motions/{motion_id}/extrapolate", "post", "202"): {
        "GetJob": ("/jobs/{job_id}", "get", "job_id"),
        "JobMotions": ("/jobs/{job_id}/motions", "get", "job_id"),
        "CancelJob": ("/jobs/{job_id}/cancel", "post", "job_id"),
        "ProgressPlot": ("/jobs/{job_id}/plots/progress.png", "get", "job_id"),
        "DeleteJob": ("/jobs/{job_id}", "delete", "job_id"),
    },
}


def _add_links(schema: dict) -> None:
    paths = schema.get("paths", {})
    for (path, method, code), links in LINKS.items():
        resp = paths.get(path, {}).get(method, {}).get("responses", {}).get(code)
        if resp is None:
            continue
        out = resp.setdefault("links", {})
        for name, (target, tmethod, param) in links.items():
            op_id = paths.get(target, {}).get(tmethod, {}).get("operationId")
            if op_id:
                out[name] = {"operationId": op_id, "parameters": {param: "$response.body#/id"}}
