"""Stored motions: the motion file compressed in its row; uploads, a capture's tutors (one per
tutor key), a job's λ optima upserted by (job, step) and their validation reports, listings."""

from __future__ import annotations

import hashlib
import json
import zlib
from typing import Any

from sqlalchemy import func, select, update
from sqlalchemy.orm import Session

from service.models import JobRow, MotionRow
from service.store.sql import insert_for, new_id, now
from solver.motion import Motion


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
