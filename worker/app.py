"""The Celery app, built from :class:`service.config.Settings` (never at import time).

Reliability settings (measured on Celery 5.7 + Redis 7, see docs/service.md):
``acks_late`` + ``reject_on_worker_lost`` (a killed pool process's job is requeued, not
acknowledged), prefetch 1, and one visibility timeout above the longest job set in the
broker, result-backend and app options alike. Job state lives in SQL, not in Celery.

Start a worker with ``motionx worker`` (it calls :func:`create_celery` and
``worker_main``); the task is a 3-line wrapper around :func:`service.jobs.execute_job`.
"""

from __future__ import annotations

import os

from celery import Celery
from celery.signals import worker_process_init
from sqlalchemy.exc import DBAPIError

from service.config import Settings
from service.jobs import execute_job
from service.procpool import die_with_parent, limit_memory

TASK_NAME = "motionx.run_job"

#: the job's own failures are job statuses; an unreachable database is retried with backoff
RETRY_ON_DB_ERRORS = dict(autoretry_for=(DBAPIError,), retry_backoff=2, retry_backoff_max=60, max_retries=None,
                          retry_jitter=True)


def celery_config(settings: Settings) -> dict:
    vt = int(settings.visibility_timeout_s)
    return dict(
        broker_url=settings.broker_url,
        result_backend=settings.result_backend,
        broker_transport_options={
            "visibility_timeout": vt,
            "unacked_restore_interval": settings.unacked_restore_interval_s,
            "unacked_restore_throttle": settings.unacked_restore_throttle,
            "socket_connect_timeout": 5,
        },
        result_backend_transport_options={"visibility_timeout": vt},
        visibility_timeout=vt,
        task_acks_late=True,
        task_reject_on_worker_lost=True,
        task_acks_on_failure_or_timeout=True,
        worker_prefetch_multiplier=1,
        task_ignore_result=True,
        task_serializer="json",
        result_serializer="json",
        accept_content=["json"],
        task_default_queue=settings.celery_queue,
        task_time_limit=settings.hard_time_limit_s,
        task_publish_retry=True,
        task_publish_retry_policy={"max_retries": 2, "interval_start": 0, "interval_step": 0.5, "interval_max": 1},
        broker_connection_retry_on_startup=True,
        broker_connection_max_retries=None,
        worker_cancel_long_running_tasks_on_connection_loss=False,
        worker_concurrency=settings.worker_concurrency,
        worker_send_task_events=False,
        enable_utc=True,
    )


def init_job_process(settings: Settings) -> None:
    """In each pool process: die with the worker (no orphan when the worker is SIGKILLed:
    its pool processes would finish their job and idle on) and cap the address space like
    the LocalRunner's job processes. (No PR_SET_PDEATHSIG here: billiard may fork from a
    thread that ends before the worker does.)"""
    die_with_parent(os.getppid(), pdeathsig=False)
    limit_memory(settings.job_memory_mb or None)


def create_celery(settings: Settings) -> Celery:
    app = Celery("motionx", set_as_current=False)
    app.conf.update(celery_config(settings))

    @worker_process_init.connect(weak=False)
    def _init(**_kw) -> None:
        init_job_process(settings)

    @app.task(name=TASK_NAME, acks_late=True, reject_on_worker_lost=True, **RETRY_ON_DB_ERRORS)
    def run_job(job_id: str) -> str:
        return execute_job(job_id, settings)

    return app
