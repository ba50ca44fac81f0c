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


def test_replay_from_written_files_reproduces_rollout(simulated):
    _, out, proc = simulated
    assert (out / "model.xml").exists(), proc.stderr
    model = mujoco.MjModel.from_xml_path(str(out / "model.xml"))
    r = np.load(out / "rollout.npz")
    assert float(r["timestep"]) == pytest.approx(model.opt.timestep)
    assert r["ctrl"].shape == (len(r["time"]), model.nu)
    assert [model.actuator(i).name for i in range(model.nu)] == list(r["actuators"])
    d = mujoco.MjData(model)
    d.qpos[:] = r["qpos0"]
    d.qvel[:] = r["qvel0"]
    qpos = np.empty_like(r["qpos"])
    for k in range(len(r["time"])):
        d.ctrl[:] = r["ctrl"][k]
        mujoco.mj_step(model, d)
        qpos[k] = d.qpos
    np.testing.assert_allclose(qpos, r["qpos"], rtol=0, atol=1e-12)
    np.testing.assert_allclose(r["time"][-1], d.time, atol=1e-12)


def test_model_is_performable(simulated):
    """The simulated model: unactuated root, one motor per joint, contacts on, 1 ms steps."""
    motion, out, _ = simulated
    model = mujoco.MjModel.from_xml_path(str(out / "model.xml"))
    names = motion.character.coordinate_names
    actuated = {model.joint(int(model.actuator_trnid[a, 0])).name for a in range(model.nu)}
    assert actuated == set(names[6:])  # no actuator on the root
    assert model.opt.timestep == 0.001
    assert not model.opt.disableflags & int(mujoco.mjtDisableBit.mjDSBL_CONTACT)
    soles = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"sole_{s}") for s in ("right", "left")]
    assert min(soles) >= 0 and all(model.geom_contype[g] for g in soles)


def test_tutor_walks_and_report(simulated):
    motion, out, proc = simulated
    rep = json.loads((out / "report.json").read_text())
    assert rep["cycle_duration_s"] == pytest.approx((motion.T - 2) / motion.fps)
    # measured (docs/simulation.md): the tutor walks 2 cycles, 4.3° joint RMS, 0.32 BW force RMS
    assert not rep["fell"], rep["fall"]
    assert proc.returncode == 0
    assert rep["cycles_walked"] == pytest.approx(CYCLES, abs=1e-2)
    assert rep["joint_tracking_rms_deg"] < 6.0
    assert rep["foot_force_rms_bw"] < 0.45
    assert len(rep["drift_per_cycle"]) == CYCLES
    assert (out / "simulated.glb").read_bytes()[:4] == b"glTF"
    assert (out / "simulation.png").stat().st_size > 0
