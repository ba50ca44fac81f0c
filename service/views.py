"""Rendering store rows as API responses (plain dicts matching service.schemas)."""

from __future__ import annotations

from datetime import UTC, datetime

from service.models import JobRow, MotionRow, ProgressRow


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
    }
    if row.job_id:
        links["job"] = f"/jobs/{row.job_id}"
    if row.parent_id:
        links["parent"] = f"/motions/{row.parent_id}"
    return dict(
        id=row.id, kind=row.kind, name=row.name, character=row.character, coordinates=row.n, frames=row.frames,
        fps=row.fps, duration_s=(row.frames - 1) / row.fps, has_wrenches=row.has_wrenches, job_id=row.job_id,
        step=row.step, lam=row.lam, parent_id=row.parent_id, plausible=row.plausible, created_at=iso(row.created_at),
        links=links,
    )


def progress_out(p: ProgressRow) -> dict:
    return dict(seq=p.seq, phase=p.phase, wall_time=p.wall_time, lam=p.lam, lam_reached=p.lam_reached,
                environment=p.environment, iterations=p.iterations, accepted=p.accepted, status=p.status)


def job_out(job: JobRow, points: list[ProgressRow]) -> dict:
    links = {
        "self": f"/jobs/{job.id}",
        "motions": f"/jobs/{job.id}/motions",
        "events": f"/jobs/{job.id}/events",
        "cancel": f"/jobs/{job.id}/cancel",
        "source": f"/motions/{job.motion_id}",
    }
    if job.tutor_motion_id:
        links["tutor"] = f"/motions/{job.tutor_motion_id}"
    spec = job.spec or {}
    return dict(
        id=job.id, status=job.status, motion_id=job.motion_id, tutor_motion_id=job.tutor_motion_id,
        target=spec.get("target", {}), control=spec.get("control", {}), lam_reached=job.lam_reached, steps=job.steps,
        solves=job.solves, attempts=job.attempts, max_attempts=job.max_attempts,
        cancel_requested=job.cancel_requested, message=job.message, runner=job.runner, created_at=iso(job.created_at),
        started_at=iso(job.started_at), finished_at=iso(job.finished_at),
        progress=[progress_out(p) for p in points], links=links,
    )
