"""Simulations of a motion: their rows and status, their stored files (a motion's earlier
simulations lose theirs when a new one succeeds), and their deletion."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sqlalchemy import delete, select, update
from sqlalchemy.orm import Session

from service.models import TERMINAL, JobRow, SimulationFileRow, SimulationRow
from service.simulation_files import FILES
from service.store.sql import new_id, now


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


def delete_simulations(session: Session, *, simulation_ids: Sequence[str]) -> None:
    if simulation_ids:
        ids = list(simulation_ids)
        session.execute(delete(SimulationFileRow).where(SimulationFileRow.simulation_id.in_(ids)))
        session.execute(delete(SimulationRow).where(SimulationRow.id.in_(ids)))


def motion_simulations(session: Session, *, motion_id: str) -> list[SimulationRow]:
    return list(session.scalars(select(SimulationRow).where(SimulationRow.motion_id == motion_id)))
