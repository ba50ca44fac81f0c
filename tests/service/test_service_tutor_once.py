"""A capture's tutor is made once, however many jobs ask for it at the same time: jobs of the
same capture and tutor options submitted together on ``motionx serve`` with two job processes —
one job makes the tutor, the other waits for it and takes it from the store (its progress
point says whose it is); a failure of the tutor is the failure of every job that asked for it."""

from __future__ import annotations

import pytest
from conftest import start_api_process
from svc_util import CHEAP, deepmimic_files, wait_job

from service.db import get_database
from service.models import JobRow, MotionRow, TutorClaimRow


@pytest.fixture(scope="module")
def two_workers(tmp_path_factory):
    d = tmp_path_factory.mktemp("tutor_once")
    a = start_api_process(d, {"MOTIONX_LOCAL_WORKERS": "2", "MOTIONX_JOB_LEASE_S": "3",
                             "MOTIONX_JOBS_PER_KEY": "2"})  # one key's jobs at the same moment
    yield a
    a.close()
    a.proc.stop()


def _db(api):
    return get_database(f"sqlite:///{api.data_dir / 'motionx.db'}")


def _tutor_point(job: dict) -> dict:
    points = [p for p in job["progress"] if p["phase"] == "tutor"]
    assert len(points) == 1, job["progress"]
    return points[0]


def test_jobs_submitted_together_make_one_tutor(two_workers, shared_data):
    api = two_workers
    capture = api.a.post("/motions", files=deepmimic_files(shared_data)).json()
    assert capture["kind"] == "capture"
    ids = [api.a.post(f"/motions/{capture['id']}/extrapolate", json=body).json()["id"]
           for body in (CHEAP, {**CHEAP, "target": {"slope_deg": 2.0}})]
    jobs = [wait_job(api.a, j, timeout=300) for j in ids]
    assert [j["status"] for j in jobs] == ["succeeded", "succeeded"], [j["message"] for j in jobs]
    points = {j["id"]: _tutor_point(j) for j in jobs}
    made = [j for j in jobs if points[j["id"]]["status"] == "tutor succeeded"]
    assert len(made) == 1, points  # one tutor computation ...
    maker = made[0]
    other = next(j for j in jobs if j is not maker)
    assert points[maker["id"]]["iterations"] > 0
    # ... the other job took it from the store: no solve of its own, the maker named
    assert points[other["id"]] | {"wall_time": 0, "seq": 0} == {
        "seq": 0, "phase": "tutor", "wall_time": 0, "lam": 0.0, "lam_reached": 0.0, "environment": {},
        "iterations": 0, "accepted": True, "status": f"tutor made by job {maker['id']}"}
    assert maker["tutor_motion_id"] == other["tutor_motion_id"] is not None
    with _db(api).read() as s:
        tutors = s.query(MotionRow).filter(MotionRow.parent_id == capture["id"]).all()
        claim = s.get(TutorClaimRow, (capture["id"], "halfboy@15"))
        assert [t.id for t in tutors] == [maker["tutor_motion_id"]] and tutors[0].kind == "tutor"
        assert (claim.job_id, claim.state) == (maker["id"], "made")
        # the other job was running while the tutor was being made (it waited, it did not come late)
        assert s.get(JobRow, other["id"]).started_at < tutors[0].created_at
    # a later job of the same capture and options takes the stored tutor at once
    late = wait_job(api.a, api.a.post(f"/motions/{capture['id']}/extrapolate", json=CHEAP).json()["id"], timeout=300)
    assert late["status"] == "succeeded" and late["tutor_motion_id"] == maker["tutor_motion_id"]
    assert _tutor_point(late)["status"] == f"tutor made by job {maker['id']}"


def test_a_failed_tutor_fails_every_job_that_asked_for_it(two_workers, shared_data):
    """Both jobs were created before the tutor failed: the one that did not make it shares the
    failure instead of making the same tutor again."""
    api = two_workers
    up = api.a.post("/motions", files=deepmimic_files(shared_data)).json()
    capture = api.a.get(up["links"]["motion_file"]).json()
    capture["frames"] = capture["frames"][:5]  # far too short for a gait cycle
    if "contacts" in capture:
        capture["contacts"]["active"] = capture["contacts"]["active"][:5]
    short = api.a.post("/motions", json=capture).json()
    ids = [api.a.post(f"/motions/{short['id']}/extrapolate", json=CHEAP).json()["id"] for _ in range(2)]
    jobs = [wait_job(api.a, j, timeout=300) for j in ids]
    assert [j["status"] for j in jobs] == ["failed", "failed"]
    with _db(api).read() as s:
        claim = s.get(TutorClaimRow, (short["id"], "halfboy@15"))
        assert claim.state == "failed" and claim.message
    maker = next(j for j in jobs if j["id"] == claim.job_id)
    other = next(j for j in jobs if j["id"] != claim.job_id)
    assert claim.message in maker["message"]
    assert other["message"] == f"tutor: {claim.message} (in job {maker['id']}, which made it for this job too)"
    assert _tutor_point(other) | {"wall_time": 0} == {
        "seq": 0, "phase": "tutor", "wall_time": 0, "lam": 0.0, "lam_reached": 0.0, "environment": {},
        "iterations": 0, "accepted": False, "status": f"tutor failed in job {maker['id']}"}
    assert other["tutor_motion_id"] is None and other["steps"] == 0
