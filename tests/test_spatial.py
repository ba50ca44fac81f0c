import casadi as ca
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from solver import spatial as sp

floats = st.floats(-10, 10, allow_nan=False, allow_infinity=False)
vec = st.tuples(floats, floats, floats)


def test_align_z_is_a_rotation_taking_z_to_axis():
    rng = np.random.default_rng(1)
    axes = [np.eye(3)[i] * s for i in range(3) for s in (1, -1)] + list(rng.normal(size=(20, 3)))
    for a in axes:
        r = sp.align_z(a)
        assert np.allclose(r @ r.T, np.eye(3), atol=1e-14)
        assert np.isclose(np.linalg.det(r), 1.0)
        assert np.allclose(r[:, 2], a / np.linalg.norm(a), atol=1e-14)


def test_align_z_rejects_zero_axis():
    with pytest.raises(ValueError, match="non-zero"):
        sp.align_z([0, 0, 0])


@given(vec, vec)
def test_cross_matches_numpy(a, b):
    assert np.allclose(sp.cross(a, b), np.cross(a, b), atol=1e-12)


@given(vec, vec, st.floats(0.1, 10), vec)
@settings(max_examples=50)
def test_inertia_apply_matches_6x6_matrix(w, v, m, c):
    rng = np.random.default_rng(0)
    a = rng.normal(size=(3, 3))
    ic = a @ a.T
    f = sp.inertia_apply(m, c, sp.const_mat(ic), (w, v))
    cx = sp.skew(c)
    big = np.block([[ic + m * cx @ cx.T, m * cx], [m * cx.T, m * np.eye(3)]])
    assert np.allclose(np.r_[f[0], f[1]], big @ np.r_[w, v], atol=1e-9)


def test_force_transform_round_trip_and_matrix():
    rng = np.random.default_rng(2)
    r = sp.rotation_about(rng.normal(size=3), 0.7)
    p = rng.normal(size=3)
    f = (tuple(rng.normal(size=3)), tuple(rng.normal(size=3)))
    fp = sp.force_to_parent(sp.const_mat(r), tuple(p), f)
    assert np.allclose(np.r_[fp[0], fp[1]], sp.spatial_force_transform(r, p) @ np.r_[f[0], f[1]])
    back = sp.force_to_child(sp.const_mat(r), tuple(p), fp)
    assert np.allclose(np.r_[back[0], back[1]], np.r_[f[0], f[1]])


def test_same_code_runs_on_numpy_batches_and_casadi():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(3, 7))
    y = rng.normal(size=(3, 7))
    num = sp.stack(sp.cross(tuple(x), tuple(y)))
    xs, ys = ca.SX.sym("x", 3), ca.SX.sym("y", 3)
    f = ca.Function("f", [xs, ys], [sp.stack(sp.cross(tuple(sp.components(xs, 3)), tuple(sp.components(ys, 3))))])
    for t in range(7):
        assert np.allclose(np.asarray(f(x[:, t], y[:, t])).ravel(), num[:, t])


def test_constant_folding_emits_no_operation_for_zero_and_one():
    x = ca.SX.sym("x")
    assert sp.mul(0.0, x) == 0.0
    assert sp.mul(1.0, x) is x
    assert sp.add(0.0, x) is x


def test_euler_round_trip():
    for yaw, pitch, roll in [(0.3, -0.4, 1.0), (-2.0, 1.2, -0.3)]:
        r = sp.euler_zyx_to_matrix(yaw, pitch, roll)
        assert np.allclose(sp.matrix_to_euler_zyx(r), (yaw, pitch, roll))
