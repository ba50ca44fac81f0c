"""Jobs: create (202 + Location), status + progress curve, λ optima, cancel, events (SSE)."""

from __future__ import annotations

import asyncio
import hashlib
import json
import time

from fastapi import APIRouter, Header
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse, Response
from sqlalchemy.exc import IntegrityError
from sse_starlette import EventSourceResponse

from service import limits, quota, store
from service.db import Database
from service.deps import QUOTA_429, CursorPageDep, DatabaseDep, OffsetPageDep, OwnerDep, RunnerDep, SettingsDep
from service.limits import LimitError
from service.models import TERMINAL
from service.problems import Problem, known_id, not_found
from service.schemas import ExtrapolateIn, JobOut, JobPage, MotionPage
from service.views import job_out, motion_out, progress_out, sse_event

router = APIRouter(tags=["jobs"])

IDEMPOTENCY_KEY = Header(
    None, alias="Idempotency-Key", min_length=1, max_length=255, pattern=r"^[\x21-\x7e]+$",
    description="retrying with the same key (and the same request) returns the same job",
)


def _job(db: Database, job_id: str, owner: str) -> dict:
    known_id("job", job_id)
    with db.read() as s:
        job = store.get_job(s, job_id=job_id, owner=owner)
        if job is None:
            raise not_found("job", job_id)
        return job_out(job, store.progress(s, job_id=job_id, attempt=job.attempts),
                       store.job_simulation(s, job_id=job_id))


def _accepted(out: dict, replayed: bool = False) -> JSONResponse:
    headers = {"Location": out["links"]["self"]}
    if replayed:
        headers["Idempotent-Replayed"] = "true"
    return JSONResponse(out, status_code=202, headers=headers)


@router.post(
    "/motions/{motion_id}/extrapolate",
    status_code=202,
    response_model=JobOut,
    summary="start an extrapolation job (a raw capture gets its tutor first)",
    description="The source is a motion with contact wrenches (used as the tutor: one gait cycle, at most "
                f"{limits.MAX_TUTOR_FRAMES} frames and {limits.MAX_TUTOR_S:g} s) or a raw capture (the job cuts one "
                "cycle and makes its tutor first). Schema-valid requests are refused with 422 when the target or "
                "the step control is inconsistent (e.g. eps above delta0), when the source motion is beyond these "
                "limits, or when an Idempotency-Key is reused with another request.",
    responses={202: {"headers": {"Location": {"schema": {"type": "string"}}}},
               404: {"description": "no such motion for this key"},
               409: {"description": "concurrent requests with the same Idempotency-Key: retry"},
               422: {"description": "inconsistent target or step control, a source motion beyond the limits, "
                                    "or an Idempotency-Key reused with another request"},
               429: QUOTA_429},
)
def extrapolate(
    motion_id: str,
    body: ExtrapolateIn,
    owner: OwnerDep,
    db: DatabaseDep,
    runner: RunnerDep,
    settings: SettingsDep,
    idempotency_key: str | None = IDEMPOTENCY_KEY,
) -> JSONResponse:
    # lazy: the API process loads the solver (CasADi) on first use only
    from solver.continuation import StepControl, Target

    known_id("motion", motion_id)
    try:  # the solver's own checks, so a job never starts with a target it refuses
        Target(**body.target.model_dump())
        StepControl(**body.control.model_dump())
    except ValueError as e:
        raise Problem(422, str(e)) from None
    spec = body.model_dump(mode="json")
    request_hash = hashlib.sha256(json.dumps({"motion": motion_id, "spec": spec}, sort_keys=True).encode()).hexdigest()
    for _ in range(3):
        try:
            with db.write() as s:
                source = store.get_motion(s, motion_id=motion_id, owner=owner)
                if source is None:
                    raise not_found("motion", motion_id)
                try:  # the method's bounds: a tutor is one gait cycle (service.limits)
                    limits.check_source(kind=source.kind, frames=source.frames, fps=source.fps,
                                        coordinates=source.n)
                except LimitError as e:
                    raise Problem(422, str(e), type="https://motionx.dev/problems/limit") from None
                existing = None
                if idempotency_key is not None:
                    existing = store.find_idempotent(s, owner=owner, key=idempotency_key, request_hash=request_hash)
                if existing is not None:
                    return _accepted(job_out(existing, store.progress(s, job_id=existing.id)), replayed=True)
                quota.check_jobs(s, settings, owner=owner, new=1)
                job = store.create_job(
                    s, owner=owner, motion_id=motion_id, spec=spec, runner=runner.name,
                    max_attempts=settings.job_max_attempts, idempotency_key=idempotency_key,
                    request_hash=request_hash,
                )
                job_id = job.id
            break
        except store.IdempotencyConflict:
            raise Problem(422, "this Idempotency-Key was already used with a different request",
                          type="https://motionx.dev/problems/idempotency-key-reuse") from None
        except IntegrityError:  # a concurrent request with the same key won: return its job
            continue
    else:
        raise Problem(409, "concurrent requests with the same Idempotency-Key; retry")
    runner.dispatch()  # its key's turn allowing; if the broker is down the job stays queued and the sweep dispatches it
    return _accepted(_job(db, job_id, owner))


@router.get("/jobs", response_model=JobPage, summary="your jobs, oldest first (without progress curves)")
def list_jobs(page: OffsetPageDep, owner: OwnerDep, db: DatabaseDep) -> dict:
    with db.read() as s:
        rows, total = store.list_jobs(s, owner=owner, offset=page.offset, limit=page.limit)
        items = [job_out(j, []) for j in rows]
    return page.answer("/jobs", items, total)


@router.get("/jobs/{job_id}", response_model=JobOut, summary="status, λ reached, progress curve, links",
            responses={404: {"description": "no such job for this key"}})
def get_job(job_id: str, owner: OwnerDep, db: DatabaseDep) -> dict:
    return _job(db, job_id, owner)


@router.get("/jobs/{job_id}/motions", response_model=MotionPage, summary="every λ optimum of the job, by step",
            responses={404: {"description": "no such job for this key"}})
def job_motions(job_id: str, page: CursorPageDep, owner: OwnerDep, db: DatabaseDep) -> JSONResponse:
    known_id("job", job_id)
    with db.read() as s:
        if store.get_job(s, job_id=job_id, owner=owner) is None:
            raise not_found("job", job_id)
        rows = store.job_motions(s, job_id=job_id, after_step=page.after, limit=page.fetch)
        total = store.count_job_motions(s, job_id=job_id)
        items = [motion_out(r) for r in rows]
    return page.answer(f"/jobs/{job_id}/motions", items, total, key="step")


@router.post("/jobs/{job_id}/cancel", status_code=202, response_model=JobOut,
             summary="cooperative cancel (a running job stops between λ steps)",
             responses={404: {"description": "no such job for this key"},
                        409: {"description": "the job has already finished"}})
def cancel_job(job_id: str, owner: OwnerDep, db: DatabaseDep) -> JSONResponse:
    known_id("job", job_id)
    with db.write() as s:
        job = store.get_job(s, job_id=job_id, owner=owner)
        if job is None:
            raise not_found("job", job_id)
        if job.status in TERMINAL:
            raise Problem(409, f"job {job_id} has already finished ({job.status})")
        store.request_cancel(s, job_id=job_id)
    return JSONResponse(_job(db, job_id, owner), status_code=202, headers={"Location": f"/jobs/{job_id}"})


@router.delete(
    "/jobs/{job_id}",
    status_code=204,
    response_class=Response,
    summary="delete a finished job: its λ optima (and what hangs on them), progress and simulations",
    responses={204: {"description": "deleted"}, 404: {"description": "no such job for this key"},
               409: {"description": "the job is still queued or running (cancel it first), or it is a library's "
                                    "cell (delete the library)"}},
)
def delete_job(job_id: str, owner: OwnerDep, db: DatabaseDep) -> Response:
    from service.routes.motions import delete_planned  # the one way to delete a plan (409 while a job runs)

    known_id("job", job_id)
    with db.write() as s:
        job = store.get_job(s, job_id=job_id, owner=owner)
        if job is None:
            raise not_found("job", job_id)
        lib = (job.spec or {}).get("library")
        if lib:
            raise Problem(409, f"job {job_id} is a cell of library {lib.get('id')}: delete the library")
        delete_planned(s, store.deletion(s, jobs=[job_id]), f"job {job_id}")
    return Response(status_code=204)


@router.get(
    "/jobs/{job_id}/events",
    summary="Server-Sent Events: progress points, new λ optima, status changes; ends when the job does",
    responses={200: {"content": {"text/event-stream": {}}}, 404: {"description": "no such job for this key"}},
)
async def job_events(job_id: str, owner: OwnerDep, db: DatabaseDep, settings: SettingsDep) -> EventSourceResponse:
    known_id("job", job_id)

    def snapshot(after_seq: int, after_step: int, attempt: int):
        with db.read() as s:
            job = store.get_job(s, job_id=job_id, owner=owner)
            if job is None:
                return None, [], []
            if job.attempts != attempt:
                after_seq = -1
            pts = store.progress(s, job_id=job_id, attempt=job.attempts, after_seq=after_seq)
            steps = store.job_motions(s, job_id=job_id, after_step=after_step, limit=1000)
            return job_out(job, []), [progress_out(p) for p in pts], [motion_out(m) for m in steps]

    first, _, _ = await run_in_threadpool(snapshot, 10**9, 10**9, 0)
    if first is None:
        raise not_found("job", job_id)

    async def stream():  # ended by sse_starlette when the client disconnects
        after_seq, after_step, attempt, last_status = -1, -1, -1, None
        deadline = time.monotonic() + settings.sse_max_s
        while time.monotonic() < deadline:
            job, pts, steps = await run_in_threadpool(snapshot, after_seq, after_step, attempt)
            if job is None:
                return
            if job["attempts"] != attempt:
                attempt, after_seq = job["attempts"], -1
            for p in pts:
                after_seq = p["seq"]
                yield sse_event("progress", p, f"{attempt}:{p['seq']}")
            for m in steps:
                after_step = m["step"]
                yield sse_event("motion", m)
            key = (job["status"], job["attempts"], job["lam_reached"])
            if key != last_status:
                last_status = key
                yield sse_event("status", job)
            if job["status"] in TERMINAL:
                yield sse_event("end", {"status": job["status"]})
                return
            await asyncio.sleep(settings.sse_poll_s)

    return EventSourceResponse(stream())
