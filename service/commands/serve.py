"""Service commands: ``serve`` (API), ``stack`` (the compose topology as
processes), ``db upgrade``, ``apikey create|revoke``, ``openapi``."""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading
from pathlib import Path

from service.cli import CliError, add_command

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
    base = f"http://{'127.0.0.1' if settings.host in ('0.0.0.0', '::') else settings.host}:{settings.port}"
    print(f"motionx: no API key existed, so one was made (id {kid}). Copy it now, only its hash is stored:\n"
          f"\n    {key}\n\n"
          f"  requests send it as a header:  curl -H \"X-API-Key: {key}\" {base}/jobs\n"
          f"  the web page takes it once:    {base}/ui/#key={key}\n",
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
        while not stop.wait(1.0):  # a process that dies is restarted after its back-off; the rest keep running
            for event in stack.supervise():
                print(json.dumps(event), file=sys.stderr, flush=True)
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
    p.add_argument("--database-url", default=None, metavar="URL",
                   help="SQLAlchemy URL (default: $DATABASE_URL, else SQLite in the data directory)")
    p.add_argument("--data-dir", default=None, metavar="DIR",
                   help="directory of the default SQLite database (default: $MOTIONX_DATA_DIR or "
                        "~/.local/share/motionx)")


def register(sub: argparse._SubParsersAction) -> None:
    s = add_command(sub, "serve", "run the HTTP API (embedded default: SQLite + local process pool)", """\
Run the HTTP API (FastAPI; OpenAPI at /openapi.json, the web page at /ui/). The embedded
default needs nothing else: SQLite (WAL) in the data directory and a local process pool.
DATABASE_URL=postgresql://... for PostgreSQL, --runner celery for Celery workers. With no API
key configured (MOTIONX_API_KEYS) or stored, it makes one and prints it once.""")
    s.add_argument("--host", default=None, metavar="ADDR",
                   help="address to listen on (default: $MOTIONX_HOST or 127.0.0.1; 0.0.0.0 for every interface)")
    s.add_argument("--port", type=int, default=None, metavar="P", help="TCP port (default: $MOTIONX_PORT or 8000)")
    s.add_argument("--runner", default=None, metavar="NAME",  # checked by Settings (service.config.RUNNER_NAMES)
                   help="who runs the jobs: local (a process pool in this process) or celery (`motionx worker`s "
                        "over Redis) (default: $MOTIONX_RUNNER or local)")
    s.add_argument("--log-level", default="info", choices=["critical", "error", "warning", "info", "debug"],
                   help="uvicorn's log level")
    s.add_argument("--access-log", action="store_true", help="log every request")
    _db_args(s)
    s.set_defaults(func=cmd_serve)

    s = add_command(sub, "stack", "start the docker-compose topology as processes: Redis (AOF), "
                    "PostgreSQL database, API, N workers; Ctrl-C stops it", """\
Start the docker-compose.yml topology as plain processes: Redis with AOF on a free port, a
PostgreSQL database (or SQLite with --sqlite), migrations, the API and N Celery workers.
Prints the URLs and the API key; Ctrl-C or SIGTERM stops everything.""")
    s.add_argument("--workers", type=int, default=2, metavar="N", help="Celery workers to start")
    s.add_argument("--port", type=int, default=0, metavar="P", help="API port (0 = a free one)")
    s.add_argument("--data-dir", default="./motionx-stack", metavar="DIR",
                   help="Redis AOF, logs (and SQLite with --sqlite)")
    s.add_argument("--database-url", default=None, metavar="URL",
                   help="use this database instead of creating one (default: a new PostgreSQL database)")
    s.add_argument("--postgres-admin-url", default="postgresql://postgres@127.0.0.1:5432/postgres", metavar="URL",
                   help="PostgreSQL server where the database is created")
    s.add_argument("--postgres-db", default="motionx_stack", metavar="NAME", help="name of the database created")
    s.add_argument("--sqlite", action="store_true", help="SQLite in --data-dir instead of PostgreSQL")
    s.add_argument("--api-key", default=None, metavar="KEY", help="API key to accept (default: a new random one, "
                   "printed)")
    s.set_defaults(func=cmd_stack)

    s = add_command(sub, "db", "database schema (Alembic)", "Manage the database schema (Alembic migrations).")
    dsub = s.add_subparsers(dest="db_command", required=True, metavar="COMMAND")
    d = add_command(dsub, "upgrade", "upgrade the schema (default: to head)")
    d.add_argument("revision", nargs="?", default="head", help="Alembic revision to upgrade to (default: head)")
    _db_args(d)
    d.set_defaults(func=cmd_db_upgrade)

    s = add_command(sub, "apikey", "create or revoke API keys (stored hashed in SQL)",
                    "Create or revoke the API keys the HTTP API accepts (only their hashes are stored).")
    ksub = s.add_subparsers(dest="apikey_command", required=True, metavar="COMMAND")
    k = add_command(ksub, "create", "create an API key and print it once (JSON)")
    k.add_argument("--name", default="", metavar="TEXT", help="a note to recognise the key by (default: none)")
    _db_args(k)
    k.set_defaults(func=cmd_apikey_create)
    k = add_command(ksub, "revoke", "revoke an API key by its id (k_...)")
    k.add_argument("id", help="the key's id, as `apikey create` printed it")
    _db_args(k)
    k.set_defaults(func=cmd_apikey_revoke)

    s = add_command(sub, "openapi", "write the OpenAPI document of the HTTP API")
    s.add_argument("--out", default="-", metavar="FILE", help="output file, - for stdout")
    s.set_defaults(func=cmd_openapi)
