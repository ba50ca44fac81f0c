"""The job queue's configuration, shared by the producer (:class:`service.runners.CeleryRunner`)
and the consumer (``motionx worker``, :mod:`worker.app`): the Celery settings, the task name,
and the retry policy. The service owns it; worker/ imports it, never the reverse.

Reliability settings (measured on Celery 5.7 + Redis 7, see docs/service.md):
``acks_late`` + ``reject_on_worker_lost`` (a killed pool process's job is requeued, not
acknowledged), prefetch 1, and one visibility timeout above the longest job set in the
broker, result-backend and app options alike. Job state lives in SQL, not in Celery.
"""

from __future__ import annotations

from celery import Celery
from sqlalchemy.exc import DBAPIError

from service.config import Settings

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


def celery_app(settings: Settings) -> Celery:
    """A Celery app configured for the queue, with no task registered: enough to publish
    (the worker registers the task, :func:`worker.app.create_celery`)."""
    app = Celery("motionx", set_as_current=False)
    app.conf.update(celery_config(settings))
    return app
