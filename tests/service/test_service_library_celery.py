"""A motion library on the real distributed stack (Redis with AOF, two Celery workers,
PostgreSQL, the API under uvicorn): SIGKILL the whole worker running a cell in the middle of the
library — no cell is lost, none is duplicated (one job per cell, one row per (job, step), the
killed cell finishes on its second attempt), as test_service_celery.py proves for one job. The
killed cell comes back through the API's sweep (its lease expired), as with the default settings."""

from __future__ import annotations

import os
import secrets
import time

import httpx
import pytest
from test_service_library import wait_library

from service.db import get_database
from service.models import JobRow, LibraryRow, MotionRow
from service.topology import Stack, create_postgres_database, drop_postgres_database, wait_worker_ready

STACK_ENV = {  # a dead worker's cell comes back through the API's sweep once its lease expires
    "MOTIONX_JOB_LEASE_S": "3",
    "MOTIONX_JOB_TIME_LIMIT_S": "120",  # far above a cell (3-4 s here; slower transcriptions stay within)
    "MOTIONX_JOB_STOP_GRACE_S": "2",
    "MOTIONX_VISIBILITY_TIMEOUT_S": "300",  # above Celery's hard limit (120 + 2 + 5 s): Redis is the last resort
    "MOTIONX_SWEEP_INTERVAL_S": "1",
    "MOTIONX_REDISPATCH_EXPIRED_S": "2",
}
#: cells of ~3-4 s each (Algorithm 3 from Δ0 = 0.01: about 8 λ steps), so one can be killed mid-way
BODY = {"grid": {"slope_deg": [-5.0, 5.0], "curve_deg": [-20.0, 20.0]},
        "control": {"method": "thesis", "delta0": 0.01, "eps": 0.001}}


@pytest.fixture(scope="module")
def stack(tmp_path_factory, pg_admin, redis_binary):
    name = f"motionx_library_test_{secrets.token_hex(4)}"
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


def test_killing_a_worker_mid_library_loses_no_cell_and_duplicates_none(stack, client, tutor_motion_json):
    tutor = client.post("/motions", content=tutor_motion_json, headers={"content-type": "application/json"}).json()
    lib = client.post(f"/motions/{tutor['id']}/library", json=BODY).json()
    lid = lib["id"]

    def cell_with_steps(lib):
        busy = any(c["status"] == "running" and c["steps"] >= 2 for c in lib["cells"])
        return busy or lib["status"] not in ("queued", "running")

    mid, _ = wait_library(client, lid, timeout=180, until=cell_with_steps)
    assert mid["status"] == "running", "the library must still be running when the worker is killed"
    victim_cell = next(c for c in mid["cells"] if c["status"] == "running" and c["steps"] >= 2)
    db = get_database(stack.database_url)
    with db.read() as s:
        pid = int(s.get(JobRow, victim_cell["job_id"]).lease_owner.split(":")[1])
    victim = next(w for w in stack.worker_procs if w.alive() and os.getpgid(pid) == w.pid)
    victim.kill()
    stack.worker_procs.remove(victim)
    t0 = time.monotonic()
    wait_worker_ready(stack.add_worker(), timeout=60)
    done, _ = wait_library(client, lid, timeout=240)
    print(f"library finished {time.monotonic() - t0:.1f} s after the SIGKILL: "
          f"{[(c['key'], c['attempts'], c['steps']) for c in done['cells']]}")
    assert done["status"] == "succeeded", done
    cells = {c["key"]: c for c in done["cells"]}
    assert len(cells) == 4 and all(c["status"] == "succeeded" and c["lam_reached"] == 1.0 for c in cells.values())
    assert cells[victim_cell["key"]]["attempts"] == 2  # the killed cell ran again, once
    assert sum(c["attempts"] for c in cells.values()) == 5  # every other cell ran once
    with db.read() as s:
        ids = {c["job_id"] for c in s.get(LibraryRow, lid).spec["cells"]}
        jobs = [j for j in s.query(JobRow).all() if (j.spec or {}).get("library", {}).get("id") == lid]
        assert {j.id for j in jobs} == ids and len(jobs) == 4  # no cell job lost or added
        for j in jobs:
            steps = sorted(r.step for r in s.query(MotionRow).filter(MotionRow.job_id == j.id).all())
            assert steps == list(range(j.steps)), (j.id, steps)  # one row per (job, step): no duplicate, no gap
    for c in cells.values():  # over HTTP too: every λ optimum once, λ increasing to 1
        items = client.get(f"{c['links']['motions']}?limit=1000").json()["items"]
        assert [m["step"] for m in items] == list(range(c["steps"]))
        lams = [m["lam"] for m in items]
        assert lams == sorted(lams) and lams[-1] == 1.0
    man = client.get(f"/libraries/{lid}/manifest").json()
    assert man["summary"]["succeeded"] == 4 and all(e["realism"]["plausible"] for e in man["cells"])
