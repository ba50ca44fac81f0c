"""Forward simulation with contacts on (mjcf.simulate, ``motionx simulate``) on the DeepMimic
HalfBoy tutor: the written rollout replays with MuJoCo's own API from the written model file,
and the controller walks (measured figures in docs/simulation.md)."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import mujoco
import numpy as np
import pytest

import solver

ROOT = Path(__file__).resolve().parents[1]
TRIAL = [str(ROOT / "data/deepmimic_humanoid3d_walk/humanoid3d_walk.txt"),
         str(ROOT / "data/deepmimic_humanoid3d_walk/humanoid3d_character.txt")]
CYCLES = 2


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("sim")
    tutor = solver.make_tutor(solver.load_trial(TRIAL), character="halfboy")
    assert tutor.status == "succeeded"
    path = tmp / "tutor.json"
    tutor.motion.save(path)
    out = tmp / "out"
    proc = subprocess.run([sys.executable, "-m", "service.cli", "simulate", str(path), "--cycles", str(CYCLES),
                           "--out", str(out)], capture_output=True, text=True, cwd=ROOT, timeout=600)
    return tutor.motion, out, proc


def test_replay_from_written_files_reproduces_rollout(simulated, replay_rollout):
    _, out, proc = simulated
    assert (out / "model.xml").exists(), proc.stderr
    model = mujoco.MjModel.from_xml_path(str(out / "model.xml"))
    r = np.load(out / "rollout.npz")
    assert float(r["timestep"]) == pytest.approx(model.opt.timestep)
    assert r["ctrl"].shape == (len(r["time"]), model.nu)
    assert [model.actuator(i).name for i in range(model.nu)] == list(r["actuators"])
    qpos, time_end = replay_rollout(model, r)
    np.testing.assert_allclose(qpos, r["qpos"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(r["time"][-1], time_end, atol=1e-12)


def test_model_is_performable(simulated):
    """The simulated model: unactuated root, one motor per joint, contacts on, 1 ms steps."""
    motion, out, _ = simulated
    model = mujoco.MjModel.from_xml_path(str(out / "model.xml"))
    names = motion.character.coordinate_names
    actuated = {model.joint(int(model.actuator_trnid[a, 0])).name for a in range(model.nu)}
    # a motor per joint and per foot's inversion hinge; none on the root
    assert actuated == set(names[6:]) | {"inversion_right", "inversion_left"}
    assert not actuated & set(names[:6])
    assert model.nbody == len(motion.character.segments) + 1  # the inversion hinge adds no body
    assert model.opt.timestep == 0.001
    assert not model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    soles = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"sole_{s}") for s in ("right", "left")]
    assert min(soles) >= 0 and all(model.geom_contype[g] for g in soles)


def test_tutor_walks_and_report(simulated):
    motion, out, proc = simulated
    rep = json.loads((out / "report.json").read_text())
    assert rep["cycle_duration_s"] == pytest.approx((motion.T - 2) / motion.fps)
    # measured (docs/simulation.md): the tutor walks 2 cycles, 2.5° joint RMS, 0.30 BW force RMS
    assert not rep["fell"], rep["fall"]
    assert proc.returncode == 0
    assert rep["cycles_walked"] == pytest.approx(CYCLES, abs=1e-2)
    assert rep["joint_tracking_rms_deg"] < 4.0
    assert rep["foot_force_rms_bw"] < 0.4
    assert len(rep["drift_per_cycle"]) == CYCLES
    # beside it, every cycle started afresh from the reference's state completes with the penalized root
    # residual (measured: 0.004 BW RMS on this tutor, docs/simulation.md)
    rs = rep["resync"]
    assert rs["cycles"] == CYCLES and rs["completed"] == CYCLES
    assert 0.0 < rs["residual_root_wrench_rms_bw"] < 0.02
    assert json.loads(proc.stdout)["resync"]["completed"] == CYCLES
    # the cycles start from the same state moved by the cycle transform, and the controller is invariant
    # under it (stored moments about the sole, not the world origin): they measure the same
    per = [c["residual_root_wrench_rms_bw"] for c in rs["per_cycle"]]
    assert max(per) - min(per) < 1e-3
    assert (out / "simulated.glb").read_bytes()[:4] == b"glTF"
    assert (out / "simulation.png").stat().st_size > 0


def test_stairs_treads_hold_the_feet_and_clear_the_swing(simulated):
    """The treads built for a flight of stairs hold every stance foot of the reference on its
    tread top, and each riser stands where the reference's swing foot passes above it."""
    from mjcf.performable import performable_model
    from mjcf.reference import Reference

    tutor, _, _ = simulated
    res = solver.extrapolate(tutor, solver.Target(step_height_m=0.08))
    assert res.status == "succeeded", res.message
    motion = res.steps[-1].motion
    ref = Reference(motion)
    _, model, geometry = performable_model(motion, 2, ref)
    assert len(geometry.treads) >= 6 and not geometry.floor and model.geom_contype[0] == 0  # treads, no floor
    d = mujoco.MjData(model)
    stance, swing = [], []
    for t in np.arange(0.0, 2 * ref.period, 0.01):
        d.qpos[geometry.coordinate_qpos] = ref.state(t)[0]
        mujoco.mj_kinematics(model, d)
        active = ref.active(t)
        contacts_now = ref.contacts[:, min(int(round(t / ref.dt)) % ref.P, ref.P - 1)]
        for sole in geometry.soles:
            owner = list(sole.owner)
            for c in range(4):
                p = d.xpos[sole.body] + d.xmat[sole.body].reshape(3, 3) @ sole.corners[c]
                h = p[2] - geometry.ground_height(d, p)
                (stance if contacts_now[owner[c]] else swing if not active[owner].any() else []).append(h)
    # stance heel/toe edges on their tread (the sole's width rolls them by a few mm)
    assert min(stance) > -0.02 and np.median(np.abs(stance)) < 0.01
    assert min(swing) > -0.015  # the swing foot passes above the risers (the controller lifts it 2 cm more)


def test_validation_report_carries_the_simulation_without_deciding_plausible(simulated):
    tutor, _, _ = simulated
    plain = solver.validate(tutor)
    rep = solver.validate(tutor, simulate=True)
    assert "simulation" not in plain
    sim = rep["simulation"]
    assert sim["cycles_requested"] == 10
    assert set(sim["checks"]) == {"cycles_walked", "joint_tracking_rms", "foot_force_rms", "peak_torque_ratio"}
    assert all(c["severity"] == "warning" for c in sim["checks"].values())  # reported, never deciding
    assert rep["plausible"] == plain["plausible"]
    walked = sim["checks"]["cycles_walked"]
    assert walked["passed"] == (walked["value"] >= 10) and walked["bound"] == "min"


def test_simulated_sole_is_the_characters_and_the_reference_clears_it(simulated):
    """The MuJoCo sole is ``Character.sole`` (heel and toe points mid-edges, the foot box's width); the
    stored centre of pressure is on it wherever the reference's sole is flat on the ground, and the
    reference's swing keeps all four sole corners above the ground."""
    motion, out, _ = simulated
    rep = json.loads((out / "report.json").read_text())
    sole = rep["agreement"]["sole"]
    assert sole["sole_matches_character"]
    assert sole["flat_stance_frames"] > 10 and sole["cop_outside_fraction_flat"] == 0.0
    clearance = rep["agreement"]["swing_clearance"]
    assert clearance["min_corner_height_m"] > 0.005  # measured: 16 mm


def test_start_is_preloaded_at_the_stored_vertical_force(simulated):
    """The start's contacts carry the stored vertical force from the first step (the body pressed into
    the soft contacts), where the unloaded start has none and oscillates."""
    from mjcf.gains import Gains
    from mjcf.performable import performable_model
    from mjcf.reference import Reference, mid_stance_time
    from mjcf.rollout import _rollout, _start
    from mjcf.tracker import Tracker

    motion, out, _ = simulated
    start = json.loads((out / "report.json").read_text())["start"]
    assert start["preloaded"] and start["stored_vertical_force_bw"] > 0.5
    assert start["first_10ms_max_difference_bw"] < 0.15  # measured: 0.12 BW
    assert start["first_60ms_rms_difference_bw"] < 0.08
    ref = Reference(motion)
    t0 = mid_stance_time(motion)
    _, model, geometry = performable_model(motion, 1, ref)
    ctl = Tracker(motion, model, geometry, ref, Gains(preload=False))
    d, info = _start(model, geometry, ctl, ref, t0, preload=False)
    run = _rollout(model, d, ctl, ref, geometry, t0, 60, True)
    unloaded = run.start_force / ctl.bw
    assert not info["preloaded"] and unloaded[0] < 0.1  # the unloaded start: no force on the first step
    assert np.max(np.abs(unloaded[:10] - start["stored_vertical_force_bw"])) > 0.5


def test_cycle_completes_from_the_reference_state_without_root_help(simulated):
    """Priced out of the QP, the root residual stays below 10⁻⁴ BW and the tutor's cycle still completes
    from the reference's state (docs/simulation.md: on the shipped tutors the root help is not needed)."""
    from mjcf.gains import Gains
    from mjcf.reference import Reference, mid_stance_time
    from mjcf.simulate import _resync

    motion, _, _ = simulated
    ref = Reference(motion)
    rs = _resync(motion, ref, mid_stance_time(motion), 1, Gains(residual_weight=1e12))
    assert rs["completed"] == 1 and rs["residual_root_wrench_rms_bw"] < 1e-4
    end = rs["per_cycle"][0]["end_error"]
    assert end["joint_rms_deg"] < 5.0 and abs(end["pelvis_height_m"]) < 0.02


@pytest.mark.parametrize("name,added", [("halfboy", 2), ("capture-full", 0)])
def test_a_foot_gets_an_inversion_hinge_only_when_it_has_none(name, added):
    """The performable model's inversion hinge (about the heel-toe line) is added to a foot that cannot
    turn about that line; a capture's 3-DOF ankle (``ankle_inversion_*``) already does, and a second hinge
    about the same axis through the same point made the mass matrix singular (the full-body tutors fell
    within 0.1 s, an arm thrown to the ground)."""
    from mjcf.builder import ContactOptions, build_performable
    from solver import character as C

    spec, parts = build_performable(C.reference(name), (0.0, 0.0, -9.81), ContactOptions(inversion=True))
    assert len(parts.inversion) == added
    m = spec.compile()
    d = mujoco.MjData(m)
    mujoco.mj_forward(m, d)
    M = np.zeros((m.nv, m.nv))
    mujoco.mj_fullM(m, d, M)
    assert np.linalg.eigvalsh(M).min() > 1e-8
