"""The offline cycle (``mjcf.cycle``) on the DeepMimic HalfBoy tutor: its states are a MuJoCo trajectory
of the character under its joint motors alone, it closes onto its start under the cycle transform,
and its controller walks the tutor for 10 cycles continuously (measured figures:
docs/simulation.md, "The offline cycle")."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest
import shared_tutors

from mjcf.cycle import CycleController, cycle_controller, despiked, feasible_cycle
from mjcf.gains import Gains
from mjcf.performable import performable_model
from mjcf.reference import Reference
from mjcf.simulate import CLOSE_TOLERANCE, simulate
from solver.environment import body_weight

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def motion(shared_data):
    res = shared_tutors.tutor(shared_data)
    assert res.status == "succeeded"
    return res.motion


@pytest.fixture(scope="module")
def cycle(motion):
    return feasible_cycle(motion)


def test_the_cycle_is_performed_by_the_motors_alone(motion, cycle):
    """Independent of the optimizer's record: from every stored state, one MuJoCo step of a model without
    any root residual under the stored motor torques; the generalized force the root would need to land
    on the next stored state (M Δq̇ / Δt on the root's six coordinates) is what the cycle lacks."""
    rec = cycle.record
    assert rec["status"] == "computed"
    # the tracker's cycle needed root help; the offline cycle needs none
    assert rec["residual_rms_bw_before"] > 0.03
    assert rec["residual_rms_bw_after"] < 5e-4 and rec["residual_rms_bw_after"] < 0.01 * rec["residual_rms_bw_before"]
    g = Gains()
    _xml, m, geo = performable_model(motion, 2, Reference(motion), g.sole_half_width, g.inversion)
    assert not len(geo.residual)
    ids = [mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_ACTUATOR, nm) for nm in cycle.motor_names]
    nv, dt = m.nv, float(m.opt.timestep)
    root = geo.coordinate_dof[:6]
    M = np.zeros((nv, nv))
    need = []
    for s in range(cycle.steps):
        d = mujoco.MjData(m)
        d.qpos[:], d.qvel[:] = cycle.states[s, :nv], cycle.states[s, nv:]
        d.ctrl[ids] = cycle.controls[s]
        mujoco.mj_step(m, d)
        mujoco.mj_fullM(m, d, M)
        need.append((M @ (cycle.states[s + 1, nv:] - d.qvel))[root] / dt)
    rms_bw = float(np.sqrt(np.mean(np.sum(np.array(need) ** 2, axis=1)))) / body_weight(motion)
    assert rms_bw < 1e-3  # the tracker's first guess needed 0.07 BW
    assert rms_bw < 3 * rec["residual_rms_bw_after"] + 1e-4  # and it agrees with the optimizer's record


def test_the_cycle_closes_onto_its_start(cycle):
    err = cycle.record["end_error_after"]
    before = cycle.record["end_error_before"]
    assert err["joint_rms_deg"] < 0.1 and err["joint_velocity_rms_deg_s"] < 2.0
    assert abs(err["pelvis_height_m"]) < 1e-3 and err["root_velocity_m_s"] < 0.01
    # ten times inside the resync's closing tolerance, which the tracker's own cycle misses
    assert all(abs(err[k]) < 0.1 * tol for k, tol in CLOSE_TOLERANCE.items())
    assert cycle.record["closes"]
    assert before["joint_velocity_rms_deg_s"] > CLOSE_TOLERANCE["joint_velocity_rms_deg_s"]


def test_the_cycle_controller_walks_ten_cycles(motion, cycle):
    """The default tracker falls after about three cycles of this tutor (docs/simulation.md)."""
    rep = simulate(motion, 10, controller=cycle_controller(cycle), resync=False).report
    assert rep["controller"] == "CycleController"
    assert not rep["fell"], rep.get("fall")
    assert rep["cycles_walked"] > 10 - 0.01
    assert rep["joint_tracking_rms_deg"] < 6.0


def test_gain_spikes_are_replaced_and_a_bad_cycle_is_refused(motion, cycle):
    K = np.ones((20, 2, 3))
    K[7] *= 1e5
    out = despiked(K)
    assert np.abs(out).max() == 1.0 and np.abs(K[7]).max() == 1e5  # the input is left as it was
    size = np.abs(cycle.gains).max(axis=(1, 2))
    assert size.max() <= 10 * np.median(size) + 1e-9
    g = Gains()
    ref = Reference(motion)
    _xml, m, geo = performable_model(motion, 2, ref, g.sole_half_width, g.inversion)
    from dataclasses import replace
    empty = replace(cycle, controls=cycle.controls[:0], states=cycle.states[:0], gains=cycle.gains[:0],
                    record={"status": "failed", "message": "test"})
    with pytest.raises(ValueError, match="not computed"):
        CycleController(motion, m, geo, ref, empty)


def test_the_command_line_performs_the_offline_cycle(motion, tmp_path):
    path = tmp_path / "tutor.json"
    motion.save(path)
    out = tmp_path / "out"
    proc = subprocess.run([sys.executable, "-m", "service.cli", "simulate", str(path), "--controller", "cycle",
                           "--cycles", "2", "--no-resync", "--out", str(out)], capture_output=True, text=True,
                          cwd=ROOT, timeout=600)
    assert proc.returncode == 0, proc.stderr
    report = json.loads((out / "report.json").read_text())
    assert report["controller"] == "CycleController" and not report["fell"]
    assert report["offline_cycle"]["closes"] and report["offline_cycle"]["residual_rms_bw_after"] < 5e-4
    assert json.loads(proc.stdout)["cycles_walked"] > 2 - 0.01  # the last step rounds the period
