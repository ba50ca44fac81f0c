"""Bounds that hold inside a job, and processes that go with the API (embedded default:
`motionx serve`, SQLite, local runner; real jobs, real signals).

- a cancel is honoured in the middle of a long IPOPT solve (the job's watchdog), and the time
  limit too (IPOPT's max_wall_time): the probe saw neither stop a job for 5+ minutes;
- every job process runs under the memory cap (RLIMIT_AS);
- after SIGTERM, SIGINT or SIGKILL of `motionx serve` no process of it is left (the probe found
  pool workers and the multiprocessing resource tracker alive with PPID 1, finishing jobs).
"""

from __future__ import annotations

import json
import os
import signal
import time

import pytest
from conftest import start_api_process
from svc_util import CHEAP, KILLABLE, address_space_limit, children, cmdline, wait_gone, wait_job

TIME_LIMIT_S = 8.0
GRACE_S = 1.0


def long_tutor(tutor_json: str, frames: int = 116) -> str:
    """A motion with wrenches of ``frames`` frames (within the tutor limits: 116 frames at
    30 fps = 3.8 s) whose base solve takes far longer than the test's time limit: the
    DeepMimic tutor's cycle repeated (walking on), played twice as fast."""
    d = json.loads(tutor_json)
    per = len(d["frames"]) - 2  # a cyclic tutor: its last two frames repeat the first two
    x = d["coordinates"].index("root_tx")
    stride = d["frames"][per][x] - d["frames"][0][x]
    idx = [k % per for k in range(frames)]
    rows = []
    for k, i in enumerate(idx):
        row = list(d["frames"][i])
        row[x] += stride * (k // per)
        rows.append(row)
    d["frames"] = rows
    d["contacts"]["active"] = [d["contacts"]["active"][i] for i in idx]
    for foot in ("right", "left"):
        d["wrenches"]["feet"][foot] = [d["wrenches"]["feet"][foot][i] for i in idx]
    d["fps"] = 30.0
    d.pop("report", None)
    return json.dumps(d)


@pytest.fixture(scope="module")
def capped(tmp_path_factory):
    """An API whose jobs have a short time limit and watchdog grace, and a memory cap."""
    a = start_api_process(tmp_path_factory.mktemp("bounds"), {
        "MOTIONX_JOB_TIME_LIMIT_S": str(TIME_LIMIT_S), "MOTIONX_JOB_STOP_GRACE_S": str(GRACE_S),
        "MOTIONX_JOB_LEASE_S": "4", "MOTIONX_JOB_MEMORY_MB": "2500", "MOTIONX_SWEEP_INTERVAL_S": "1"})
    yield a
    a.close()
    a.proc.stop()


@pytest.fixture(scope="module")
def long_id(capped, tutor_motion_json) -> str:
    r = capped.a.post("/motions", content=long_tutor(tutor_motion_json), headers={"content-type": "application/json"})
    assert r.status_code == 201 and r.json()["kind"] == "motion" and r.json()["frames"] == 116, r.text
    return r.json()["id"]


@pytest.fixture(scope="module")
def tutor_id(capped, tutor_motion_json) -> str:
    r = capped.a.post("/motions", content=tutor_motion_json, headers={"content-type": "application/json"})
    assert r.status_code == 201
    return r.json()["id"]


def test_cancel_is_honoured_inside_a_solve(capped, long_id, tutor_id):
    job = capped.a.post(f"/motions/{long_id}/extrapolate", json={"target": {"slope_deg": 4.0}}).json()
    wait_job(capped.a, job["id"], timeout=60, until=lambda j: j["status"] != "queued")
    time.sleep(0.5)  # inside the base problem's solve (tens of seconds on its own)
    assert capped.a.post(f"/jobs/{job['id']}/cancel").status_code == 202
    done = wait_job(capped.a, job["id"], timeout=30)
    assert done["status"] == "canceled", done
    # inside the base problem's solve: IPOPT's iteration callback stops it at its next iteration
    # ("canceled"), or the watchdog ends the process after the grace ("stopped in the middle")
    assert done["message"] == "canceled" or "stopped in the middle" in done["message"], done
    # the job's process was replaced: the next job runs
    nxt = capped.a.post(f"/motions/{tutor_id}/extrapolate", json=CHEAP).json()
    assert wait_job(capped.a, nxt["id"], timeout=120)["status"] == "succeeded"


def test_time_limit_holds_inside_a_solve(capped, long_id):
    job = capped.a.post(f"/motions/{long_id}/extrapolate", json={"target": {"curve_deg": 20.0}}).json()
    done = wait_job(capped.a, job["id"], timeout=60)
    assert done["status"] == "failed" and f"time limit of {TIME_LIMIT_S:g} s exceeded" in done["message"], done
    started = wait_job(capped.a, job["id"], timeout=1)["started_at"]
    assert started is not None


def test_job_processes_run_under_the_memory_cap(capped, tutor_id):
    job = capped.a.post(f"/motions/{tutor_id}/extrapolate", json=KILLABLE).json()
    j = wait_job(capped.a, job["id"], timeout=60, until=lambda j: j["status"] != "queued")
    kids = children(capped.proc.pid)
    assert kids, "the API has no child processes"
    assert all(address_space_limit(k) is not None for k in kids)
    limits = {address_space_limit(k) for k in kids if "service.procpool" in cmdline(k)}
    assert 2500 * 1024 * 1024 in limits, limits  # the job process (the compute process has its own cap)
    wait_job(capped.a, j["id"], timeout=120)


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT, signal.SIGKILL], ids=["TERM", "INT", "KILL"])
def test_no_process_outlives_motionx_serve(tmp_path, tutor_motion_json, sig):
    a = start_api_process(tmp_path, {"MOTIONX_LOCAL_WORKERS": "2", "MOTIONX_JOBS_PER_KEY": "2"})  # one key, two jobs
    try:
        tid = a.a.post("/motions", content=tutor_motion_json, headers={"content-type": "application/json"}).json()["id"]
        running = a.a.post(f"/motions/{tid}/extrapolate", json=KILLABLE).json()
        a.a.post(f"/motions/{tid}/extrapolate", json=KILLABLE)
        a.a.post(f"/motions/{tid}/extrapolate", json=CHEAP)  # queued behind the two
        wait_job(a.a, running["id"], timeout=60, until=lambda j: j["status"] != "queued")
        kids = children(a.proc.pid)
        assert len(kids) >= 3, [cmdline(k) for k in kids]  # 2 job processes and a compute process
        assert not [k for k in kids if "resource_tracker" in cmdline(k)]
        os.kill(a.proc.pid, sig)  # the main process only: not its process group
        a.proc.proc.wait(30)
        left = [(k, cmdline(k)) for k in wait_gone(kids, timeout=3.0)]
        assert not left, left
    finally:
        a.close()
        a.proc.kill()
