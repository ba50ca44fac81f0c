import dataclasses

import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from mjcf.check import check_dynamics, random_states
from mjcf.replay import MujocoReplay
from solver import character as C
from solver import spatial as sp
from solver.dynamics import casadi_functions, rnea, root_wrench

CHARACTERS = ["halfboy", "fullbody", "capture-lower", "capture-full"]


@pytest.mark.parametrize("name", CHARACTERS)
def test_rnea_equals_mujoco_inverse(name):
    """Random q, q̇, q̈, gravity direction and foot wrenches: our RNEA == mj_inverse to 1e-9."""
    res = check_dynamics(C.reference(name), samples=40, seed=11)
    assert res["max_rel_err_joint"] <= 1e-9, res
    assert res["max_rel_err_root"] <= 1e-9, res


def test_batched_equals_frame_by_frame_and_mujoco_batch():
    ch = C.fullbody()
    st_ = random_states(ch, 12, np.random.default_rng(3))
    g = np.array([0.0, 0.0, -9.81])
    batch = rnea(ch, st_["q"], st_["qd"], st_["qdd"], g)
    for t in range(12):
        one = rnea(ch, st_["q"][:, t], st_["qd"][:, t], st_["qdd"][:, t], g)
        assert np.allclose(one.tau, batch.tau[:, t], rtol=1e-13, atol=1e-10)
    tau, h0 = MujocoReplay.create(ch).inverse(st_["q"], st_["qd"], st_["qdd"])
    assert np.allclose(batch.tau, tau, rtol=1e-9, atol=1e-9)
    assert np.allclose(batch.h0, h0, rtol=1e-9, atol=1e-9)


def test_casadi_function_equals_numpy():
    ch = C.halfboy()
    f = casadi_functions(ch)["rnea"]
    st_ = random_states(ch, 5, np.random.default_rng(4))
    for t in range(5):
        args = (st_["q"][:, t], st_["qd"][:, t], st_["qdd"][:, t], st_["g"][:, t])
        tau, h0 = f(*args)
        num = rnea(ch, *args)
        assert np.allclose(np.asarray(tau).ravel(), num.tau, rtol=1e-12, atol=1e-10)
        assert np.allclose(np.asarray(h0).ravel(), num.h0, rtol=1e-12, atol=1e-10)


def test_casadi_derivatives_equal_finite_differences():
    ch = C.halfboy()
    n = ch.n
    q, qd, qdd = ca.SX.sym("q", n), ca.SX.sym("qd", n), ca.SX.sym("qdd", n)
    g = ca.DM([0.4, 0.1, -9.7])
    h0 = casadi_functions(ch)["h0"](q, qd, qdd, g)
    x = ca.vertcat(q, qd, qdd)
    jac = ca.Function("j", [x], [ca.jacobian(h0, x)])
    rng = np.random.default_rng(7)
    x0 = rng.uniform(-0.6, 0.6, 3 * n)
    J = np.asarray(jac(x0))
    eps = 1e-6
    gn = np.asarray(g).ravel()
    fd = np.empty_like(J)
    for i in range(3 * n):
        xp, xm = x0.copy(), x0.copy()
        xp[i] += eps
        xm[i] -= eps
        hp = root_wrench(ch, xp[:n], xp[n : 2 * n], xp[2 * n :], gn)
        hm = root_wrench(ch, xm[:n], xm[n : 2 * n], xm[2 * n :], gn)
        fd[:, i] = (hp - hm) / (2 * eps)
    assert np.allclose(J, fd, rtol=1e-6, atol=1e-5)


def _rotated_world(ch: C.Character, rot: np.ndarray) -> C.Character:
    root = dataclasses.replace(ch.segments[0], orientation=rot)
    return dataclasses.replace(ch, segments=(root,) + ch.segments[1:])


angles = st.floats(-np.pi, np.pi, allow_nan=False)


@given(angles, angles, angles, st.integers(0, 2**31 - 1))
@settings(max_examples=25, deadline=None)
def test_rotating_world_and_gravity_rotates_the_root_wrench(a, b, c, seed):
    ch = C.halfboy()
    rot = sp.euler_zyx_to_matrix(a, b, c)
    rch = _rotated_world(ch, rot)
    st_ = random_states(ch, 1, np.random.default_rng(seed))
    q, qd, qdd = st_["q"][:, 0], st_["qd"][:, 0], st_["qdd"][:, 0]
    g = np.array([0.0, 0.0, -9.81])
    w = st_["fext"]["foot_r"][:, 0]
    base = rnea(ch, q, qd, qdd, g, {ch.model.seg_body["foot_r"]: w})
    turned = rnea(rch, q, qd, qdd, rot @ g, {rch.model.seg_body["foot_r"]: np.r_[rot @ w[:3], rot @ w[3:]]})
    assert np.allclose(turned.tau, base.tau, rtol=1e-9, atol=1e-8)
    assert np.allclose(turned.h0[:3], rot @ base.h0[:3], rtol=1e-9, atol=1e-8)
    assert np.allclose(turned.h0[3:], rot @ base.h0[3:], rtol=1e-9, atol=1e-8)


@given(st.integers(0, 2**31 - 1), st.sampled_from(CHARACTERS))
@settings(max_examples=20, deadline=None)
def test_free_fall_needs_no_root_wrench(seed, name):
    """Any posture, any orientation, moving at constant velocity, falling with gravity: h0 = 0, τ = 0."""
    ch = C.reference(name)
    rng = np.random.default_rng(seed)
    q = random_states(ch, 1, rng)["q"][:, 0]
    qd = np.zeros(ch.n)
    qd[:3] = rng.normal(size=3)  # translating, not rotating
    g = rng.normal(size=3)
    g *= 9.81 / np.linalg.norm(g)
    qdd = np.zeros(ch.n)
    qdd[:3] = g  # the root accelerates with gravity
    res = rnea(ch, q, qd, qdd, g)
    assert np.abs(res.h0).max() < 1e-9
    assert np.abs(res.tau).max() < 1e-9


def test_standing_still_needs_the_body_weight():
    ch = C.halfboy()
    res = rnea(ch, np.zeros(ch.n), np.zeros(ch.n), np.zeros(ch.n))
    assert res.h0[5] == pytest.approx(ch.weight)
    assert np.allclose(res.h0[3:5], 0.0, atol=1e-12)


def test_bad_external_body_is_refused():
    ch = C.halfboy()
    with pytest.raises(ValueError, match="unknown body"):
        rnea(ch, np.zeros(ch.n), np.zeros(ch.n), np.zeros(ch.n), fext={99: np.zeros(6)})
