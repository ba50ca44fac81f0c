"""Jobs: created once per idempotency key, dispatched in per-key turns, canceled cooperatively,
run one attempt at a time under a lease (claim, renewal, fencing), their progress points, their
outcome, and the jobs nobody will run unless dispatched again."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from sqlalchemy import Select, delete, false, func, or_, select, update
from sqlalchemy.orm import Session

from service.models import TERMINAL, IdempotencyRow, JobRow, MotionRow, ProgressRow
from service.store.sql import insert_for, new_id, now


class IdempotencyConflict(Exception):
    """The Idempotency-Key was used before with a different request."""


def find_idempotent(session: Session, *, owner: str, key: str, request_hash: str) -> JobRow | None:
    row = session.get(IdempotencyRow, (owner, key))
    if row is None:
        return None
    if row.request_hash != request_hash:
        raise IdempotencyConflict(key)
    return session.get(JobRow, row.job_id)


def create_job(
    session: Session,
    *,
    owner: str,
    motion_id: str,
    spec: dict,
    runner: str,
    max_attempts: int,
    idempotency_key: str | None = None,
    request_hash: str = "",
    kind: str = "extrapolate",
    created_at: float | None = None,
) -> JobRow:
    """Insert a queued job (and its idempotency record). A concurrent duplicate key makes
    the commit fail with IntegrityError; the caller then reads the winner."""
    t = now() if created_at is None else created_at
    job = JobRow(
        id=new_id("j"), owner=owner, motion_id=motion_id, kind=kind, spec=spec, status="queued", message="",
        lam_reached=0.0, steps=0, solves=0, attempts=0, max_attempts=max_attempts, cancel_requested=False,
        runner=runner, created_at=t, updated_at=t,
    )
    session.add(job)
    session.flush()
    if idempotency_key is not None:
        session.add(IdempotencyRow(owner=owner, key=idempotency_key, request_hash=request_hash, job_id=job.id,
                                   created_at=t))
        session.flush()
    return job


def get_job(session: Session, *, job_id: str, owner: str | None) -> JobRow | None:
    row = session.get(JobRow, job_id)
    if row is None or (owner is not None and row.owner != owner):
        return None
    return row


def list_jobs(session: Session, *, owner: str, offset: int = 0, limit: int = 50) -> tuple[list[JobRow], int]:
    """The owner's extrapolation jobs (a simulation's job is listed with its motion's simulation)."""
    q = select(JobRow).where(JobRow.owner == owner, JobRow.kind == "extrapolate")
    total = session.scalar(select(func.count()).select_from(q.subquery())) or 0
    rows = list(session.scalars(q.order_by(JobRow.created_at, JobRow.id).offset(offset).limit(limit)))
    return rows, total


def mark_dispatched(session: Session, *, job_id: str) -> None:
    session.execute(update(JobRow).where(JobRow.id == job_id).values(dispatched_at=now()))


def undo_dispatch(session: Session, *, job_ids: Sequence[str]) -> None:
    """Forget the dispatch of queued jobs that did not reach a runner (the broker was down): the
    next :func:`dispatch_fair` takes them again."""
    if job_ids:
        session.execute(update(JobRow).where(JobRow.id.in_(list(job_ids)), JobRow.status == "queued")
                        .values(dispatched_at=None))


def forget_dispatches(session: Session, *, runner: str) -> int:
    """Queued jobs of ``runner`` count as never dispatched (the LocalRunner on start: its previous
    process's queue is gone)."""
    r = session.execute(update(JobRow).where(JobRow.runner == runner, JobRow.status == "queued",
                                             JobRow.dispatched_at.is_not(None)).values(dispatched_at=None))
    return r.rowcount or 0


def dispatch_fair(session: Session, *, runner: str, per_key: int, limit: int = 1000) -> list[str]:
    """The queued jobs of ``runner`` to dispatch now, marked dispatched (in the caller's write
    transaction): of each key, its oldest never-dispatched jobs while it has fewer than
    ``per_key`` jobs running or dispatched. So one key's many jobs wait in SQL, not in the
    broker's queue ahead of other keys' jobs; the rest are dispatched as its jobs end."""
    active = dict(session.execute(
        select(JobRow.owner, func.count()).where(
            JobRow.runner == runner,
            (JobRow.status == "running") | ((JobRow.status == "queued") & JobRow.dispatched_at.is_not(None)))
        .group_by(JobRow.owner)).all())
    waiting = session.execute(
        select(JobRow.id, JobRow.owner).where(JobRow.runner == runner, JobRow.status == "queued",
                                              JobRow.dispatched_at.is_(None))
        .order_by(JobRow.created_at, JobRow.id).limit(limit)).all()
    out = []
    for job_id, owner in waiting:
        if active.get(owner, 0) < per_key:
            active[owner] = active.get(owner, 0) + 1
            out.append(job_id)
    if out:
        session.execute(update(JobRow).where(JobRow.id.in_(out)).values(dispatched_at=now()))
    return out


def request_cancel(session: Session, *, job_id: str) -> JobRow | None:
    """Cooperative cancel: a queued job is canceled at once, a running one is flagged
    (the job checks the flag between λ steps). Terminal jobs are left as they are."""
    job = session.scalar(select(JobRow).where(JobRow.id == job_id).with_for_update())
    if job is None or job.status in TERMINAL:
        return job
    t = now()
    job.cancel_requested = True
    job.updated_at = t
    if job.status == "queued":
        job.status, job.finished_at, job.message = "canceled", t, "canceled before it started"
    return job


Outcome = Literal["claimed", "terminal", "busy", "exhausted", "missing"]


@dataclass(frozen=True)
class Claim:
    outcome: Outcome
    attempt: int = 0
    lease_owner: str | None = None


def claim_job(
    session: Session,
    *,
    job_id: str,
    token: str,
    lease_s: float,
    holder_alive: Callable[[str], bool] = lambda _token: True,
) -> Claim:
    """Take the job for one attempt (run inside ``Database.write()``).

    - terminal (succeeded/failed/canceled/impasse): nothing to do (a redelivered message);
    - running under a live lease held by someone else: ``busy`` (a duplicate delivery);
    - attempts used up: the job is marked failed (``exhausted``);
    - otherwise the attempt counter goes up and the lease is ours (``claimed``).
    """
    job = session.scalar(select(JobRow).where(JobRow.id == job_id).with_for_update())
    if job is None:
        return Claim("missing")
    if job.status in TERMINAL:
        return Claim("terminal")
    t = now()
    if (
        job.status == "running"
        and job.lease_owner not in (None, token)
        and (job.lease_until or 0) > t
        and holder_alive(job.lease_owner)
    ):
        return Claim("busy", lease_owner=job.lease_owner)
    if job.cancel_requested:
        job.status, job.finished_at, job.updated_at = "canceled", t, t
        job.message = job.message or "canceled"
        return Claim("terminal")
    if job.attempts >= job.max_attempts:
        job.status, job.finished_at, job.updated_at = "failed", t, t
        job.message = f"gave up after {job.attempts} attempts (the job's process stopped each time)"
        job.lease_owner = None
        return Claim("exhausted")
    job.attempts += 1
    job.status = "running"
    job.lease_owner = token
    job.lease_until = t + lease_s
    job.started_at = job.started_at or t
    job.updated_at = t
    return Claim("claimed", attempt=job.attempts)


@dataclass(frozen=True)
class Lease:
    held: bool
    cancel_requested: bool


def renew_lease(session: Session, *, job_id: str, token: str, lease_s: float) -> Lease:
    """Extend our lease; tells whether we still hold it and whether a cancel was requested."""
    t = now()
    r = session.execute(
        update(JobRow)
        .where(JobRow.id == job_id, JobRow.lease_owner == token, JobRow.status == "running")
        .values(lease_until=t + lease_s, updated_at=t)
    )
    cancel = bool(session.scalar(select(JobRow.cancel_requested).where(JobRow.id == job_id)))
    return Lease(held=r.rowcount == 1, cancel_requested=cancel)


def set_tutor(session: Session, *, job_id: str, token: str, tutor_motion_id: str) -> None:
    session.execute(
        update(JobRow).where(JobRow.id == job_id, JobRow.lease_owner == token)
        .values(tutor_motion_id=tutor_motion_id, updated_at=now())
    )


def append_progress(
    session: Session,
    *,
    job_id: str,
    attempt: int,
    seq: int,
    phase: str,
    wall_time: float,
    lam: float,
    lam_reached: float,
    environment: dict,
    iterations: int,
    accepted: bool,
    status: str,
    solves: int | None = None,
) -> None:
    stmt = insert_for(session, ProgressRow).values(
        job_id=job_id, attempt=attempt, seq=seq, phase=phase, wall_time=float(wall_time), lam=float(lam),
        lam_reached=float(lam_reached), environment=environment, iterations=int(iterations), accepted=bool(accepted),
        status=str(status)[:200], at=now(),
    ).on_conflict_do_nothing()
    session.execute(stmt)
    session.execute(
        update(JobRow).where(JobRow.id == job_id, JobRow.attempts == attempt)
        .values(lam_reached=float(lam_reached), solves=JobRow.solves if solves is None else solves, updated_at=now())
    )


def progress(session: Session, *, job_id: str, attempt: int | None = None, after_seq: int = -1) -> list[ProgressRow]:
    """Progress points of one attempt (default: the job's latest)."""
    if attempt is None:
        attempt = session.scalar(select(JobRow.attempts).where(JobRow.id == job_id)) or 0
    q = (
        select(ProgressRow)
        .where(ProgressRow.job_id == job_id, ProgressRow.attempt == attempt, ProgressRow.seq > after_seq)
        .order_by(ProgressRow.seq)
    )
    return list(session.scalars(q))


def finish_job(
    session: Session,
    *,
    job_id: str,
    token: str,
    status: str,
    message: str = "",
    lam_reached: float | None = None,
    steps: int | None = None,
    solves: int | None = None,
) -> bool:
    """Record the outcome of our attempt — only if we still hold the lease (fencing).

    ``steps``: the number of λ optima this attempt produced; rows of a previous attempt
    beyond it are removed, so the job's motions are exactly this attempt's.
    """
    if status not in TERMINAL:
        raise ValueError(f"not a terminal status: {status!r}")
    t = now()
    values: dict[str, Any] = dict(status=status, message=message[:4000], finished_at=t, updated_at=t,
                                  lease_until=None)
    if lam_reached is not None:
        values["lam_reached"] = float(lam_reached)
    if steps is not None:
        values["steps"] = steps
    if solves is not None:
        values["solves"] = solves
    r = session.execute(
        update(JobRow).where(JobRow.id == job_id, JobRow.lease_owner == token, JobRow.status == "running")
        .values(**values)
    )
    if r.rowcount != 1:
        return False
    if steps is not None:
        session.execute(delete(MotionRow).where(MotionRow.job_id == job_id, MotionRow.step >= steps))
    return True


def fail_unfinished(session: Session, *, job_id: str, message: str) -> bool:
    """Mark a job failed unless it already ended (a runner's last word on a job whose
    process it had to kill)."""
    t = now()
    r = session.execute(
        update(JobRow).where(JobRow.id == job_id, JobRow.status.in_(("queued", "running")))
        .values(status="failed", message=message[:4000], finished_at=t, updated_at=t, lease_until=None)
    )
    return r.rowcount == 1


def stranded_jobs(
    session: Session, *, runner: str, queued_after: float, running_after: float, limit: int = 100,
    redispatch_gap: float = 0.0, dispatched_only: bool = False,
) -> list[str]:
    """Jobs nobody will run unless dispatched again: queued and never dispatched (or
    dispatched longer ago than ``queued_after`` s), or running with a lease expired for
    longer than ``running_after`` s (its process died: a broker would only redeliver it after
    its visibility timeout). Once re-dispatched for an expired lease (dispatched after the lease
    ended), a running job is not dispatched again within ``redispatch_gap`` s (one new delivery
    at a time, while it waits for a free worker). ``dispatched_only``: queued jobs never
    dispatched are left to :func:`dispatch_fair`."""
    t = now()
    never = JobRow.dispatched_at.is_(None) if not dispatched_only else false()
    q: Select = (
        select(JobRow.id)
        .where(
            JobRow.runner == runner,
            or_(
                (JobRow.status == "queued") & (never | (JobRow.dispatched_at < t - queued_after)),
                (JobRow.status == "running") & (JobRow.lease_until < t - running_after)
                & (JobRow.dispatched_at.is_(None) | (JobRow.dispatched_at < JobRow.lease_until)
                   | (JobRow.dispatched_at < t - redispatch_gap)),
            ),
        )
        .order_by(JobRow.created_at)
        .limit(limit)
    )
    return list(session.scalars(q))
