from __future__ import annotations

from fastapi import APIRouter, Depends
from sqlalchemy import text

from service.db import Database
from service.deps import get_db, get_runner
from service.runners import Runner
from service.schemas import Health

router = APIRouter(tags=["service"])


@router.get("/health", response_model=Health, summary="liveness and dependencies (no API key needed)")
def health(db: Database = Depends(get_db), runner: Runner = Depends(get_runner)) -> Health:
    try:
        with db.read() as s:
            s.execute(text("SELECT 1"))
        database = "ok"
    except Exception as e:
        database = f"unreachable: {type(e).__name__}"
    state = runner.health()  # the LocalRunner's pool, or the broker for Celery
    broker = state if runner.name == "celery" else None
    ok = database == "ok" and state == "ok"
    return Health(status="ok" if ok else "degraded", database=database, runner=runner.name, broker=broker)
