"""Per-key quotas (docs/service.md, "Sharing the service"): what one API key may have in flight
and stored. A key over a quota gets 429 with ``Retry-After``, its problem naming the quota
(``quota`` in the body, and in ``detail``); the other keys are not affected.

The checks run inside the caller's write transaction, next to the insert they guard. The heavy
requests' quota is :class:`service.work.Compute`'s (in the API process, per key).
"""

from __future__ import annotations

from sqlalchemy.orm import Session

from service import store
from service.config import Settings
from service.work import busy

#: Retry-After (s) of each quota: jobs and simulations end in minutes, storage is freed by DELETE
RETRY_JOBS_S, RETRY_SIMULATIONS_S, RETRY_STORAGE_S = 30, 30, 3600

MB = 1024 * 1024


def check_jobs(session: Session, settings: Settings, *, owner: str, new: int) -> None:
    """429 ``jobs`` when ``new`` more jobs would put the key past its jobs queued or running."""
    n = store.active_jobs(session, owner=owner)
    if n + new > settings.quota_jobs:
        raise busy(f"quota jobs: this API key has {n} jobs queued or running and asks for {new} more; the limit is "
                   f"{settings.quota_jobs} (a library's cells count); retry when some have ended, or cancel some",
                   "jobs", RETRY_JOBS_S)
    check_storage(session, settings, owner=owner)


def check_simulations(session: Session, settings: Settings, *, owner: str) -> None:
    """429 ``simulations`` when the key has its limit of simulations queued or running."""
    n = store.active_jobs(session, owner=owner, kind="simulation")
    if n >= settings.quota_simulations:
        raise busy(f"quota simulations: this API key has {n} simulations queued or running, the limit is "
                   f"{settings.quota_simulations}; retry when one has ended", "simulations", RETRY_SIMULATIONS_S)
    check_jobs(session, settings, owner=owner, new=1)


def check_storage(session: Session, settings: Settings, *, owner: str, adding: int = 0) -> None:
    """429 ``storage`` when the key stores (or would store, ``adding`` bytes more) more than its
    limit: new work is refused until it deletes motions, jobs, libraries or simulations."""
    used = store.storage_bytes(session, owner=owner)
    if used + adding > settings.quota_storage_mb * MB:
        raise busy(f"quota storage: this API key stores {used / MB:.1f} MB"
                   + (f" and this would add {adding / MB:.1f} MB" if adding else "")
                   + f"; the limit is {settings.quota_storage_mb:g} MB: delete motions, jobs, libraries or "
                   "simulations to make room", "storage", RETRY_STORAGE_S)


def usage(session: Session, settings: Settings, *, owner: str) -> dict:
    """The key's usage next to its quotas (GET /usage)."""
    return {
        "storage_bytes": store.storage_bytes(session, owner=owner),
        "storage_limit_bytes": int(settings.quota_storage_mb * MB),
        "jobs_in_flight": store.active_jobs(session, owner=owner),
        "jobs_limit": settings.quota_jobs,
        "simulations_in_flight": store.active_jobs(session, owner=owner, kind="simulation"),
        "simulations_limit": settings.quota_simulations,
        "heavy_requests_limit": settings.quota_heavy_requests,
    }
