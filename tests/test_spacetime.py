"""Spacetime optimization: the tutor pipeline on real trials, and the NLP's own contracts."""

import casadi as ca
import numpy as np
import pytest

from mjcf.validate import validate
from solver import character as C
from solver.kinematics import contact_points, markers
from solver.motion import Motion, validate_schema
from solver.pipeline import make_tutor, problem_for, synthesis_character
from solver.spacetime import Environment, ProblemData, SolverOptions, SpacetimeProblem, WarmStart

DM = "deepmimic_humanoid3d_walk"


@pytest.fixture(scope="module")
def deepmimic_capture(shared_data):
    from solver.io import load_trial

    d = shared_data / DM
    return load_trial([d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt"])


@pytest.fixture(scope="module")
def c3d_capture(shared_data):
    from solver.io import load_trial

    return load_trial([shared_data / "btk_pig_flatfoot_full" / "PiG_Motion-FlatFoot-Full.c3d"])


@pytest.fixture(scope="module")
def halfboy_tutor(deepmimic_capture):
    res = make_tutor(deepmimic_capture, character="halfboy", fps=15)
    assert res.status == "succeeded", res.message
    return res


def _assert_plausible(motion: Motion) -> dict:
    rep = validate(motion)
    w = rep["body_weight_N"]
    assert rep["root_residual"]["max_force_N"] <= 1e-6 * w, rep["root_residual"]
    assert rep["root_residual"]["max_moment_Nm"] <= 1e-6 * w * rep["leg_length_m"]
    mj = rep["mujoco_replay"]
    assert mj["max_force_rel_weight"] <= 1e-6 and mj["max_moment_rel_weight_leg"] <= 1e-6
    assert mj["agreement_force_rel_weight"] <= 1e-6 and mj["agreement_moment_rel_weight_leg"] <= 1e-6
    assert rep["slip_mm"] < 1e-3 and rep["penetration_mm"] < 1e-3 and rep["contact_height_error_mm"] < 1e-3
    assert rep["cop_outside_mm"] < 1e-3
    assert rep["plausible"], rep["problems"]
    return rep


def test_halfboy_tutor_from_deepmimic_is_plausible(halfboy_tutor):
    tut = halfboy_tutor.motion
    assert tut.character.n == 16 and tut.fps == 15
    _assert_plausible(tut)
    # the thesis calls ~3 mm per marker imperceptible; the realistic and natural transcription
    # moves the 15 fps capture (itself not dynamically consistent; its swing toes skim the floor
    # and its change of support has no shared frame) by about three centimetres
    assert halfboy_tutor.stats["marker_distance_to_capture_mm"]["mean"] < 35.0
    # the total ground reaction carries the body: mean vertical force over the cycle ≈ weight
    fz = tut.wrenches[:, 5, 1:-1].sum(axis=0)
    assert np.mean(fz) == pytest.approx(tut.character.weight, rel=0.05)


def test_tutor_is_cyclic_and_keeps_the_contact_schedule(halfboy_tutor):
    tut = halfboy_tutor.motion
    q, T = tut.q, tut.T
    assert np.allclose(q[6:, T - 2 :], q[6:, :2], atol=1e-12)  # joints repeat (eliminated)
    assert np.allclose(q[[2, 4, 5]][:, T - 2 :], q[[2, 4, 5]][:, :2], atol=1e-12)  # height, pitch, roll
    assert np.allclose(tut.contacts[:, T - 2 :], tut.contacts[:, :2])
    cp = contact_points(tut.character, q)
    assert np.abs(cp[:, 2, :][tut.contacts]).max() < 1e-8  # active points on the ground
    assert cp[:, 2, :][~tut.contacts].min() > -1e-8  # inactive points above it
    B = tut.foot_contact()
    assert np.all(tut.wrenches[0][:, ~B[0]] == 0) and np.all(tut.wrenches[1][:, ~B[1]] == 0)


def test_motion_file_v2_round_trip_and_schema(halfboy_tutor, tmp_path):
    tut = halfboy_tutor.motion
    path = tmp_path / "tutor.json"
    tut.save(path)
    import json

    validate_schema(json.loads(path.read_text()))
    back = Motion.load(path)
    assert np.array_equal(back.q, tut.q) and np.array_equal(back.wrenches, tut.wrenches)
    assert back.coordinate_names == tut.coordinate_names
    assert back.provenance["step"] == "tutor"
    assert back.context.environment is not None and back.environment.friction == 1.0
    assert (back.interpolation, back.cyclic) == ("cubic-spline", True)
    # a version 1 file (central differences) is still read, and means central differences
    d = json.loads(path.read_text())
    d["version"] = 1
    del d["trajectory"]
    v1 = Motion.from_dict(d)
    assert (v1.interpolation, v1.cyclic) == ("central-differences", False)


def test_tutors_from_c3d_halfboy_and_fullbody(c3d_capture):
    for kind, fps, n in (("halfboy", 15, 16), ("fullbody", 30, 43)):
        res = make_tutor(c3d_capture, character=kind, fps=fps)
        assert res.status == "succeeded", res.message
        kept = res.stats.get("kept_coordinates") or []  # the superfluous ones the capture uses (full body)
        assert res.motion.character.n == n + len(kept) and (kind == "fullbody" or not kept)
        assert set(kept) <= set(C.FULL_SUPERFLUOUS) and set(kept) <= set(res.motion.character.coordinate_names)
        _assert_plausible(res.motion)


def test_simplify_removes_superfluous_coordinates_close_to_the_capture(c3d_capture):
    syn, cap = synthesis_character(c3d_capture.character, "fullbody")
    assert cap.n == 63 and syn.n == 43
    assert not set(C.FULL_SUPERFLUOUS) & set(syn.coordinate_names)
    res = make_tutor(c3d_capture, character="halfboy", fps=15)
    assert res.stats["simplify"]["marker_rms_mm"] < 15.0


def test_base_problem_returns_the_tutor(halfboy_tutor):
    """A plausible motion used as its own guide is close to the optimum: only the costs that do not
    measure the distance to the guide (jerk, wrench change, the ground reactions' moment about the
    centre of mass) move it, by the markers' worth of their weight (about a centimetre)."""
    tut = halfboy_tutor.motion
    prob = problem_for(tut.character, tut.T, tut.fps, tut.contacts)
    res = prob.solve(ProblemData(tut.q, heading_change=0.0), WarmStart(tut.q, tut.wrenches))
    assert res.success and res.iterations < 60
    assert res.marker_rms < 0.015


def test_solver_failure_is_a_status_not_a_solution(halfboy_tutor, deepmimic_capture):
    """A solve that cannot finish is reported as such; the pipeline keeps its last iterate apart."""
    tut = halfboy_tutor.motion
    prob = problem_for(tut.character, tut.T, tut.fps, tut.contacts)
    tilted = Environment((-9.81 * np.sin(0.4), 0.0, -9.81 * np.cos(0.4)))
    res = prob.solve(ProblemData(tut.q, env=tilted), WarmStart(tut.q, tut.wrenches), SolverOptions(max_iter=3))
    assert not res.success and res.status == "Maximum_Iterations_Exceeded"
    failed = make_tutor(deepmimic_capture, character="halfboy", fps=15, max_iter=3)
    assert failed.status == "failed" and failed.motion is None
    assert "correction did not converge" in failed.message
    assert failed.last_iterate is not None and failed.last_iterate["q"].shape == tut.q.shape


def test_structured_derivatives_equal_automatic_ones():
    """The Hessian and Jacobian assembled from per-frame derivatives equal CasADi's own."""
    ch = C.halfboy()
    T = 7
    A = np.zeros((4, T), dtype=bool)
    A[0, :4] = A[1, :5] = True
    A[2, 3:] = A[3, 2:] = True
    A[:, -2:] = A[:, :2]
    prob = SpacetimeProblem(ch, T, 15.0, A)
    x = prob._nlp["x"]
    p = prob._nlp["p"]
    lam_f = ca.MX.sym("lf")
    lam_g = ca.MX.sym("lg", prob.ng)
    L = lam_f * prob._nlp["f"] + ca.dot(lam_g, prob._nlp["g"])
    auto_h = ca.Function("h", [x, p, lam_f, lam_g], [ca.triu(ca.hessian(L, x)[0])])
    auto_j = ca.Function("j", [x, p], [ca.jacobian(prob._nlp["g"], x)])
    rng = np.random.default_rng(0)
    q = rng.uniform(-0.3, 0.3, (ch.n, T))
    q[0] = np.linspace(0, 0.5, T)
    q[2] = 0.5
    from solver.spacetime import Weights

    pv = prob.parameters(prob.guide_markers(q + 0.01), q, Environment(), Weights(), prob.ref_points(q),
                         prob.anchor_points(q), 0.3, prob.com_points(q))
    xv = rng.normal(0, 0.3, prob.nx)
    lg = rng.normal(size=prob.ng)
    H1 = np.asarray(ca.densify(prob._hess(xv, pv, 0.7, lg)))
    H2 = np.asarray(ca.densify(auto_h(xv, pv, 0.7, lg)))
    J1 = np.asarray(ca.densify(prob._jac(xv, pv)[1]))
    J2 = np.asarray(ca.densify(auto_j(xv, pv)))
    assert np.allclose(H1, H2, rtol=1e-9, atol=1e-9 * np.abs(H2).max())
    assert np.allclose(J1, J2, rtol=1e-9, atol=1e-9 * np.abs(J2).max())


def test_contact_equations_are_independent(halfboy_tutor):
    """No redundant contact, cyclic or spline equations (docs/spacetime.md, What makes it converge): the equality
    Jacobian (rows scaled to unit norm: they mix metres, radians and body weights) has full row rank."""
    from solver.spacetime import Weights
    from solver.trajectory import spline_velocities

    tut = halfboy_tutor.motion
    prob = problem_for(tut.character, tut.T, tut.fps, tut.contacts)
    ref = prob.ref_points(tut.q)
    xv = np.concatenate([prob.pack_q(tut.q), prob.pack_v(spline_velocities(tut.q, tut.dt)),
                         prob.pack_wrenches(tut.wrenches, ref)])
    pv = prob.parameters(prob.guide_markers(tut.q), tut.q, Environment(), Weights(), ref, prob.anchor_points(tut.q),
                         0.0, prob.com_points(tut.q))
    J = np.asarray(ca.densify(prob._jac(xv, pv)[1]))
    eq = prob._lbg_a == prob._ubg_a
    Je = J[eq] / np.linalg.norm(J[eq], axis=1, keepdims=True)
    s = np.linalg.svd(Je, compute_uv=False)
    assert s.min() > 1e-6 * s.max(), f"rank-deficient equality Jacobian: σ_min/σ_max = {s.min() / s.max():.1e}"


def test_a_warm_start_takes_an_earlier_solves_multipliers_when_it_has_them():
    """IPOPT starts warm from both multipliers of a solve; a result without them (the tutor taken as
    its own optimum) leaves the start cold."""
    from solver.spacetime import SolveResult

    q = np.zeros((6, 5))
    cold = WarmStart(q)
    assert not cold.warm
    solved = SolveResult(True, "Solve_Succeeded", 9, 0.1, q, None, 0.0, 0.0, np.ones(4), np.ones(2), 0.0)
    warm = cold.with_multipliers(solved)
    assert warm.warm and warm.q is q and warm.lam_x is solved.lam_x and warm.lam_g is solved.lam_g
    taken = SolveResult(True, "tutor", 0, 0.0, q, None, 0.0, 0.0, None, None, 0.0)
    assert not cold.with_multipliers(taken).warm


def test_bad_inputs_are_refused_clearly(halfboy_tutor):
    tut = halfboy_tutor.motion
    prob = problem_for(tut.character, tut.T, tut.fps, tut.contacts)
    with pytest.raises(ValueError, match="guide must be"):
        prob.solve(ProblemData(tut.q[:, :-1]))
    bad = tut.q.copy()
    bad[3, 2] = np.nan
    with pytest.raises(ValueError, match="finite"):
        prob.solve(ProblemData(tut.q), WarmStart(bad))
    A = tut.contacts.copy()
    A[0, -1] = not A[0, 1]
    with pytest.raises(ValueError, match="repeat frames 1-2"):
        SpacetimeProblem(tut.character, tut.T, tut.fps, A)
    with pytest.raises(ValueError, match="contact schedule must be"):
        SpacetimeProblem(tut.character, tut.T, tut.fps, A[:, :-1])


def test_tutor_needs_an_upper_body_for_fullbody(shared_data):
    from solver.pipeline import PipelineError

    with pytest.raises(PipelineError, match="whole-body capture"):
        synthesis_character(C.capture_lower(), "fullbody")
    with pytest.raises(PipelineError, match="unknown synthesis character"):
        synthesis_character(C.capture_full(), "robot")


def test_markers_of_tutor_follow_the_capture_markers(halfboy_tutor, deepmimic_capture):
    """Every segment-tip marker stays within a few centimetres of the capture at every frame."""
    tut = halfboy_tutor.motion
    syn, cap = synthesis_character(deepmimic_capture.character, "halfboy")
    assert [s.name for s in syn.segments] == [s.name for s in cap.segments]
    mk = markers(tut.character, tut.q)
    assert mk.shape[0] == len([s for s in syn.segments if s.length > 0])
    assert np.isfinite(mk).all()


def _term_cost(prob, name: str, xv: np.ndarray, pv: np.ndarray) -> float:
    """The summed value of the problem's cost term ``name`` at (x, p)."""
    x = prob._nlp["x"]
    term = next(t_ for t_ in prob._terms if t_.name == name)
    return float(ca.Function("c", [x, prob._nlp["p"]], [ca.sum2(term.outputs(x))])(xv, pv))


def _sine_walk(ch, fps: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """One 1 s cycle (+ 2 overlap frames) of every coordinate on a sine of random amplitude and
    phase, with a two-step contact schedule: (q, contacts, amplitudes)."""
    rng = np.random.default_rng(1)
    amp = rng.uniform(0.05, 0.3, ch.n)  # rad (and m for the root translation, not in the cost)
    phase = rng.uniform(0, 2 * np.pi, ch.n)
    N = fps  # frames per cycle
    T = N + 2
    t = np.arange(T) / fps
    q = amp[:, None] * np.sin(2 * np.pi * t[None, :] + phase[:, None])
    q[2] += 0.9
    A = np.zeros((4, T), dtype=bool)
    A[0, : N // 2] = A[1, : N // 2 + 1] = True
    A[2, N // 2 - 1 :] = A[3, N // 2 - 2 :] = True
    A[:, -2:] = A[:, :2]
    return q, A, amp


def test_each_weight_reaches_the_nlp_in_its_named_slot():
    """The parameter vector carries each of ``Weights``' fields in its own named slot
    (``WEIGHT_SLOTS``): doubling one weight doubles that slot and leaves every other one."""
    from dataclasses import replace

    from solver.spacetime import Weights
    from solver.spacetime.types import WEIGHT_SLOTS, weight_slots

    ch = C.halfboy()
    q, A, _ = _sine_walk(ch, 15)
    prob = SpacetimeProblem(ch, q.shape[1], 15.0, A)
    o, s = prob._p_layout["wts"]

    def slots(w: Weights) -> dict[str, float]:
        p = prob.parameters(prob.guide_markers(q), q, Environment(), w, prob.ref_points(q), prob.anchor_points(q), 0.0)
        return weight_slots(p[o : o + s])

    ones = Weights(**{name: 1.0 for name in WEIGHT_SLOTS})  # every slot non-zero (com_track's default is 0)
    base = slots(ones)
    assert set(base) == {f for f in Weights.__dataclass_fields__} and all(v > 0 for v in base.values())
    for name in WEIGHT_SLOTS:
        got = slots(replace(ones, **{name: 2.0}))
        assert got == pytest.approx({k: (2.0 if k == name else 1.0) * v for k, v in base.items()}, rel=1e-12), name


def test_rate_costs_do_not_depend_on_the_frame_rate():
    """The jerk and wrench-change costs (and the kinematic fit's smoothness) are time averages with
    a fixed time scale (1/15 s): the same smooth motion and ground wrenches cost the same at 15 and
    30 frames/s, the jerk and the smoothness close to their continuous values. (With the frame
    interval as the scale, 30 frames/s made the jerk 64 times, the wrench change 4 times and the
    smoothness 16 times cheaper; the full body's trunk counter-rotated at 5 Hz to turn.)"""
    from solver.spacetime import Weights
    from solver.spacetime.layout import RATE_TIME
    from solver.trajectory import spline_velocities

    ch = C.halfboy()
    amp = _sine_walk(ch, 15)[2]
    f = 1.0  # Hz: one cycle of 1 s
    expected = float(np.mean((amp[3:] * (2 * np.pi * f) ** 3 * RATE_TIME**3) ** 2 / 2))
    costs: dict[str, dict[int, float]] = {"jerk": {}, "wrate": {}, "smooth": {}}
    for fps in (15, 30):
        q, A, _ = _sine_walk(ch, fps)
        T, t = q.shape[1], np.arange(q.shape[1]) / fps
        prob = SpacetimeProblem(ch, T, float(fps), A)
        ref = prob.ref_points(q)
        # smooth wrenches: forces through each foot's reference point plus a free moment
        W = np.zeros((2, 6, T))
        for k in range(2):
            W[k, 3:] = 300.0 * np.sin(2 * np.pi * f * t[None, :] + np.arange(3)[:, None] + k)
            W[k, 2] = 5.0 * np.cos(2 * np.pi * f * t + k)
            W[k, :3] += np.cross(ref[3 * k : 3 * k + 3].T, W[k, 3:].T).T
        pv = prob.parameters(prob.guide_markers(q), q, Environment(), Weights(jerk=1.0, wrench_rate=1.0), ref,
                             prob.anchor_points(q), 0.0, prob.com_points(q))
        xv = np.concatenate([prob.pack_q(q), prob.pack_v(spline_velocities(q, 1.0 / fps)), prob.pack_wrenches(W, ref)])
        for name in ("jerk", "wrate"):
            costs[name][fps] = _term_cost(prob, name, xv, pv)
        # the kinematic fit's smoothness (second differences of the rotations) on the same motion
        fit = SpacetimeProblem(ch, T, float(fps), A, dynamics=False)
        pv = fit.parameters(fit.guide_markers(q), q, Environment(), Weights(smoothness=1.0), fit.ref_points(q),
                            fit.anchor_points(q), 0.0)
        costs["smooth"][fps] = _term_cost(fit, "acc", fit.pack_q(q), pv)
    assert costs["jerk"][15] == pytest.approx(expected, rel=0.05), (costs, expected)
    assert costs["jerk"][30] == pytest.approx(expected, rel=0.02), (costs, expected)
    assert costs["wrate"][30] == pytest.approx(costs["wrate"][15], rel=0.03), costs
    # mean of (second difference × (1/15 s / h)²)² = (acceleration × (1/15 s)²)² (a 16-fold gap before)
    smooth = float(np.mean((amp[3:] * (2 * np.pi * f) ** 2 * RATE_TIME**2) ** 2 / 2))
    assert costs["smooth"][15] == pytest.approx(smooth, rel=0.05), (costs, smooth)
    assert costs["smooth"][30] == pytest.approx(smooth, rel=0.02), (costs, smooth)
