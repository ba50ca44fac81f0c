"""The docker-compose topology as plain processes (Docker cannot run everywhere).

Redis with AOF persistence on a free port, a PostgreSQL database (or SQLite), the API
(``motionx serve``) and N Celery workers (``motionx worker``) — the same services,
commands and environment variables as ``docker-compose.yml``. Used by ``motionx stack``
and by the integration tests (which kill and restart these processes).
"""

from __future__ import annotations

import json
import logging
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import time
import urllib.error
import urllib.request
from dataclasses import dataclass, field
from pathlib import Path
from typing import IO, Any

from tenacity import RetryError, Retrying, retry_if_exception, retry_if_result, stop_after_delay, wait_fixed

log = logging.getLogger(__name__)


class TopologyError(RuntimeError):
    pass


def free_port(host: str = "127.0.0.1") -> int:
    with socket.socket() as s:
        s.bind((host, 0))
        return s.getsockname()[1]


def wait_until(pred, timeout: float, what: str, interval: float = 0.1):
    """``pred()``'s first true answer, asked every ``interval`` seconds for at most ``timeout``
    seconds. An exception is retried too (the server is not listening yet), except a
    ``TopologyError``: the process waited for has exited, which is raised at once."""
    retrying = Retrying(stop=stop_after_delay(timeout), wait=wait_fixed(interval),
                        retry=retry_if_result(lambda v: not v)
                        | retry_if_exception(lambda e: not isinstance(e, TopologyError)))
    try:
        return retrying(pred)
    except RetryError as e:
        last = e.last_attempt
        why = f" ({last.exception()})" if last.failed else ""
        raise TopologyError(f"timed out after {timeout:g} s waiting for {what}{why}") from None


# --- Redis ------------------------------------------------------------------------------


@dataclass
class RedisServer:
    """redis-server with AOF (``appendfsync everysec``) in ``dir``, bound to loopback."""

    dir: Path
    port: int = 0
    appendonly: bool = True
    fsync: str = "everysec"
    binary: str = "redis-server"
    proc: subprocess.Popen | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self.dir = Path(self.dir)
        if not self.port:
            self.port = free_port()

    @property
    def url(self) -> str:
        return f"redis://127.0.0.1:{self.port}/0"

    def start(self, timeout: float = 15.0) -> RedisServer:
        exe = shutil.which(self.binary)
        if exe is None:
            raise TopologyError("redis-server not found (apt-get install redis-server)")
        self.dir.mkdir(parents=True, exist_ok=True)
        args = [
            exe, "--port", str(self.port), "--bind", "127.0.0.1", "--dir", str(self.dir),
            "--appendonly", "yes" if self.appendonly else "no", "--appendfsync", self.fsync,
            "--save", "", "--daemonize", "no", "--logfile", str(self.dir / "redis.log"),
            "--protected-mode", "yes",
        ]
        self.proc = subprocess.Popen(args, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                                     start_new_session=True)
        wait_until(self.ping, timeout, f"redis on port {self.port}")
        return self

    def client(self):
        import redis  # lazy: only `motionx stack` needs it

        return redis.Redis(host="127.0.0.1", port=self.port, socket_timeout=5, socket_connect_timeout=2)

    def ping(self) -> bool:
        if self.proc is not None and self.proc.poll() is not None:
            raise TopologyError(f"redis-server exited with {self.proc.returncode} (see {self.dir / 'redis.log'})")
        with self.client() as c:
            # while loading the AOF, redis answers LOADING errors: not ready yet
            return bool(c.ping()) and c.info("persistence").get("loading", 0) == 0

    def stop(self, timeout: float = 15.0) -> None:
        """Graceful: SIGTERM makes redis fsync the AOF and exit."""
        if self.proc is None or self.proc.poll() is not None:
            return
        self.proc.send_signal(signal.SIGTERM)
        try:
            self.proc.wait(timeout)
        except subprocess.TimeoutExpired:
            self.proc.kill()
            self.proc.wait(5)

    def kill(self) -> None:
        """A crash: SIGKILL, no final fsync (AOF everysec loses at most ~1 s of writes)."""
        if self.proc is not None and self.proc.poll() is None:
            self.proc.kill()
            self.proc.wait(10)

    def restart(self, *, crash: bool = False, timeout: float = 15.0) -> None:
        self.kill() if crash else self.stop()
        self.start(timeout)


# --- PostgreSQL -------------------------------------------------------------------------


def _pg_admin(admin_url: str):
    import psycopg  # lazy: only `motionx stack` needs it

    return psycopg.connect(admin_url.replace("postgresql+psycopg://", "postgresql://"), autocommit=True,
                           connect_timeout=5)


def create_postgres_database(admin_url: str, name: str, *, exist_ok: bool = True) -> str:
    """Create database ``name`` on the server of ``admin_url``; returns its SQLAlchemy URL."""
    from psycopg import sql  # lazy: only `motionx stack` needs it
    from sqlalchemy.engine import make_url

    with _pg_admin(admin_url) as conn:
        exists = conn.execute("SELECT 1 FROM pg_database WHERE datname = %s", (name,)).fetchone()
        if exists and not exist_ok:
            raise TopologyError(f"database {name!r} exists")
        if not exists:
            conn.execute(sql.SQL("CREATE DATABASE {}").format(sql.Identifier(name)))
    u = make_url(admin_url).set(drivername="postgresql+psycopg", database=name)
    return u.render_as_string(hide_password=False)


def drop_postgres_database(admin_url: str, name: str) -> None:
    from psycopg import sql  # lazy: only `motionx stack` needs it

    with _pg_admin(admin_url) as conn:
        conn.execute(sql.SQL("DROP DATABASE IF EXISTS {} WITH (FORCE)").format(sql.Identifier(name)))


class PostgresServer:
    """A PostgreSQL cluster in a temporary folder of its own (initdb, trust auth) on a free
    loopback port, run as the ``postgres`` user when we are root (the server refuses to run as
    root, and cannot enter pytest's private temporary folders). ``stop()``/``start()`` is a real
    server restart: every connection is cut. ``remove()`` deletes the folder."""

    def __init__(self) -> None:
        import tempfile

        self.root, self.port = Path(tempfile.mkdtemp(prefix="motionx-pg-")), free_port()
        self.data, self.log = self.root / "pgdata", self.root / "pg.log"
        self.bin = Path(shutil.which("pg_ctl") or "pg_ctl").resolve().parent

    def _run(self, *args: str, check: bool = True):
        cmd = [str(self.bin / args[0]), *args[1:]]
        if os.geteuid() == 0:
            cmd = ["runuser", "-u", "postgres", "--", *cmd]
        return subprocess.run(cmd, check=check, capture_output=True, text=True, timeout=120)

    def init(self) -> PostgresServer:
        self.root.mkdir(parents=True, exist_ok=True)
        if os.geteuid() == 0:
            shutil.chown(self.root, "postgres", "postgres")
        self._run("initdb", "-D", str(self.data), "-A", "trust", "-U", "postgres", "--no-sync")
        return self

    def start(self) -> None:
        opts = f"-p {self.port} -k {self.root} -c listen_addresses=127.0.0.1 -c fsync=off"
        self._run("pg_ctl", "-D", str(self.data), "-l", str(self.log), "-o", opts, "-w", "start")

    def stop(self) -> None:
        self._run("pg_ctl", "-D", str(self.data), "-m", "fast", "-w", "stop", check=False)

    def remove(self) -> None:
        self.stop()
        shutil.rmtree(self.root, ignore_errors=True)

    @property
    def admin_url(self) -> str:
        return f"postgresql://postgres@127.0.0.1:{self.port}/postgres"


# --- API and workers --------------------------------------------------------------------


def motionx_cmd(*args: str) -> list[str]:
    return [sys.executable, "-m", "service.cli", *args]


def service_env(*, database_url: str, broker_url: str, api_keys: str, data_dir: Path,
                extra: dict[str, str] | None = None) -> dict[str, str]:
    env = dict(os.environ)
    env.update(
        MOTIONX_RUNNER="celery", DATABASE_URL=database_url, MOTIONX_DATABASE_URL=database_url,
        MOTIONX_BROKER_URL=broker_url, MOTIONX_API_KEYS=api_keys, MOTIONX_DATA_DIR=str(data_dir),
        MOTIONX_AUTO_MIGRATE="false", PYTHONUNBUFFERED="1",
    )
    env.update(extra or {})
    return env


@dataclass
class Proc:
    """A child process in its own session (so the whole group can be killed)."""

    name: str
    args: list[str]
    env: dict[str, str]
    log_path: Path
    proc: subprocess.Popen | None = field(default=None, repr=False)
    _log: IO | None = field(default=None, repr=False)

    def start(self) -> Proc:
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        self._log = open(self.log_path, "ab")  # noqa: SIM115 (the process writes it until stop() closes it)
        self.proc = subprocess.Popen(self.args, env=self.env, stdout=self._log, stderr=subprocess.STDOUT,
                                     start_new_session=True, cwd=str(Path(__file__).resolve().parents[1]))
        return self

    @property
    def pid(self) -> int:
        assert self.proc is not None
        return self.proc.pid

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None

    def log_text(self) -> str:
        try:
            return self.log_path.read_text(errors="replace")
        except FileNotFoundError:
            return ""

    def stop(self, timeout: float = 20.0, sig: int = signal.SIGTERM) -> None:
        if self.proc is None:
            return
        if self.proc.poll() is None:
            try:
                os.killpg(self.proc.pid, sig)
            except ProcessLookupError:
                pass
            try:
                self.proc.wait(timeout)
            except subprocess.TimeoutExpired:
                self.kill()
        self._reap_group()
        if self._log:
            self._log.close()
            self._log = None

    def kill(self) -> None:
        """SIGKILL the whole process group (main process and its pool children)."""
        if self.proc is None:
            return
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        self.proc.wait(10)
        self._reap_group()

    def _reap_group(self) -> None:
        # pool children of a killed worker may outlive it for a moment: make sure they go
        try:
            os.killpg(self.proc.pid, signal.SIGKILL)
        except (ProcessLookupError, PermissionError):
            pass


def start_api(env: dict[str, str], *, port: int, log_path: Path, host: str = "127.0.0.1") -> Proc:
    return Proc("api", motionx_cmd("serve", "--host", host, "--port", str(port)), env, log_path).start()


def start_worker(env: dict[str, str], *, name: str, log_path: Path, concurrency: int = 1) -> Proc:
    return Proc(name, motionx_cmd("worker", "--hostname", f"{name}@%h", "--concurrency", str(concurrency)),
                env, log_path).start()


def http_json(url: str, *, method: str = "GET", body: dict | None = None, headers: dict | None = None,
              timeout: float = 10.0) -> tuple[int, dict]:
    data = json.dumps(body).encode() if body is not None else None
    req = urllib.request.Request(url, data=data, method=method, headers={
        **({"content-type": "application/json"} if data else {}), **(headers or {})})
    try:
        with urllib.request.urlopen(req, timeout=timeout) as r:
            return r.status, json.loads(r.read() or b"{}")
    except urllib.error.HTTPError as e:
        return e.code, json.loads(e.read() or b"{}")


def wait_api(base_url: str, proc: Proc | None = None, timeout: float = 60.0) -> dict:
    def ready():
        if proc is not None and not proc.alive():
            raise TopologyError(f"{proc.name} exited:\n{proc.log_text()[-3000:]}")
        code, body = http_json(base_url + "/health", timeout=2)
        return body if code == 200 else None

    return wait_until(ready, timeout, f"API at {base_url}", interval=0.2)


def wait_worker_ready(worker: Proc, timeout: float = 60.0) -> None:
    def ready():
        if not worker.alive():
            raise TopologyError(f"{worker.name} exited:\n{worker.log_text()[-3000:]}")
        return " ready." in worker.log_text()

    wait_until(ready, timeout, f"worker {worker.name}", interval=0.2)


@dataclass
class Backoff:
    """When a process that died may be started again: 1 s after its first death, then twice as
    long after each death that follows a short run (shorter than ``stable_s``), at most ``max_s``;
    a run of ``stable_s`` or more resets it — as a container restart policy does."""

    first_s: float = 1.0
    max_s: float = 60.0
    stable_s: float = 60.0
    delay: float = 0.0
    due: float | None = None
    restarts: int = 0

    def died(self, now: float, started: float) -> float:
        """A death seen at ``now`` of a process started at ``started``: the time it may start again."""
        ran = now - started
        self.delay = self.first_s if ran >= self.stable_s or not self.delay else min(self.max_s, 2 * self.delay)
        self.due = now + self.delay
        return self.due


@dataclass
class Stack:
    """Redis (AOF) + database + API + N workers, as processes. ``start()`` / ``stop()``;
    ``supervise()``, called every second or so, restarts a process that died (with
    :class:`Backoff`) while the others keep running."""

    data_dir: Path
    workers: int = 2
    concurrency: int = 1
    port: int = 0
    database_url: str | None = None  # None: SQLite in data_dir
    api_keys: str = ""
    extra_env: dict[str, str] = field(default_factory=dict)
    redis: RedisServer | None = None
    api: Proc | None = None
    worker_procs: list[Proc] = field(default_factory=list)
    backoff: dict[str, Backoff] = field(default_factory=dict)
    started: dict[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        self.data_dir = Path(self.data_dir)
        self.port = self.port or free_port()
        self.api_keys = self.api_keys or ("mx_" + secrets.token_urlsafe(24))
        self.database_url = self.database_url or f"sqlite:///{self.data_dir / 'motionx.db'}"

    @property
    def base_url(self) -> str:
        return f"http://127.0.0.1:{self.port}"

    @property
    def env(self) -> dict[str, str]:
        assert self.redis is not None
        return service_env(database_url=self.database_url, broker_url=self.redis.url, api_keys=self.api_keys,
                           data_dir=self.data_dir,
                           extra={"MOTIONX_JOB_SLOTS": str(self.workers * self.concurrency), **self.extra_env})

    def start(self, timeout: float = 90.0) -> Stack:
        from service.db import upgrade  # lazy: only `motionx stack` needs it

        self.data_dir.mkdir(parents=True, exist_ok=True)
        self.redis = RedisServer(self.data_dir / "redis").start()
        upgrade(self.database_url)
        self.api = start_api(self.env, port=self.port, log_path=self.data_dir / "logs" / "api.log")
        self.started["api"] = time.monotonic()
        for _ in range(self.workers):
            self.add_worker()
        wait_api(self.base_url, self.api, timeout)
        for w in self.worker_procs:
            wait_worker_ready(w, timeout)
        return self

    def add_worker(self) -> Proc:
        i = len(self.worker_procs)
        name = f"worker{i + 1}-{secrets.token_hex(2)}"
        w = start_worker(self.env, name=name, log_path=self.data_dir / "logs" / f"{name}.log",
                         concurrency=self.concurrency)
        self.worker_procs.append(w)
        self.started[name] = time.monotonic()
        return w

    def supervise(self, now: float | None = None) -> list[dict]:
        """Restart what died (Redis, the API, a worker), each after its back-off; the others keep
        running. Returns what happened (one dict per death seen or restart made)."""
        now = time.monotonic() if now is None else now
        events: list[dict] = []
        procs: list[tuple[str, Any]] = [("api", self.api), *((w.name, w) for w in self.worker_procs)]
        if self.redis is not None:
            procs.insert(0, ("redis", self.redis))
        for name, p in procs:
            alive = (p.proc is not None and p.proc.poll() is None) if name == "redis" else p.alive()
            if alive:
                continue
            b = self.backoff.setdefault(name, Backoff())
            if b.due is None:
                code = p.proc.returncode if p.proc is not None else None
                due = b.died(now, self.started.get(name, now))
                events.append({"exited": name, "status": code, "restart_in_s": round(due - now, 1)})
                continue
            if now < b.due:
                continue
            try:
                if name == "redis":
                    p.start()
                else:
                    p.stop(timeout=2)  # closes its log; reaps what is left of its process group
                    p.start()
            except (OSError, TopologyError) as e:
                due = b.died(now, now)
                events.append({"restart_failed": name, "error": str(e)[:200], "restart_in_s": round(due - now, 1)})
                continue
            b.due, b.restarts = None, b.restarts + 1
            self.started[name] = now
            events.append({"restarted": name, "pid": p.proc.pid if p.proc is not None else None,
                           "restarts": b.restarts})
        return events

    def describe(self) -> dict:
        return {
            "api": self.base_url, "redis": self.redis.url if self.redis else None, "database": self.database_url,
            "api_key": self.api_keys.split(",")[0], "workers": [w.name for w in self.worker_procs],
            "pids": {"api": self.api.pid if self.api else None, "redis": self.redis.proc.pid if self.redis else None,
                     **{w.name: w.pid for w in self.worker_procs}},
            "logs": str(self.data_dir / "logs"),
        }

    def stop(self) -> None:
        for w in self.worker_procs:
            w.stop()
        if self.api:
            self.api.stop()
        if self.redis:
            self.redis.stop()
