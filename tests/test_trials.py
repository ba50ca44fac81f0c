"""Every shared trial (data/, 7 folders) through ``motionx grf`` (+ ``grf-compare`` where it has
plates) and ``motionx tutor``, as a user runs them; what the input looks like is reported."""

import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from solver.motion import Motion

TM = "opensim_gait2354_subject01_treadmill"
LW = "opensim_loadedwalking_subject05"
LW_GRF = "loadedwalking_subject05_noload_free_trial03_grf.mot"

# name -> (input files relative to data/, extra flags, grf-compare measurement flags or None)
TRIALS = {
    "opensim_overground": ([f"{LW}/Rajagopal2016_subject05_v30516.osim",
                            f"{LW}/loadedwalking_subject05_noload_free_trial03_ik_solution.mot", f"{LW}/{LW_GRF}"],
                           [], ["--grf", f"{LW}/{LW_GRF}"]),
    "opensim_treadmill": ([f"{TM}/subject01.osim", f"{TM}/subject01_walk1_ik.mot", f"{TM}/subject01_walk1_grf.mot",
                           f"{TM}/subject01_walk1_grf.xml"], ["--belt-speed", "auto"],
                          ["--grf", f"{TM}/subject01_walk1_grf.mot",
                           "--external-loads", f"{TM}/subject01_walk1_grf.xml"]),
    "opensim_treadmill_markers": ([f"{TM}/subject01.osim", f"{TM}/marker_trajectories.trc",
                                   f"{TM}/subject01_walk1_grf.mot", f"{TM}/subject01_walk1_grf.xml"],
                                  ["--belt-speed", "auto"],
                                  ["--grf", f"{TM}/subject01_walk1_grf.mot", "--external-loads",
                                   f"{TM}/subject01_walk1_grf.xml"]),
    "c3d_pig": (["btk_pig_flatfoot_full/PiG_Motion-FlatFoot-Full.c3d"], [],
                ["--c3d", "btk_pig_flatfoot_full/PiG_Motion-FlatFoot-Full.c3d"]),
    "c3d_qualisys": (["qualisys_ior_walk/Qualisys.c3d"], ["--mass", "66"],
                     ["--c3d", "qualisys_ior_walk/Qualisys.c3d", "--mass", "66"]),
    "deepmimic": (["deepmimic_humanoid3d_walk/humanoid3d_walk.txt",
                   "deepmimic_humanoid3d_walk/humanoid3d_character.txt"], [], None),
    "bvh_cmu_straight": (["cmu16_bvh/16_15_walk.bvh"], ["--mass", "60"], None),
    "bvh_cmu_left_turn": (["cmu16_bvh/16_17_walk_90deg_left_turn.bvh"], ["--mass", "60"], None),
    "bvh_cmu_right_turn": (["cmu16_bvh/16_19_walk_90deg_right_turn.bvh"], ["--mass", "60"], None),
}
PLATES = [k for k, v in TRIALS.items() if v[2] is not None]


def motionx(*args) -> subprocess.CompletedProcess:
    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    return subprocess.run([exe, *map(str, args)], capture_output=True, text=True, timeout=600)


def params(names):
    return list(names)


def check_input(info: dict, plates: bool) -> None:
    """The input summary: mass, stance intervals per foot, implied mass with plates, fit error."""
    assert info["mass_kg"] > 20 and info["frames"] > 10
    for side in ("right", "left"):
        st = info["stances"][side]
        assert st and all(b >= a for a, b in st), (side, st)
    assert info["landmark_fit_error_mm"]["mean"] < 5.0
    if plates:
        assert info["mass_implied_kg"] is not None
        rel = abs(info["mass_implied_kg"] - info["mass_kg"]) / info["mass_implied_kg"]
        assert (rel > 0.05) == ("mass_warning" in info), info  # warned exactly when off by more than 5 %


@pytest.fixture(scope="module")
def grf_runs(shared_data, tmp_path_factory):
    """``motionx grf`` once per trial (the CSVs are compared and inspected by several tests)."""
    out = {}
    d = tmp_path_factory.mktemp("grf")
    cache = {}

    def run(name):
        if name not in cache:
            files, flags, _ = TRIALS[name]
            csv_path = d / f"{name}.csv"
            r = motionx("grf", "--input", *[shared_data / f for f in files], *flags, "--out", csv_path)
            cache[name] = (r, csv_path)
        return cache[name]

    out["run"] = run
    return out


@pytest.mark.parametrize("name", params(TRIALS))
def test_grf_estimate_of_every_trial(grf_runs, name):
    r, path = grf_runs["run"](name)
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    with open(path, newline="") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == info["rows"] > 20
    # on average the feet carry the body weight (N, whatever the input's vertical axis)
    axes = info["frame"].lower()
    up = "fy" if ("y up" in axes or "y = up" in axes) else "fz"
    total = np.array([float(x[up]) for x in rows]).reshape(-1, 2).sum(1)
    assert np.mean(total) == pytest.approx(info["mass_kg"] * 9.81, rel=0.15)
    check_input(info["input"], plates=TRIALS[name][2] is not None)
    if "mass_warning" in info["input"]:
        assert "motionx: warning:" in r.stderr and "--mass KG" in r.stderr


@pytest.mark.parametrize("name", params(PLATES))
def test_grf_compare_of_every_trial_with_plates(grf_runs, shared_data, name, tmp_path):
    r, path = grf_runs["run"](name)
    assert r.returncode == 0, r.stderr
    meas = [shared_data / a if a.endswith((".mot", ".xml", ".c3d")) else a for a in TRIALS[name][2]]
    js = tmp_path / "cmp.json"
    c = motionx("grf-compare", "--estimate", path, *meas, "--json", js)
    assert c.returncode == 0, c.stderr
    m = json.loads(js.read_text())
    assert m["all"]["n_frames"] >= 40
    assert m["all"]["rows"]["fz"]["rel_rms"] < 0.2  # the vertical force is the body's weight and bounce


@pytest.fixture(scope="module")
def tutors(shared_data, tmp_path_factory):
    d = tmp_path_factory.mktemp("tutors")
    cache = {}

    def run(name, character="halfboy"):
        key = (name, character)
        if key not in cache:
            files, flags, _ = TRIALS[name]
            out = d / f"{name}_{character}.json"
            r = motionx("tutor", *[shared_data / f for f in files], *flags, "--character", character,
                        "--fps", "15", "--out", out, "--json")
            cache[key] = (r, out)
        return cache[key]

    return run


@pytest.mark.parametrize("name", params(TRIALS))
def test_tutor_of_every_trial(tutors, name):
    r, out = tutors(name)
    assert r.returncode == 0, r.stderr + r.stdout
    info = json.loads(r.stdout)
    assert info["status"] == "succeeded" and info["plausible"]
    check_input(info["input"], plates=TRIALS[name][2] is not None)
    m = Motion.load(out)
    # 15 frames/s, adjusted so that the cycle's frames span the subject's own period (half a frame at most)
    assert m.provenance["step"] == "tutor" and m.fps == pytest.approx(15, abs=0.5 * m.fps / (m.T - 2))


def _heading_change_deg(q: np.ndarray) -> float:
    """Root yaw change over a cycle with two overlap frames (frame T-2 against frame 0), degrees."""
    return float(np.degrees(q[3, -2] - q[3, 0]))


def _velocity_turn_deg(q: np.ndarray) -> float:
    """Rotation of the root's horizontal velocity from the cycle's first step to its overlap step."""
    a, b = q[:2, 1] - q[:2, 0], q[:2, -1] - q[:2, -2]
    return float(np.degrees(np.angle(np.exp(1j * (np.arctan2(b[1], b[0]) - np.arctan2(a[1], a[0]))))))


@pytest.mark.parametrize("name, sign", [("bvh_cmu_left_turn", 1), ("bvh_cmu_right_turn", -1)])
def test_turning_clips_make_curved_tutors(tutors, shared_data, name, sign):
    """The spacetime problem's cyclic constraint lives in the walker's heading frame, so a cycle
    taken in a turn is a curved base motion: the tutor's heading changes over its cycle the way
    the capture's does, and its velocity comes back rotated by exactly that heading change."""
    from solver.gait import extract_cycle
    from solver.io import load_trial

    r, out = tutors(name)
    assert r.returncode == 0, r.stderr + r.stdout
    tut = Motion.load(out)
    files = TRIALS[name][0]
    cap = load_trial([shared_data / f for f in files], mass=60.0)
    cyc, _ = extract_cycle(cap, 15)
    assert sign * _heading_change_deg(cyc.q) > 15.0  # the capture's first cycle is in the turn
    turn = _heading_change_deg(tut.q)
    assert sign * turn > 3.0, turn
    assert _velocity_turn_deg(tut.q) == pytest.approx(turn, abs=0.5)
    straight = Motion.load(tutors("bvh_cmu_straight")[1]).q
    assert abs(_heading_change_deg(straight)) < 5.0
    assert _velocity_turn_deg(straight) == pytest.approx(_heading_change_deg(straight), abs=0.5)
