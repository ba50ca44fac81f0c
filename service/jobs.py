"""The one job function, run by both runners (LocalRunner's process pool, Celery workers).

``execute_job(job_id, settings)`` claims the job row (attempt counter with a cap, a lease
renewed while it runs), makes the tutor when the source is a raw capture (stored as its
own motion), runs the continuation and writes every progress record and every accepted
λ optimum to SQL as it goes (optima upserted by (job, step), so a re-run after a crash
rewrites the same rows). It never raises for a solver failure: that is a job status.
"""

from __future__ import annotations

import logging
import os
import socket
import threading
import time
import uuid
from typing import Any

from sqlalchemy.exc import DBAPIError

from service import store
from service.config import Settings
from service.db import Database, get_database

log = logging.getLogger(__name__)

#: How long a new attempt waits for a live lease held by another process before it
#: concludes that it is a duplicate delivery (multiples of the lease).
BUSY_WAIT_LEASES = 1.5


def lease_token() -> str:
    return f"{socket.gethostname()}:{os.getpid()}:{uuid.uuid4().hex[:8]}"


def holder_alive(token: str) -> bool:
    """False when the lease holder is a process of this host that no longer exists."""
    try:
        host, pid_s, _ = token.rsplit(":", 2)
        pid = int(pid_s)
    except ValueError:
        return True
    if host != socket.gethostname():
        return True
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    # a zombie (killed, not yet reaped) still answers kill(0): look at its state
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (OSError, IndexError):
        return True


class Heartbeat:
    """Renews the job's lease from a thread; tells the job to stop when the lease is lost
    or a cancel was requested (read by ``should_cancel`` between λ steps)."""

    def __init__(self, db: Database, job_id: str, token: str, lease_s: float) -> None:
        self.db, self.job_id, self.token, self.lease_s = db, job_id, token, lease_s
        self.cancel_requested = False
        self.lost = False
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, name=f"lease-{job_id}", daemon=True)

    def __enter__(self) -> Heartbeat:
        self._thread.start()
        return self

    def __exit__(self, *exc: Any) -> None:
        self._stop.set()
        self._thread.join(timeout=5)

    def beat(self) -> None:
        try:
            with self.db.write() as s:
                lease = store.renew_lease(s, job_id=self.job_id, token=self.token, lease_s=self.lease_s)
        except Exception:  # a transient DB error: the next beat retries, the lease has slack
            log.warning("job %s: lease renewal failed", self.job_id, exc_info=True)
            return
        self.lost = self.lost or not lease.held
        self.cancel_requested = lease.cancel_requested

    def _run(self) -> None:
        interval = max(0.2, min(self.lease_s / 4.0, 5.0))
        while not self._stop.wait(interval):
            self.beat()


def _claim(db: Database, job_id: str, token: str, settings: Settings) -> store.Claim:
    deadline = time.monotonic() + BUSY_WAIT_LEASES * settings.job_lease_s
    while True:
        with db.write() as s:
            claim = store.claim_job(s, job_id=job_id, token=token, lease_s=settings.job_lease_s,
                                    holder_alive=holder_alive)
        if claim.outcome != "busy" or time.monotonic() > deadline:
            return claim
        time.sleep(min(1.0, settings.job_lease_s / 4.0))


def execute_job(job_id: str, settings: Settings) -> str:
    """Run job ``job_id`` to a terminal status (or do nothing if it has one). Returns the
    outcome: the job's final status, or terminal/busy/exhausted/missing/lost."""
    db = get_database(settings.sqlalchemy_url)
    token = lease_token()
    claim = _claim(db, job_id, token, settings)
    if claim.outcome != "claimed":
        log.info("job %s: %s, nothing to do", job_id, claim.outcome)
        return claim.outcome
    log.info("job %s: attempt %d (%s)", job_id, claim.attempt, token)
    with Heartbeat(db, job_id, token, settings.job_lease_s) as hb:
        try:
            status, message, extra = _run(db, job_id, claim.attempt, token, settings, hb)
        except DBAPIError:  # the store itself is unreachable: not the job's fault, let the runner retry it
            raise
        except Exception as e:  # the job boundary: a failure becomes a status, never a crash
            log.exception("job %s failed", job_id)
            status, message, extra = "failed", f"{type(e).__name__}: {e}", {}
        if hb.lost:
            log.warning("job %s: lease lost (another attempt took over); result not recorded", job_id)
            return "lost"
        with db.write() as s:
            ok = store.finish_job(s, job_id=job_id, token=token, status=status, message=message, **extra)
    return status if ok else "lost"


def _run(db: Database, job_id: str, attempt: int, token: str, settings: Settings, hb: Heartbeat):
    from solver.continuation import StepControl, Target, extrapolate
    from solver.pipeline import jsonable

    with db.read() as s:
        job = store.get_job(s, job_id=job_id, owner=None)
        source = store.get_motion(s, motion_id=job.motion_id, owner=None)
        spec, owner = dict(job.spec), job.owner
        kind, source_id = source.kind, source.id
        motion = store.load_motion(source)

    t0 = time.monotonic()
    deadline = t0 + settings.job_time_limit_s
    seq = {"n": 0, "solves": 0}

    def record(phase: str, **kw: Any) -> None:
        if phase == "extrapolate":
            seq["solves"] += 1
        with db.write() as s:
            store.append_progress(s, job_id=job_id, attempt=attempt, seq=seq["n"], phase=phase,
                                  solves=seq["solves"], **kw)
        seq["n"] += 1

    if kind == "capture":
        tutor_opts = spec.get("tutor") or {}
        character = tutor_opts.get("character", settings.default_character)
        fps = float(tutor_opts.get("fps", settings.default_tutor_fps))
        tutor_key = f"{character}@{fps:g}"
        with db.read() as s:
            row = store.get_or_add_tutor(s, owner=owner, parent_id=source_id, tutor_key=tutor_key)
            tutor = store.load_motion(row) if row is not None else None
            tutor_id = row.id if row is not None else None
        if tutor is None:
            from solver.pipeline import make_tutor

            res = make_tutor(motion, character=character, fps=fps)
            record("tutor", wall_time=time.monotonic() - t0, lam=0.0, lam_reached=0.0, environment={},
                   iterations=_tutor_iterations(res.stats), accepted=res.status == "succeeded",
                   status=f"tutor {res.status}")
            if res.status != "succeeded" or res.motion is None:
                return "failed", f"tutor: {res.message or res.status}", {}
            with db.write() as s:
                tutor_id = store.get_or_add_tutor(s, owner=owner, parent_id=source_id, tutor_key=tutor_key,
                                                  motion=res.motion).id
            tutor = res.motion
        with db.write() as s:
            store.set_tutor(s, job_id=job_id, token=token, tutor_motion_id=tutor_id)
    else:
        tutor = motion

    target = Target(**spec["target"])
    control = StepControl(**spec.get("control", {}))

    def on_progress(rec) -> None:
        record("extrapolate", wall_time=rec.wall_time, lam=rec.lam, lam_reached=rec.lam_reached,
               environment=jsonable(dict(rec.environment)),
               iterations=rec.iterations, accepted=rec.accepted, status=rec.status)

    def on_step(step) -> None:
        validation = validation_report(step.motion) if settings.validate_steps else None
        with db.write() as s:
            store.save_step(s, job_id=job_id, owner=owner, step=step.step, lam=step.lam, motion=step.motion,
                            validation=validation)

    def should_cancel() -> bool:
        return hb.cancel_requested or hb.lost or time.monotonic() > deadline

    result = extrapolate(tutor, target, control, on_progress=on_progress, on_step=on_step,
                         should_cancel=should_cancel)
    status, message = result.status, result.message
    if status == "canceled" and not hb.cancel_requested and time.monotonic() > deadline:
        status, message = "failed", f"time limit of {settings.job_time_limit_s:g} s exceeded"
    if status not in ("succeeded", "impasse", "canceled", "failed"):
        status, message = "failed", f"unexpected extrapolation status {result.status!r}: {result.message}"
    return status, message, dict(lam_reached=result.lam_reached, steps=len(result.steps), solves=result.solves)


def _tutor_iterations(stats: Any) -> int:
    """Solver iterations of the tutor pipeline (simplification + correction attempts)."""
    stats = stats or {}
    n = (stats.get("simplify") or {}).get("iterations") or 0
    for a in (stats.get("correct") or {}).get("attempts") or []:
        n += a.get("iterations") or 0
    return int(n)


def validation_report(motion) -> dict | None:
    """The plausibility report (MuJoCo replay included) of one λ optimum, or an error note."""
    try:
        from mjcf.validate import validate
        from solver.pipeline import jsonable
    except ImportError:
        return None
    try:
        return jsonable(validate(motion))
    except Exception as e:  # a failing check must not fail the job: the report says so
        log.warning("validation failed", exc_info=True)
        return {"plausible": False, "error": f"{type(e).__name__}: {e}"}
