"""True to the subject (issue): the default tutor — the full body at 30 frames/s — of an OpenSim walk
keeps the capture's joints within 2° RMS, its ground reactions near the force plates the optimizer never
saw, and passes every naturalness check with no feature on a bound; HalfBoy does not crouch."""

from __future__ import annotations

import numpy as np
import pytest

from solver.motion import FEET


@pytest.fixture(scope="module")
def treadmill(shared_data):
    from solver.io import load_trial

    d = shared_data / "opensim_gait2354_subject01_treadmill"
    return load_trial([d / "subject01.osim", d / "subject01_walk1_ik.mot", d / "subject01_walk1_grf.mot",
                       d / "subject01_walk1_grf.xml"], belt_speed="auto")


@pytest.fixture(scope="module")
def default_tutor(treadmill):
    from solver.pipeline import make_tutor

    res = make_tutor(treadmill)  # the defaults: what a user gets
    assert res.status == "succeeded", res.message
    return res


def test_the_default_tutor_is_the_full_body_at_the_subjects_own_30_fps(default_tutor):
    m = default_tutor.motion
    assert m.character.name == "fullbody"
    assert m.fps == pytest.approx(30.0, abs=0.5 * 30.0 / (m.T - 2))
    # gait2354's subtalar joint moves (up to 19°): the full body keeps it; its arms hang still: they swing
    assert {"ankle_inversion_r", "ankle_inversion_l"} <= set(default_tutor.stats["kept_coordinates"])
    assert default_tutor.stats["arm_swing"]["synthesized"]


def test_the_default_tutor_keeps_the_captures_joints_within_two_degrees(default_tutor):
    rms = default_tutor.stats["joint_rms_to_capture_deg"]
    assert rms["overall"] < 2.0, rms
    assert max(rms["per_coordinate"].values()) < 4.0, rms["per_coordinate"]
    assert not any(k.startswith(("shoulder_", "elbow_")) for k in rms["per_coordinate"])  # not captured


def test_its_ground_reactions_follow_the_plates_it_never_saw(default_tutor):
    plates = default_tutor.stats["grf_against_plates"]
    for side in FEET:
        assert plates[side]["vertical"]["rms_bw"] < 0.1, plates[side]
        assert plates[side]["fore_aft"]["rms_bw"] < 0.05, plates[side]
        assert plates[side]["vertical"]["max_bw"] == pytest.approx(plates[side]["vertical"]["plates_max_bw"],
                                                                   abs=0.15)
    shapes = default_tutor.motion.report["naturalness"]["figures"]["vertical_force_shape"]
    assert len(shapes) == 2  # a loading peak and a push-off peak above a mid-stance valley, each stance
    assert all(min(s["loading_peak_bw"], s["push_off_peak_bw"]) - s["valley_bw"] > 0.1 for s in shapes)


def test_it_is_natural_with_no_feature_on_a_bound(default_tutor):
    from solver.spacetime.types import Naturalness

    rep = default_tutor.motion.report
    assert rep["plausible"] and rep["natural"], rep["naturalness"]["failed"]
    checks = rep["naturalness"]["checks"]
    for name in ("fit_quality", "joint_speed", "fore_aft_pattern", "vertical_force_shape"):
        assert checks[name]["passed"], (name, checks[name])
    assert checks["vertical_force_shape"]["severity"] == "failure"  # the plates show the valley
    clearance = checks["swing_clearance"]["value"]
    assert clearance > checks["swing_clearance"]["limit"] + 0.003  # 9 mm: the check's limit
    assert clearance > Naturalness().clearance_m + 0.005  # 3 mm: the optimizer's safety net, far off
    assert checks["crossover"]["value"] < Naturalness().crossover_m - 0.005
    # the optimizer's own record: no naturalness safety row (clearance, crossover, a swing point on the
    # ground) and no joint at its limit carries the optimum (the feet's physics rows may: an unloaded foot)
    active = default_tutor.motion.provenance["solver"]["active_bounds"]
    assert not {"clearance", "crossover", "contact", "joint_rate"} & set(active), active
    assert not any(k.startswith("bound:") for k in active), active


def test_halfboy_does_not_crouch(shared_data):
    """HalfBoy keeps the subject's stance knee within 10° of the capture's mean over each stance (the
    old default crouched 10-26° deeper; its trunk, head and arms welded to its pelvis, HalfBoy cannot keep
    the subject's centre of mass and joints both: 8° and 3° deeper on this walk)."""
    from solver.io import load_trial
    from solver.pipeline import _select, make_tutor, prepare_cycle

    d = shared_data / "opensim_loadedwalking_subject05"
    cap = load_trial([d / "Rajagopal2016_subject05_v30516.osim",
                      d / "loadedwalking_subject05_noload_free_trial03_ik_solution.mot",
                      d / "loadedwalking_subject05_noload_free_trial03_grf.mot"])
    res = make_tutor(cap, character="halfboy")
    assert res.status == "succeeded" and res.motion.fps == pytest.approx(15.0, abs=0.5)
    m = res.motion
    prep = prepare_cycle(cap, character="halfboy")
    qc = _select(prep.capture_character, prep.q, m.character)
    B = m.foot_contact()[:, : m.T - 2]
    for k, s in enumerate(("r", "l")):
        i = m.character.coordinate_names.index(f"knee_angle_{s}")
        stance = B[k]
        tutor_knee = np.degrees(m.q[i, : m.T - 2][stance]).mean()
        capture_knee = np.degrees(qc[i, : m.T - 2][stance]).mean()
        assert abs(tutor_knee - capture_knee) < 10.0, (s, tutor_knee, capture_knee)
