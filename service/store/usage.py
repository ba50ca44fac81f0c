"""What a key uses, for its quotas: its jobs queued or running, and the bytes it stores."""

from __future__ import annotations

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from service.models import JobRow, MotionRow, SimulationFileRow, SimulationRow

ACTIVE = ("queued", "running")


def active_jobs(session: Session, *, owner: str, kind: str | None = None) -> int:
    """The key's jobs queued or running (``kind``: of that kind only)."""
    q = select(func.count()).select_from(JobRow).where(JobRow.owner == owner, JobRow.status.in_(ACTIVE))
    if kind is not None:
        q = q.where(JobRow.kind == kind)
    return session.scalar(q) or 0


def storage_bytes(session: Session, *, owner: str) -> int:
    """What the key stores: its motions (compressed) and its simulations' files, bytes."""
    motions = session.scalar(select(func.coalesce(func.sum(MotionRow.size), 0)).where(MotionRow.owner == owner))
    files = session.scalar(
        select(func.coalesce(func.sum(SimulationFileRow.size), 0))
        .join(SimulationRow, SimulationRow.id == SimulationFileRow.simulation_id)
        .where(SimulationRow.owner == owner))
    return int(motions or 0) + int(files or 0)
