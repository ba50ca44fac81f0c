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
                "--fps", "15", "--out", out, "--json")
    assert r.returncode == 0, r.stderr + r.stdout
    info = json.loads(r.stdout)
    assert info["status"] == "succeeded" and info["plausible"] and info["coordinates"] == 16
    out.with_suffix(".stdout.json").write_text(r.stdout)
    return out


def test_tutor_prints_a_short_summary_for_a_person(tutor_file):
    """Without --json: a few lines saying what was written and whether it is plausible."""
    from service.commands.tutor import _tutor_summary

    info = json.loads(tutor_file.with_suffix(".stdout.json").read_text())
    text = _tutor_summary(info)
    lines = text.splitlines()
    assert 3 <= len(lines) <= 6 and all(len(line) < 160 for line in lines), text
    assert lines[0].startswith("tutor succeeded in ") and "IPOPT iterations" in lines[0]
    # the input summary (the `input` key of --json) in short: format, mass and where it comes from, stances
    assert info["input"]["format"] == "deepmimic" and info["input"]["mass_kg"] == 45.0
    assert lines[1].startswith("  input: deepmimic, ") and "45 kg (character file)" in lines[1]
    assert f"stances right {len(info['input']['stances']['right'])}" in lines[1]
    assert f"wrote {tutor_file}: halfboy, 16 coordinates" in text and "at 15 fps" in text
    assert "plausible: root residual" in text and "{" not in text
    assert f"motionx extrapolate {tutor_file}" in lines[-1]


def test_a_failed_tutor_says_so_in_one_line_and_writes_nothing(shared_data, tmp_path):
    d = shared_data / "deepmimic_humanoid3d_walk"
    r = motionx("tutor", d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt", "--max-iter", "2",
                "--out", tmp_path / "t.json")
    assert r.returncode == 1 and not (tmp_path / "t.json").exists()
    assert r.stdout.startswith("tutor failed in ") and r.stdout.strip().endswith("nothing written")
    assert len(r.stdout.strip().splitlines()) == 1


def test_tutor_writes_a_plausible_motion_file(tutor_file):
    m = Motion.load(tutor_file)
    assert m.provenance["step"] == "tutor" and m.fps == 15
    assert m.report["plausible"] and m.report["mujoco_replay"]["agreement_force_rel_weight"] < 1e-6


def test_validate_reports_and_flags_implausible_motions(tutor_file, tmp_path):
    r = motionx("validate", tutor_file, "--json")
    assert r.returncode == 0, r.stderr
    rep = json.loads(r.stdout)
    assert rep["plausible"] and rep["mujoco_replay"]["max_force_rel_weight"] < 1e-6
    # 10 % less ground reaction: the root must be propped up by a fictitious force
    m = Motion.load(tutor_file)
    weak = m.evolve(wrenches=0.9 * m.wrenches, report=None)
    weak.save(tmp_path / "weak.json")
    r = motionx("validate", tmp_path / "weak.json", "--json")
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
    files = sorted(out.glob("step_*_lambda_*.motion.json"))
    assert len(files) == summary["accepted"] == len(summary["motions"]) == len(list(out.glob("step_*")))
    # one naming scheme with the demo: step_NNN_lambda_L.motion.json
    assert [f.name for f in files] == [f"step_{i:03d}_lambda_{Motion.load(f).provenance['lambda']:.4f}.motion.json"
                                       for i, f in enumerate(files)]
    lams = [Motion.load(f).provenance["lambda"] for f in files]
    assert lams == sorted(lams) and lams[0] == 0.0 and lams[-1] == 1.0
    with (out / "progress.csv").open() as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == summary["solves"] + 1  # λ = 0 is the tutor itself (a record, no solve)
    assert {"phase", "wall_time_s", "lambda", "slope_deg", "iterations", "accepted"} <= set(rows[0])
    assert float(rows[-1]["slope_deg"]) == pytest.approx(-8.0)
    assert (out / "progress.png").stat().st_size > 1000
    # the summary for a person: status, the target as given (not rounded), where the files are
    lines = r.stdout.strip().splitlines()
    assert lines[0].startswith("succeeded: λ = 1.0000 toward slope -8°") and "{" not in r.stdout
    assert f"wrote {out}/" in r.stdout


def test_extrapolate_refuses_a_folder_holding_an_earlier_run(tutor_file, tmp_path):
    """The README's `export DIR/step_*_lambda_1.0000.motion.json` glob must find one file: no
    stale steps from an earlier run next to this run's."""
    out = tmp_path / "again"
    r = motionx("extrapolate", tutor_file, "--friction", "0.7", "--delta0", "0.5", "--out", out, "--quiet",
                "--json")
    assert r.returncode == 0, r.stderr
    first = json.loads(r.stdout)["motions"]
    stale = out / "step_007_lambda_0.9500.motion.json"  # as a longer earlier run would have left
    stale.write_text("{}")
    (out / "notes.txt").write_text("mine")
    r = motionx("extrapolate", tutor_file, "--friction", "0.8", "--delta0", "0.5", "--out", out, "--quiet")
    assert r.returncode == 2 and len(r.stderr.strip().splitlines()) == 1
    assert "is not empty" in r.stderr and "--force" in r.stderr
    assert stale.exists() and json.loads((out / "summary.json").read_text())["target"]["friction"] == 0.7
    r = motionx("extrapolate", tutor_file, "--friction", "0.8", "--delta0", "0.5", "--out", out, "--quiet",
                "--overwrite", "--json")
    assert r.returncode == 0, r.stderr
    summary = json.loads(r.stdout)
    assert summary["target"]["friction"] == 0.8
    steps = sorted(p.name for p in out.glob("step_*"))
    assert steps == summary["motions"] and len(list(out.glob("*_lambda_1.0000*"))) == 1
    assert not stale.exists()
    assert (out / "notes.txt").read_text() == "mine"  # not the tool's: kept
    assert first  # the first run wrote steps too
    r = motionx("extrapolate", tutor_file, "--friction", "0.8", "--out", out / "notes.txt")
    assert r.returncode == 2 and "not a directory" in r.stderr


def test_validate_into_a_closed_pipe_ends_quietly(tutor_file):
    """`motionx validate … | head`: no BrokenPipeError traceback."""
    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    p = subprocess.Popen([exe, "validate", str(tutor_file), "--pretty"], stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE)
    p.stdout.close()
    err = p.stderr.read().decode()
    assert p.wait(timeout=120) == 141 and err == "", err


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


@pytest.mark.parametrize("sig, status", [("SIGINT", 130), ("SIGTERM", 143)])
def test_a_signal_cancels_extrapolate_keeping_what_it_has(tutor_file, tmp_path, sig, status):
    """Ctrl-C (or SIGTERM) in the middle of `motionx extrapolate`: the solve stops at its next
    IPOPT iteration, the λ optima kept so far stay, progress.csv and summary.json say
    "canceled", and the exit status is 130 (143)."""
    import signal
    import time

    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    out = tmp_path / "ex"
    p = subprocess.Popen([exe, "extrapolate", str(tutor_file), "--slope", "30", "--method", "thesis", "--delta0",
                          "0.005", "--eps", "0.001", "--out", str(out), "--quiet"],
                         stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        deadline = time.monotonic() + 120
        while not list(out.glob("step_001_*.motion.json")) and time.monotonic() < deadline and p.poll() is None:
            time.sleep(0.05)
        assert p.poll() is None, "the walk ended before it could be interrupted"
        p.send_signal(getattr(signal, sig))
        stdout, stderr = p.communicate(timeout=120)
    finally:
        p.kill()
    assert p.returncode == status, stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "canceled" and summary["message"].startswith(
        "interrupted" if sig == "SIGINT" else "terminated")
    assert 0 < summary["lambda_reached"] < 1 and summary["motions"]
    assert all((out / f).is_file() for f in summary["motions"])
    rows = list(csv.DictReader((out / "progress.csv").open()))
    assert rows and float(rows[-1]["lambda_reached"]) == pytest.approx(summary["lambda_reached"])
    assert "Traceback" not in stderr
