"""End to end with real components: Redis (our own, AOF), Celery worker processes,
PostgreSQL (our own database), the API under uvicorn — all over loopback HTTP.

Proven here:
- a job submitted over HTTP runs on a Celery worker and its motions come back over HTTP,
  identical to the local runner's (same tutor, same λ optima, bit for bit);
- kill a worker's pool process mid-job, and separately the whole worker: the job still
  finishes, exactly once in effect (attempts = 2, one set of motions, no duplicate step,
  identical to an uninterrupted run);
- restart Redis (gracefully, and as a crash) with jobs queued: none lost;
- cancel, Server-Sent Events.

Each crash/restart loop runs MOTIONX_RELIABILITY_REPEAT times (default 1 in make test; `make reliability` runs 20, e.g.
``MOTIONX_RELIABILITY_REPEAT=20 python -m pytest tests/service -k reliability``).
"""

from __future__ import annotations

import json
import os
import secrets
import signal
import time

import httpx
import pytest
from conftest import repeat_count
from svc_util import (
    CHEAP,
    KILLABLE,
    address_space_limit,
    children,
    deepmimic_files,
    job_motions,
    same_motions,
    wait_gone,
    wait_job,
)

from service.db import get_database
from service.models import JobRow, MotionRow
from service.topology import Stack, create_postgres_database, drop_postgres_database, wait_worker_ready

REPEAT = repeat_count(1)
# Short timeouts so a killed worker's job comes back within seconds (the production defaults
# are 1 h / 2 h): the job time limit stays well above the test jobs (a raw capture's natural
# tutor 5 s alone, steps 1-4 s) — 12x that on an idle machine, and times the machine's load per
# core when the stack starts (load 10 on 2 cores: x5), so that a busy machine slows the jobs
# without failing them.
BUSY = max(1.0, os.getloadavg()[0] / (os.cpu_count() or 1))
JOB_TIME_LIMIT_S = round(60 * BUSY)
JOB_STOP_GRACE_S = 2
#: above Celery's hard limit (the job limit + its grace + max(5 s, 10 %): service.config)
VISIBILITY_TIMEOUT_S = JOB_TIME_LIMIT_S + JOB_STOP_GRACE_S + max(5, -(-JOB_TIME_LIMIT_S // 10)) + 1
STACK_ENV = {
    "MOTIONX_JOB_LEASE_S": "3",
    "MOTIONX_JOB_TIME_LIMIT_S": str(JOB_TIME_LIMIT_S),
    "MOTIONX_JOB_STOP_GRACE_S": str(JOB_STOP_GRACE_S),
    "MOTIONX_VISIBILITY_TIMEOUT_S": str(VISIBILITY_TIMEOUT_S),
    "MOTIONX_UNACKED_RESTORE_INTERVAL_S": "1",
    "MOTIONX_UNACKED_RESTORE_THROTTLE": "1",
    "MOTIONX_SWEEP_INTERVAL_S": "3600",  # no re-dispatch by the API: Redis alone must keep the jobs
    "MOTIONX_JOBS_PER_KEY": "8",  # one key's jobs all in Redis at once (per-key turns: test_service_sharing.py)
    "MOTIONX_VALIDATE_STEPS": "true",
}


@pytest.fixture(scope="module")
def stack(tmp_path_factory, pg_admin, redis_binary):
    name = f"motionx_celery_test_{secrets.token_hex(4)}"
    url = create_postgres_database(pg_admin, name, exist_ok=False)
    st = Stack(data_dir=tmp_path_factory.mktemp("stack"), workers=2, database_url=url, extra_env=STACK_ENV)
    try:
        st.start()
        yield st
    finally:
        st.stop()
        for (pid, u), db in list(__import__("service.db", fromlist=["_ENGINES"])._ENGINES.items()):
            if u == url:
                db.dispose()
        drop_postgres_database(pg_admin, name)


@pytest.fixture(scope="module")
def client(stack):
    with httpx.Client(base_url=stack.base_url, headers={"X-API-Key": stack.api_keys}, timeout=30) as c:
        yield c


@pytest.fixture(scope="module")
def tutor_id(client, tutor_motion_json) -> str:
    r = client.post("/motions", content=tutor_motion_json, headers={"content-type": "application/json"})
    assert r.status_code == 201 and r.json()["kind"] == "motion"
    return r.json()["id"]


@pytest.fixture(scope="module")
def killable_reference(client, tutor_id) -> list[dict]:
    """The λ optima of an uninterrupted KILLABLE job: what every interrupted run must equal."""
    job = client.post(f"/motions/{tutor_id}/extrapolate", json=KILLABLE).json()
    done = wait_job(client, job["id"], timeout=120)
    assert done["status"] == "succeeded" and done["attempts"] == 1, done
    ref = job_motions(client, job["id"])
    assert len(ref) == done["steps"] >= 8
    return ref


def _job_row(stack, job_id) -> JobRow:
    with get_database(stack.database_url).read() as s:
        return s.get(JobRow, job_id)


def _assert_exactly_once(stack, client, job_id, reference) -> dict:
    job = client.get(f"/jobs/{job_id}").json()
    assert job["status"] == "succeeded", job
    got = job_motions(client, job_id)
    assert [m["step"] for m in got] == list(range(len(got)))  # no duplicate, no gap
    assert same_motions(got, reference)
    with get_database(stack.database_url).read() as s:  # and in SQL itself: one row per (job, step)
        rows = s.query(MotionRow).filter(MotionRow.job_id == job_id).all()
    assert sorted(r.step for r in rows) == list(range(len(reference)))
    return job


def _kill_worker_running(stack, client, job_id):
    """Once the job has stored 2 steps, SIGKILL the whole worker (process group) running it."""
    j = wait_job(client, job_id, timeout=60, until=_running_with_steps(2))
    assert j["status"] == "running", "the job must still be running when its worker is killed"
    pid = int(_job_row(stack, job_id).lease_owner.split(":")[1])
    victim = next(w for w in stack.worker_procs if w.alive() and os.getpgid(pid) == w.pid)
    victim.kill()
    return victim


def _running_with_steps(n):
    return lambda j: j["status"] in ("succeeded", "failed", "canceled", "impasse") or (
        j["status"] == "running" and j["steps"] >= n)


# --- e2e ------------------------------------------------------------------------------------


def test_celery_job_over_http_matches_local_runner(stack, client, api, shared_data):
    """Raw capture -> tutor -> extrapolation on a Celery worker; the same request on the
    embedded local runner (SQLite) gives the same tutor and the same λ optima, exactly."""
    results, jobs = {}, {}
    for name, c in (("celery", client), ("local", api.a)):  # one after the other: a tutor each, on 2 cores
        up = c.post("/motions", files=deepmimic_files(shared_data))
        assert up.status_code == 201 and up.json()["kind"] == "capture"
        r = c.post(f"/motions/{up.json()['id']}/extrapolate", json=CHEAP)
        assert r.status_code == 202 and r.headers["location"] == f"/jobs/{r.json()['id']}"
        results[name] = (r.json()["id"], c)
        jobs[name] = wait_job(c, r.json()["id"], timeout=180)
    for name, job in jobs.items():
        assert job["status"] == "succeeded", (name, job.get("message"), job)
        assert job["runner"] == name and job["attempts"] == 1 and job["lam_reached"] == 1.0
        phases = [p["phase"] for p in job["progress"]]
        assert phases[0] == "tutor" and phases.count("extrapolate") == job["solves"] + 1 >= 3  # + λ = 0, the tutor
        assert job["progress"][-1]["lam_reached"] == 1.0
        assert job["tutor_motion_id"] and job["links"]["tutor"] == f"/motions/{job['tutor_motion_id']}"
    tutors = [c.get(f"/motions/{jobs[n]['tutor_motion_id']}", params={"format": "motion"}).json()
              for n, (_, c) in results.items()]
    assert tutors[0]["frames"] == tutors[1]["frames"] and tutors[0]["wrenches"] == tutors[1]["wrenches"]
    celery_motions = job_motions(client, jobs["celery"]["id"], page=2)  # several pages
    local_motions = job_motions(api.a, jobs["local"]["id"])
    assert len(celery_motions) == jobs["celery"]["steps"] >= 2
    assert same_motions(celery_motions, local_motions)
    last = celery_motions[-1]["id"], [m for m in local_motions][-1]["id"]
    clips = [client.get(f"/motions/{last[0]}").content, api.a.get(f"/motions/{last[1]}").content]
    assert clips[0] == clips[1] and json.loads(clips[0])["format"] == "motionx.clip"
    rep = client.get(f"/motions/{last[0]}/validation").json()
    assert rep["plausible"] is True and "mujoco_replay" in rep


def test_events_stream_until_the_end(client, tutor_id):
    job = client.post(f"/motions/{tutor_id}/extrapolate", json=CHEAP).json()
    events = []
    with client.stream("GET", f"/jobs/{job['id']}/events", timeout=60) as r:
        assert r.headers["content-type"].startswith("text/event-stream")
        ev = None
        for line in r.iter_lines():
            if line.startswith("event: "):
                ev = line[7:]
            elif line.startswith("data: "):
                events.append((ev, json.loads(line[6:])))
                if ev == "end":
                    break
    kinds = [e for e, _ in events]
    assert kinds[-1] == "end" and events[-1][1]["status"] == "succeeded"
    final = client.get(f"/jobs/{job['id']}").json()
    # progress: every solve, and λ = 0 (the tutor itself, no solve)
    assert kinds.count("motion") == final["steps"] and kinds.count("progress") == final["solves"] + 1
    assert [d["step"] for e, d in events if e == "motion"] == list(range(final["steps"]))


def test_simulation_runs_on_a_celery_worker(client, tutor_id):
    """A simulation (POST /motions/{id}/simulation) is a job the Celery worker runs; its report
    and files are stored in PostgreSQL and served back."""
    r = client.post(f"/motions/{tutor_id}/simulation", json={"cycles": 1})
    assert r.status_code == 202, r.text
    assert client.get(f"/jobs/{r.json()['job_id']}").json()["runner"] == "celery"
    deadline = time.monotonic() + 180
    while not (sim := client.get(f"/motions/{tutor_id}/simulation").json())["terminal"]:
        assert time.monotonic() < deadline, sim
        time.sleep(0.2)
    assert sim["status"] == "succeeded", sim["message"]
    assert sim["report"]["cycles_walked"] > 0.99 and sim["report"]["fell"] is False
    glb = client.get(sim["links"]["simulated.glb"])
    assert glb.status_code == 200 and glb.content[:4] == b"glTF" and len(glb.content) == sim["files"]["simulated.glb"]


def test_cancel_running_job(stack, client, tutor_id):
    job = client.post(f"/motions/{tutor_id}/extrapolate", json=KILLABLE).json()
    wait_job(client, job["id"], timeout=60, until=_running_with_steps(2))
    r = client.post(f"/jobs/{job['id']}/cancel")
    assert r.status_code == 202
    done = wait_job(client, job["id"], timeout=60)
    assert done["status"] == "canceled" and done["lam_reached"] < 1.0
    assert len(job_motions(client, job["id"])) == done["steps"] >= 2
    assert client.post(f"/jobs/{job['id']}/cancel").status_code == 409


# --- crashes --------------------------------------------------------------------------------


@pytest.mark.parametrize("i", range(REPEAT))
def test_reliability_kill_pool_process_mid_job(stack, client, tutor_id, killable_reference, i):
    """SIGKILL the pool process running the job: Celery requeues it (acks_late +
    reject_on_worker_lost); a new attempt takes over and the job ends exactly once."""
    job = client.post(f"/motions/{tutor_id}/extrapolate", json=KILLABLE).json()
    j = wait_job(client, job["id"], timeout=60, until=_running_with_steps(2))
    assert j["status"] == "running", "the job must still be running when its process is killed"
    pid = int(_job_row(stack, job["id"]).lease_owner.split(":")[1])
    assert pid not in {w.pid for w in stack.worker_procs}  # a pool child, not the worker itself
    os.kill(pid, signal.SIGKILL)
    done = wait_job(client, job["id"], timeout=90)
    assert done["attempts"] == 2, done
    _assert_exactly_once(stack, client, job["id"], killable_reference)


@pytest.mark.parametrize("i", range(REPEAT))
def test_reliability_kill_whole_worker_mid_job(stack, client, tutor_id, killable_reference, i):
    """SIGKILL the whole worker (main process and pool): the unacknowledged job waits in
    Redis until the visibility timeout, then another worker runs it; exactly once."""
    job = client.post(f"/motions/{tutor_id}/extrapolate", json=KILLABLE).json()
    stack.worker_procs.remove(_kill_worker_running(stack, client, job["id"]))
    wait_worker_ready(stack.add_worker(), timeout=60)  # keep two workers for what follows
    done = wait_job(client, job["id"], timeout=VISIBILITY_TIMEOUT_S + 90)
    assert done["attempts"] == 2, done
    _assert_exactly_once(stack, client, job["id"], killable_reference)


@pytest.mark.parametrize("i", range(REPEAT))
def test_reliability_redis_restart_with_jobs_queued(stack, client, tutor_id, i):
    """Jobs queued in Redis survive a Redis restart thanks to AOF — a graceful restart on
    even rounds, a crash (SIGKILL after the 1 s fsync window) on odd ones."""
    for w in stack.worker_procs:  # nobody consumes: the jobs stay queued in Redis
        w.stop()
    stack.worker_procs.clear()
    n = 4
    ids = [client.post(f"/motions/{tutor_id}/extrapolate", json=CHEAP).json()["id"] for _ in range(n)]
    with stack.redis.client() as r:
        assert r.llen("motionx") == n
    if i % 2:
        time.sleep(1.5)  # appendfsync everysec
    stack.redis.restart(crash=bool(i % 2))
    with stack.redis.client() as r:
        assert r.llen("motionx") == n, "queued jobs lost in the Redis restart"
    for _ in range(2):
        stack.add_worker()
    for jid in ids:
        done = wait_job(client, jid, timeout=120)
        assert done["status"] == "succeeded" and done["attempts"] == 1, done
    for w in stack.worker_procs:
        wait_worker_ready(w, timeout=60)


def test_reliability_redis_restart_during_a_running_job(stack, client, tutor_id, killable_reference):
    """Redis goes away while a worker runs a job: the worker reconnects, the job finishes
    once (a redelivery, if any, finds it done)."""
    job = client.post(f"/motions/{tutor_id}/extrapolate", json=KILLABLE).json()
    wait_job(client, job["id"], timeout=60, until=_running_with_steps(2))
    stack.redis.restart()
    wait_job(client, job["id"], timeout=90)
    _assert_exactly_once(stack, client, job["id"], killable_reference)
    # the queue still works afterwards
    again = client.post(f"/motions/{tutor_id}/extrapolate", json=CHEAP).json()
    assert wait_job(client, again["id"], timeout=90)["status"] == "succeeded"


def test_broker_down_at_submission_loses_nothing(tmp_path, redis_binary, tutor_motion_json):
    """Redis is down when the job is created: the API still answers 202 (the job is in SQL,
    queued, undispatched); once Redis is back, the API's sweep dispatches it. (SQLite here.)"""
    st = Stack(data_dir=tmp_path, workers=1, extra_env={**STACK_ENV, "MOTIONX_SWEEP_INTERVAL_S": "1"})
    st.start()
    try:
        with httpx.Client(base_url=st.base_url, headers={"X-API-Key": st.api_keys}, timeout=30) as c:
            mid = c.post("/motions", content=tutor_motion_json,
                         headers={"content-type": "application/json"}).json()["id"]
            st.redis.stop()
            r = c.post(f"/motions/{mid}/extrapolate", json=CHEAP)
            assert r.status_code == 202 and r.json()["status"] == "queued"
            h = c.get("/health").json()
            assert h["status"] == "degraded" and h["broker"].startswith("unreachable")
            # while the broker is down the job stays queued in SQL (the sweep's attempts to publish it
            # are undone: service.store.undo_dispatch), never running
            t_end = time.monotonic() + 3.0
            while time.monotonic() < t_end:
                assert c.get(f"/jobs/{r.json()['id']}").json()["status"] == "queued"
                time.sleep(0.2)
            st.redis.start()
            done = wait_job(c, r.json()["id"], timeout=120)
            assert (done["status"], done["attempts"]) == ("succeeded", 1), done
    finally:
        st.stop()


# --- defaults and orphans -------------------------------------------------------------------------


def test_worker_pool_processes_die_with_their_worker_and_are_capped(stack, client):
    """SIGKILL of a worker's main process alone (not its process group): its pool processes
    exit within about a second (they watch their parent), instead of living on as orphans that
    finish jobs and idle. They run under the job memory cap (RLIMIT_AS, 2048 MB by default)."""
    w = stack.worker_procs[0]
    pool = children(w.pid)
    assert pool, "the worker has no pool process"
    assert {address_space_limit(p) for p in pool} == {2048 * 1024 * 1024}
    os.kill(w.pid, signal.SIGKILL)
    w.proc.wait(10)
    assert wait_gone(pool, timeout=5.0) == []
    stack.worker_procs.remove(w)
    w.stop()
    wait_worker_ready(stack.add_worker(), timeout=60)


def test_celery_recovers_a_killed_worker_with_default_settings(tmp_path, redis_binary, tutor_motion_json,
                                                               killable_reference):
    """The probe: with Celery's default settings (visibility timeout 7200 s), a job whose worker
    was SIGKILLed stayed 'running' for two hours. With the defaults now, the API's sweep
    re-dispatches it once its lease (15 s) has expired, and another worker takes it over:
    it ends exactly once, within a minute. (No timing setting is overridden here.)"""
    st = Stack(data_dir=tmp_path, workers=2)
    st.start()
    try:
        with httpx.Client(base_url=st.base_url, headers={"X-API-Key": st.api_keys}, timeout=30) as c:
            mid = c.post("/motions", content=tutor_motion_json,
                         headers={"content-type": "application/json"}).json()["id"]
            job = c.post(f"/motions/{mid}/extrapolate", json=KILLABLE).json()
            _kill_worker_running(st, c, job["id"])
            t0 = time.monotonic()
            done = wait_job(c, job["id"], timeout=180)
            recovery = time.monotonic() - t0
            assert (done["status"], done["attempts"]) == ("succeeded", 2), done
            got = job_motions(c, job["id"])
            assert [m["step"] for m in got] == list(range(len(got)))
            assert same_motions(got, killable_reference)
            print(f"recovered {recovery:.1f} s after the SIGKILL")
    finally:
        st.stop()
