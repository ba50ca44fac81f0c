"""Plots as PNG: a job's progress curve, a motion's ground reaction forces and root residuals.

The URLs are a contract (the web page and ``motionx demo`` fetch them). Rendering is
``service.plots``; the motion plots are cached with the exports (by content hash), the
progress plot by (job, attempt, points so far): progress points are only ever appended.
"""

from __future__ import annotations

from collections.abc import Callable

from fastapi import APIRouter, Depends, Request
from fastapi.responses import Response

from service import store
from service.db import Database
from service.deps import get_db, get_owner
from service.plots import PlotError, grf_png, progress_png, residuals_png
from service.problems import Problem, not_found
from service.views import progress_out

router = APIRouter(tags=["plots"])

PNG = "image/png"
_PNG_CONTENT = {PNG: {"schema": {"type": "string", "format": "binary"}}}


def _png_responses(what: str, *, wrenches: bool = False) -> dict:
    out: dict = {200: {"content": _PNG_CONTENT, "description": "the plot (PNG)"},
                 404: {"description": f"no such {what} for this key"}}
    if wrenches:
        out[422] = {"description": "the motion has no contact wrenches (a raw capture)"}
        out[501] = {"description": "plotting (or the MuJoCo replay) not available in this build"}
    return out


@router.get(
    "/jobs/{job_id}/plots/progress.png",
    response_class=Response,
    summary="the job's progress curve: λ tried (accepted/rejected) and reached, and the environment value "
            "reached, against wall time",
    responses=_png_responses("job"),
)
def progress_plot(job_id: str, request: Request, owner: str = Depends(get_owner),
                  db: Database = Depends(get_db)) -> Response:
    with db.read() as s:
        job = store.get_job(s, job_id=job_id, owner=owner)
        if job is None:
            raise not_found("job", job_id)
        points = [progress_out(p) for p in store.progress(s, job_id=job_id, attempt=job.attempts)]
        target = dict((job.spec or {}).get("target") or {})
        key = ("plot:progress", job.id, job.attempts, len(points), points[-1]["seq"] if points else -1)
    cache = request.app.state.export_cache
    hit = cache.get(key)
    if hit is not None:
        return Response(hit[0], media_type=PNG)
    try:
        body = progress_png(points, target)
    except PlotError as e:
        raise Problem(422, str(e)) from None
    cache.put(key, body, PNG)
    return Response(body, media_type=PNG)


def _motion_plot(request: Request, db: Database, owner: str, motion_id: str, kind: str,
                 render: Callable[[object], bytes]) -> Response:
    with db.read() as s:
        row = store.get_motion(s, motion_id=motion_id, owner=owner)
        if row is None:
            raise not_found("motion", motion_id)
        key = (row.sha256, f"plot:{kind}")
        cache = request.app.state.export_cache
        hit = cache.get(key)
        if hit is not None:
            return Response(hit[0], media_type=PNG)
        if not row.has_wrenches:
            raise Problem(422, f"motion {motion_id!r} has no contact wrenches (a raw capture): "
                          "extrapolate it to get its tutor, whose plots exist")
        motion = store.load_motion(row)
    try:
        body = render(motion)
    except PlotError as e:
        raise Problem(422, str(e)) from None
    except ImportError as e:
        raise Problem(501, f"{kind} plot not available in this build ({e})") from None
    cache.put(key, body, PNG)
    return Response(body, media_type=PNG)


@router.get(
    "/motions/{motion_id}/plots/grf.png",
    response_class=Response,
    summary="ground reaction forces per foot (fx, fy, fz against time, contact phases shaded)",
    responses=_png_responses("motion", wrenches=True),
)
def grf_plot(motion_id: str, request: Request, owner: str = Depends(get_owner),
             db: Database = Depends(get_db)) -> Response:
    return _motion_plot(request, db, owner, motion_id, "grf", grf_png)


@router.get(
    "/motions/{motion_id}/plots/residuals.png",
    response_class=Response,
    summary="root residual of the equations of motion per frame, ours and MuJoCo's replay",
    responses=_png_responses("motion", wrenches=True),
)
def residuals_plot(motion_id: str, request: Request, owner: str = Depends(get_owner),
                   db: Database = Depends(get_db)) -> Response:
    return _motion_plot(request, db, owner, motion_id, "residuals", residuals_png)
