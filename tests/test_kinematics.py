import mujoco
import numpy as np
import pytest

from mjcf.builder import MARKER_PREFIX, compile_model
from solver import character as C
from solver.kinematics import contact_points, finite_differences, joint_screws, marker_points, markers


@pytest.mark.parametrize("name", ["halfboy", "capture-full"])
def test_markers_and_contact_points_match_mujoco_sites(name):
    ch = C.reference(name)
    model = compile_model(ch)
    data = mujoco.MjData(model)
    rng = np.random.default_rng(5)
    q = rng.uniform(-0.8, 0.8, (ch.n, 4))
    mk = markers(ch, q)
    cp = contact_points(ch, q)
    for t in range(4):
        for i, nm in enumerate(ch.coordinate_names):
            data.qpos[model.jnt_qposadr[model.joint(nm).id]] = q[i, t]
        mujoco.mj_kinematics(model, data)
        for j, (seg, _) in enumerate(marker_points(ch)):
            assert np.allclose(mk[j, :, t], data.site(MARKER_PREFIX + seg).xpos, atol=1e-12)
        for j, c in enumerate(ch.contacts):
            assert np.allclose(cp[j, :, t], data.site(c.name).xpos, atol=1e-12)


def test_standing_pose_puts_soles_at_leg_length():
    ch = C.halfboy()
    q = np.zeros(ch.n)
    cp = contact_points(ch, q)
    # contact points sit 1 cm above the sole; the sole is 0.53 H below the hips
    assert np.allclose(cp[:, 2], -0.53 * 1.2 + 0.01)


def test_finite_differences_are_exact_on_quadratics():
    t = np.arange(10) / 15.0
    Q = np.vstack([3 * t**2 - t + 1, -0.5 * t**2])
    qd, qdd = finite_differences(Q, 1 / 15.0)
    assert np.allclose(qd, np.vstack([6 * t[1:-1] - 1, -t[1:-1]]))
    assert np.allclose(qdd, np.vstack([np.full(8, 6.0), np.full(8, -1.0)]))
    with pytest.raises(ValueError, match="T >= 3"):
        finite_differences(Q[:, :2], 0.1)


def test_joint_screws_give_the_jacobian_transpose():
    """The generalized force of a world wrench on the foot is S_kᵀ w for ancestors of the foot."""
    ch = C.halfboy()
    model = compile_model(ch)
    data = mujoco.MjData(model)
    q = np.random.default_rng(1).uniform(-0.5, 0.5, ch.n)
    for i, nm in enumerate(ch.coordinate_names):
        data.qpos[model.jnt_qposadr[model.joint(nm).id]] = q[i]
    mujoco.mj_forward(model, data)
    w = np.array([1.0, -2.0, 0.5, 10.0, 3.0, -40.0])
    qfrc = np.zeros(model.nv)
    mujoco.mj_applyFT(model, data, w[3:], w[:3], np.zeros(3), model.body("foot_r").id, qfrc)
    s = joint_screws(ch, q)
    anc = set(ch.model.ancestors(ch.model.seg_body["foot_r"]))
    for i, nm in enumerate(ch.coordinate_names):
        expected = s[i] @ w if i in anc else 0.0
        assert qfrc[model.jnt_dofadr[model.joint(nm).id]] == pytest.approx(expected, abs=1e-10)
