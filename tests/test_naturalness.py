"""Naturalness (solver.naturalness): each check measures what it says on walks with a known answer,
the optimizer's naturalness bounds hold on a real tutor (and its feet stand on their soles), the
report judges a motion against its capture too, and the gait processing that the bounds need
(a levelled sole, a shared frame at each change of support) does what it says on real trials."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shared_tutors

from solver.character.reference import REFERENCE
from solver.kinematics import contact_points, sole_corners, standing_leg_length
from solver.motion import FEET, Motion
from solver.naturalness import NaturalnessLimits, checks_of, gait_figures, naturalness_report

FPS = 15.0
N = 8  # distinct frames of the synthetic cycles; T = N + 2
LIM = NaturalnessLimits()


def stand(speed: float = 1.0, lift: float = 0.0) -> tuple:
    """HalfBoy (the thesis's 1.20 m boy) standing upright, feet flat on the ground (+ ``lift``),
    carried forward at ``speed`` m/s along +x: (character, q (n, T), weight N)."""
    ch = REFERENCE["halfboy"]()
    q = np.zeros((ch.n, N + 2))
    q[0] = speed * np.arange(N + 2) / FPS
    q[2] = standing_leg_length(ch) + lift
    return ch, q, ch.total_mass * 9.81


def schedule(ch, right: list[int], left: list[int]) -> np.ndarray:
    """(P, T) both points of each foot on at the given distinct frames; frames N, N+1 repeat 0, 1."""
    A = np.zeros((len(ch.contacts), N + 2), dtype=bool)
    for j, c in enumerate(ch.contacts):
        for t in right if c.side == "right" else left:
            A[j, t] = True
    A[:, N:] = A[:, :2]
    return A


def loads(weight: float, right: list[float], left: list[float], fx: tuple[float, float] = (0.0, 0.0)) -> np.ndarray:
    """(2, 3, T) per-foot forces: vertical loads and fore-aft forces in body weights."""
    F = np.zeros((2, 3, N + 2))
    for k, fz in enumerate((right, left)):
        F[k, 2, :N] = np.asarray(fz) * weight
        F[k, 0, :N] = fx[k] * weight * (np.asarray(fz) > 0)
    F[..., N:] = F[..., :2]
    return F


def checks(ch, q, A, F=None, gravity=(0.0, 0.0, -9.81)) -> dict:
    """The checks as the report's JSON holds them (name → figure, limit, passed, ...)."""
    return {k: c.to_dict() for k, c in checks_of(gait_figures(ch, q, FPS, A, forces=F, gravity=gravity)).items()}


# --- each check on a known answer ------------------------------------------------------------------


def test_a_dragging_swing_foot_fails_and_a_lifted_one_passes_by_its_height():
    ch, q, _ = stand(speed=1.0)
    A = schedule(ch, right=[], left=list(range(N)))  # the right foot swings, moving at 1 m/s
    c = checks(ch, q, A)["swing_clearance"]
    assert c["value"] == pytest.approx(0.0, abs=1e-9) and not c["passed"] and c["severity"] == "failure"
    ch, q, _ = stand(speed=1.0, lift=0.02)
    c = checks(ch, q, A)["swing_clearance"]
    assert c["value"] == pytest.approx(0.02, abs=1e-9) and c["passed"]
    # a swing foot slower than the moving speed is landing, not dragging: not counted
    ch, q, _ = stand(speed=0.5)
    assert checks(ch, q, A)["swing_clearance"]["value"] is None


@pytest.mark.parametrize("pitch_deg, passed", [(30.0, True), (50.0, False)])
def test_foot_pitch_under_load_is_the_heel_toe_line_elevation(pitch_deg, passed):
    ch, q, W = stand(speed=0.0)
    q[ch.index("ankle_angle_l")] = -math.radians(pitch_deg)  # plantarflexion: heel up, toe down
    A = schedule(ch, right=[], left=list(range(N)))
    c = checks(ch, q, A, loads(W, [0.0] * N, [0.8] * N))["foot_pitch_under_load"]
    assert c["value"] == pytest.approx(pitch_deg, abs=1e-6) and c["passed"] is passed
    # unloaded (0.4 BW < 0.5) the same pitch is free
    assert checks(ch, q, A, loads(W, [0.0] * N, [0.4] * N))["foot_pitch_under_load"]["value"] is None


@pytest.mark.parametrize("frames, passed", [(1, True), (3, False)])
def test_a_joint_held_at_its_limit_fails_beyond_one_frame(frames, passed):
    ch, q, _ = stand()
    i = ch.index("hip_rotation_r")
    q[i, :frames] = ch.upper[i] - math.radians(0.5 * LIM.limit_band_deg)
    A = schedule(ch, right=list(range(N)), left=list(range(N)))
    c = checks(ch, q, A)["joint_limits"]
    assert c["value"] == frames and c["passed"] is passed and "hip_rotation_r" in c["what"]


def test_only_hinges_with_a_range_are_judged_at_their_limits_and_kept_off_them():
    """The check and the optimizer's bounds share one rule (``limited_coordinates``): the root's
    six coordinates and a hinge whose whole range is a few degrees are neither judged at their
    limits nor bounded inside them."""
    from dataclasses import replace

    from solver.naturalness import limited_coordinates

    ch, q, _ = stand()
    i = ch.index("hip_rotation_r")
    seg = next(s for s in ch.segments if any(d.name == "hip_rotation_r" for d in s.dofs))
    dofs = tuple(replace(d, lower=-math.radians(3.0), upper=math.radians(3.0)) if d.name == "hip_rotation_r" else d
                 for d in seg.dofs)
    narrow = replace(ch, segments=tuple(replace(s, dofs=dofs) if s is seg else s for s in ch.segments))
    assert limited_coordinates(ch)[6:].all() and not limited_coordinates(ch)[:6].any()
    assert not limited_coordinates(narrow)[i]
    q[i] = narrow.upper[i]  # held at its (narrow) limit all cycle: not judged
    A = schedule(ch, right=list(range(N)), left=list(range(N)))
    assert checks(narrow, q, A)["joint_limits"]["value"] == 0


def test_a_loaded_foot_across_the_pelvis_fails_by_its_distance():
    ch, q, W = stand(speed=1.0)
    q[ch.index("hip_adduction_r")] = math.radians(15.0)  # the right foot swings in, to the left of the pelvis
    A = schedule(ch, right=list(range(N)), left=[])
    cp = contact_points(ch, q)
    far = float(cp[[j for j, c in enumerate(ch.contacts) if c.side == "right"], 1].mean(axis=0).max() - q[1, 0])
    assert far > 0.05  # across the midline (+y is the walker's left: the far side of a right foot)
    c = checks(ch, q, A, loads(W, [1.0] * N, [0.0] * N))["crossover"]
    assert c["value"] == pytest.approx(far, abs=1e-9) and not c["passed"]


def test_the_load_jumping_from_foot_to_foot_fails_and_a_shared_double_support_passes():
    ch, q, W = stand()
    A = schedule(ch, right=[0, 1, 2, 3, 4], left=[4, 5, 6, 7, 0])  # double support at frames 0 and 4
    right, left = [0.5, 1, 1, 1, 0.3, 0, 0, 0], [0.5, 0, 0, 0, 0.7, 1, 1, 1]
    c = checks(ch, q, A, loads(W, right, left))["shared_load"]
    assert c["value"] == pytest.approx(0.3) and c["passed"]
    right[4], left[4] = 1.0, 0.0  # in contact, but the left foot takes nothing at frame 4
    c = checks(ch, q, A, loads(W, right, left))["shared_load"]
    assert c["value"] == pytest.approx(0.0) and not c["passed"]


def test_fore_aft_force_limit_applies_on_level_ground_only():
    ch, q, W = stand()
    A = schedule(ch, right=list(range(N)), left=[])
    F = loads(W, [1.0] * N, [0.0] * N, fx=(0.4, 0.0))
    c = checks(ch, q, A, F)["fore_aft_force"]
    assert c["value"] == pytest.approx(0.4) and not c["passed"]
    assert checks(ch, q, A, loads(W, [1.0] * N, [0.0] * N, fx=(-0.2, 0.0)))["fore_aft_force"]["passed"]
    g = 9.81 * np.array([-math.sin(0.2), 0.0, -math.cos(0.2)])  # an 11.5° uphill slope (gravity tilted)
    c = checks(ch, q, A, F, gravity=g)["fore_aft_force"]
    assert c["applies"] is False and c["passed"]


def test_trunk_leaning_back_uphill_against_the_tutor_fails_by_the_slope_angle():
    """An upright pelvis on a 10° uphill (gravity tilted back) leans back 10° against gravity: the
    tutor, upright on level ground, leaned 0°."""
    ch, q, W = stand()
    A = schedule(ch, right=list(range(N)), left=[])
    tutor = gait_figures(ch, q, FPS, A)
    g = 9.81 * np.array([-math.sin(math.radians(10)), 0.0, -math.cos(math.radians(10))])
    fig = gait_figures(ch, q, FPS, A, gravity=g)
    assert fig["slope_along_deg"] == pytest.approx(10.0) and fig["trunk_lean_deg"]["mean"] == pytest.approx(-10.0)
    c = checks_of(fig, reference={"tutor": tutor})["trunk_lean"]
    assert c.value == pytest.approx(10.0) and not c.passed
    q2 = q.copy()
    q2[4] = math.radians(12.0)  # the pelvis pitched forward 12°: leaning 2° forward against gravity
    c = checks_of(gait_figures(ch, q2, FPS, A, gravity=g), reference={"tutor": tutor})["trunk_lean"]
    assert c.value == pytest.approx(-2.0) and c.passed


def test_the_capture_figures_stand_beside_each_check():
    ch, q, W = stand(speed=1.0)
    A = schedule(ch, right=[], left=list(range(N)))
    capture = gait_figures(ch, q, FPS, A)  # its swing foot drags too
    ch, q2, _ = stand(speed=1.0, lift=0.01)
    c = checks_of(gait_figures(ch, q2, FPS, A), reference={"capture": capture})["swing_clearance"]
    assert c.capture == pytest.approx(0.0, abs=1e-9) and c.capture_passed is False and c.passed
    assert c.source is not None and "Begg" in c.source


# --- a real tutor ---------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def tutor(shared_data):
    res = shared_tutors.tutor(shared_data, fps=FPS)
    assert res.status == "succeeded", res.message
    return res


def test_the_tutor_is_natural_and_its_report_judges_it_against_the_capture(tutor):
    m = tutor.motion
    rep = m.report
    assert rep["plausible"] and rep["natural"], rep["naturalness"]["failed"]
    nat = rep["naturalness"]
    assert set(nat["checks"]) >= {"swing_clearance", "foot_pitch_under_load", "joint_limits", "crossover",
                                  "shared_load", "fore_aft_force", "vertical_force_shape", "pelvis_pitch_range"}
    for name in ("swing_clearance", "joint_limits", "crossover", "pelvis_pitch_range"):
        assert "capture" in nat["checks"][name], name  # the captured walk's own figure (no plates: kinematics)
    assert all(c["source"] for c in nat["checks"].values())
    # what the tutor kept of the capture
    rms = tutor.stats["joint_rms_to_capture_deg"]
    assert 0.0 < rms["overall"] < 20.0 and set(rms["per_coordinate"]) >= {"hip_flexion_r", "knee_angle_l"}
    Motion.from_dict(m.to_dict())  # the report is JSON


def test_the_tutor_keeps_the_optimizers_naturalness_bounds(tutor):
    from solver.spacetime.types import Naturalness

    m, nat = tutor.motion, Naturalness()
    W = m.character.total_mass * 9.81
    B = m.foot_contact()
    corners = sole_corners(m.character, m.q)  # (2, 4, 3, T)
    for k in range(2):
        swing = ~B[k, : m.T - 2]
        assert swing.any()
        assert corners[k, :, 2, : m.T - 2][:, swing].min() >= nat.clearance_m - 1e-6
    # feet drawn where they stand: a foot with both contact points down rests on its sole (it rolls
    # with the leg, the inversion being locked: within 1 cm)
    for k, side in enumerate(FEET):
        both = m.contacts[[j for j, c in enumerate(m.character.contacts) if c.side == side]].all(axis=0)
        assert both.any()
        assert np.abs(corners[k, :, 2][:, both]).max() < 0.01
    # both feet loaded in the middle of every double support
    both = B[0, : m.T - 2] & B[1, : m.T - 2]
    fz = m.wrenches[:, 5, : m.T - 2] / W
    assert both.any() and fz[:, both].max(axis=0).min() > 0.3
    assert np.minimum(fz[0], fz[1])[both].max() >= nat.shared_load - 1e-6
    # the limited joints (the check's) stay the margin inside their limits
    from solver.naturalness import limited_coordinates

    lim = limited_coordinates(m.character)
    ch, margin = m.character, math.radians(nat.limit_margin_deg)
    assert lim.sum() >= 10
    assert (m.q[lim] >= (ch.lower[lim] + margin - 1e-6)[:, None]).all()
    assert (m.q[lim] <= (ch.upper[lim] - margin + 1e-6)[:, None]).all()


def test_a_curve_keeps_its_feet_on_their_own_side_of_the_pelvis(shared_data):
    """Extrapolated to a 90° curve in one cycle, the Plug-in Gait walk's feet stay where the walker puts
    them across the pelvis's heading as well as across the path (``Weights.pelvis_side``): the loaded foot
    stands at least 1 cm inside the optimizer's 2 cm crossover bound (without that cost the optimum stood
    on it, 20 mm across the pelvis's heading)."""
    from solver.continuation import Target, extrapolate
    from solver.spacetime.types import Naturalness

    tut = shared_tutors.tutor(shared_data, ("btk_pig_flatfoot_full/PiG_Motion-FlatFoot-Full.c3d",), fps=FPS)
    res = extrapolate(tut.motion, Target(curve_deg=90.0))
    assert res.lam_reached == 1.0, res.message
    m = res.steps[-1].motion
    assert m.report["natural"], m.report["naturalness"]["failed"]
    crossover = m.report["naturalness"]["figures"]["crossover"]
    assert crossover["max_far_side_m"] <= Naturalness().crossover_m - 0.01, crossover
    assert "crossover" not in m.provenance["solver"]["active_bounds"]  # the optimizer's record agrees


def test_the_optimizer_names_the_bounds_its_optimum_rests_on(tutor):
    """A 90° curve in one HalfBoy cycle is the hardest turn of the shared walks: where the optimum's
    record says a crossover row is on its bound, the naturalness check (computed from the motion, not the
    optimizer) measures the loaded foot at that bound; joints named at their bounds are at their limits."""
    from solver.continuation import Target, extrapolate
    from solver.spacetime.types import Naturalness

    res = extrapolate(tutor.motion, Target(curve_deg=90.0))
    assert res.steps and res.steps[-1].lam > 0.5, res.message
    for step in res.steps[1:]:
        m = step.motion
        active = m.provenance["solver"]["active_bounds"]
        if "crossover" in active:
            assert m.report["naturalness"]["figures"]["crossover"]["max_far_side_m"] > (
                Naturalness().crossover_m - 0.002), (step.lam, active)
        ch = m.character
        for key in active:
            if key.startswith("bound:"):
                i = ch.coordinate_names.index(key.removeprefix("bound:"))
                assert min(np.abs(m.q[i] - ch.lower[i]).min(), np.abs(m.q[i] - ch.upper[i]).min()) < math.radians(
                    Naturalness().limit_margin_deg) + 1e-4, key


def test_a_change_of_support_without_a_shared_frame_gets_one(tutor):
    """The DeepMimic walk at 15 frames/s: the right toe's last contact frame is the frame before the
    left heel's first; the left heel, 9 mm below its stance height one frame earlier, gets it."""
    (added,) = tutor.stats["double_support_added"]
    assert added["point"] == "heel_l" and added["frame"] == 10 and added["height_above_stance_m"] < 0.0


def test_ensure_double_support_picks_the_lower_point():
    from solver.gait import ensure_double_support

    ch, q, _ = stand(speed=0.0)
    A = schedule(ch, right=[0, 1, 2, 3], left=[4, 5, 6, 7])  # the load would jump at frames 4 and 0
    out, changes = ensure_double_support(ch, q, A)
    assert len(changes) == 2
    B = Motion(ch, FPS, q, contacts=out).foot_contact()[:, :N]
    assert (B[0] & B[1]).sum() == 2 and np.array_equal(out[:, N:], out[:, :2])
    q[2, 3] += 0.05  # frame 3 lifted 5 cm: the left heel there is not on the ground, the right toe at 4 is
    lifted, _ = ensure_double_support(ch, q, A)
    assert not (lifted[:, 3] & ~A[:, 3]).any()  # frame 3 (lifted 5 cm) gets no new contact


def test_sole_calibration_levels_a_retargeted_foot(shared_data):
    """The CMU BVH skeleton's heel point stands ~3.5 cm above its toe point at flat foot; levelled,
    heel and toe agree within a millimetre."""
    from solver.gait import extract_cycle
    from solver.io import load_trial
    from solver.pipeline import sole_calibration

    cap = load_trial(shared_data / "cmu16_bvh" / "16_15_walk.bvh", mass=60.0)
    cyc, A = extract_cycle(cap, FPS, start="auto")

    def heel_minus_toe(ch):
        cp = contact_points(ch, cyc.q)
        out = []
        for side in FEET:
            h, t = sorted((j for j, c in enumerate(ch.contacts) if c.side == side),
                          key=lambda j: ch.contacts[j].position[0])
            flat = A[h] & A[t]
            out.append(float(np.median(cp[h, 2][flat] - cp[t, 2][flat])))
        return out

    before = heel_minus_toe(cap.character)
    levelled, moved = sole_calibration(cap.character, cyc.q, A)
    after = heel_minus_toe(levelled)
    assert min(before) > 0.02 and set(moved["heel_above_toe_mm"]) == {"right", "left"}
    assert max(abs(x) for x in after) < 0.001


def test_feet_without_a_heel_and_a_toe_point_are_not_checked_and_not_called_natural(tutor):
    from dataclasses import replace

    from solver.plausibility import report

    m = tutor.motion
    ch = m.character
    keep = [j for j, c in enumerate(ch.contacts) if c.name != "toe_l"]
    one_point = replace(ch, contacts=tuple(ch.contacts[j] for j in keep))
    m1 = replace(m, character=one_point, contacts=m.contacts[keep], report=None)
    nat = naturalness_report(m1)
    assert nat["passed"] is None and nat["checks"] == {} and "not checked" in nat["notes"][0]
    assert report(m1)["natural"] is None


def test_a_report_without_wrenches_checks_the_kinematics_only(tutor):
    m = tutor.simplified
    rep = naturalness_report(m)
    assert "swing_clearance" in rep["checks"] and "shared_load" not in rep["checks"]
