"""Fixtures with real components: our own Redis (AOF, free port), our own PostgreSQL
database (created and dropped on 127.0.0.1:5432), the API as a uvicorn process over HTTP.

Environment:
  MOTIONX_TEST_PG_ADMIN  admin URL of the PostgreSQL server (default postgresql://postgres@127.0.0.1:5432/postgres)
  MOTIONX_RELIABILITY_REPEAT  repetitions of the crash/restart loops (default sized for `make test`)
"""

from __future__ import annotations

import os
import secrets
import shutil
from pathlib import Path

import httpx
import pytest
from svc_util import KEY_A, KEY_B

from service.topology import (
    Proc,
    RedisServer,
    create_postgres_database,
    drop_postgres_database,
    free_port,
    motionx_cmd,
    wait_api,
)

PG_ADMIN = os.environ.get("MOTIONX_TEST_PG_ADMIN", "postgresql://postgres@127.0.0.1:5432/postgres")


def _pg_available() -> str | None:
    try:
        import psycopg

        with psycopg.connect(PG_ADMIN, connect_timeout=3) as c:
            c.execute("SELECT 1")
        return None
    except Exception as e:
        return str(e)


@pytest.fixture(scope="session")
def pg_admin() -> str:
    err = _pg_available()
    if err:
        pytest.fail(f"PostgreSQL not reachable at {PG_ADMIN} ({err}); .ci/run starts it")
    return PG_ADMIN


@pytest.fixture(scope="session")
def pg_url(pg_admin) -> str:
    """A fresh database on the shared server, dropped at the end of the session."""
    name = f"motionx_test_{os.getpid()}_{secrets.token_hex(3)}"
    url = create_postgres_database(pg_admin, name, exist_ok=False)
    yield url
    from service.db import _ENGINES

    for (pid, u), db in list(_ENGINES.items()):
        if u == url:
            db.dispose()
            del _ENGINES[(pid, u)]
    drop_postgres_database(pg_admin, name)


@pytest.fixture(scope="session")
def redis_binary() -> str:
    exe = shutil.which("redis-server")
    if exe is None:
        pytest.fail("redis-server not installed (apt-get install redis-server); .ci/run installs it")
    return exe


@pytest.fixture
def redis_server(tmp_path, redis_binary):
    """Our own redis-server with AOF on a free port (never the machine's shared 6379)."""
    r = RedisServer(tmp_path / "redis").start()
    yield r
    r.stop()


class Api:
    """The API over HTTP (uvicorn in its own process)."""

    def __init__(self, proc: Proc, base_url: str, data_dir: Path) -> None:
        self.proc, self.base_url, self.data_dir = proc, base_url, data_dir
        self.a = httpx.Client(base_url=base_url, headers={"X-API-Key": KEY_A}, timeout=30)
        self.b = httpx.Client(base_url=base_url, headers={"X-API-Key": KEY_B}, timeout=30)
        self.anon = httpx.Client(base_url=base_url, timeout=30)

    def close(self) -> None:
        for c in (self.a, self.b, self.anon):
            c.close()


def start_api_process(data_dir: Path, env_extra: dict[str, str] | None = None) -> Api:
    port = free_port()
    env = dict(os.environ)
    env.update(MOTIONX_DATA_DIR=str(data_dir), MOTIONX_API_KEYS=f"{KEY_A},{KEY_B}", MOTIONX_RUNNER="local",
               MOTIONX_LOCAL_WORKERS="1", PYTHONUNBUFFERED="1", MOTIONX_MAX_BODY_BYTES=str(2 * 1024 * 1024))
    env.pop("DATABASE_URL", None)
    env.update(env_extra or {})
    proc = Proc("api", motionx_cmd("serve", "--port", str(port)), env, data_dir / "api.log").start()
    base = f"http://127.0.0.1:{port}"
    try:
        wait_api(base, proc, timeout=60)
    except Exception:
        proc.stop()
        raise
    return Api(proc, base, data_dir)


@pytest.fixture(scope="module")
def api(tmp_path_factory):
    """``motionx serve`` (embedded default: SQLite + local runner) on a free port."""
    d = tmp_path_factory.mktemp("api")
    a = start_api_process(d)
    yield a
    a.close()
    a.proc.stop()


@pytest.fixture(scope="session")
def tutor_motion_json(shared_data) -> str:
    from svc_util import tutor_json

    return tutor_json(shared_data)


def repeat_count(default: int) -> int:
    """MOTIONX_RELIABILITY_REPEAT: repetitions of each crash/restart loop (20+ to trust it)."""
    return max(1, int(os.environ.get("MOTIONX_RELIABILITY_REPEAT", default)))
