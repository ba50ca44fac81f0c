"""The one job function, run by both runners (LocalRunner's process pool, Celery workers).

``execute_job(job_id, settings)`` claims the job row (attempt counter with a cap, a lease
renewed while it runs), gets the tutor when the source is a raw capture — the stored one, or
made by this job and stored as its own motion, while the other jobs needing the same tutor
wait for it (one maker per tutor across processes and workers: ``service.store.claim_tutor``)
—, runs the continuation and writes every progress record and every accepted
λ optimum to SQL as it goes (optima upserted by (job, step), so a re-run after a crash
rewrites the same rows). It never raises for a solver failure: that is a job status.

Bounds (docs/service.md, "Limits"): the source motion must fit the method's limits
(:mod:`service.limits`: a tutor is one gait cycle); every IPOPT solve of the extrapolation
carries the job's time limit (``max_wall_time``); between λ steps the continuation checks
cancel, lease and time limit; and the heartbeat thread is also a watchdog: a job still
running ``job_stop_grace_s`` after a cancel or past its time limit — inside a solve, the tutor
pipeline or anything else — has its status recorded and its process ended (the runner
replaces the process). The job process's address space is capped by the runner
(``MOTIONX_JOB_MEMORY_MB``: the LocalRunner's process pool, Celery's worker_process_init).
"""

from __future__ import annotations

import logging
import math
import os
import socket
import threading
import time
import uuid
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Literal

from sqlalchemy.exc import DBAPIError
from tenacity import Retrying, retry_if_result, stop_after_delay, wait_fixed

from service import limits, store
from service.config import Settings, enable_native_code, load_check_modules
from service.db import Database, get_database
from service.limits import LimitError

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


#: exit status of a job process ended by its watchdog
HARD_STOP_EXIT = 86


class Heartbeat:
    """Renews the job's lease from a thread; tells the job to stop when the lease is lost
    or a cancel was requested (read by ``should_cancel`` between λ steps).

    It is also the job's watchdog: ``grace`` seconds after a cancel was seen, or after
    ``deadline`` (monotonic), a job that has not stopped by itself is stopped here — its
    terminal status recorded (fenced by the lease; the λ optima stored so far stay) and the
    process ended with ``os._exit``. The job's own writes hold ``write_lock``, so the
    watchdog never cuts one in half. A lost lease past ``grace`` ends the process without a
    record (another attempt owns the job)."""

    def __init__(self, db: Database, job_id: str, token: str, lease_s: float, *,
                 deadline: float = math.inf, grace: float = 10.0, time_limit_s: float | None = None) -> None:
        self.db, self.job_id, self.token, self.lease_s = db, job_id, token, lease_s
        self.deadline, self.grace, self.time_limit_s = deadline, grace, time_limit_s
        self.cancel_requested = False
        self.lost = False
        self.write_lock = threading.Lock()
        self.steps = 0  # λ optima stored by this attempt
        self.lam_reached = 0.0
        self.solves = 0
        self._cancel_seen: float | None = None
        self._lost_seen: float | None = None
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
        interval = max(0.2, min(self.lease_s / 4.0, 5.0, self.grace / 4.0))
        while not self._stop.wait(interval):
            self.beat()
            self.watch()

    def watch(self) -> None:
        now = time.monotonic()
        if self.cancel_requested and self._cancel_seen is None:
            self._cancel_seen = now
        if self.lost and self._lost_seen is None:
            self._lost_seen = now
        if self._lost_seen is not None and now - self._lost_seen > self.grace:
            log.warning("job %s: lease lost and still running after %g s: ending the process", self.job_id,
                        self.grace)
            os._exit(HARD_STOP_EXIT)
        if self._cancel_seen is not None and now - self._cancel_seen > self.grace:
            self.hard_stop("canceled", f"canceled (stopped in the middle of a computation after {self.grace:g} s)")
        elif now > self.deadline + self.grace:
            limit = f"{self.time_limit_s:g} s" if self.time_limit_s is not None else "its time limit"
            self.hard_stop("failed", f"time limit of {limit} exceeded (stopped in the middle of a computation)")

    def hard_stop(self, status: str, message: str) -> None:
        """Record ``status`` and end the process: the job did not stop by itself."""
        got = self.write_lock.acquire(timeout=30.0)  # never released: the process ends below
        try:
            if not got:
                raise TimeoutError("the job's own database write did not finish")
            with self.db.write() as s:
                store.finish_job(s, job_id=self.job_id, token=self.token, status=status, message=message,
                                 lam_reached=self.lam_reached, steps=self.steps, solves=self.solves)
            log.warning("job %s: %s; ending its process", self.job_id, message)
        except Exception:  # the lease expires and the next attempt finds the cancel / time limit again
            log.exception("job %s: could not record the hard stop", self.job_id)
        finally:
            logging.shutdown()
            os._exit(HARD_STOP_EXIT)


def _claim(db: Database, job_id: str, token: str, settings: Settings) -> store.Claim:
    """The claim of the job; while another live holder has it ("busy"), asked again for up to
    ``BUSY_WAIT_LEASES`` leases (then the busy claim is the answer)."""

    def claim() -> store.Claim:
        with db.write() as s:
            return store.claim_job(s, job_id=job_id, token=token, lease_s=settings.job_lease_s,
                                   holder_alive=holder_alive)

    retrying = Retrying(stop=stop_after_delay(BUSY_WAIT_LEASES * settings.job_lease_s),
                        wait=wait_fixed(min(1.0, settings.job_lease_s / 4.0)),
                        retry=retry_if_result(lambda c: c.outcome == "busy"),
                        retry_error_callback=lambda state: state.outcome.result())
    return retrying(claim)


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
    enable_native_code(settings)
    load_check_modules(settings)
    deadline = time.monotonic() + settings.job_time_limit_s
    with Heartbeat(db, job_id, token, settings.job_lease_s, deadline=deadline, grace=settings.job_stop_grace_s,
                   time_limit_s=settings.job_time_limit_s) as hb:
        try:
            status, message, extra = _run(db, job_id, claim.attempt, token, settings, hb)
        except DBAPIError:  # the store itself is unreachable: not the job's fault, let the runner retry it
            raise
        except Exception as e:  # the job boundary: a failure becomes a status, never a crash
            if _out_of_memory(e):
                log.error("job %s: out of memory", job_id)
            elif isinstance(e, LimitError) or limits.refusal_text(e, ""):  # the input's fault: no traceback
                log.info("job %s refused: %s", job_id, e)
            else:
                log.exception("job %s failed", job_id)
            status, message, extra = "failed", failure_message(e, settings), {}
        if hb.lost:
            log.warning("job %s: lease lost (another attempt took over); result not recorded", job_id)
            return "lost"
        with hb.write_lock, db.write() as s:
            ok = store.finish_job(s, job_id=job_id, token=token, status=status, message=message, **extra)
    return status if ok else "lost"


def _out_of_memory(e: BaseException) -> bool:
    return isinstance(e, MemoryError) or "bad_alloc" in str(e)  # Python's, or C++'s inside CasADi


def failure_message(e: BaseException, settings: Settings) -> str:
    """A failed job's message for an exception it raised: a limit's or a refusal's own text,
    out of memory with the job's cap, else a generic sentence (the traceback is in the log)."""
    if isinstance(e, LimitError):
        return str(e)
    if _out_of_memory(e):
        cap = f" of {settings.job_memory_mb:g} MB" if settings.job_memory_mb else ""
        return f"out of memory: the job needs more than its memory limit{cap}"
    return job_error_message(e)


def job_error_message(e: BaseException, doing: str = "running the job") -> str:
    """What a failed job says about an exception: the message of a refusal our code raised on
    purpose (bad input, a pipeline that cannot go on), cut to a short text; for anything else a
    generic sentence (the traceback is in the log)."""
    return limits.refusal_text(e, f"internal error while {doing} (logged on the server)")


def solve_status(status: str) -> str:
    """A progress record's status as the API shows it: a solver's numerical failure
    (``error: <exception text>``) without the exception's internals (they are in the log)."""
    if status.startswith("error:"):
        log.warning("solve failed: %s", status)
        return "error: the solver failed on this step (numerical error)"
    return status


def _run(db: Database, job_id: str, attempt: int, token: str, settings: Settings, hb: Heartbeat):
    # lazy: the solver loads in the job's process, not the API's
    from solver.continuation import StepControl, Target, extrapolate, needs_rising
    from solver.pipeline import jsonable
    from solver.spacetime import SpacetimeProblem

    with db.read() as s:
        job = store.get_job(s, job_id=job_id, owner=None)
        if job.kind == "simulation":  # a forward simulation of a stored motion (service.simulation)
            sim = store.job_simulation(s, job_id=job_id)
            sim_id = sim.id if sim is not None else ""
        else:
            sim_id = None
            source = store.get_motion(s, motion_id=job.motion_id, owner=None)
            spec, owner, created_at = dict(job.spec), job.owner, job.created_at
            kind, source_id = source.kind, source.id
            limits.check_source(kind=kind, frames=source.frames, fps=source.fps, coordinates=source.n)
            motion = store.load_motion(source)
    if sim_id is not None:
        if not sim_id:
            return "failed", "no simulation for this job", {}
        return (*_simulate(db, sim_id, hb), {})

    t0 = time.monotonic()
    deadline = hb.deadline
    seq = {"n": 0, "solves": 0}

    def record(phase: str, **kw: Any) -> None:
        if phase == "extrapolate" and kw.get("status") != "tutor":  # λ = 0 taken from the tutor: no solve
            seq["solves"] += 1
        with hb.write_lock, db.write() as s:
            store.append_progress(s, job_id=job_id, attempt=attempt, seq=seq["n"], phase=phase,
                                  solves=seq["solves"], **kw)
        seq["n"] += 1
        hb.solves = seq["solves"]

    if kind == "capture":
        character, fps = settings.tutor_of(spec.get("tutor"))
        made = _tutor(db, job_id=job_id, token=token, created_at=created_at, owner=owner, parent_id=source_id,
                      tutor_key=f"{character}@{fps:g}", capture=motion, character=character, fps=fps, hb=hb,
                      t0=t0, record=record, settings=settings)
        if isinstance(made, tuple):  # the job ends here: (status, message)
            return made[0], made[1], {}
        tutor, tutor_id = made.motion, made.motion_id
        with hb.write_lock, db.write() as s:
            store.set_tutor(s, job_id=job_id, token=token, tutor_motion_id=tutor_id)
        limits.check_tutor(frames=tutor.T, fps=float(tutor.fps), coordinates=tutor.n, made=True)
    else:
        tutor = motion

    target = Target(**spec["target"])
    control = StepControl(**spec.get("control", {}))
    start, offset = None, 0
    if spec.get("library"):  # a library cell: start from the best stored optimum (service.library)
        start, offset = _cell_start(db, job_id, spec["library"], owner, target, hb)

    def on_progress(rec) -> None:
        record("extrapolate", wall_time=rec.wall_time, lam=rec.lam, lam_reached=rec.lam_reached,
               environment=jsonable(dict(rec.environment)),
               iterations=rec.iterations, accepted=rec.accepted, status=solve_status(rec.status))

    def on_step(step) -> None:
        validation = validation_report(step.motion) if settings.validate_steps else None
        with hb.write_lock, db.write() as s:
            store.save_step(s, job_id=job_id, owner=owner, step=step.step + offset, lam=step.lam,
                            motion=step.motion, validation=validation)
        hb.steps, hb.lam_reached = step.step + offset + 1, float(step.lam)

    def should_cancel() -> bool:
        return hb.cancel_requested or hb.lost or time.monotonic() > deadline

    # each IPOPT solve stops by itself at the job's time limit (IPOPT's own max_wall_time)
    problem = SpacetimeProblem(tutor.character, tutor.T, tutor.fps, tutor.contacts,
                               ipopt_options={"ipopt.max_wall_time": float(settings.job_time_limit_s)},
                               rising=needs_rising(target))
    result = extrapolate(tutor, target, control, on_progress=on_progress, on_step=on_step,
                         should_cancel=should_cancel, problem=problem, start=start)
    status, message = result.status, result.message
    if status != "succeeded" and not hb.cancel_requested and time.monotonic() > deadline:
        # stopped by the time limit: between steps, or inside a solve (IPOPT's max_wall_time)
        status, message = "failed", f"time limit of {settings.job_time_limit_s:g} s exceeded ({result.message})"
    if status not in ("succeeded", "impasse", "canceled", "failed"):
        status, message = "failed", f"unexpected extrapolation status {result.status!r}: {result.message}"
    lam_reached = max(result.lam_reached, start[0]) if start else result.lam_reached
    steps = len(result.steps) + offset
    cycles = int(spec.get("simulate_cycles") or 0)
    if cycles and steps and status in ("succeeded", "impasse") and not should_cancel():
        # the job's final motion, simulated in MuJoCo: its outcome is the simulation's, not the job's
        with hb.write_lock, db.write() as s:
            final = store.step_row(s, job_id=job_id, step=steps - 1)
            sim = store.job_simulation(s, job_id=job_id)  # an earlier attempt's (the step's id is stable)
            if sim is None or sim.motion_id != final.id:
                sim = store.create_simulation(s, owner=owner, motion_id=final.id, job_id=job_id, cycles=cycles)
            sim_id = sim.id
        sim_status, sim_message = _simulate(db, sim_id, hb)
        message = f"{message}; simulation of the final motion {sim_status}: {sim_message}".lstrip("; ")
    return status, message, dict(lam_reached=lam_reached, steps=steps, solves=result.solves)


def _simulate(db: Database, simulation_id: str, hb: Heartbeat) -> tuple[str, str]:
    """A stored motion simulated in MuJoCo (service.simulation.run_simulation): its (status, message)."""
    from service.simulation import run_simulation  # lazy: MuJoCo loads in the job's process

    try:
        return run_simulation(db, simulation_id, write_lock=hb.write_lock)
    except DBAPIError:
        raise
    except Exception as e:  # recorded as the simulation's failure (the traceback is in the log)
        if isinstance(e, MemoryError):
            raise
        log.exception("simulation %s failed", simulation_id)
        message = job_error_message(e, "simulating the motion")
        with hb.write_lock, db.write() as s:
            store.set_simulation_status(s, simulation_id=simulation_id, status="failed", message=message)
        return "failed", message


@dataclass(frozen=True)
class _Tutor:
    motion: Any  # solver.motion.Motion
    motion_id: str


def _tutor(db: Database, *, job_id: str, token: str, created_at: float, owner: str, parent_id: str, tutor_key: str,
           capture: Any, character: str, fps: float, hb: Heartbeat, t0: float, record: Callable[..., None],
           settings: Settings) -> _Tutor | tuple[str, str]:
    """The tutor of capture ``parent_id`` for ``tutor_key``, made by one job at a time
    (:func:`service.store.claim_tutor`): the stored one; or made here (``solver.pipeline.make_tutor``)
    and stored; or, while another live job makes it, waited for (polled, the job's lease renewed
    meanwhile) and then taken from the store. Its progress point (phase ``tutor``) says which: the
    tutor pipeline's status and iterations, or ``tutor made by job …`` with 0 iterations and the
    time waited. Returns the tutor, or the job's end (status, message): canceled or out of time
    while waiting or making it, or the tutor failed (here, or in the job that made it for this one)."""
    turn = _tutor_turn(db, job_id=job_id, token=token, created_at=created_at, parent_id=parent_id,
                       tutor_key=tutor_key, hb=hb, poll_s=max(0.2, min(1.0, settings.job_lease_s / 4.0)))
    if turn.outcome == "wait":  # stopped while another job makes the tutor
        by = f" (the tutor is being made by job {turn.maker})"
        if hb.cancel_requested or hb.lost:
            return "canceled", f"canceled while waiting for the tutor{by}"
        return "failed", f"time limit of {settings.job_time_limit_s:g} s exceeded while waiting for the tutor{by}"
    if turn.outcome == "failed":
        record("tutor", wall_time=time.monotonic() - t0, lam=0.0, lam_reached=0.0, environment={}, iterations=0,
               accepted=False, status=f"tutor failed in job {turn.maker}")
        return "failed", f"tutor: {turn.message} (in job {turn.maker}, which made it for this job too)"
    if turn.outcome == "ready":
        assert turn.tutor_id is not None
        with db.read() as s:
            row = store.get_motion(s, motion_id=turn.tutor_id, owner=None)
            assert row is not None  # motions are never deleted
            tutor = store.load_motion(row)
        record("tutor", wall_time=time.monotonic() - t0, lam=0.0, lam_reached=0.0, environment={}, iterations=0,
               accepted=True, status=f"tutor made by job {turn.maker}" if turn.maker else "tutor stored earlier")
        return _Tutor(tutor, turn.tutor_id)
    from solver.pipeline import make_tutor  # lazy: the solver loads in the job's process, not the API's

    def end(state: Literal["failed", "released"], message: str = "") -> None:
        with hb.write_lock, db.write() as s:
            store.end_tutor_claim(s, parent_id=parent_id, tutor_key=tutor_key, token=token, state=state,
                                  message=message)

    try:
        # a cancel (or a lost lease) stops the tutor's solve at its next IPOPT iteration
        res = make_tutor(capture, character=character, fps=fps,
                         should_cancel=lambda: hb.cancel_requested or hb.lost)
    except DBAPIError:  # the store is unreachable: the maker's lease runs out and the claim with it
        raise
    except Exception as e:  # the job fails with it (execute_job), and so do the jobs waiting for this tutor
        end("failed", failure_message(e, settings))
        raise
    record("tutor", wall_time=time.monotonic() - t0, lam=0.0, lam_reached=0.0, environment={},
           iterations=_tutor_iterations(res.stats), accepted=res.status == "succeeded", status=f"tutor {res.status}")
    if res.status == "canceled":
        end("released")  # stopped, not failed: the next job needing this tutor makes it
        return "canceled" if hb.cancel_requested else "failed", f"tutor: {res.message}"
    if res.status != "succeeded" or res.motion is None:
        end("failed", res.message or res.status)
        return "failed", f"tutor: {res.message or res.status}"
    with hb.write_lock, db.write() as s:
        row = store.get_or_add_tutor(s, owner=owner, parent_id=parent_id, tutor_key=tutor_key, motion=res.motion)
        assert row is not None  # stored just now, or by an earlier attempt
        store.end_tutor_claim(s, parent_id=parent_id, tutor_key=tutor_key, token=token, state="made")
    return _Tutor(res.motion, row.id)


def _tutor_turn(db: Database, *, job_id: str, token: str, created_at: float, parent_id: str, tutor_key: str,
                hb: Heartbeat, poll_s: float) -> store.TutorTurn:
    """The job's turn at the tutor (:func:`service.store.claim_tutor`), asked again every
    ``poll_s`` while another live job makes it; still ``wait`` when the job must stop meanwhile
    (a cancel, a lost lease, its time limit)."""
    while True:
        with hb.write_lock, db.write() as s:
            turn = store.claim_tutor(s, parent_id=parent_id, tutor_key=tutor_key, job_id=job_id, token=token,
                                     job_created_at=created_at, holder_alive=holder_alive)
        if turn.outcome != "wait" or hb.cancel_requested or hb.lost or time.monotonic() > hb.deadline:
            return turn
        time.sleep(poll_s)


def _cell_start(db: Database, job_id: str, ref: dict, owner: str, target, hb: Heartbeat):
    """A library cell's warm start: the stored optimum furthest along its homotopy, stored as
    the cell's step 0 (its provenance says where it came from). Returns (start, step offset)."""
    from service import library  # lazy: the solver loads in the job's process, not the API's

    found = library.warm_start(db, job_id, ref)
    if found is None:
        return None, 0
    ws, motion, validation, src_job, src_step = found
    prov = dict(motion.provenance)
    prov.update({"lambda": ws.lam, "target": target.to_dict(),
                 "warm_start": {"lam": ws.lam, "source_cell": ws.source_cell, "source_lam": ws.source_lam,
                                "source_job": src_job, "source_step": src_step}})
    motion = motion.evolve(provenance=prov)
    with hb.write_lock, db.write() as s:
        store.save_step(s, job_id=job_id, owner=owner, step=0, lam=ws.lam, motion=motion, validation=validation)
    hb.steps, hb.lam_reached = 1, ws.lam
    log.info("job %s: warm start at λ = %.4f from cell %s (λ = %.4f)", job_id, ws.lam, ws.source_cell,
             ws.source_lam)
    return (ws.lam, motion), 1


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
        from mjcf.validate import validate  # lazy: the solver loads in the job's process, not the API's
        from solver.pipeline import jsonable
    except ImportError:
        return None
    try:
        return jsonable(validate(motion))
    except Exception as e:  # a failing check must not fail the job: the report says so
        log.warning("validation failed", exc_info=True)
        return {"plausible": False, "error": job_error_message(e, "validating the motion")}
