"""Runners: how a queued job (an id in SQL) gets executed.

Both call the same function, :func:`service.jobs.execute_job`:

- :class:`LocalRunner` — supervised job processes of the API process (the embedded default:
  nothing else to run). Jobs left queued or running by a previous API process are
  resubmitted on start; a job whose process dies is resubmitted (its next attempt takes over).
- :class:`CeleryRunner` — publishes the job id to Redis; ``motionx worker`` processes run it.

``sweep()`` (called periodically by the API) dispatches jobs nobody would otherwise run:
never dispatched (the broker was down at creation), or running with a lease long expired.
"""

from __future__ import annotations

import logging
import threading
from concurrent.futures import Future
from typing import Protocol

from service import store
from service.config import Settings
from service.db import Database
from service.jobs import execute_job
from service.procpool import ProcPool, TaskTimeout, WorkerLost
from service.queue import TASK_NAME, celery_app

log = logging.getLogger(__name__)

#: imported by every job process before it takes work (and before its memory cap applies)
JOB_MODULES = ("numpy", "casadi", "mujoco", "solver.pipeline", "solver.continuation", "mjcf.validate", "service.jobs")
#: the supervisor kills a job's process this long after the hard time limit: the job's own
#: watchdog (service.jobs.Heartbeat) should have stopped it well before
JOB_KILL_MARGIN_S = 60.0


class Runner(Protocol):
    name: str

    def start(self) -> None: ...

    def submit(self, job_id: str) -> bool: ...

    def dispatch(self) -> list[str]: ...

    def sweep(self) -> list[str]: ...

    def health(self) -> str: ...

    def close(self) -> None: ...


def _mark_dispatched(db: Database, job_id: str) -> None:
    with db.write() as s:
        store.mark_dispatched(s, job_id=job_id)


def _fair_turns(db: Database, settings: Settings, runner: str) -> list[str]:
    """The queued jobs whose turn it is (:func:`service.store.dispatch_fair`), marked dispatched."""
    with db.write() as s:
        return store.dispatch_fair(s, runner=runner, per_key=settings.key_job_slots)


class LocalRunner:
    """Jobs in supervised child processes of the API (:class:`service.procpool.ProcPool`).

    One process per concurrent job (``local_workers``), each with the job memory cap. A process
    that dies fails only its own job's attempt: the job is resubmitted and the next attempt
    takes over its lease at once (the holder is a dead process of this host). The processes
    die with the API (SIGTERM, SIGINT or SIGKILL alike).
    """

    name = "local"

    def __init__(self, settings: Settings, db: Database) -> None:
        self.settings, self.db = settings, db
        self._lock = threading.Lock()
        self._pool: ProcPool | None = None
        self._inflight: dict[str, Future] = {}
        self._dispatch_lock = threading.Lock()

    def start(self) -> None:
        with self._lock:
            self._pool = ProcPool("job", self.settings.local_workers, memory_mb=self.settings.job_memory_mb,
                                  warm=JOB_MODULES).start()
        with self.db.write() as s:  # the previous process's queue is gone: queued jobs take their turn again
            store.forget_dispatches(s, runner=self.name)
        self.recover(all_unfinished=True)
        self.dispatch()

    def dispatch(self) -> list[str]:
        """Submit the queued jobs whose turn it is: a key has at most ``jobs_per_key`` jobs in the
        job processes at once (:func:`service.store.dispatch_fair`), the rest wait in SQL."""
        with self._dispatch_lock:
            ids = _fair_turns(self.db, self.settings, self.name)
            for j in ids:
                self._submit(j)
        return ids

    def submit(self, job_id: str) -> bool:
        ok = self._submit(job_id)
        _mark_dispatched(self.db, job_id)
        return ok

    def _submit(self, job_id: str) -> bool:
        with self._lock:
            if self._pool is None:
                raise RuntimeError("LocalRunner not started")
            fut = self._inflight.get(job_id)
            if fut is not None and not fut.done():
                return True
            try:
                fut = self._pool.submit(execute_job, job_id, self.settings, timeout=self.settings.hard_time_limit_s
                                        + JOB_KILL_MARGIN_S)
            except RuntimeError:  # closing
                return False
            self._inflight[job_id] = fut
        fut.add_done_callback(lambda f, j=job_id: self._done(j, f))
        return True

    def _done(self, job_id: str, fut: Future) -> None:
        with self._lock:
            if self._inflight.get(job_id) is fut:
                del self._inflight[job_id]
            closing = self._pool is None
        exc = fut.exception() if not fut.cancelled() else None
        if closing:
            return
        if exc is None:  # a job ended: the next key's turn
            self._dispatch_soon()
            return
        if isinstance(exc, TaskTimeout):  # the job ignored its own limits: it ends here, failed
            log.error("job %s: its process was killed past the hard time limit", job_id)
            try:
                with self.db.write() as s:
                    store.fail_unfinished(s, job_id=job_id, message=f"time limit of "
                                          f"{self.settings.job_time_limit_s:g} s exceeded (the job's process was "
                                          "stopped)")
            except Exception:
                log.warning("job %s: could not record the time limit", job_id, exc_info=True)
        elif isinstance(exc, WorkerLost):  # the process died: the next attempt takes over (attempts are capped)
            log.warning("job %s: %s; resubmitting", job_id, exc)
            self._resubmit_soon(job_id)
        else:  # e.g. the database was unreachable: the sweep resubmits it
            log.error("job %s raised in its process: %r", job_id, exc)

    def _dispatch_soon(self) -> None:
        def run() -> None:
            try:
                self.dispatch()
            except Exception:  # the periodic sweep tries again
                log.warning("dispatch failed", exc_info=True)

        threading.Thread(target=run, name="local-dispatch", daemon=True).start()

    def _resubmit_soon(self, job_id: str, delay: float = 0.2) -> None:
        def run() -> None:
            try:
                self.submit(job_id)
            except Exception:  # the periodic sweep tries again
                log.warning("job %s: resubmission failed", job_id, exc_info=True)

        t = threading.Timer(delay, run)
        t.daemon = True
        t.start()

    def recover(self, *, all_unfinished: bool = False) -> list[str]:
        """Resubmit the running jobs whose process is gone (all of them on start), and the queued
        jobs dispatched to this runner that are no longer in its pool; never-dispatched ones wait
        for their turn (:meth:`dispatch`)."""
        big = 1e18
        with self._dispatch_lock:  # a job being dispatched is in self._inflight before the lock is released
            with self.db.read() as s:  # the pool's queue is this process's memory: a dispatched job not in it
                ids = store.stranded_jobs(  # was lost (its process failed, e.g. the database was unreachable)
                    s, runner=self.name, queued_after=0.0,
                    running_after=-big if all_unfinished else 0.0, limit=1000, dispatched_only=True,
                )
            with self._lock:
                ids = [j for j in ids if j not in self._inflight]
            for j in ids:
                self.submit(j)
        if ids:
            log.info("local runner: (re)submitted %d job(s)", len(ids))
        return ids

    def sweep(self) -> list[str]:
        return self.recover() + self.dispatch()

    def health(self) -> str:
        pool = self._pool
        return "ok" if pool is not None and pool.healthy() else "stopped"

    def pids(self) -> list[int]:
        pool = self._pool
        return pool.pids() if pool is not None else []

    def close(self) -> None:
        """Stop the job processes. Running jobs stay 'running': their holder is gone, so the
        next start (or another API process's sweep, after the lease) resumes them."""
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.close(timeout=5.0)


class CeleryRunner:
    name = "celery"

    def __init__(self, settings: Settings, db: Database) -> None:
        self.settings, self.db = settings, db
        self.app = celery_app(settings)  # publishes only: the task runs in `motionx worker`

    def start(self) -> None:
        self.sweep()

    def _send(self, job_id: str) -> bool:
        try:
            self.app.send_task(TASK_NAME, args=[job_id], queue=self.settings.celery_queue)
        except Exception as e:  # broker down: the job stays queued in SQL; the sweep dispatches it later
            log.warning("could not dispatch job %s (%s); will retry", job_id, e)
            return False
        return True

    def submit(self, job_id: str) -> bool:
        if not self._send(job_id):
            return False
        _mark_dispatched(self.db, job_id)
        return True

    def dispatch(self) -> list[str]:
        """Publish the queued jobs whose turn it is: a key has at most ``jobs_per_key`` jobs running
        or in the broker's queue (:func:`service.store.dispatch_fair`); the rest wait in SQL and
        are published by the sweep as that key's jobs end."""
        ids = _fair_turns(self.db, self.settings, self.name)
        failed = [j for j in ids if not self._send(j)]
        if failed:
            with self.db.write() as s:
                store.undo_dispatch(s, job_ids=failed)
        return [j for j in ids if j not in failed]

    def sweep(self) -> list[str]:
        """Dispatch again what Redis would only redeliver after its visibility timeout: a job
        never dispatched (broker down), or running with an expired lease (its worker died; the
        next attempt takes over the lease, so a late duplicate delivery is a no-op)."""
        with self.db.read() as s:
            ids = store.stranded_jobs(s, runner=self.name, queued_after=self.settings.redispatch_after,
                                      running_after=self.settings.redispatch_expired_s,
                                      redispatch_gap=self.settings.redispatch_gap_s, dispatched_only=True)
        done = [j for j in ids if self.submit(j)]
        if done:
            log.info("celery runner: re-dispatched %d stranded job(s)", len(done))
        return done + self.dispatch()

    def health(self) -> str:
        try:
            with self.app.connection_for_write() as conn:
                conn.ensure_connection(max_retries=1, timeout=2)
            return "ok"
        except Exception as e:
            return f"unreachable: {type(e).__name__}"

    def close(self) -> None:
        self.app.close()


#: the runners by name (``Settings.runner``, ``motionx serve --runner``): the service's registry
RUNNERS: dict[str, type[LocalRunner] | type[CeleryRunner]] = {"local": LocalRunner, "celery": CeleryRunner}


def make_runner(settings: Settings, db: Database) -> Runner:
    return RUNNERS[settings.runner](settings, db)
