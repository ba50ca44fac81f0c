"""Database engine and sessions (SQLite in WAL mode by default, PostgreSQL by URL).

One code path for both: the only dialect differences are the connection set-up below
(SQLite pragmas and ``BEGIN IMMEDIATE`` for writing transactions) and the upsert
construct picked in :func:`service.store.insert_for`.

Engines are created on demand (never at import time) and cached per process and URL,
so a forked or spawned job process opens its own connections.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from sqlalchemy import Engine, create_engine, event
from sqlalchemy.engine import make_url
from sqlalchemy.orm import Session, sessionmaker

_ENGINES: dict[tuple[int, str], Database] = {}
_LOCK = threading.Lock()


class Database:
    """An engine plus two session factories: ``read()`` and ``write()`` (both context managers).

    ``write()`` starts the transaction with ``BEGIN IMMEDIATE`` on SQLite (the write lock is
    taken up front, so a read-then-write transaction cannot fail with SQLITE_BUSY half-way);
    on PostgreSQL both are ordinary transactions (row locks via ``SELECT ... FOR UPDATE``).
    """

    def __init__(self, url: str, *, echo: bool = False) -> None:
        self.url = url
        self.engine = _make_engine(url, echo=echo)
        self.is_sqlite = self.engine.dialect.name == "sqlite"
        self._read = sessionmaker(self.engine, expire_on_commit=False)
        writer = self.engine.execution_options(motionx_write=True) if self.is_sqlite else self.engine
        self._write = sessionmaker(writer, expire_on_commit=False)

    @contextmanager
    def read(self) -> Iterator[Session]:
        with self._read() as s:
            yield s

    @contextmanager
    def write(self) -> Iterator[Session]:
        """A transaction committed on success, rolled back on error."""
        with self._write() as s, s.begin():
            yield s

    def dispose(self) -> None:
        self.engine.dispose()


def _make_engine(url: str, *, echo: bool = False) -> Engine:
    u = make_url(url)
    if u.get_backend_name() == "sqlite":
        if u.database and u.database != ":memory:":
            Path(u.database).expanduser().parent.mkdir(parents=True, exist_ok=True)
        engine = create_engine(
            url, echo=echo, connect_args={"check_same_thread": False, "timeout": 30.0}, pool_pre_ping=False
        )

        @event.listens_for(engine, "connect")
        def _on_connect(dbapi_conn, _record):  # pragma: no cover - exercised by every SQLite test
            dbapi_conn.isolation_level = None  # we emit BEGIN ourselves (see _on_begin)
            cur = dbapi_conn.cursor()
            cur.execute("PRAGMA journal_mode=WAL")
            cur.execute("PRAGMA synchronous=NORMAL")
            cur.execute("PRAGMA foreign_keys=ON")
            cur.execute("PRAGMA busy_timeout=30000")
            cur.close()

        @event.listens_for(engine, "begin")
        def _on_begin(conn):
            conn.exec_driver_sql("BEGIN IMMEDIATE" if conn.get_execution_options().get("motionx_write") else "BEGIN")

        return engine
    return create_engine(url, echo=echo, pool_pre_ping=True, pool_size=5, max_overflow=10)


def get_database(url: str) -> Database:
    """The process's :class:`Database` for ``url`` (created on first use)."""
    key = (os.getpid(), url)
    with _LOCK:
        db = _ENGINES.get(key)
        if db is None:
            db = _ENGINES[key] = Database(url)
        return db


def migrations_dir() -> Path:
    return Path(__file__).with_name("migrations")


def alembic_config(url: str):
    from alembic.config import Config  # lazy: Alembic only for migrations

    cfg = Config()
    cfg.set_main_option("script_location", str(migrations_dir()))
    cfg.set_main_option("sqlalchemy.url", url.replace("%", "%%"))
    cfg.attributes["motionx_url"] = url
    return cfg


def upgrade(url: str, revision: str = "head") -> None:
    """Bring the schema at ``url`` to ``revision`` (Alembic)."""
    from alembic import command  # lazy: Alembic only for migrations

    command.upgrade(alembic_config(url), revision)


def current_revision(url: str) -> str | None:
    from alembic.runtime.migration import MigrationContext  # lazy: Alembic only for migrations

    db = get_database(url)
    with db.engine.connect() as conn:
        return MigrationContext.configure(conn).get_current_revision()
