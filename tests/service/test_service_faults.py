"""Infrastructure faults answer 503 with Retry-After, never 500: a PostgreSQL server restarted
under load (a server of our own, on its own port), while a job runs; the job still ends exactly
once. (A compute process killed mid-request: test_service_sharing.py.)"""

from __future__ import annotations

import collections
import threading
import time

import httpx
import pytest
from conftest import start_api_process
from svc_util import CHEAP, wait_job

from service.topology import PostgresServer, create_postgres_database


@pytest.fixture(scope="module")
def pg():
    p = PostgresServer().init()
    p.start()
    yield p
    p.remove()


@pytest.fixture(scope="module")
def api(pg, tmp_path_factory):
    url = create_postgres_database(pg.admin_url, "motionx_faults", exist_ok=False)
    a = start_api_process(tmp_path_factory.mktemp("faults"), {"DATABASE_URL": url, "MOTIONX_SWEEP_INTERVAL_S": "1",
                                                              "MOTIONX_JOB_LEASE_S": "3"})
    yield a
    a.close()
    a.proc.stop()


def test_a_postgresql_restart_answers_503_with_retry_after_and_jobs_end_once(api, pg, tutor_motion_json):
    tid = api.a.post("/motions", content=tutor_motion_json, headers={"content-type": "application/json"}).json()["id"]
    job = api.a.post(f"/motions/{tid}/extrapolate", json=CHEAP).json()
    seen: collections.Counter[int] = collections.Counter()
    bad: list[tuple[int, str]] = []
    stop = threading.Event()

    def poll() -> None:
        with httpx.Client(base_url=api.base_url, headers=api.a.headers, timeout=30) as c:
            while not stop.is_set():
                for path in (f"/motions/{tid}", f"/jobs/{job['id']}", "/motions?limit=5", "/usage"):
                    r = c.get(path)
                    seen[r.status_code] += 1
                    if r.status_code == 503 and int(r.headers.get("retry-after", "0")) <= 0:
                        bad.append((503, "no Retry-After"))
                    elif r.status_code not in (200, 503):
                        bad.append((r.status_code, r.text[:300]))

    threads = [threading.Thread(target=poll) for _ in range(3)]
    for t in threads:
        t.start()
    time.sleep(0.5)
    pg.stop()  # a restart with an outage of a second
    time.sleep(1.0)
    pg.start()
    time.sleep(2.0)
    stop.set()
    for t in threads:
        t.join(60)
    assert not bad, bad[:5]
    assert seen[503] > 0 and seen[200] > 0, seen
    done = wait_job(api.a, job["id"], timeout=180)
    assert done["status"] == "succeeded", done["message"]
    steps = [m["step"] for m in api.a.get(f"/jobs/{job['id']}/motions?limit=100").json()["items"]]
    assert steps == list(range(done["steps"])) and steps, steps  # every λ optimum once
    assert "unhandled error on" not in api.proc.log_text()
