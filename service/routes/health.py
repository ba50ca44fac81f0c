from __future__ import annotations

from fastapi import APIRouter, Request
from sqlalchemy import text

from service.deps import DatabaseDep, RunnerDep
from service.schemas import Health

router = APIRouter(tags=["service"])


@router.get("/health", response_model=Health, summary="liveness and dependencies (no API key needed)")
def health(request: Request, db: DatabaseDep, runner: RunnerDep) -> Health:
    """Cheap by design: heavy requests run in compute processes, so this answers at once even
    while exports or uploads are being computed."""
    try:
        with db.read() as s:
            s.execute(text("SELECT 1"))
        database = "ok"
    except Exception as e:
        database = f"unreachable: {type(e).__name__}"
    state = runner.health()  # the LocalRunner's job processes, or the broker for Celery
    broker = state if runner.name == "celery" else None
    pool = request.app.state.compute.pool
    compute = "ok" if pool is None or pool.healthy() else "stopped"
    ok = database == "ok" and state == "ok" and compute == "ok"
    return Health(status="ok" if ok else "degraded", database=database, runner=runner.name, broker=broker,
                  compute=compute)
