"""The Moco side-by-side bench (``bench.moco``): a MocoTrack that cannot run is a recorded status with
its reason, never the bench's end."""

from __future__ import annotations

from bench.moco import moco_job, run_moco


def test_a_missing_trial_folder_is_refused_with_what_is_missing(tmp_path):
    job = moco_job(tmp_path / "nowhere", 0.5, 1.2)
    row = run_moco(job, timeout=60.0)
    assert row["status"] == "error", row
    msg = row["message"]
    assert "nowhere" in msg and "model.osim" in msg and "reference.mot" in msg and "external_loads.xml" in msg, msg
    assert row["cpu_s"] >= 0.0 and len(row["load_before"]) == 3


def test_the_job_spans_one_cycle_at_the_mesh_rate(tmp_path):
    job = moco_job(tmp_path, 0.63333, 1.22833)
    assert (job["t0"], job["t1"]) == (0.633, 1.862)
    assert job["mesh_intervals"] == 37 and abs(job["mesh_interval"] * 37 - (1.862 - 0.633)) < 1e-12
    assert job["convergence_tolerance"] == 1e-2 and job["hessian"] == "limited-memory"
