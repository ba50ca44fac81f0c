"""Plots as PNG: a job's progress curve, a motion's ground reaction forces, root residuals and filmstrip.

The URLs are a contract (the web page and ``motionx demo`` fetch them). Rendering is
``service.plots``, in the API's compute processes (:mod:`service.work`); the motion plots are
cached with the exports (by content hash), the progress plot by (job, attempt, points so far):
progress points are only ever appended.
"""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from service import store, work
from service.db import Database
from service.deps import QUOTA_429, UNAVAILABLE_503, DatabaseDep, OwnerDep
from service.problems import Problem, known_id, not_found
from service.views import progress_out
from service.work import Compute

router = APIRouter(tags=["plots"])

PNG = "image/png"
_PNG_CONTENT = {PNG: {"schema": {"type": "string", "format": "binary"}}}


def _png_responses(what: str, *, wrenches: bool = False) -> dict:
    out: dict = {200: {"content": _PNG_CONTENT, "description": "the plot (PNG)"},
                 404: {"description": f"no such {what} for this key"}}
    if wrenches:
        out[422] = {"description": "the motion has no contact wrenches (a raw capture)"}
        out[501] = {"description": "plotting (or the MuJoCo replay) not available in this build"}
    out[429] = QUOTA_429
    out[503] = UNAVAILABLE_503
    return out


@router.get(
    "/jobs/{job_id}/plots/progress.png",
    response_class=Response,
    summary="the job's progress curve: λ tried (accepted/rejected) and reached, and the environment value "
            "reached, against wall time",
    responses=_png_responses("job"),
)
async def progress_plot(job_id: str, request: Request, owner: OwnerDep,
                        db: DatabaseDep) -> Response:
    known_id("job", job_id)

    def load():
        with db.read() as s:
            job = store.get_job(s, job_id=job_id, owner=owner)
            if job is None:
                raise not_found("job", job_id)
            points = [progress_out(p) for p in store.progress(s, job_id=job_id, attempt=job.attempts)]
            target = dict((job.spec or {}).get("target") or {})
            key = ("plot:progress", job.id, job.attempts, len(points), points[-1]["seq"] if points else -1)
            return points, target, key

    points, target, key = await run_in_threadpool(load)
    compute: Compute = request.app.state.compute
    body, _ = await compute.cached(key, _progress, points, target, what="the progress plot", owner=owner,
                                   request=request)
    return Response(body, media_type=PNG)


def _progress(points: list[dict], target: dict) -> tuple[bytes, str]:
    return work.progress_plot(points, target), PNG


def _motion_plot_png(data: bytes, kind: str) -> tuple[bytes, str]:
    return work.motion_plot(data, kind), PNG


async def _motion_plot(request: Request, db: Database, owner: str, motion_id: str, kind: str,
                       wrenches: bool = True) -> Response:
    known_id("motion", motion_id)

    def load():
        with db.read() as s:
            row = store.get_motion(s, motion_id=motion_id, owner=owner)
            if row is None:
                raise not_found("motion", motion_id)
            if wrenches and not row.has_wrenches:
                raise Problem(422, f"motion {motion_id!r} has no contact wrenches (a raw capture): "
                              "extrapolate it to get its tutor, whose plots exist")
            return row.sha256, row.data

    sha, data = await run_in_threadpool(load)
    compute: Compute = request.app.state.compute
    body, _ = await compute.cached((sha, f"plot:{kind}"), _motion_plot_png, data, kind, what=f"the {kind} plot",
                                   owner=owner, request=request)
    return Response(body, media_type=PNG)


@router.get(
    "/motions/{motion_id}/plots/grf.png",
    response_class=Response,
    summary="ground reaction forces per foot (fx, fy, fz against time, contact phases shaded)",
    responses=_png_responses("motion", wrenches=True),
)
async def grf_plot(motion_id: str, request: Request, owner: OwnerDep,
                   db: DatabaseDep) -> Response:
    return await _motion_plot(request, db, owner, motion_id, "grf")


@router.get(
    "/motions/{motion_id}/plots/residuals.png",
    response_class=Response,
    summary="root residual of the equations of motion per frame, ours and MuJoCo's replay",
    responses=_png_responses("motion", wrenches=True),
)
async def residuals_plot(motion_id: str, request: Request, owner: OwnerDep,
                         db: DatabaseDep) -> Response:
    return await _motion_plot(request, db, owner, motion_id, "residuals")


@router.get(
    "/motions/{motion_id}/plots/filmstrip.png",
    response_class=Response,
    summary="the motion's cycle seen from the side, from behind and from above: stick figures, the feet's soles, "
            "the ground and the ground-force arrows",
    responses=_png_responses("motion"),
)
async def filmstrip_plot(motion_id: str, request: Request, owner: OwnerDep,
                         db: DatabaseDep) -> Response:
    return await _motion_plot(request, db, owner, motion_id, "filmstrip", wrenches=False)
