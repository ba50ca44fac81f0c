"""Who makes a capture's tutor: one job at a time, however many jobs, workers and processes need
it (:func:`claim_tutor`, :func:`end_tutor_claim`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Literal

from sqlalchemy import delete, select, update
from sqlalchemy.orm import Session

from service.models import JobRow, TutorClaimRow
from service.store.motions import find_tutor
from service.store.sql import insert_for, now

TutorOutcome = Literal["ready", "make", "wait", "failed"]


@dataclass(frozen=True)
class TutorTurn:
    """What a job that needs a tutor does next (:func:`claim_tutor`).

    - ``ready``: the tutor is stored (``tutor_id``); ``maker`` is the job that made it, when known;
    - ``make``: this job makes it (the claim is its own until :func:`end_tutor_claim`);
    - ``wait``: ``maker``, a live job, is making it: ask again a little later;
    - ``failed``: ``maker`` failed to make it (``message``) after this job was created.
    """

    outcome: TutorOutcome
    tutor_id: str | None = None
    maker: str | None = None
    message: str = ""


def _tutor_made_by_live_job(session: Session, claim: TutorClaimRow, t: float,
                            holder_alive: Callable[[str], bool]) -> bool:
    """The claim's job still runs under the lease the claim was taken with."""
    job = session.get(JobRow, claim.job_id)
    return (job is not None and job.status == "running" and job.lease_owner == claim.token
            and (job.lease_until or 0.0) > t and holder_alive(claim.token))


def claim_tutor(
    session: Session,
    *,
    parent_id: str,
    tutor_key: str,
    job_id: str,
    token: str,
    job_created_at: float,
    holder_alive: Callable[[str], bool] = lambda _token: True,
) -> TutorTurn:
    """The turn of job ``job_id`` (its lease ``token``) at the tutor of capture ``parent_id`` for
    ``tutor_key``, so that a tutor is made by one job at a time however many jobs, workers and
    processes need it (run inside ``Database.write()``; see :class:`TutorTurn`).

    The claim row is locked (``SELECT … FOR UPDATE`` on PostgreSQL; SQLite's writing
    transactions are serial) before the tutor is looked up, and a new claim is an
    ``INSERT … ON CONFLICT DO NOTHING``: of concurrent jobs one inserts it and makes the tutor,
    the others wait. A claim is taken over when its job no longer holds the lease it was taken
    with (the job ended, its process died or its lease expired), or when it failed before this
    job was created (``job_created_at``): a job asked for after a failure tries again, one asked
    for before it shares it."""
    claim = session.scalar(select(TutorClaimRow).where(TutorClaimRow.parent_id == parent_id,
                                                       TutorClaimRow.tutor_key == tutor_key).with_for_update())
    row = find_tutor(session, parent_id=parent_id, tutor_key=tutor_key)
    if row is not None:
        return TutorTurn("ready", tutor_id=row.id,
                         maker=claim.job_id if claim is not None and claim.state == "made" else None)
    t = now()
    if claim is None:
        session.execute(insert_for(session, TutorClaimRow).values(
            parent_id=parent_id, tutor_key=tutor_key, job_id=job_id, token=token, state="making", message="",
            claimed_at=t, ended_at=None).on_conflict_do_nothing())
        won = session.scalar(select(TutorClaimRow.token).where(TutorClaimRow.parent_id == parent_id,
                                                               TutorClaimRow.tutor_key == tutor_key)) == token
        return TutorTurn("make") if won else TutorTurn("wait")  # another job's insert won: ask again later
    if claim.token == token:
        return TutorTurn("make")
    if claim.state == "making" and _tutor_made_by_live_job(session, claim, t, holder_alive):
        return TutorTurn("wait", maker=claim.job_id)
    if claim.state == "failed" and claim.ended_at is not None and job_created_at <= claim.ended_at:
        return TutorTurn("failed", maker=claim.job_id, message=claim.message)
    claim.job_id, claim.token, claim.state, claim.message, claim.claimed_at, claim.ended_at = (
        job_id, token, "making", "", t, None)
    return TutorTurn("make")


def end_tutor_claim(
    session: Session, *, parent_id: str, tutor_key: str, token: str,
    state: Literal["made", "failed", "released"], message: str = "",
) -> bool:
    """End our claim on a tutor: ``made`` (in the transaction that stores it), ``failed``
    (``message``: jobs created before now share the failure) or ``released`` (stopped
    without a result, e.g. canceled: the next job needing it makes it). Fenced by ``token``;
    returns whether the claim was still ours."""
    where = (TutorClaimRow.parent_id == parent_id, TutorClaimRow.tutor_key == tutor_key,
             TutorClaimRow.token == token)
    if state == "released":
        return session.execute(delete(TutorClaimRow).where(*where)).rowcount == 1
    r = session.execute(update(TutorClaimRow).where(*where).values(state=state, message=message[:4000],
                                                                   ended_at=now()))
    return r.rowcount == 1
