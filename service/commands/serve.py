"""Service commands: ``serve`` (API), ``worker`` (Celery), ``stack`` (the compose topology as
processes), ``db upgrade``, ``apikey create|revoke``, ``openapi``."""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import threading
from pathlib import Path

from service.cli import CliError

log = logging.getLogger("motionx")


def _settings(**overrides):
    from pydantic import ValidationError

    from service.config import Settings

    try:
        return Settings(**{k: v for k, v in overrides.items() if v is not None})
    except ValidationError as e:
        raise CliError(f"invalid settings: {e.errors()[0]['msg']}") from None


def _ensure_api_key(settings) -> None:
    """The embedded default needs nothing else: with no key anywhere, make one and say so."""
    from service import store
    from service.db import get_database

    if settings.static_api_keys:
        return
    db = get_database(settings.sqlalchemy_url)
    with db.write() as s:
        if store.count_api_keys(s):
            return
        kid, key = store.create_api_key(s, name="created by motionx serve")
    print(f"motionx: no API key existed; created {kid}: {key}  (keep it; only its hash is stored)",
          file=sys.stderr, flush=True)


def cmd_serve(args: argparse.Namespace) -> int:
    import uvicorn

    from service.app import create_app
    from service.db import upgrade

    settings = _settings(host=args.host, port=args.port, runner=args.runner, database_url=args.database_url,
                         data_dir=args.data_dir)
    if settings.auto_migrate:
        upgrade(settings.sqlalchemy_url)
    _ensure_api_key(settings)
    print(json.dumps({"api": f"http://{settings.host}:{settings.port}",
                      "page": f"http://{settings.host}:{settings.port}/ui/", "runner": settings.runner,
                      "database": settings.sqlalchemy_url.split("@")[-1]}), flush=True)
    uvicorn.run(create_app(settings), host=settings.host, port=settings.port, log_level=args.log_level,
                timeout_graceful_shutdown=10, access_log=args.access_log)
    return 0


def cmd_worker(args: argparse.Namespace) -> int:
    from worker.app import create_celery

    settings = _settings(broker_url=args.broker_url, database_url=args.database_url,
                         worker_concurrency=args.concurrency)
    app = create_celery(settings)
    # import the pipeline once in the worker's main process: every pool process forked from
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


def cmd_stack(args: argparse.Namespace) -> int:
    from service.topology import Stack, TopologyError, create_postgres_database

    data_dir = Path(args.data_dir).resolve()
    database_url = args.database_url
    if database_url is None and not args.sqlite:
        try:
            database_url = create_postgres_database(args.postgres_admin_url, args.postgres_db)
        except Exception as e:
            raise CliError(f"PostgreSQL at {args.postgres_admin_url}: {e} (or use --sqlite)") from None
    stack = Stack(data_dir=data_dir, workers=args.workers, port=args.port, database_url=database_url,
                  api_keys=args.api_key or "")
    stop = threading.Event()
    for sig in (signal.SIGTERM, signal.SIGINT):
        signal.signal(sig, lambda *_: stop.set())
    try:
        stack.start()
        print(json.dumps(stack.describe()), flush=True)
        while not stop.wait(1.0):
            dead = [p.name for p in [stack.api, *stack.worker_procs] if p is not None and not p.alive()]
            if stack.redis and stack.redis.proc.poll() is not None:
                dead.append("redis")
            if dead:
                print(json.dumps({"exited": dead}), file=sys.stderr, flush=True)
                return 1
        return 0
    except TopologyError as e:
        raise CliError(str(e)) from None
    finally:
        stack.stop()


def cmd_db_upgrade(args: argparse.Namespace) -> int:
    from service.db import current_revision, upgrade

    settings = _settings(database_url=args.database_url, data_dir=args.data_dir)
    upgrade(settings.sqlalchemy_url, args.revision)
    print(json.dumps({"database": settings.sqlalchemy_url.split("@")[-1],
                      "revision": current_revision(settings.sqlalchemy_url)}))
    return 0


def cmd_apikey_create(args: argparse.Namespace) -> int:
    from service import store
    from service.db import get_database, upgrade

    settings = _settings(database_url=args.database_url, data_dir=args.data_dir)
    upgrade(settings.sqlalchemy_url)
    with get_database(settings.sqlalchemy_url).write() as s:
        kid, key = store.create_api_key(s, name=args.name)
    print(json.dumps({"id": kid, "key": key, "name": args.name}))
    return 0


def cmd_apikey_revoke(args: argparse.Namespace) -> int:
    from service import store
    from service.db import get_database

    settings = _settings(database_url=args.database_url, data_dir=args.data_dir)
    with get_database(settings.sqlalchemy_url).write() as s:
        ok = store.revoke_api_key(s, key_id=args.id)
    if not ok:
        raise CliError(f"no active API key {args.id!r}")
    print(json.dumps({"revoked": args.id}))
    return 0


def cmd_openapi(args: argparse.Namespace) -> int:
    from service.app import create_app

    doc = json.dumps(create_app(_settings()).openapi(), indent=2, sort_keys=True)
    if args.out == "-":
        sys.stdout.write(doc + "\n")
    else:
        Path(args.out).write_text(doc + "\n")
    return 0


def _db_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--database-url", default=None, help="SQLAlchemy URL (default: $DATABASE_URL or SQLite)")
    p.add_argument("--data-dir", default=None, help="directory of the default SQLite database")


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("serve", help="run the HTTP API (embedded default: SQLite + local process pool)")
    s.add_argument("--host", default=None)
    s.add_argument("--port", type=int, default=None)
    s.add_argument("--runner", choices=["local", "celery"], default=None)
    s.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"])
    s.add_argument("--access-log", action="store_true")
    _db_args(s)
    s.set_defaults(func=cmd_serve)

    s = sub.add_parser("worker", help="run a Celery worker executing extrapolation jobs")
    s.add_argument("--concurrency", type=int, default=None, help="pool processes (default 1)")
    s.add_argument("--hostname", default=None, help="Celery node name (default motionx-<pid>@%%h)")
    s.add_argument("--loglevel", default="INFO")
    s.add_argument("--broker-url", default=None)
    s.add_argument("--database-url", default=None)
    s.set_defaults(func=cmd_worker)

    s = sub.add_parser("stack", help="start the docker-compose topology as processes: Redis (AOF), "
                       "PostgreSQL database, API, N workers; Ctrl-C stops it")
    s.add_argument("--workers", type=int, default=2)
    s.add_argument("--port", type=int, default=0, help="API port (default: a free one)")
    s.add_argument("--data-dir", default="./motionx-stack", help="Redis AOF, logs (and SQLite with --sqlite)")
    s.add_argument("--database-url", default=None, help="use this database instead of creating one")
    s.add_argument("--postgres-admin-url", default="postgresql://postgres@127.0.0.1:5432/postgres")
    s.add_argument("--postgres-db", default="motionx_stack")
    s.add_argument("--sqlite", action="store_true", help="SQLite in --data-dir instead of PostgreSQL")
    s.add_argument("--api-key", default=None, help="API key to accept (default: a new random one, printed)")
    s.set_defaults(func=cmd_stack)

    s = sub.add_parser("db", help="database schema (Alembic)")
    dsub = s.add_subparsers(dest="db_command", required=True)
    d = dsub.add_parser("upgrade", help="upgrade the schema (default: to head)")
    d.add_argument("revision", nargs="?", default="head")
    _db_args(d)
    d.set_defaults(func=cmd_db_upgrade)

    s = sub.add_parser("apikey", help="create or revoke API keys (stored hashed in SQL)")
    ksub = s.add_subparsers(dest="apikey_command", required=True)
    k = ksub.add_parser("create")
    k.add_argument("--name", default="")
    _db_args(k)
    k.set_defaults(func=cmd_apikey_create)
    k = ksub.add_parser("revoke")
    k.add_argument("id")
    _db_args(k)
    k.set_defaults(func=cmd_apikey_revoke)

    s = sub.add_parser("openapi", help="write the OpenAPI document of the HTTP API")
    s.add_argument("--out", default="-")
    s.set_defaults(func=cmd_openapi)
