"""Replacing the forward simulation's controller (``mjcf.controller``, docs/simulation.md "Replacing
the controller") on the DeepMimic HalfBoy tutor: the run calls a controller's hooks in their
documented order and nothing else; MuJoCo applies the torques it returns; its termination ends the
run with its reason; the default Tracker, reached through the hooks only, runs as the default."""

from __future__ import annotations

from collections import Counter
from pathlib import Path
from typing import Any

import mujoco
import numpy as np
import pytest

import solver
from mjcf.controller import Controller, FallTermination
from mjcf.gains import Gains
from mjcf.simulate import simulate
from mjcf.tracker import Tracker

ROOT = Path(__file__).resolve().parents[1]
TRIAL = [str(ROOT / "data/deepmimic_humanoid3d_walk/humanoid3d_walk.txt"),
         str(ROOT / "data/deepmimic_humanoid3d_walk/humanoid3d_character.txt")]
STEPS = 25


@pytest.fixture(scope="module")
def motion():
    tutor = solver.make_tutor(solver.load_trial(TRIAL), character="halfboy")
    assert tutor.status == "succeeded"
    return tutor.motion


class HoldPose:
    """PD on every motor toward the start's pose (critically damped at ω = 20 rad/s, scaled by each
    joint's inertia), no reference and no balance, written against the protocol alone; it ends the
    run after ``stop_after`` steps, else at the default fall."""

    control_period = 2
    torque_limit = None

    def __init__(self, motion, model, geometry, reference, stop_after: int) -> None:
        joints = model.actuator_trnid[geometry.motors, 0]
        self.motors, self.qadr, self.dof = geometry.motors, model.jnt_qposadr[joints], model.jnt_dofadr[joints]
        self.inertia = model.dof_M0[self.dof]
        self.nu, self.stop_after = model.nu, stop_after
        self.fall = FallTermination(model, geometry, reference)

    def initialize(self, data: mujoco.MjData, t0: float) -> None:
        self.log, self.sent, self.applied, self.steps = ["initialize"], [], [], 0
        self.q0 = data.qpos[self.qadr].copy()
        self.fall.start(data, t0)

    def control(self, data: mujoco.MjData, t_ref: float) -> np.ndarray:
        self.log.append("control")
        tau = np.zeros(self.nu)  # a root residual's actuators (resync runs) stay off
        tau[self.motors] = self.inertia * (20.0**2 * (self.q0 - data.qpos[self.qadr]) - 2 * 20.0 * data.qvel[self.dof])
        self.sent.append(tau.copy())
        return tau

    def measures(self, data: mujoco.MjData) -> dict[str, Any]:
        self.log.append("measures")
        return {"hold_error": data.qpos[self.qadr] - self.q0}

    def after_step(self, data: mujoco.MjData) -> None:
        self.log.append("after_step")
        self.steps += 1
        self.applied.append(data.qfrc_actuator[self.dof].copy())  # the generalized force on each motor's joint

    def clock_rate(self, data: mujoco.MjData, t_ref: float) -> float:
        self.log.append("clock_rate")
        return 1.0

    def termination(self, data: mujoco.MjData, t_ref: float) -> str | None:
        self.log.append("termination")
        return f"held for {self.steps} steps" if self.steps >= self.stop_after else self.fall(data, t_ref)


def test_a_replacement_controller_runs_by_its_hooks_and_ends_at_its_termination(motion, replay_rollout):
    made: list[HoldPose] = []

    def factory(motion, model, geometry, reference) -> Controller:
        made.append(HoldPose(motion, model, geometry, reference, STEPS))
        return made[-1]

    res = simulate(motion, 1, controller=factory)
    ctl = made[0]
    # its termination ended the run, with its reason, in the continuous run and in each resync cycle
    assert res.fell and res.fall_reason == f"held for {STEPS} steps" == res.report["fall"]["reason"]
    assert len(res.time) == STEPS and res.fall_time == pytest.approx(STEPS * res.timestep)
    assert [c["fall_reason"] for c in res.report["resync"]["per_cycle"]] == [f"held for {STEPS} steps"]
    assert res.report["torque_limit_nm"] is None and res.report["control_period_s"] == 2 * res.timestep
    # the hooks, in order: control every 2 steps, measures every 10 ms (10 steps), then the step's three
    expected = ["initialize"]
    for s in range(STEPS):
        expected += ["control"] * (s % 2 == 0) + ["measures"] * (s % 10 == 0)
        expected += ["after_step", "clock_rate", "termination"]
    assert ctl.log == expected
    assert res.series["hold_error"].shape == (3, len(ctl.motors))
    # its torques, held between its calls, are the run's ctrl and what MuJoCo applied to the joints
    sent = np.repeat(np.array(ctl.sent), 2, axis=0)[:STEPS]
    np.testing.assert_array_equal(res.ctrl, sent)
    np.testing.assert_allclose(np.array(ctl.applied), sent[:, ctl.motors], rtol=0, atol=1e-12)
    model = mujoco.MjModel.from_xml_string(res.xml)
    qpos, _ = replay_rollout(model, {"qpos0": res.qpos0, "qvel0": res.qvel0, "ctrl": res.ctrl, "qpos": res.qpos,
                                     "time": res.time})
    np.testing.assert_array_equal(qpos, res.qpos)  # MuJoCo's own stepping of those controls is the run


class Recorder:
    """The protocol's hooks of an inner controller and nothing else, each call counted."""

    def __init__(self, inner: Controller) -> None:
        self.inner, self.calls = inner, Counter[str]()
        self.control_period, self.torque_limit = inner.control_period, inner.torque_limit

    def initialize(self, data, t0):
        self.calls["initialize"] += 1
        return self.inner.initialize(data, t0)

    def control(self, data, t_ref):
        self.calls["control"] += 1
        return self.inner.control(data, t_ref)

    def measures(self, data):
        return self.inner.measures(data)

    def after_step(self, data):
        return self.inner.after_step(data)

    def clock_rate(self, data, t_ref):
        return self.inner.clock_rate(data, t_ref)

    def termination(self, data, t_ref):
        self.calls["termination"] += 1
        return self.inner.termination(data, t_ref)


def test_the_default_tracker_through_its_hooks_alone_is_the_default_run(motion):
    base = simulate(motion, 1, resync=False)
    made: list[Recorder] = []

    def factory(motion, model, geometry, reference) -> Controller:
        made.append(Recorder(Tracker(motion, model, geometry, reference, Gains())))
        return made[-1]

    via = simulate(motion, 1, controller=factory, resync=False)
    assert not base.fell and made[0].calls["termination"] == len(base.time)
    np.testing.assert_array_equal(via.ctrl, base.ctrl)
    np.testing.assert_array_equal(via.qpos, base.qpos)
    assert via.series.keys() == base.series.keys() >= {"foot_force_qp", "stance_corners", "anchor"}
    for k in base.series:
        np.testing.assert_array_equal(via.series[k], base.series[k])
    assert via.report["torque_limit_nm"] == base.report["torque_limit_nm"]
