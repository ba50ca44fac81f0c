"""The embedded default (`motionx serve`: SQLite + local process pool) with real jobs:
failures are statuses, and a job survives the death of its process or of the API itself."""

from __future__ import annotations

import os
import signal

import pytest
from conftest import repeat_count, start_api_process
from svc_util import CHEAP, KILLABLE, job_motions, same_motions, wait_job

from service.db import get_database
from service.models import JobRow

REPEAT = repeat_count(1)


@pytest.fixture(scope="module")
def local_api(tmp_path_factory):
    d = tmp_path_factory.mktemp("local")
    a = start_api_process(d, {"MOTIONX_SWEEP_INTERVAL_S": "1", "MOTIONX_JOB_LEASE_S": "3"})
    yield a
    a.close()
    a.proc.stop()


@pytest.fixture(scope="module")
def tutor_id(local_api, tutor_motion_json):
    r = local_api.a.post("/motions", content=tutor_motion_json, headers={"content-type": "application/json"})
    assert r.status_code == 201
    return r.json()["id"]


@pytest.fixture(scope="module")
def reference(local_api, tutor_id):
    job = local_api.a.post(f"/motions/{tutor_id}/extrapolate", json=KILLABLE).json()
    assert wait_job(local_api.a, job["id"], timeout=120)["status"] == "succeeded"
    return job_motions(local_api.a, job["id"])


def _lease_pid(api, job_id) -> int:
    with get_database(f"sqlite:///{api.data_dir / 'motionx.db'}").read() as s:
        return int(s.get(JobRow, job_id).lease_owner.split(":")[1])


def _running(n=2):
    return lambda j: j["status"] not in ("queued", "running") or (j["status"] == "running" and j["steps"] >= n)


def test_impossible_target_ends_in_impasse(local_api, tutor_id):
    body = {"target": {"slope_deg": 80}, "control": {"method": "thesis", "delta0": 1.0, "eps": 0.5, "max_iter": 30}}
    job = local_api.a.post(f"/motions/{tutor_id}/extrapolate", json=body).json()
    done = wait_job(local_api.a, job["id"], timeout=120)
    assert done["status"] == "impasse" and done["lam_reached"] == 0.0 and "impasse" in done["message"]
    assert [p["accepted"] for p in done["progress"]][:1] == [True] and not done["progress"][-1]["accepted"]
    assert done["steps"] == len(job_motions(local_api.a, job["id"])) == 1  # λ = 0 is still a result


def test_tutor_failure_is_a_failed_job(local_api, shared_data):
    from svc_util import deepmimic_files

    up = local_api.a.post("/motions", files=deepmimic_files(shared_data)).json()
    capture = local_api.a.get(up["links"]["motion_file"]).json()
    capture["frames"] = capture["frames"][:5]  # far too short for a gait cycle
    if "contacts" in capture:
        capture["contacts"]["active"] = capture["contacts"]["active"][:5]
    short = local_api.a.post("/motions", json=capture).json()
    job = local_api.a.post(f"/motions/{short['id']}/extrapolate", json=CHEAP).json()
    done = wait_job(local_api.a, job["id"], timeout=120)
    assert done["status"] == "failed" and done["message"], done
    assert done["steps"] == 0 and job_motions(local_api.a, job["id"]) == []
    assert local_api.anon.get("/health").json()["status"] == "ok"  # the server did not crash


@pytest.mark.parametrize("i", range(REPEAT))
def test_reliability_local_pool_process_killed(local_api, tutor_id, reference, i):
    job = local_api.a.post(f"/motions/{tutor_id}/extrapolate", json=KILLABLE).json()
    j = wait_job(local_api.a, job["id"], timeout=60, until=_running())
    assert j["status"] == "running"
    pid = _lease_pid(local_api, job["id"])
    assert pid != local_api.proc.pid
    os.kill(pid, signal.SIGKILL)  # the pool breaks; the API replaces it and resubmits
    done = wait_job(local_api.a, job["id"], timeout=120)
    assert (done["status"], done["attempts"]) == ("succeeded", 2), done
    assert same_motions(job_motions(local_api.a, job["id"]), reference)


def test_reliability_api_killed_mid_job_resumes_on_restart(tmp_path, tutor_motion_json):
    """SIGKILL the whole API (pool included) mid-job; the next `motionx serve` on the same
    SQLite file resumes the job, which ends exactly once."""
    env = {"MOTIONX_SWEEP_INTERVAL_S": "1", "MOTIONX_JOB_LEASE_S": "3"}
    a = start_api_process(tmp_path, env)
    try:
        tid = a.a.post("/motions", content=tutor_motion_json, headers={"content-type": "application/json"}).json()["id"]
        ref_job = a.a.post(f"/motions/{tid}/extrapolate", json=KILLABLE).json()["id"]
        assert wait_job(a.a, ref_job, timeout=120)["status"] == "succeeded"
        ref = job_motions(a.a, ref_job)
        job = a.a.post(f"/motions/{tid}/extrapolate", json=KILLABLE).json()
        queued = a.a.post(f"/motions/{tid}/extrapolate", json=CHEAP).json()  # waits behind it (1 pool process)
        assert wait_job(a.a, job["id"], timeout=60, until=_running())["status"] == "running"
    finally:
        a.close()
        a.proc.kill()
    b = start_api_process(tmp_path, env)
    try:
        done = wait_job(b.a, job["id"], timeout=120)
        assert (done["status"], done["attempts"]) == ("succeeded", 2), done
        assert same_motions(job_motions(b.a, job["id"]), ref)
        q = wait_job(b.a, queued["id"], timeout=120)
        assert (q["status"], q["attempts"]) == ("succeeded", 1)
    finally:
        b.close()
        b.proc.stop()
