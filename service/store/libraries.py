"""Motion libraries: a library and its cell jobs inserted together, looked up, listed and
canceled, and the λ optima its cells stored."""

from __future__ import annotations

from collections.abc import Sequence

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from service.models import JobRow, LibraryRow, MotionRow
from service.store.jobs import create_job, request_cancel
from service.store.sql import new_id, now


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
