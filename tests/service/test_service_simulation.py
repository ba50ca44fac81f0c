"""Simulating a stored motion over the API (POST/GET /motions/{id}/simulation): background work
run by the local runner's job processes, its report and files stored in SQL; the stored
rollout replays with MuJoCo's own API from the stored model; bad requests get 422/404."""

from __future__ import annotations

import io
import time

import mujoco
import numpy as np
import pytest
from svc_util import CHEAP, halfboy_motion, wait_job

from service.simulation import FILES


def wait_simulation(client, motion_id: str, *, timeout: float) -> dict:
    deadline = time.monotonic() + timeout
    while True:
        r = client.get(f"/motions/{motion_id}/simulation")
        assert r.status_code == 200, r.text
        sim = r.json()
        if sim["terminal"]:
            return sim
        if time.monotonic() > deadline:
            raise AssertionError(f"simulation not done after {timeout:g} s: {sim}")
        time.sleep(0.2)


@pytest.fixture(scope="module")
def tutor_id(api, tutor_motion_json) -> str:
    r = api.a.post("/motions", content=tutor_motion_json, headers={"content-type": "application/json"})
    assert r.status_code == 201, r.text
    return r.json()["id"]


@pytest.fixture(scope="module")
def simulated(api, tutor_id) -> dict:
    r = api.a.post(f"/motions/{tutor_id}/simulation", json={"cycles": 1})
    assert r.status_code == 202, r.text
    assert r.headers["location"] == f"/motions/{tutor_id}/simulation"
    first = r.json()
    # asked again while it is queued or running: the same simulation, not a second one
    again = api.a.post(f"/motions/{tutor_id}/simulation", json={"cycles": 1})
    assert again.status_code == 202
    if not again.json()["terminal"]:
        assert again.json()["id"] == first["id"]
    return wait_simulation(api.a, tutor_id, timeout=180)


def test_simulation_report_and_files(api, tutor_id, simulated):
    sim = simulated
    assert sim["status"] == "succeeded", sim["message"]
    rep = sim["report"]
    # the DeepMimic HalfBoy tutor walks its cycle (tests/test_simulate.py: 2 cycles without falling)
    assert rep["fell"] is False, rep.get("fall")
    assert rep["cycles_walked"] == pytest.approx(1.0, abs=1e-2)
    assert 0.0 < rep["joint_tracking_rms_deg"] < 6.0
    assert 0.0 < rep["foot_force_rms_bw"] < 0.45
    assert rep["peak_torque_ratio_max"] > 0.0 and rep["realtime_factor"] > 0.0
    assert len(rep["drift_per_cycle"]) == 1
    # beside the continuous run, the cycle started from the reference's state with the root residual
    assert rep["resync"]["cycles"] == 1 and rep["resync"]["completed"] == 1
    assert 0.0 <= rep["resync"]["residual_root_wrench_rms_bw"] < 0.05
    assert set(sim["files"]) == set(FILES)
    for name, media_type in FILES.items():
        r = api.a.get(sim["links"][name])
        assert r.status_code == 200 and r.headers["content-type"].startswith(media_type), name
        assert len(r.content) == sim["files"][name]
    assert api.a.get(sim["links"]["simulated.glb"]).content[:4] == b"glTF"
    assert api.a.get(sim["links"]["simulation.png"]).content[:8] == b"\x89PNG\r\n\x1a\n"
    assert api.a.get(sim["links"]["report.json"]).json()["cycles_walked"] == rep["cycles_walked"]
    # another key sees nothing of it
    assert api.b.get(f"/motions/{tutor_id}/simulation").status_code == 404
    assert api.b.get(f"/motions/{tutor_id}/simulation/model.xml").status_code == 404
    # the simulation's job is not listed with the extrapolation jobs
    assert sim["job_id"] not in [j["id"] for j in api.a.get("/jobs?limit=100").json()["items"]]


def test_stored_rollout_replays_with_mujoco(api, simulated, replay_rollout):
    model = mujoco.MjModel.from_xml_string(api.a.get(simulated["links"]["model.xml"]).text)
    r = np.load(io.BytesIO(api.a.get(simulated["links"]["rollout.npz"]).content))
    assert float(r["timestep"]) == pytest.approx(model.opt.timestep)
    assert [model.actuator(i).name for i in range(model.nu)] == list(r["actuators"])
    qpos, time_end = replay_rollout(model, r)
    np.testing.assert_allclose(qpos, r["qpos"], rtol=0, atol=1e-12)
    assert time_end == pytest.approx(r["time"][-1], abs=1e-12)


@pytest.mark.parametrize("cycles", [0, 101, 2.5, "3"])
def test_cycles_out_of_range_422(api, tutor_id, cycles):
    r = api.a.post(f"/motions/{tutor_id}/simulation", json={"cycles": cycles})
    assert r.status_code == 422, r.text
    assert "cycles" in r.text


def test_capture_cannot_be_simulated_422(api):
    r = api.a.post("/motions", json=halfboy_motion().to_dict())
    assert r.status_code == 201, r.text
    mid = r.json()["id"]
    r = api.a.post(f"/motions/{mid}/simulation", json={"cycles": 1})
    assert r.status_code == 422, r.text
    assert "gait cycle" in r.json()["detail"]
    assert api.a.get(f"/motions/{mid}/simulation").status_code == 404


def test_unknown_motion_404(api):
    missing = "m_" + "0" * 32
    assert api.a.post(f"/motions/{missing}/simulation", json={"cycles": 1}).status_code == 404
    assert api.a.get(f"/motions/{missing}/simulation").status_code == 404
    assert api.a.get(f"/motions/{missing}/simulation/model.xml").status_code == 404


def test_job_simulates_its_final_motion(api, tutor_id):
    """``simulate_cycles`` on a job: its final λ optimum is simulated and the job links to it."""
    r = api.a.post(f"/motions/{tutor_id}/extrapolate", json={**CHEAP, "simulate_cycles": 1})
    assert r.status_code == 202, r.text
    job = wait_job(api.a, r.json()["id"], timeout=180)
    assert job["status"] == "succeeded", job["message"]
    assert "simulation" in job["links"], job
    final = api.a.get(f"/jobs/{job['id']}/motions?limit=100").json()["items"][-1]
    assert job["links"]["simulation"] == f"/motions/{final['id']}/simulation"
    sim = api.a.get(job["links"]["simulation"]).json()
    assert sim["status"] == "succeeded", sim["message"]
    assert sim["job_id"] == job["id"] and sim["cycles"] == 1
    assert sim["report"]["cycles_walked"] > 0.0
    assert r.json()["links"].get("simulation") is None  # not before the job's end
    bad = api.a.post(f"/motions/{tutor_id}/extrapolate", json={**CHEAP, "simulate_cycles": 101})
    assert bad.status_code == 422
