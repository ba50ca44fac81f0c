"""Motion libraries: create (one job per cell), status and progress per cell and overall,
cancel, manifest, library GLB (service.library)."""

from __future__ import annotations

import asyncio
import time
from typing import Literal

from fastapi import APIRouter, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse, Response
from sse_starlette import EventSourceResponse

from service import library, limits, quota, store, work
from service.db import Database
from service.deps import QUOTA_429, UNAVAILABLE_503, DatabaseDep, OffsetPageDep, OwnerDep, RunnerDep, SettingsDep
from service.limits import LimitError
from service.models import TERMINAL
from service.problems import Problem, known_id, not_found
from service.schemas import LibraryIn, LibraryOut, LibraryPage
from service.views import sse_event
from service.work import Compute
from solver.formats import EXPORT_WORLDS

#: the worlds a library GLB is written in (solver.formats, the default first)
ExportWorld = Literal[tuple(EXPORT_WORLDS)]  # type: ignore[valid-type]
DEFAULT_WORLD = next(iter(EXPORT_WORLDS))

router = APIRouter(tags=["libraries"])


def _library(db: Database, library_id: str, owner: str) -> dict:
    known_id("library", library_id)
    with db.read() as s:
        row = store.get_library(s, library_id=library_id, owner=owner)
        if row is None:
            raise not_found("library", library_id)
        return library.library_out(s, row)


@router.post(
    "/motions/{motion_id}/library",
    status_code=202,
    response_model=LibraryOut,
    summary="start a motion library: one extrapolation job per cell of a grid (or per target of a list)",
    description="The cells are queued as independent jobs (nearest the tutor first) and run by the workers; "
                "each starts from the stored optimum furthest along its own homotopy (docs/service.md, "
                "'Motion libraries'). A grid has at most 125 cells; its axes and their bounds are "
                "the solver's grid axes (GET /axes).",
    responses={202: {"headers": {"Location": {"schema": {"type": "string"}}}},
               404: {"description": "no such motion for this key"},
               422: {"description": "an unknown axis, a value out of its bounds, too many cells, a repeated value or "
                                    "target, or a source motion beyond the limits"},
               429: QUOTA_429},
)
def create_library(
    motion_id: str,
    body: LibraryIn,
    owner: OwnerDep,
    db: DatabaseDep,
    runner: RunnerDep,
    settings: SettingsDep,
) -> JSONResponse:
    from solver.continuation import StepControl  # lazy: the API process loads the solver (CasADi) on first use only
    from solver.library import LibraryError

    known_id("motion", motion_id)
    req = body.model_dump(mode="json", exclude_none=True)
    req["grid"] = body.grid.model_dump(mode="json", exclude_none=True) if body.grid is not None else None
    if body.targets is not None:
        req["targets"] = [t.model_dump(mode="json", exclude_none=True) for t in body.targets]
    try:
        StepControl(**body.control.model_dump())
        spec, cells, dispatch = library.plan(req)
    except (LibraryError, ValueError) as e:
        raise Problem(422, str(e)) from None
    with db.write() as s:
        source = store.get_motion(s, motion_id=motion_id, owner=owner)
        if source is None:
            raise not_found("motion", motion_id)
        try:
            limits.check_source(kind=source.kind, frames=source.frames, fps=source.fps, coordinates=source.n)
        except LimitError as e:
            raise Problem(422, str(e), type="https://motionx.dev/problems/limit") from None
        quota.check_jobs(s, settings, owner=owner, new=len(cells))
        row, _ = store.create_library(s, owner=owner, motion_id=motion_id, spec=spec, cells=cells,
                                      runner=runner.name, max_attempts=settings.job_max_attempts, dispatch=dispatch)
        lid = row.id
    runner.dispatch()  # nearest the tutor first, the key's turns allowing; a broker down: the sweep does it
    out = _library(db, lid, owner)
    return JSONResponse(out, status_code=202, headers={"Location": out["links"]["self"]})


@router.get("/libraries", response_model=LibraryPage, summary="your motion libraries, oldest first")
def list_libraries(page: OffsetPageDep, owner: OwnerDep, db: DatabaseDep) -> dict:
    with db.read() as s:
        rows, total = store.list_libraries(s, owner=owner, offset=page.offset, limit=page.limit)
        items = [library.library_out(s, r) for r in rows]
    return page.answer("/libraries", items, total)


@router.get("/libraries/{library_id}", response_model=LibraryOut,
            summary="status, progress per cell and overall, links",
            responses={404: {"description": "no such library for this key"}})
def get_library(library_id: str, owner: OwnerDep, db: DatabaseDep) -> dict:
    return _library(db, library_id, owner)


@router.post("/libraries/{library_id}/cancel", status_code=202, response_model=LibraryOut,
             summary="cancel every unfinished cell (running ones stop between λ steps)",
             responses={404: {"description": "no such library for this key"},
                        409: {"description": "the library has already finished"}})
def cancel_library(library_id: str, owner: OwnerDep, db: DatabaseDep) -> JSONResponse:
    known_id("library", library_id)
    with db.write() as s:
        row = store.get_library(s, library_id=library_id, owner=owner)
        if row is None:
            raise not_found("library", library_id)
        if library.library_out(s, row)["status"] in TERMINAL:
            raise Problem(409, f"library {library_id} has already finished")
        store.request_library_cancel(s, library=row)
    return JSONResponse(_library(db, library_id, owner), status_code=202,
                        headers={"Location": f"/libraries/{library_id}"})


@router.get("/libraries/{library_id}/manifest",
            summary="the manifest: cell -> parameters, status, files, realism figures, cycle metadata",
            responses={404: {"description": "no such library for this key"}})
def get_manifest(library_id: str, owner: OwnerDep, db: DatabaseDep) -> dict:
    known_id("library", library_id)
    with db.read() as s:
        row = store.get_library(s, library_id=library_id, owner=owner)
        if row is None:
            raise not_found("library", library_id)
        return library.manifest(s, row)


@router.get(
    "/libraries/{library_id}/library.glb",
    summary="one GLB: the skeleton once, one looping animation per cell with a clip (named by its key), "
            "the grid in asset.extras.library and the game-ready data in each animation's extras",
    responses={200: {"content": {"model/gltf-binary": {}}}, 404: {"description": "no such library for this key"},
               409: {"description": "no cell has a motion yet"},
               422: {"description": "rig=source on a library whose input has no rig of its own"},
               429: QUOTA_429, 503: UNAVAILABLE_503},
)
async def get_library_glb(library_id: str, request: Request, owner: OwnerDep, db: DatabaseDep,
                          rig: Literal["character", "source"] = Query(
                              "character", description="source: on the input's own character (a BVH, skinned "
                                                       "glTF or DeepMimic input), one animation per cell"),
                          world: ExportWorld = Query(
                              DEFAULT_WORLD, description="; ".join(f"{k}: {v}" for k, v in EXPORT_WORLDS.items())
                              + " (docs/export.md, 'The world and the ground'); each cell's ground is a node "
                                "'ground <cell>'")
                          ) -> Response:
    known_id("library", library_id)

    def load():
        with db.read() as s:
            row = store.get_library(s, library_id=library_id, owner=owner)
            if row is None:
                raise not_found("library", library_id)
            items = [(c["key"], clip.sha256, clip.data) for c, clip in library.clips(s, row) if clip is not None]
            grid = {"id": row.id, "axes": row.spec.get("grid"), "targets": row.spec.get("targets"),
                    "cells": [{"key": c["key"], "parameters": c["parameters"], "status": c["status"]}
                              for c in library.library_out(s, row)["cells"]],
                    "manifest": f"/libraries/{row.id}/manifest"}
            return items, grid

    items, grid = await run_in_threadpool(load)
    if not items:
        raise Problem(409, f"library {library_id} has no cell with a motion yet")
    compute: Compute = request.app.state.compute
    key = ("library.glb", tuple((k, sha) for k, sha, _ in items), repr(grid), rig, world)
    body, mt = await compute.cached(key, work.library_glb, [(k, d) for k, _, d in items], grid, rig, world,
                                    what="the library GLB", owner=owner, request=request)
    return Response(body, media_type=mt)


@router.get(
    "/libraries/{library_id}/events",
    summary="Server-Sent Events: a cell's status or λ reached changed (cell), the library's progress (status); "
            "ends when the library does",
    responses={200: {"content": {"text/event-stream": {}}}, 404: {"description": "no such library for this key"}},
)
async def library_events(library_id: str, owner: OwnerDep, db: DatabaseDep,
                         settings: SettingsDep) -> EventSourceResponse:
    known_id("library", library_id)

    def snapshot() -> dict | None:
        with db.read() as s:
            row = store.get_library(s, library_id=library_id, owner=owner)
            return library.library_out(s, row) if row is not None else None

    if await run_in_threadpool(snapshot) is None:
        raise not_found("library", library_id)

    async def stream():  # ended by sse_starlette when the client disconnects
        seen: dict[str, tuple] = {}
        last = None
        deadline = time.monotonic() + settings.sse_max_s
        while time.monotonic() < deadline:
            lib = await run_in_threadpool(snapshot)
            if lib is None:
                return
            for c in lib["cells"]:
                key = (c["status"], c["lam_reached"], c["steps"], c["attempts"])
                if seen.get(c["key"]) != key:
                    seen[c["key"]] = key
                    yield sse_event("cell", c)
            state = (lib["status"], lib["progress"]["done"], round(lib["progress"]["fraction"], 6))
            if state != last:
                last = state
                yield sse_event("status", {k: lib[k] for k in ("id", "status", "progress", "cancel_requested")})
            if lib["status"] in TERMINAL:
                yield sse_event("end", {"status": lib["status"]})
                return
            await asyncio.sleep(settings.sse_poll_s)

    return EventSourceResponse(stream())


@router.delete(
    "/libraries/{library_id}",
    status_code=204,
    response_class=Response,
    summary="delete a library and its cells (their jobs, λ optima, progress and simulations)",
    responses={204: {"description": "deleted"}, 404: {"description": "no such library for this key"},
               409: {"description": "a cell is still queued or running: cancel the library first"}},
)
def delete_library(library_id: str, owner: OwnerDep, db: DatabaseDep) -> Response:
    from service.routes.motions import delete_planned  # the one way to delete a plan (409 while a job runs)

    known_id("library", library_id)
    with db.write() as s:
        if store.get_library(s, library_id=library_id, owner=owner) is None:
            raise not_found("library", library_id)
        delete_planned(s, store.deletion(s, libraries=[library_id]), f"library {library_id}")
    return Response(status_code=204)
