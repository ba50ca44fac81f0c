"""``make demo`` end to end: ``motionx demo`` with its defaults (the shared DeepMimic walk,
a downhill slope of −11.25° and a 90° curve over HTTP on the embedded service) writes every
λ motion, its exports, plausibility reports and plots, and a summary that states what was
reached. The files are checked with their own formats' readers, not by name only."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from solver.motion import motion_from_dict

PNG = b"\x89PNG\r\n\x1a\n"


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory, shared_data):
    out = tmp_path_factory.mktemp("demo") / "out"
    exe = Path(sys.executable).with_name("motionx")
    env = dict(os.environ, MOTIONX_DATA=str(shared_data))
    p = subprocess.run([str(exe), "demo", "--out", str(out)], env=env, capture_output=True, text=True, timeout=600)
    return p, out


def test_demo_reaches_both_targets_and_prints_a_summary(demo_run):
    p, out = demo_run
    assert p.returncode == 0, p.stdout[-3000:] + p.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["input"] == ["humanoid3d_walk.txt", "humanoid3d_character.txt"]
    jobs = {j["name"]: j for j in summary["jobs"]}
    assert set(jobs) == {"downhill", "curve"}
    assert jobs["downhill"]["target"] == {"slope_deg": -11.25}
    assert jobs["curve"]["target"] == {"curve_deg": 90.0}
    for name, j in jobs.items():
        assert j["status"] == "succeeded", (name, j)
        assert j["lambda_reached"] == pytest.approx(1.0)
        key, value = next(iter(j["target"].items()))
        assert j["reached"][key] == pytest.approx(value, abs=1e-9)
        assert j["motions"] >= 2 and j["plausible"] == j["motions"], j
        assert j["max_root_residual_rel_weight"] < 1e-6
    # the printed summary names both jobs with their λ and where the files are
    tail = p.stdout[p.stdout.index("[demo] job "):]
    assert "downhill" in tail and "curve" in tail and "1.000" in tail and str(out) in p.stdout
    # a progress bar was drawn while polling (one line per change when not on a terminal)
    assert p.stdout.count("λ=") >= 4 and "[" in p.stdout and "#" in p.stdout


def test_demo_files_are_what_they_claim(demo_run):
    from solver.export.clip import validate_clip

    p, out = demo_run
    assert p.returncode == 0, p.stderr[-3000:]
    for job in ("downhill", "curve"):
        d = out / job
        motions = sorted(d.glob("lambda_*.motion.json"))
        assert len(motions) >= 2
        lams = []
        for mf in motions:
            stem = mf.name[: -len(".motion.json")]
            m = motion_from_dict(json.loads(mf.read_text()))
            assert m.provenance["step"] == "extrapolate"
            assert float(stem.split("_")[1]) == pytest.approx(m.provenance["lambda"], abs=1e-4)
            lams.append(m.provenance["lambda"])
            clip = json.loads((d / f"{stem}.clip.json").read_text())
            validate_clip(clip)
            assert clip["frame_count"] == m.T
            glb = (d / f"{stem}.glb").read_bytes()
            assert glb[:4] == b"glTF" and int.from_bytes(glb[4:8], "little") == 2
            assert int.from_bytes(glb[8:12], "little") == len(glb)
            bvh = (d / f"{stem}.bvh").read_text()
            assert bvh.startswith("HIERARCHY") and f"Frames: {m.T}" in bvh
            rep = json.loads((d / f"{stem}.validation.json").read_text())
            assert rep["plausible"] is True
        assert lams == sorted(lams) and max(lams) == pytest.approx(1.0)
        # the last λ motion of the job stands on the target ground
        env = m.provenance["environment_values"]
        target = json.loads((out / "summary.json").read_text())["jobs"]
        want = next(j["target"] for j in target if j["name"] == job)
        for k, v in want.items():
            assert env[k] == pytest.approx(v)
        for png in ("progress.png", "final.grf.png", "final.residuals.png"):
            data = (d / png).read_bytes()
            assert data[:8] == PNG and len(data) > 5000, (job, png)
        assert json.loads((d / "job.json").read_text())["status"] == "succeeded"
        motion_from_dict(json.loads((d / "tutor.motion.json").read_text()))
