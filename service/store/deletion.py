"""Deletion with what hangs on a resource: a motion's tutors, the jobs started from it (or using it
as their tutor) and their λ optima, its libraries and their cells, and the simulations of any of
them."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from sqlalchemy import delete, select
from sqlalchemy.orm import Session

from service.models import IdempotencyRow, JobRow, LibraryRow, MotionRow, ProgressRow, SimulationRow, TutorClaimRow
from service.store.simulations import delete_simulations
from service.store.usage import ACTIVE


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
