from __future__ import annotations

from fastapi import APIRouter, Request
from sqlalchemy import func, select, text

from service import quota
from service.deps import DatabaseDep, OwnerDep, RunnerDep, SettingsDep
from service.models import JobRow
from service.schemas import Health, Usage

router = APIRouter(tags=["service"])


@router.get("/health", response_model=Health, summary="liveness, dependencies and saturation (no API key needed)")
def health(request: Request, db: DatabaseDep, runner: RunnerDep, settings: SettingsDep) -> Health:
    """Cheap by design: heavy requests run in compute processes, so this answers at once even
    while exports or uploads are being computed. ``saturation`` says how busy the service is:
    ``compute.waiting`` > 0 means heavy requests queue for a process, ``jobs.queued`` jobs wait
    for a slot (their key's turn, or a free worker)."""
    jobs: dict[str, int] = {}
    try:
        with db.read() as s:
            s.execute(text("SELECT 1"))
            counts = s.execute(select(JobRow.status, func.count()).where(JobRow.status.in_(("queued", "running")))
                               .group_by(JobRow.status)).all()
            jobs = {str(k): int(v) for k, v in counts}
        database = "ok"
    except Exception as e:
        database = f"unreachable: {type(e).__name__}"
    state = runner.health()  # the LocalRunner's job processes, or the broker for Celery
    broker = state if runner.name == "celery" else None
    compute_state = request.app.state.compute
    pool = compute_state.pool
    compute = "ok" if pool is None or pool.healthy() else "stopped"
    ok = database == "ok" and state == "ok" and compute == "ok"
    c = compute_state.saturation()
    saturation = {
        "compute": {**c, "saturated": c["processes"] > 0 and c["running"] >= c["processes"]},
        "jobs": {"queued": jobs.get("queued", 0), "running": jobs.get("running", 0),
                 "slots": settings.total_job_slots, "per_key": settings.key_job_slots,
                 "saturated": jobs.get("running", 0) >= settings.total_job_slots},
    }
    return Health(status="ok" if ok else "degraded", database=database, runner=runner.name, broker=broker,
                  compute=compute, saturation=saturation)


@router.get("/usage", response_model=Usage, summary="your API key's usage next to its quotas")
def usage(owner: OwnerDep, db: DatabaseDep, settings: SettingsDep) -> dict:
    with db.read() as s:
        return quota.usage(s, settings, owner=owner)
