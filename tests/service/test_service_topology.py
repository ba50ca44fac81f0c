"""docker-compose.yml and its process twin (`motionx stack`): same services, commands and
settings; the stack starts Redis (AOF), a PostgreSQL database, the API and N workers,
serves, and stops everything on SIGTERM."""

from __future__ import annotations

import json
import os
import secrets
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest
import yaml

from service.config import Settings
from service.topology import drop_postgres_database, service_env

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def compose() -> dict:
    return yaml.safe_load((ROOT / "docker-compose.yml").read_text())


def test_compose_has_the_services_and_reliability_settings(compose):
    svc = compose["services"]
    assert {"api", "worker", "redis", "postgres", "migrate"} <= set(svc)
    redis_cmd = svc["redis"]["command"]
    assert redis_cmd[redis_cmd.index("--appendonly") + 1] == "yes"
    assert svc["redis"]["volumes"] and svc["postgres"]["volumes"]
    assert svc["api"]["command"][:2] == ["motionx", "serve"]
    assert svc["worker"]["command"][:2] == ["motionx", "worker"]
    assert svc["migrate"]["command"] == ["motionx", "db", "upgrade"]
    assert "ports" not in svc["worker"] and "container_name" not in svc["worker"]  # scalable
    env = svc["worker"]["environment"]
    assert env == svc["api"]["environment"]
    s = Settings(**{k[len("MOTIONX_"):].lower(): v for k, v in env.items()
                    if k.startswith("MOTIONX_") and k != "MOTIONX_API_KEYS"},
                 database_url=env["DATABASE_URL"])
    assert s.runner == "celery" and s.sqlalchemy_url.startswith("postgresql+psycopg://")
    assert s.visibility_timeout_s > s.hard_time_limit_s


def test_compose_environment_names_are_settings(compose):
    """Every MOTIONX_* variable of the compose file is a real setting (a typo would be ignored silently)."""
    fields = {f"MOTIONX_{name.upper()}" for name in Settings.model_fields}
    env = compose["services"]["api"]["environment"]
    unknown = [k for k in env if k.startswith("MOTIONX_") and k not in fields]
    assert not unknown
    stack_env = service_env(database_url="sqlite://", broker_url="redis://x", api_keys="k", data_dir=Path("/tmp"))
    assert {k for k in env} <= set(stack_env) | {"MOTIONX_JOB_TIME_LIMIT_S", "MOTIONX_VISIBILITY_TIMEOUT_S",
                                                  "MOTIONX_JOB_MAX_ATTEMPTS", "MOTIONX_JOB_LEASE_S",
                                                  "MOTIONX_JOB_MEMORY_MB", "MOTIONX_COMPUTE_MEMORY_MB",
                                                  "MOTIONX_COMPUTE_WORKERS", "MOTIONX_JOB_SLOTS"}


def test_dockerfile_installs_every_package():
    text = (ROOT / "Dockerfile").read_text()
    for pkg in ("solver", "mjcf", "service", "worker"):
        assert f"COPY {pkg} ./{pkg}" in text


def _pids_alive(pids) -> list[int]:
    alive = []
    for p in pids:
        try:
            os.kill(p, 0)
            with open(f"/proc/{p}/stat") as f:
                if f.read().rsplit(")", 1)[1].split()[0] != "Z":
                    alive.append(p)
        except (ProcessLookupError, FileNotFoundError):
            pass
    return alive


def test_motionx_stack_starts_serves_and_stops(tmp_path, pg_admin, redis_binary):
    db_name = f"motionx_stack_test_{secrets.token_hex(4)}"
    key = "stack-key-" + secrets.token_hex(6)
    proc = subprocess.Popen(
        [sys.executable, "-m", "service.cli", "stack", "--workers", "2", "--data-dir", str(tmp_path / "stack"),
         "--postgres-admin-url", pg_admin, "--postgres-db", db_name, "--api-key", key],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, start_new_session=True,
    )
    try:
        ready, _, _ = select.select([proc.stdout], [], [], 120)  # bounded wait for the stack's JSON line
        assert ready, "motionx stack printed nothing within 120 s"
        line = proc.stdout.readline()
        assert line, proc.stderr.read()
        info = json.loads(line)
        assert info["database"].endswith(f"/{db_name}") and len(info["workers"]) == 2
        with httpx.Client(base_url=info["api"], headers={"X-API-Key": key}, timeout=10) as c:
            h = c.get("/health").json()
            assert (h["status"], h["runner"], h["broker"], h["database"]) == ("ok", "celery", "ok", "ok")
            assert c.get("/jobs").status_code == 200
        aof = list((tmp_path / "stack" / "redis").rglob("*.aof*"))
        assert aof, "Redis runs with AOF persistence"
        pids = list(info["pids"].values())
        assert len(_pids_alive(pids)) == 4
        # a dead worker is restarted after its back-off (1 s), and nothing else stops or restarts
        dead = info["workers"][0]
        os.killpg(info["pids"][dead], signal.SIGKILL)
        events, deadline = [], time.monotonic() + 30
        while not any(e.get("restarted") == dead for e in events) and time.monotonic() < deadline:
            ready, _, _ = select.select([proc.stderr], [], [], 1.0)
            if ready:
                line = proc.stderr.readline()
                if line.startswith("{"):
                    events.append(json.loads(line))
        assert [e.get("exited") for e in events if "exited" in e] == [dead], events
        new_pid = next(e["pid"] for e in events if e.get("restarted") == dead)
        others = [pid for name, pid in info["pids"].items() if name != dead]
        assert proc.poll() is None and len(_pids_alive([*others, new_pid])) == 4
        with httpx.Client(base_url=info["api"], headers={"X-API-Key": key}, timeout=10) as c:
            assert c.get("/health").json()["status"] == "ok"
        pids = [*others, new_pid]
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(60) == 0
        deadline = time.monotonic() + 20
        while _pids_alive(pids) and time.monotonic() < deadline:
            time.sleep(0.2)
        assert not _pids_alive(pids)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait(10)
        drop_postgres_database(pg_admin, db_name)


def test_restart_backoff_doubles_after_short_runs_and_resets_after_a_stable_one():
    from service.topology import Backoff

    b = Backoff(first_s=1.0, max_s=8.0, stable_s=60.0)
    t = 1000.0
    delays = []
    for _ in range(6):  # dies right after each start
        delays.append(b.died(t, t - 0.5) - t)
    assert delays == [1.0, 2.0, 4.0, 8.0, 8.0, 8.0]
    assert b.died(t, t - 120.0) - t == 1.0  # it ran for 2 minutes: the back-off starts over
