"""The Celery worker's app: :func:`service.queue.celery_app` plus the one task, a 3-line
wrapper around :func:`service.jobs.execute_job`, and the pool processes' setup.

Start a worker with ``motionx worker`` (:mod:`worker.command` calls :func:`create_celery` and
``worker_main``). The queue's settings and the task name live in :mod:`service.queue`.
"""

from __future__ import annotations

import os

from celery import Celery
from celery.signals import worker_process_init

from service.config import Settings
from service.jobs import execute_job
from service.procpool import die_with_parent, limit_memory
from service.queue import RETRY_ON_DB_ERRORS, TASK_NAME, celery_app, celery_config

__all__ = ["TASK_NAME", "celery_config", "create_celery", "init_job_process"]


def init_job_process(settings: Settings) -> None:
    """In each pool process: die with the worker (no orphan when the worker is SIGKILLed:
    its pool processes would finish their job and idle on) and cap the address space like
    the LocalRunner's job processes. (No PR_SET_PDEATHSIG here: billiard may fork from a
    thread that ends before the worker does.)"""
    die_with_parent(os.getppid(), pdeathsig=False)
    limit_memory(settings.job_memory_mb or None)


def create_celery(settings: Settings) -> Celery:
    app = celery_app(settings)

    @worker_process_init.connect(weak=False)
    def _init(**_kw) -> None:
        init_job_process(settings)

    @app.task(name=TASK_NAME, acks_late=True, reject_on_worker_lost=True, **RETRY_ON_DB_ERRORS)
    def run_job(job_id: str) -> str:
        return execute_job(job_id, settings)

    return app
