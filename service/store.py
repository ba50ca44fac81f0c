"""The durable store: free functions over a SQLAlchemy session (keyword-only arguments).

Everything a job produces lives here, in SQL: jobs (status, attempts, lease), progress
points keyed by (job, attempt, seq), motions keyed by id — a job's λ optima also by
(job, step), so a re-run upserts instead of duplicating; a capture's tutor by (capture, tutor
key), made by one job at a time (:func:`claim_tutor`).

Callers own the transaction (``Database.write()`` / ``Database.read()``).
"""

from __future__ import annotations

import hashlib
import json
import secrets
import time
import uuid
import zlib
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any, Literal

from sqlalchemy import Select, delete, false, func, or_, select, update
from sqlalchemy.orm import Session

from service.models import (
    TERMINAL,
    ApiKey,
    IdempotencyRow,
    JobRow,
    LibraryRow,
    MotionRow,
    ProgressRow,
    SimulationFileRow,
    SimulationRow,
    TutorClaimRow,
)
from service.simulation_files import FILES
from solver.motion import Motion


def new_id(prefix: str) -> str:
    return f"{prefix}_{uuid.uuid4().hex}"


def now() -> float:
    return time.time()


def insert_for(session: Session, table):
    """The dialect's INSERT construct (both have ``on_conflict_do_update/nothing``)."""
    if session.get_bind().dialect.name == "postgresql":
        from sqlalchemy.dialects.postgresql import insert  # the dialect's own upsert
    else:
        from sqlalchemy.dialects.sqlite import insert  # the dialect's own upsert
    return insert(table)


# --- API keys ---------------------------------------------------------------------------


def hash_key(key: str) -> str:
    return hashlib.sha256(key.encode("utf-8")).hexdigest()


def static_owner(key: str) -> str:
    """Owner id of a key given in the settings (stable across restarts)."""
    return "s_" + hash_key(key)[:32]


def create_api_key(session: Session, *, name: str = "") -> tuple[str, str]:
    """A new API key: returns (owner id, the key). Only its hash is stored."""
    key = "mx_" + secrets.token_urlsafe(32)
    kid = new_id("k")
    session.add(ApiKey(id=kid, name=name, key_hash=hash_key(key), created_at=now()))
    return kid, key


def count_api_keys(session: Session) -> int:
    return session.scalar(select(func.count()).select_from(ApiKey).where(ApiKey.revoked_at.is_(None))) or 0


def revoke_api_key(session: Session, *, key_id: str) -> bool:
    r = session.execute(update(ApiKey).where(ApiKey.id == key_id, ApiKey.revoked_at.is_(None)).values(revoked_at=now()))
    return r.rowcount == 1


def owner_for_key(session: Session, *, key: str, static_keys: Sequence[str] = ()) -> str | None:
    for k in static_keys:
        if secrets.compare_digest(k.encode(), key.encode()):
            return static_owner(k)
    row = session.scalar(select(ApiKey).where(ApiKey.key_hash == hash_key(key), ApiKey.revoked_at.is_(None)))
    return row.id if row else None


# --- motions ----------------------------------------------------------------------------


def encode_motion(motion: Motion) -> tuple[bytes, str]:
    text = motion.to_json().encode("utf-8")
    return zlib.compress(text, 6), hashlib.sha256(text).hexdigest()


def motion_json(row: MotionRow) -> bytes:
    """The stored motion file v2 (JSON bytes)."""
    return zlib.decompress(row.data)


def load_motion(row: MotionRow) -> Motion:
    return Motion.from_dict(json.loads(motion_json(row)))


def _motion_fields(motion: Motion) -> dict[str, Any]:
    data, digest = encode_motion(motion)
    return dict(
        character=motion.reference_name or motion.character.name,
        n=motion.n,
        frames=motion.T,
        fps=float(motion.fps),
        has_wrenches=motion.wrenches is not None,
        data=data,
        sha256=digest,
        size=len(data),
    )


def add_motion(
    session: Session, *, owner: str, motion: Motion, kind: str, name: str = "", parent_id: str | None = None
) -> MotionRow:
    row = MotionRow(
        id=new_id("m"), owner=owner, kind=kind, name=name, parent_id=parent_id, created_at=now(),
        **_motion_fields(motion),
    )
    session.add(row)
    session.flush()
    return row


def add_encoded(session: Session, *, owner: str, encoded: Any, name: str = "") -> MotionRow:
    """Store a motion validated and encoded elsewhere (``service.uploads.Encoded``: the API's
    compute processes do that work, the API only inserts the row)."""
    row = MotionRow(
        id=new_id("m"), owner=owner, kind=encoded.kind, name=name, parent_id=None, created_at=now(),
        character=encoded.character, n=encoded.n, frames=encoded.frames, fps=encoded.fps,
        has_wrenches=encoded.has_wrenches, data=encoded.data, sha256=encoded.sha256, size=len(encoded.data),
    )
    session.add(row)
    session.flush()
    return row


def get_motion(session: Session, *, motion_id: str, owner: str | None, lock: bool = False) -> MotionRow | None:
    """The motion, if it exists and belongs to ``owner`` (None = any owner: internal use);
    ``lock``: its row locked for the transaction (``FOR UPDATE`` on PostgreSQL)."""
    row = session.get(MotionRow, motion_id, with_for_update=lock or None)
    if row is None or (owner is not None and row.owner != owner):
        return None
    return row


def get_or_add_tutor(
    session: Session, *, owner: str, parent_id: str, tutor_key: str, motion: Motion | None = None
) -> MotionRow | None:
    """The tutor of motion ``parent_id`` for ``tutor_key`` (character@fps); stored once.

    With ``motion`` None it only looks it up (:func:`find_tutor`).
    """
    row = find_tutor(session, parent_id=parent_id, tutor_key=tutor_key)
    if row is not None or motion is None:
        return row
    values = dict(
        id=new_id("m"), owner=owner, kind="tutor", name="", parent_id=parent_id, tutor_key=tutor_key,
        created_at=now(), **_motion_fields(motion),
    )
    session.execute(insert_for(session, MotionRow).values(**values).on_conflict_do_nothing())
    return find_tutor(session, parent_id=parent_id, tutor_key=tutor_key)


def find_tutor(session: Session, *, parent_id: str, tutor_key: str) -> MotionRow | None:
    """The stored tutor of motion ``parent_id`` for ``tutor_key``, if there is one."""
    return session.scalar(select(MotionRow).where(MotionRow.parent_id == parent_id, MotionRow.tutor_key == tutor_key))


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


def save_step(
    session: Session,
    *,
    job_id: str,
    owner: str,
    step: int,
    lam: float,
    motion: Motion,
    validation: dict | None = None,
) -> str:
    """Upsert the λ optimum ``step`` of ``job_id``; returns its motion id (stable across re-runs)."""
    fields = _motion_fields(motion)
    plausible = None if validation is None else bool(validation.get("plausible"))
    values = dict(
        id=new_id("m"), owner=owner, kind="step", name="", job_id=job_id, step=step, lam=float(lam),
        created_at=now(), validation=validation, plausible=plausible, **fields,
    )
    stmt = insert_for(session, MotionRow).values(**values)
    stmt = stmt.on_conflict_do_update(
        index_elements=[MotionRow.job_id, MotionRow.step],
        set_=dict(lam=stmt.excluded.lam, validation=stmt.excluded.validation, plausible=stmt.excluded.plausible,
                  **{k: getattr(stmt.excluded, k) for k in fields}),
    )
    session.execute(stmt)
    mid = session.scalar(select(MotionRow.id).where(MotionRow.job_id == job_id, MotionRow.step == step))
    session.execute(
        update(JobRow).where(JobRow.id == job_id).values(
            steps=func.max(JobRow.steps, step + 1) if session.get_bind().dialect.name == "sqlite"
            else func.greatest(JobRow.steps, step + 1),
            updated_at=now(),
        )
    )
    return mid


def set_validation(session: Session, *, motion_id: str, report: dict) -> None:
    session.execute(
        update(MotionRow).where(MotionRow.id == motion_id)
        .values(validation=report, plausible=bool(report.get("plausible")))
    )


def job_motions(
    session: Session, *, job_id: str, after_step: int = -1, limit: int = 50
) -> list[MotionRow]:
    q = (
        select(MotionRow)
        .where(MotionRow.job_id == job_id, MotionRow.step > after_step)
        .order_by(MotionRow.step)
        .limit(limit)
    )
    return list(session.scalars(q))


def count_job_motions(session: Session, *, job_id: str) -> int:
    return session.scalar(select(func.count()).select_from(MotionRow).where(MotionRow.job_id == job_id)) or 0


def list_motions(session: Session, *, owner: str, offset: int = 0, limit: int = 50) -> tuple[list[MotionRow], int]:
    q = select(MotionRow).where(MotionRow.owner == owner)
    total = session.scalar(select(func.count()).select_from(q.subquery())) or 0
    rows = list(session.scalars(q.order_by(MotionRow.created_at, MotionRow.id).offset(offset).limit(limit)))
    return rows, total


# --- jobs -------------------------------------------------------------------------------


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


# --- per-key usage (quotas) ------------------------------------------------------------------

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


# --- deletion -------------------------------------------------------------------------------


@dataclass
class Deletion:
    """What goes with a resource: motions, jobs, libraries and simulations (ids)."""

    motions: set[str]
    jobs: set[str]
    libraries: set[str]
    simulations: set[str]

    def active_jobs(self, session: Session) -> list[str]:
        if not self.jobs:
            return []
        return list(session.scalars(select(JobRow.id).where(JobRow.id.in_(list(self.jobs)),
                                                            JobRow.status.in_(ACTIVE)).limit(5)))


def _ids(session: Session, q) -> set[str]:
    return set(session.scalars(q))


def deletion(session: Session, *, motions: Sequence[str] = (), jobs: Sequence[str] = (),
             libraries: Sequence[str] = ()) -> Deletion:
    """Everything that hangs on these motions, jobs and libraries: a motion's tutors, the jobs
    started from a motion (or using it as their tutor) and their λ optima, the libraries of a
    motion and their cells, and the simulations of any of them — to the end of the chain."""
    d = Deletion(set(motions), set(jobs), set(libraries), set())
    while True:
        before = (len(d.motions), len(d.jobs), len(d.libraries))
        for lib in session.scalars(select(LibraryRow).where(
                LibraryRow.id.in_(list(d.libraries)) | LibraryRow.motion_id.in_(list(d.motions)))):
            d.libraries.add(lib.id)
            d.jobs |= {c["job_id"] for c in (lib.spec or {}).get("cells", [])}
        m = list(d.motions)
        d.motions |= _ids(session, select(MotionRow.id).where(MotionRow.parent_id.in_(m)))
        d.jobs |= _ids(session, select(JobRow.id).where(JobRow.motion_id.in_(m) | JobRow.tutor_motion_id.in_(m)))
        d.motions |= _ids(session, select(MotionRow.id).where(MotionRow.job_id.in_(list(d.jobs))))
        if (len(d.motions), len(d.jobs), len(d.libraries)) == before:
            break
    d.simulations = _ids(session, select(SimulationRow.id).where(
        SimulationRow.motion_id.in_(list(d.motions)) | SimulationRow.job_id.in_(list(d.jobs))))
    return d


def delete_all(session: Session, d: Deletion) -> None:
    """Delete what :func:`deletion` found (in the caller's write transaction)."""
    sims, jobs, motions = list(d.simulations), list(d.jobs), list(d.motions)
    delete_simulations(session, simulation_ids=sims)
    if jobs:
        session.execute(delete(ProgressRow).where(ProgressRow.job_id.in_(jobs)))
        session.execute(delete(IdempotencyRow).where(IdempotencyRow.job_id.in_(jobs)))
    if motions:
        session.execute(delete(TutorClaimRow).where(TutorClaimRow.parent_id.in_(motions)))
        session.execute(delete(MotionRow).where(MotionRow.id.in_(motions)))
    if jobs:
        session.execute(delete(MotionRow).where(MotionRow.job_id.in_(jobs)))
        session.execute(delete(JobRow).where(JobRow.id.in_(jobs)))
    if d.libraries:
        session.execute(delete(LibraryRow).where(LibraryRow.id.in_(list(d.libraries))))


def delete_simulations(session: Session, *, simulation_ids: Sequence[str]) -> None:
    if simulation_ids:
        ids = list(simulation_ids)
        session.execute(delete(SimulationFileRow).where(SimulationFileRow.simulation_id.in_(ids)))
        session.execute(delete(SimulationRow).where(SimulationRow.id.in_(ids)))


def motion_simulations(session: Session, *, motion_id: str) -> list[SimulationRow]:
    return list(session.scalars(select(SimulationRow).where(SimulationRow.motion_id == motion_id)))


def blob_size(session: Session, column, key_column, key) -> int | None:
    """The length of one stored blob (``column`` of the row whose ``key_column`` is ``key``)."""
    return session.scalar(select(func.length(column)).where(key_column == key))


def blob_chunk(session: Session, column, where, offset: int, size: int) -> bytes:
    """``size`` bytes of a stored blob from ``offset``, read in SQL (``substr``: SQLite and
    PostgreSQL alike), so a download never holds the whole blob in the API's memory."""
    out = session.scalar(select(func.substr(column, offset + 1, size)).where(*where))
    return bytes(out or b"")


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


# --- libraries ------------------------------------------------------------------------------


def create_library(
    session: Session, *, owner: str, motion_id: str, spec: dict, cells: Sequence[tuple[str, dict, dict]],
    runner: str, max_attempts: int, dispatch: Sequence[str] = (),
) -> tuple[LibraryRow, list[str]]:
    """Insert a library and its cell jobs (one queued job per (key, parameters, job spec)), in
    the caller's transaction: all of them or none. Returns the row and the job ids in the
    order given. The jobs are created (and so dispatched) in the order of the keys in
    ``dispatch`` (default: as given)."""
    lid = new_id("l")
    t = now()
    turn = {key: i for i, key in enumerate(dispatch)}
    by_key: dict[str, str] = {}
    for key, _, job_spec in sorted(cells, key=lambda c: turn.get(c[0], len(turn))):
        job = create_job(session, owner=owner, motion_id=motion_id,
                         spec={**job_spec, "library": {"id": lid, "cell": key}}, runner=runner,
                         max_attempts=max_attempts, created_at=t + 1e-6 * len(by_key))
        by_key[key] = job.id
    listed = [{"key": key, "parameters": params, "job_id": by_key[key]} for key, params, _ in cells]
    ids = [by_key[key] for key, _, _ in cells]
    row = LibraryRow(id=lid, owner=owner, motion_id=motion_id, spec={**spec, "cells": listed},
                     cancel_requested=False, created_at=t)
    session.add(row)
    session.flush()
    return row, ids


def get_library(session: Session, *, library_id: str, owner: str | None) -> LibraryRow | None:
    row = session.get(LibraryRow, library_id)
    if row is None or (owner is not None and row.owner != owner):
        return None
    return row


def list_libraries(session: Session, *, owner: str, offset: int = 0, limit: int = 50) -> tuple[list[LibraryRow], int]:
    q = select(LibraryRow).where(LibraryRow.owner == owner)
    total = session.scalar(select(func.count()).select_from(q.subquery())) or 0
    rows = list(session.scalars(q.order_by(LibraryRow.created_at, LibraryRow.id).offset(offset).limit(limit)))
    return rows, total


def library_jobs(session: Session, *, library: LibraryRow) -> dict[str, JobRow]:
    """The library's cell jobs by job id."""
    ids = [c["job_id"] for c in library.spec.get("cells", [])]
    return {j.id: j for j in session.scalars(select(JobRow).where(JobRow.id.in_(ids)))} if ids else {}


def stored_optima(session: Session, *, job_ids: Sequence[str]) -> list[tuple[str, int, float, bool | None, str]]:
    """(job id, step, λ, plausible, motion id) of every stored λ optimum of these jobs (no motion data)."""
    if not job_ids:
        return []
    q = select(MotionRow.job_id, MotionRow.step, MotionRow.lam, MotionRow.plausible, MotionRow.id).where(
        MotionRow.job_id.in_(list(job_ids)))
    return [(j, int(st), float(lam), p, mid) for j, st, lam, p, mid in session.execute(q)]


def step_row(session: Session, *, job_id: str, step: int) -> MotionRow | None:
    return session.scalar(select(MotionRow).where(MotionRow.job_id == job_id, MotionRow.step == step))


def request_library_cancel(session: Session, *, library: LibraryRow) -> None:
    """Cancel every cell that has not finished (queued ones at once, running ones cooperatively)."""
    library.cancel_requested = True
    for c in library.spec.get("cells", []):
        request_cancel(session, job_id=c["job_id"])


# --- simulations ----------------------------------------------------------------------------


def create_simulation(session: Session, *, owner: str, motion_id: str, job_id: str, cycles: int) -> SimulationRow:
    row = SimulationRow(id=new_id("s"), owner=owner, motion_id=motion_id, job_id=job_id, cycles=cycles,
                        status="queued", message="", report=None, created_at=now())
    session.add(row)
    session.flush()
    return row


def get_simulation(session: Session, *, simulation_id: str, owner: str | None) -> SimulationRow | None:
    row = session.get(SimulationRow, simulation_id)
    if row is None or (owner is not None and row.owner != owner):
        return None
    return row


def latest_simulation(session: Session, *, motion_id: str, owner: str | None) -> SimulationRow | None:
    """The motion's most recent simulation (None: never simulated)."""
    q = select(SimulationRow).where(SimulationRow.motion_id == motion_id)
    if owner is not None:
        q = q.where(SimulationRow.owner == owner)
    return session.scalar(q.order_by(SimulationRow.created_at.desc(), SimulationRow.id.desc()).limit(1))


def job_simulation(session: Session, *, job_id: str) -> SimulationRow | None:
    """The simulation a job runs or ran (a simulation job's, or an extrapolation job's final motion's)."""
    return session.scalar(select(SimulationRow).where(SimulationRow.job_id == job_id)
                          .order_by(SimulationRow.created_at.desc()).limit(1))


def simulation_state(session: Session, *, simulation: SimulationRow) -> tuple[str, str]:
    """(status, message) of a simulation: its own, unless it never finished and its job did (the
    job's process died for good, was canceled or ran out of time): then the job's end."""
    if simulation.status in ("succeeded", "failed"):
        return simulation.status, simulation.message
    job = session.get(JobRow, simulation.job_id)
    if job is not None and job.status in TERMINAL and (job.kind == "simulation" or job.status != "succeeded"):
        status = "failed" if job.status != "canceled" else "canceled"
        return status, job.message or f"its job ended ({job.status}) before the simulation did"
    return simulation.status, simulation.message


def set_simulation_status(session: Session, *, simulation_id: str, status: str, message: str = "") -> None:
    t = now()
    values: dict[str, Any] = dict(status=status, message=message[:4000])
    if status == "running":
        values["started_at"] = t
    else:
        values["finished_at"] = t
    session.execute(update(SimulationRow).where(SimulationRow.id == simulation_id).values(**values))


def finish_simulation(session: Session, *, simulation_id: str, report: dict, files: dict[str, bytes],
                      message: str) -> None:
    """Store a simulation's report and files (replacing an earlier attempt's) and mark it succeeded."""
    session.execute(delete(SimulationFileRow).where(SimulationFileRow.simulation_id == simulation_id))
    sim = session.get(SimulationRow, simulation_id)
    if sim is not None:  # the motion's earlier simulations are superseded: their files go (the rows stay)
        older = select(SimulationRow.id).where(SimulationRow.motion_id == sim.motion_id,
                                               SimulationRow.id != simulation_id,
                                               SimulationRow.created_at <= sim.created_at)
        session.execute(delete(SimulationFileRow).where(SimulationFileRow.simulation_id.in_(older)))
    for name, data in files.items():
        session.add(SimulationFileRow(simulation_id=simulation_id, name=name, media_type=FILES[name], size=len(data),
                                      data=data))
    session.execute(update(SimulationRow).where(SimulationRow.id == simulation_id)
                    .values(status="succeeded", message=message[:4000], report=report, finished_at=now()))


def simulation_files(session: Session, *, simulation_id: str) -> dict[str, int]:
    """The names and sizes of a simulation's stored files."""
    q = select(SimulationFileRow.name, SimulationFileRow.size).where(SimulationFileRow.simulation_id == simulation_id)
    return {n: int(sz) for n, sz in session.execute(q)}


def simulation_file(session: Session, *, simulation_id: str, name: str) -> SimulationFileRow | None:
    return session.get(SimulationFileRow, (simulation_id, name))
