"""Rendering store rows as API responses (plain dicts matching service.schemas), and as
Server-Sent Events (``sse_event``)."""

from __future__ import annotations

import json
from datetime import UTC, datetime

from sse_starlette import ServerSentEvent

from service.models import TERMINAL, JobRow, MotionRow, ProgressRow, SimulationRow

#: how finely an answer reports a value: λ and the environment's values to 1e-9 (the solver's
#: arithmetic leaves e.g. 0.05 + 0.1 = 0.15000000000000002), times in seconds to the millisecond
VALUE_DECIMALS, SECONDS_DECIMALS = 9, 3


def reported(x, decimals: int = VALUE_DECIMALS):
    """``x`` as an answer shows it: a float rounded to ``decimals`` (mappings and lists element
    by element); None, integers, booleans and text as they are."""
    if isinstance(x, float):
        return round(x, decimals)
    if isinstance(x, dict):
        return {k: reported(v, decimals) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [reported(v, decimals) for v in x]
    return x


def iso(t: float | None) -> str | None:
    if t is None:
        return None
    return datetime.fromtimestamp(t, UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def motion_out(row: MotionRow) -> dict:
    links = {
        "self": f"/motions/{row.id}",
        "clip": f"/motions/{row.id}?format=json",
        "motion_file": f"/motions/{row.id}?format=motion",
        "validation": f"/motions/{row.id}/validation",
        "extrapolate": f"/motions/{row.id}/extrapolate",
        "simulation": f"/motions/{row.id}/simulation",
    }
    if row.job_id:
        links["job"] = f"/jobs/{row.job_id}"
    if row.parent_id:
        links["parent"] = f"/motions/{row.parent_id}"
    return dict(
        id=row.id, kind=row.kind, name=row.name, character=row.character, coordinates=row.n, frames=row.frames,
        fps=row.fps, duration_s=reported((row.frames - 1) / row.fps, SECONDS_DECIMALS), has_wrenches=row.has_wrenches,
        job_id=row.job_id, step=row.step, lam=reported(row.lam), parent_id=row.parent_id, plausible=row.plausible,
        created_at=iso(row.created_at), links=links,
    )


def progress_out(p: ProgressRow) -> dict:
    return dict(seq=p.seq, phase=p.phase, wall_time=reported(p.wall_time, SECONDS_DECIMALS), lam=reported(p.lam),
                lam_reached=reported(p.lam_reached), environment=reported(p.environment), iterations=p.iterations,
                accepted=p.accepted, status=p.status)


def job_out(job: JobRow, points: list[ProgressRow], simulation: SimulationRow | None = None) -> dict:
    links = {
        "self": f"/jobs/{job.id}",
        "motions": f"/jobs/{job.id}/motions",
        "events": f"/jobs/{job.id}/events",
        "cancel": f"/jobs/{job.id}/cancel",
        "source": f"/motions/{job.motion_id}",
    }
    if job.tutor_motion_id:
        links["tutor"] = f"/motions/{job.tutor_motion_id}"
    if simulation is not None:  # the job's final motion simulated (ExtrapolateIn.simulate_cycles)
        links["simulation"] = f"/motions/{simulation.motion_id}/simulation"
    spec = job.spec or {}
    return dict(
        id=job.id, status=job.status, terminal=job.status in TERMINAL, motion_id=job.motion_id,
        tutor_motion_id=job.tutor_motion_id,
        target=spec.get("target", {}), control=spec.get("control", {}), lam_reached=reported(job.lam_reached),
        steps=job.steps, solves=job.solves, attempts=job.attempts, max_attempts=job.max_attempts,
        cancel_requested=job.cancel_requested, message=job.message, runner=job.runner, created_at=iso(job.created_at),
        started_at=iso(job.started_at), finished_at=iso(job.finished_at),
        progress=[progress_out(p) for p in points], links=links,
    )


def simulation_out(sim: SimulationRow, status: str, message: str, files: dict[str, int]) -> dict:
    """A simulation (``status``/``message``: service.store.simulation_state) and its downloads."""
    base = f"/motions/{sim.motion_id}/simulation"
    links = {"self": base, "motion": f"/motions/{sim.motion_id}", "job": f"/jobs/{sim.job_id}"}
    links.update({name: f"{base}/{name}" for name in files})
    return dict(id=sim.id, motion_id=sim.motion_id, job_id=sim.job_id, cycles=sim.cycles, status=status,
                terminal=status in ("succeeded", "failed", "canceled"), message=message,
                report=sim.report if status == "succeeded" else None, files=files, created_at=iso(sim.created_at),
                started_at=iso(sim.started_at), finished_at=iso(sim.finished_at), links=links)


def sse_event(event: str, data: dict, ident: str | None = None) -> ServerSentEvent:
    """One Server-Sent Event: its name, its data as compact JSON, and its id if given."""
    return ServerSentEvent(json.dumps(data, separators=(",", ":")), event=event, id=ident)
