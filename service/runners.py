"""Runners: how a queued job (an id in SQL) gets executed.

Both call the same function, :func:`service.jobs.execute_job`:

- :class:`LocalRunner` — a process pool inside the API process (the embedded default:
  nothing else to run). Jobs left queued or running by a previous API process are
  resubmitted on start; a pool broken by a dying child is replaced.
- :class:`CeleryRunner` — publishes the job id to Redis; ``motionx worker`` processes run it.

``sweep()`` (called periodically by the API) dispatches jobs nobody would otherwise run:
never dispatched (the broker was down at creation), or running with a lease long expired.
"""

from __future__ import annotations

import logging
import multiprocessing
import threading
from concurrent.futures import Future, ProcessPoolExecutor
from concurrent.futures.process import BrokenProcessPool
from typing import Protocol

from service import store
from service.config import Settings
from service.db import Database
from service.jobs import execute_job

log = logging.getLogger(__name__)


class Runner(Protocol):
    name: str

    def start(self) -> None: ...

    def submit(self, job_id: str) -> bool: ...

    def sweep(self) -> list[str]: ...

    def health(self) -> str: ...

    def close(self) -> None: ...


def _mark_dispatched(db: Database, job_id: str) -> None:
    with db.write() as s:
        store.mark_dispatched(s, job_id=job_id)


class LocalRunner:
    name = "local"

    def __init__(self, settings: Settings, db: Database) -> None:
        self.settings, self.db = settings, db
        self._lock = threading.Lock()
        self._pool: ProcessPoolExecutor | None = None
        self._inflight: dict[str, Future] = {}
        self._broken = False
        self._recovery_pending = False

    def _new_pool(self) -> ProcessPoolExecutor:
        # spawn: the API process has threads (event loop, DB pool); forking it is unsafe
        return ProcessPoolExecutor(self.settings.local_workers, mp_context=multiprocessing.get_context("spawn"))

    def start(self) -> None:
        with self._lock:
            self._pool = self._new_pool()
        self.recover(all_unfinished=True)

    def submit(self, job_id: str) -> bool:
        with self._lock:
            if self._pool is None:
                raise RuntimeError("LocalRunner not started")
            fut = self._inflight.get(job_id)
            if fut is not None and not fut.done():
                return True
            try:
                fut = self._pool.submit(execute_job, job_id, self.settings)
            except (BrokenProcessPool, RuntimeError):
                self._broken = True
                log.warning("local pool unusable; job %s waits for the next sweep", job_id)
                return False
            self._inflight[job_id] = fut
            pool = self._pool
        fut.add_done_callback(lambda f, j=job_id, p=pool: self._done(j, f, p))
        _mark_dispatched(self.db, job_id)
        return True

    def _done(self, job_id: str, fut: Future, pool: ProcessPoolExecutor | None) -> None:
        with self._lock:
            if self._inflight.get(job_id) is fut:
                del self._inflight[job_id]
            current = pool is self._pool
        exc = fut.exception() if not fut.cancelled() else None
        if isinstance(exc, BrokenProcessPool) and current:
            log.warning("local pool broken (a job process died) while running %s", job_id)
            self._broken = True
            self._recover_soon()
        elif exc is not None:  # e.g. the database was unreachable: the sweep resubmits it
            log.error("job %s raised in the pool: %r", job_id, exc)

    def _recover_soon(self, delay: float = 0.5) -> None:
        """Replace a broken pool without waiting for the next sweep (once per breakage)."""
        with self._lock:
            if self._recovery_pending or self._pool is None:
                return
            self._recovery_pending = True

        def run() -> None:
            try:
                self.recover()
            except Exception:  # the periodic sweep tries again
                log.warning("pool recovery failed", exc_info=True)
            finally:
                self._recovery_pending = False

        t = threading.Timer(delay, run)
        t.daemon = True
        t.start()

    def recover(self, *, all_unfinished: bool = False) -> list[str]:
        old = None
        with self._lock:
            if self._broken and self._pool is not None:
                old, self._pool, self._broken = self._pool, self._new_pool(), False
                self._inflight.clear()
                all_unfinished = True
        if old is not None:
            old.shutdown(wait=False, cancel_futures=True)
        big = 1e18
        with self.db.read() as s:
            ids = store.stranded_jobs(
                s, runner=self.name,
                queued_after=-big if all_unfinished else self.settings.redispatch_after,
                running_after=-big if all_unfinished else 0.0,
                limit=1000,
            )
        with self._lock:
            ids = [j for j in ids if j not in self._inflight]
        for j in ids:
            self.submit(j)
        if ids:
            log.info("local runner: (re)submitted %d job(s)", len(ids))
        return ids

    def sweep(self) -> list[str]:
        return self.recover()

    def health(self) -> str:
        return "broken" if self._broken else "ok"

    def close(self) -> None:
        with self._lock:
            pool, self._pool = self._pool, None
        if pool is not None:
            pool.shutdown(wait=False, cancel_futures=True)
            for p in list((getattr(pool, "_processes", None) or {}).values()):
                p.terminate()  # running jobs stay 'running'; their lease expires and the next start resumes them


class CeleryRunner:
    name = "celery"

    def __init__(self, settings: Settings, db: Database) -> None:
        from worker.app import create_celery

        self.settings, self.db = settings, db
        self.app = create_celery(settings)

    def start(self) -> None:
        self.sweep()

    def submit(self, job_id: str) -> bool:
        from worker.app import TASK_NAME

        try:
            self.app.send_task(TASK_NAME, args=[job_id], queue=self.settings.celery_queue)
        except Exception as e:  # broker down: the job stays queued in SQL; the sweep dispatches it later
            log.warning("could not dispatch job %s (%s); will retry", job_id, e)
            return False
        _mark_dispatched(self.db, job_id)
        return True

    def sweep(self) -> list[str]:
        with self.db.read() as s:
            ids = store.stranded_jobs(s, runner=self.name, queued_after=self.settings.redispatch_after,
                                      running_after=self.settings.redispatch_after)
        done = [j for j in ids if self.submit(j)]
        if done:
            log.info("celery runner: re-dispatched %d stranded job(s)", len(done))
        return done

    def health(self) -> str:
        try:
            with self.app.connection_for_write() as conn:
                conn.ensure_connection(max_retries=1, timeout=2)
            return "ok"
        except Exception as e:
            return f"unreachable: {type(e).__name__}"

    def close(self) -> None:
        self.app.close()


def make_runner(settings: Settings, db: Database) -> Runner:
    return CeleryRunner(settings, db) if settings.runner == "celery" else LocalRunner(settings, db)
