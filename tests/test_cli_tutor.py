"""`motionx tutor`, `validate`, `extrapolate`, `mjcf --motion` from the outside."""

import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

from solver.motion import Motion


def motionx(*args: str, timeout: int = 600) -> subprocess.CompletedProcess:
    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    return subprocess.run([exe, *map(str, args)], capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def tutor_file(shared_data, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("tutor") / "tutor.json"
    d = shared_data / "deepmimic_humanoid3d_walk"
    r = motionx("tutor", d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt", "--character", "halfboy",
                "--fps", "15", "--out", out)
    assert r.returncode == 0, r.stderr + r.stdout
    info = json.loads(r.stdout)
    assert info["status"] == "succeeded" and info["plausible"] and info["coordinates"] == 16
    return out


def test_tutor_writes_a_plausible_motion_file(tutor_file):
    m = Motion.load(tutor_file)
    assert m.provenance["step"] == "tutor" and m.fps == 15
    assert m.report["plausible"] and m.report["mujoco_replay"]["agreement_force_rel_weight"] < 1e-6


def test_validate_reports_and_flags_implausible_motions(tutor_file, tmp_path):
    r = motionx("validate", tutor_file)
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert rep["plausible"] and rep["mujoco_replay"]["max_force_rel_weight"] < 1e-6
    # 10 % less ground reaction: the root must be propped up by a fictitious force
    m = Motion.load(tutor_file)
    weak = m.evolve(wrenches=0.9 * m.wrenches, report=None)
    weak.save(tmp_path / "weak.json")
    r = motionx("validate", tmp_path / "weak.json")
    assert r.returncode == 1
    rep = json.loads(r.stdout)
    assert not rep["plausible"] and rep["root_residual"]["max_force_rel_weight"] > 1e-3
    assert rep["mujoco_replay"]["agreement_force_rel_weight"] < 1e-9  # MuJoCo sees the same residual


def test_validate_refuses_bad_files(tmp_path):
    (tmp_path / "bad.json").write_text('{"format": "motionx.motion", "version": 1}')
    r = motionx("validate", tmp_path / "bad.json")
    assert r.returncode == 2 and "character" in r.stderr
    r = motionx("validate", tmp_path / "missing.json")
    assert r.returncode == 2 and "not found" in r.stderr


def test_extrapolate_writes_every_lambda_progress_and_summary(tutor_file, tmp_path):
    out = tmp_path / "slope"
    r = motionx("extrapolate", tutor_file, "--slope", "-8", "--out", out, "--quiet")
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "succeeded" and summary["lambda_reached"] == 1.0
    assert summary["final"]["plausible"] and summary["final"]["mujoco_agreement_rel_weight"] < 1e-6
    files = sorted(out.glob("motion_*.json"))
    assert len(files) == summary["accepted"] == len(summary["motions"])
    lams = [Motion.load(f).provenance["lambda"] for f in files]
    assert lams == sorted(lams) and lams[0] == 0.0 and lams[-1] == 1.0
    with (out / "progress.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == summary["solves"]
    assert {"wall_time_s", "lambda", "slope_deg", "iterations", "accepted"} <= set(rows[0])
    assert float(rows[-1]["slope_deg"]) == pytest.approx(-8.0)
    assert (out / "progress.png").stat().st_size > 1000


def test_extrapolate_refuses_bad_requests(tutor_file, tmp_path, shared_data):
    r = motionx("extrapolate", tutor_file, "--out", tmp_path / "x")
    assert r.returncode == 2 and "give a target" in r.stderr
    r = motionx("extrapolate", tutor_file, "--slope", "nan", "--out", tmp_path / "x")
    assert r.returncode == 2 and "finite" in r.stderr
    r = motionx("extrapolate", tutor_file, "--friction", "-1", "--out", tmp_path / "x")
    assert r.returncode == 2 and "friction" in r.stderr
    raw = Motion.load(tutor_file).evolve(wrenches=None, report=None)
    raw.save(tmp_path / "raw.json")
    r = motionx("extrapolate", tmp_path / "raw.json", "--slope", "5", "--out", tmp_path / "x")
    assert r.returncode == 2 and "not a tutor" in r.stderr


def test_mjcf_of_a_motion_is_the_model_validate_replays(tutor_file, tmp_path):
    out = tmp_path / "m.xml"
    r = motionx("mjcf", "--motion", tutor_file, "--out", out)
    assert r.returncode == 0, r.stderr
    model = mujoco.MjModel.from_xml_path(str(out))
    m = Motion.load(tutor_file)
    assert model.nq == m.n
    assert mujoco.mj_getTotalmass(model) == pytest.approx(m.character.total_mass, rel=1e-5)
    assert {model.joint(i).name for i in range(model.njnt)} == set(m.coordinate_names)
    assert np.allclose(model.opt.gravity, [0, 0, -9.81])


def test_tutor_refuses_unreadable_input(tmp_path):
    (tmp_path / "x.bvh").write_text("not a bvh")
    r = motionx("tutor", tmp_path / "x.bvh", "--mass", "60", "--out", tmp_path / "t.json")
    assert r.returncode == 2 and "cannot import" in r.stderr
