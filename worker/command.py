"""``motionx worker``: a Celery worker executing extrapolation jobs (:mod:`worker.app`).

The command is registered by ``service.commands.MODULES`` naming this module (the command
line is the one place that assembles every package); service/ never imports worker/.
"""

from __future__ import annotations

import argparse
import os

from service.cli import add_command
from service.commands.serve import _settings


def cmd_worker(args: argparse.Namespace) -> int:
    # lazy (heavy: Celery, SQLAlchemy, the job code): the command line imports every command module
    from worker.app import create_celery

    settings = _settings(broker_url=args.broker_url, database_url=args.database_url,
                         worker_concurrency=args.concurrency)
    app = create_celery(settings)
    # lazy as above; imported once in the worker's main process, so every pool process forked from
    # it (also the one replacing a killed child) starts warm, with the same code
    import mjcf.validate  # noqa: F401
    import solver.continuation
    import solver.pipeline  # noqa: F401

    argv = [
        "worker", f"--loglevel={args.loglevel}", "-Q", settings.celery_queue,
        f"--concurrency={settings.worker_concurrency}", f"--hostname={args.hostname or f'motionx-{os.getpid()}@%h'}",
        "--without-gossip", "--without-mingle",
    ]
    app.worker_main(argv)
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    s = add_command(sub, "worker", "run a Celery worker executing extrapolation jobs", """\
Run a Celery worker that executes extrapolation jobs from the Redis queue (the same job
function as the local runner), with late acknowledgement and prefetch 1.""")
    s.add_argument("--concurrency", type=int, default=None, metavar="N",
                   help="pool processes (default: $MOTIONX_WORKER_CONCURRENCY or 1)")
    s.add_argument("--hostname", default=None, metavar="NAME", help="Celery node name (default: motionx-<pid>@%%h)")
    s.add_argument("--loglevel", default="INFO", metavar="LEVEL", help="Celery's log level")
    s.add_argument("--broker-url", default=None, metavar="URL",
                   help="Redis URL (default: $MOTIONX_BROKER_URL or redis://127.0.0.1:6379/0)")
    s.add_argument("--database-url", default=None, metavar="URL",
                   help="SQLAlchemy URL (default: $DATABASE_URL, else SQLite)")
    s.set_defaults(func=cmd_worker)
