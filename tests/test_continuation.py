"""Extrapolation by continuation: homotopies, step control, every λ a plausible motion."""

import math
import time

import numpy as np
import pytest
import shared_tutors

from solver import spatial as sp
from solver.continuation import (
    ProgressRecord,
    StepControl,
    Target,
    environment_at,
    extrapolate,
    guide_at,
    motion_at,
)
from solver.spacetime import Environment
from solver.transforms import curve, slope


@pytest.fixture(scope="module")
def tutor(shared_data):
    res = shared_tutors.tutor(shared_data)
    assert res.status == "succeeded", res.message
    return res.motion


def _heading_change(q: np.ndarray) -> float:
    return float(q[3, -2] - q[3, 0])


def test_uphill_slope_reaches_the_target_and_every_step_is_plausible(tutor):
    records: list[ProgressRecord] = []
    steps = []
    res = extrapolate(tutor, Target(slope_deg=11.25), StepControl(), on_progress=records.append,
                      on_step=steps.append)
    assert res.status == "succeeded" and res.lam_reached == 1.0
    assert [s.lam for s in res.steps] == sorted(s.lam for s in res.steps) and res.steps[0].lam == 0.0
    assert len(steps) == len(res.steps) and len(records) == res.solves + 1
    assert records[0].status == "tutor" and records[0].lam == 0.0  # λ = 0 is the tutor itself: no solve
    assert all(r1.wall_time <= r2.wall_time for r1, r2 in zip(records, records[1:]))
    for s in res.steps:
        rep = s.motion.report
        assert rep["plausible"], rep["problems"]
        assert rep["root_residual"]["max_force_rel_weight"] <= 1e-6
    final = res.steps[-1].motion
    g = np.array(final.environment.to_dict()["gravity"])
    th = math.radians(11.25)
    assert np.allclose(g, [-9.81 * math.sin(th), 0.0, -9.81 * math.cos(th)], atol=1e-12)
    # walking uphill against tilted gravity: over a cycle the ground pushes forward by m g sin θ
    # more than on the level (central differences bias both means alike by ~2 % of weight)
    fx = final.wrenches[:, 3, 1:-1].sum(axis=0).mean() - tutor.wrenches[:, 3, 1:-1].sum(axis=0).mean()
    assert fx == pytest.approx(final.character.total_mass * 9.81 * math.sin(th), rel=0.1)


@pytest.mark.parametrize("method", ["thesis", "adaptive"])
def test_curve_bends_the_walk(tutor, method):
    assert StepControl().method == "thesis"  # the default (docs/continuation.md: measured faster, as far)
    res = extrapolate(tutor, Target(curve_deg=60.0), StepControl(method=method))
    assert res.status == "succeeded"
    q = res.steps[-1].motion.q
    assert math.degrees(_heading_change(q)) == pytest.approx(60.0, abs=10.0)
    assert abs(math.degrees(_heading_change(tutor.q))) < 10.0


def test_friction_and_gravity_targets_change_the_environment(tutor):
    res = extrapolate(tutor, Target(friction=0.4, gravity=7.0), StepControl())
    assert res.status == "succeeded"
    env = res.steps[-1].motion.environment.to_dict()
    assert env["friction"] == pytest.approx(0.4) and np.linalg.norm(env["gravity"]) == pytest.approx(7.0)
    w = res.steps[-1].motion.wrenches
    B = res.steps[-1].motion.foot_contact()
    for k in range(2):
        f = w[k, 3:, 1:-1][:, B[k, 1:-1]]
        assert np.all(np.hypot(f[0], f[1]) <= 0.4 * f[2] + 1e-4 * tutor.character.weight)


def test_impasse_and_cancel_are_results_not_errors(tutor):
    # a step budget of 2 IPOPT iterations cannot converge: the walk stops at λ = 0 with a status
    res = extrapolate(tutor, Target(slope_deg=5.0), StepControl(max_iter=2, delta0=0.2, eps=0.1))
    assert res.status == "impasse" and res.lam_reached == 0.0 and "impasse" in res.message
    assert len(res.steps) == 1  # the base problem's optimum is kept
    # cancel between steps: the optima found so far are kept
    steps = []
    res = extrapolate(tutor, Target(slope_deg=5.0), StepControl(), on_step=steps.append,
                      should_cancel=lambda: len(steps) >= 2)
    assert res.status == "canceled" and 0.0 < res.lam_reached < 1.0 and len(res.steps) == 2
    # cancel inside a solve: IPOPT's iteration callback stops it at once (only λ = 0 is stored)
    calls = []

    def cancel() -> bool:
        calls.append(1)
        return len(calls) > 3

    res = extrapolate(tutor, Target(slope_deg=5.0), StepControl(), should_cancel=cancel)
    assert res.status == "canceled" and res.lam_reached == 0.0 and [s.lam for s in res.steps] == [0.0]
    assert res.records[-1].status == "User_Requested_Stop" and res.records[-1].iterations < 5
    # ... also when the stopped solve's step, halved, falls below ε: canceled, not an impasse
    calls.clear()
    res = extrapolate(tutor, Target(slope_deg=5.0), StepControl(delta0=1e-4, eps=1e-4), should_cancel=cancel)
    assert res.status == "canceled" and res.records[-1].status == "User_Requested_Stop", res.message


def test_thesis_controller_and_motion_at(tutor):
    res = extrapolate(tutor, Target(slope_deg=-6.0), StepControl(method="thesis"))
    assert res.status == "succeeded"
    lams = [s.lam for s in res.steps]
    assert lams[:3] == pytest.approx([0.0, 0.05, 0.15])  # Δ0 then doubling (Algorithm 3)
    near = motion_at(tutor, Target(slope_deg=-6.0), 0.16, res.steps)
    assert near.provenance["lambda"] == pytest.approx(0.15)
    exact = motion_at(tutor, Target(slope_deg=-6.0), 0.2, res.steps, exact=True)
    assert exact.provenance["lambda"] == pytest.approx(0.2) and exact.report["plausible"]
    with pytest.raises(ValueError, match="outside"):
        motion_at(tutor, Target(slope_deg=-6.0), 1.5, res.steps)


def test_extrapolation_refuses_a_non_tutor(tutor):
    with pytest.raises(ValueError, match="needs a tutor"):
        extrapolate(tutor.evolve(wrenches=None), Target(slope_deg=5.0))
    with pytest.raises(ValueError, match="slope_deg"):
        Target(slope_deg=float("nan"))
    with pytest.raises(ValueError, match="friction"):
        Target(friction=-1.0)


# --- homotopy data and guide transforms -----------------------------------------------------


def test_environment_interpolates_and_rotates_gravity():
    env, values = environment_at(Environment(), Target(slope_deg=20.0, gravity=1.62, friction=0.3), 0.5)
    g = np.asarray(env.gravity)
    assert np.linalg.norm(g) == pytest.approx(9.81 + 0.5 * (1.62 - 9.81))
    assert math.degrees(math.atan2(-g[0], -g[2])) == pytest.approx(10.0)
    assert env.friction == pytest.approx(0.65) and values["slope_deg"] == pytest.approx(10.0)


def test_slope_guide_tilts_the_root_and_keeps_its_height_along_gravity():
    rng = np.random.default_rng(0)
    T = 9
    Q = np.zeros((16, T))
    Q[0] = np.linspace(0, 1, T)
    Q[2] = 0.6 + 0.02 * rng.normal(size=T)
    Q[3:6] = 0.05 * rng.normal(size=(3, T))
    th = math.radians(15)
    S = slope(Q, th)
    d = sp.rotation_about([0, 1, 0], th) @ np.array([0, 0, -1.0])
    assert np.allclose(S[2] / -d[2], Q[2])  # distance to the ground along gravity kept
    for t in range(T):
        r0 = sp.euler_zyx_to_matrix(*Q[3:6, t])
        r1 = sp.euler_zyx_to_matrix(*S[3:6, t])
        assert np.allclose(r1, sp.rotation_about([0, 1, 0], th) @ r0)
    assert np.array_equal(S[6:], Q[6:])


def test_curve_guide_maps_the_path_onto_an_arc():
    T = 12
    Q = np.zeros((16, T))
    Q[0] = np.linspace(0, 1.1, T)
    Q[1] = 0.02 * np.sin(np.linspace(0, 6, T))
    assert np.allclose(curve(Q, 0.0), Q)
    th = math.pi / 2
    C_ = curve(Q, th)
    chord = Q[:2, T - 2] - Q[:2, 0]
    dT = np.linalg.norm(chord)
    u = chord / dT
    v = np.array([-u[1], u[0]])
    d_t = u @ (Q[:2] - Q[:2, :1])
    e_t = v @ (Q[:2] - Q[:2, :1])
    assert np.allclose(C_[3] - Q[3], th * d_t / dT)  # yaw follows the arc
    # each root lies at its lateral deviation from the circle of radius d_T/θ centred left of the start
    R = dT / th
    centre = Q[:2, 0] + R * v
    r = np.linalg.norm(C_[:2] - centre[:, None], axis=0)
    assert np.allclose(r, R - e_t)
    assert np.allclose(C_[2:3], Q[2:3])
    with pytest.raises(ValueError, match="does not travel"):
        curve(np.zeros((16, T)), th)


def test_guide_at_composes_curve_then_slope(tutor):
    tgt = Target(slope_deg=10.0, curve_deg=30.0)
    g = guide_at(tutor.q, tgt, 0.5)
    expected = slope(curve(tutor.q, math.radians(15.0)), math.radians(5.0))
    assert np.allclose(g, expected)


def test_impossible_slope_ends_in_an_impasse_and_keeps_only_realistic_motions(tutor):
    """An 80° slope cannot be walked: the walk stops at the last realistic λ, as an impasse, and
    every stored optimum passes the realism checks (a coarser ε keeps the test short)."""
    res = extrapolate(tutor, Target(slope_deg=80.0), StepControl(eps=0.05, max_iter=100))
    assert res.status == "impasse" and 0.0 < res.lam_reached < 0.8, (res.status, res.lam_reached)
    assert all(s.motion.report["plausible"] and s.motion.report["realism"]["passed"] for s in res.steps)


# --- stairs as stairs: treads of a rise and a going, risers, nosings ------------------------------


def test_stairs_bad_targets_are_refused_clearly():
    with pytest.raises(ValueError, match=r"step_going_m must be within \[0.2, 1\] m, got 0"):
        Target(step_height_m=0.17, step_going_m=0.0)
    with pytest.raises(ValueError, match=r"step_height_m must be within \[-0.3, 0.3\] m, got 0.4"):
        Target(step_height_m=0.4)
    with pytest.raises(ValueError, match="step_going_m needs step_height_m"):
        Target(step_going_m=0.28)  # a going without a rise: no stairs to be deep
    assert Target(step_height_m=-0.17).step_going_m is None  # the default going is the continuation's


@pytest.fixture(scope="module")
def stairs(tutor):
    """The tutor's continuation to stairs of 0.17 m rise and 0.28 m going, up and down."""
    out = {}
    for name, rise in (("up", 0.17), ("down", -0.17)):
        t0 = time.perf_counter()
        out[name] = (extrapolate(tutor, Target(step_height_m=rise, step_going_m=0.28), StepControl()),
                     time.perf_counter() - t0)
    return out


@pytest.mark.parametrize("way", ["up", "down"])
def test_stairs_continuation_keeps_the_feet_on_their_treads_and_clears_every_nosing(tutor, stairs, way):
    """Every accepted λ is plausible and natural (the stairs checks included); the last optimum
    stands each stance foot on its own tread, one going per step, and its swinging feet clear
    every nosing by 2 cm along the spline (docs/naturalness.md, "Stairs": measured figures)."""
    from solver.naturalness import naturalness_report
    from solver.stairs import flight_of

    res, _ = stairs[way]
    # measured (docs/naturalness.md, "Stairs"): up and down reach λ = 1 natural
    assert res.status == "succeeded" and res.lam_reached == 1.0, (res.status, res.lam_reached, res.message)
    for st in res.steps:
        rep = st.motion.report
        assert rep["plausible"] and rep["natural"], rep["naturalness"].get("failed")
    m = res.steps[-1].motion
    lam = res.lam_reached
    env = m.environment
    going = tutor_going = float(np.linalg.norm(tutor.q[:2, -2] - tutor.q[:2, 0])) / 2
    going = tutor_going + lam * (0.28 - tutor_going)  # the going shortens from the level step
    assert env.step_going_m == pytest.approx(going) and env.step_height_m == pytest.approx(lam * (0.17 if way == "up"
                                                                                                   else -0.17))
    f = flight_of(m)
    assert f is not None and f.at == env.stairs_at  # the geometry the optimizer used is stored with the motion
    assert float(f.direction @ (m.q[:2, -2] - m.q[:2, 0])) == pytest.approx(2 * going, abs=1e-6)  # one going a step
    checks = naturalness_report(m)["checks"]
    assert checks["nosing_clearance"]["value"] >= 0.02 and checks["nosing_clearance"]["passed"]
    assert checks["stance_over_nosing"]["value"] <= 0.02 and checks["stance_into_riser"]["value"] <= 0.005
    # the swing lifts the foot over the steps as people do: the tutor's level swing peaks at 72-78° of knee
    # and 36-38° of hip flexion; people climbing 90-100° / 55-65°, descending 85-100° / 25-40°
    assert checks["stairs_swing_knee"]["value"] >= 80.0
    assert checks["stairs_swing_hip"]["value"] >= (50.0 if way == "up" else 25.0)
    # each stance foot's contact points on its own tread, at its height
    from solver.kinematics import contact_points

    cp = contact_points(m.character, m.q)
    B = m.foot_contact()
    for j, c in enumerate(m.character.contacts):
        k = 0 if c.side == "right" else 1
        on = m.contacts[j, : m.T - 2]
        s = f.along(cp[j, :2, : m.T - 2])[on]
        tread = f.left[k, : m.T - 2][on]
        assert np.all((s >= tread * going) & (s <= (tread + 1) * going)), c.name
        np.testing.assert_allclose(cp[j, 2, : m.T - 2][on], tread * f.rise, atol=1e-3)
    assert B.any()


def test_stairs_checks_see_a_foot_off_its_tread(stairs):
    """The same optimum with its flight moved half a going: stance feet over the nosings, and the
    checks fail it."""
    from solver.naturalness import naturalness_report

    m = stairs["up"][0].steps[-1].motion
    env = m.environment
    x, y, heading = env.stairs_at
    g = env.step_going_m
    moved = env.with_(stairs_at=(x + 0.5 * g * math.cos(heading), y + 0.5 * g * math.sin(heading), heading))
    rep = naturalness_report(m.evolve(context=m.context.with_(environment=moved)))
    assert not rep["passed"]
    assert {"stance_over_nosing", "stance_into_riser"} & set(rep["failed"])
