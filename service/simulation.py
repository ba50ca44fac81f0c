"""A simulation's files, written one way for ``motionx simulate`` and for the API.

:func:`write_simulation` writes what :func:`mjcf.simulate.simulate` produced into a folder:
``model.xml`` (the model simulated), ``rollout.npz`` (timestep, qpos0, qvel0 and per step
time, ctrl in actuator order, qpos: it replays with MuJoCo's own API), ``report.json``,
``simulation.png`` (pelvis path, vertical foot forces) and ``simulated.glb`` (the simulated
walk at the motion's frame rate on the motion's character).

Over the API a simulation is a job of kind ``simulation`` (run by the same runners as the
extrapolation jobs, :func:`service.jobs.execute_job`); :func:`run_simulation` is its body: it
simulates a stored motion and stores the report and the files in SQL (``simulations``,
``simulation_files``). The solver and MuJoCo load lazily, in the job's process.
"""

from __future__ import annotations

import json
import logging
import tempfile
from pathlib import Path
from typing import Any

from service import store
from service.simulation_files import FILES

log = logging.getLogger(__name__)

#: the cycles a request may ask for (CPU: about 1 s per HalfBoy cycle, 1.5 s per full-body cycle, twice that with
#: the resync runs every simulation also makes: report.json "resync")
MIN_CYCLES, MAX_CYCLES, DEFAULT_CYCLES = 1, 100, 10
#: what the command line prints of the report
SUMMARY_KEYS = ("cycles_walked", "fell", "joint_tracking_rms_deg", "foot_force_rms_bw", "peak_torque_ratio_max",
                "realtime_factor")


def _plot(result, motion, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from solver.environment import body_weight

    S = result.series
    bw = body_weight(motion)
    fig, axes = plt.subplots(1, 2, figsize=(11, 4.2))
    ax = axes[0]
    ax.plot(S["q_ref"][:, 0], S["q_ref"][:, 1], "k--", lw=1, label="reference")
    ax.plot(S["q"][:, 0], S["q"][:, 1], "C0", lw=1.2, label="simulated")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title("pelvis path")
    ax.axis("equal")
    ax.legend(fontsize=8)
    ax = axes[1]
    for f, (side, c) in enumerate((("right", "C3"), ("left", "C2"))):
        ax.plot(S["t"], S["foot_force_ref"][:, f, 2] / bw, c + "--", lw=1, label=f"{side} stored")
        ax.plot(S["t"], S["foot_force"][:, f, 2] / bw, c, lw=1, label=f"{side} simulated")
    ax.set_xlabel("time (s)")
    ax.set_ylabel("vertical foot force (BW)")
    ax.set_title("foot forces")
    ax.legend(fontsize=7, ncol=2)
    if result.fell:
        for a in axes[1:]:
            a.axvline(float(result.fall_time or 0.0), color="k", lw=0.8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def write_simulation(result, motion, out: Path) -> dict[str, Any]:
    """Write the files of ``result`` (a :class:`mjcf.simulate.SimulationResult` of ``motion``)
    into ``out`` (created); returns the report as written to report.json."""
    import numpy as np

    from solver.export import export_motion
    from solver.motion import Motion, MotionContext

    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "model.xml").write_text(result.xml)
    np.savez_compressed(out / "rollout.npz", timestep=result.timestep, qpos0=result.qpos0, qvel0=result.qvel0,
                        time=result.time, ctrl=result.ctrl, qpos=result.qpos,
                        actuators=np.array(result.actuator_names))
    report = dict(result.report)
    report["files"] = {"model": "model.xml", "rollout": "rollout.npz", "plot": "simulation.png",
                       "glb": "simulated.glb"}
    (out / "report.json").write_text(json.dumps(report, indent=1))
    _plot(result, motion, out / "simulation.png")
    # the simulated walk, resampled at the motion's rate, on the motion's character
    step = max(1, int(round(1.0 / (motion.fps * result.timestep))))
    q = result.qpos[step - 1::step][:, result.coordinate_qpos].T
    if q.shape[1] >= 2:
        sim = Motion(motion.character, motion.fps, q, provenance={"source": "mujoco simulation"},
                     context=MotionContext(environment=motion.environment))
        export_motion(sim, "gltf", out / "simulated.glb")
    return report


def cannot_simulate(motion) -> str | None:
    """Why ``motion`` cannot be simulated (the conditions :func:`mjcf.simulate.simulate` states
    in its SimulationError), or None: checked when a simulation is asked for, so a request
    for a capture gets its 422 at once rather than a failed job."""
    if not motion.cyclic or motion.T < 5:
        return "simulation needs a gait cycle (a cyclic motion: frames T−2, T−1 repeat 0, 1)"
    if motion.contacts is None or motion.wrenches is None:
        return "simulation needs the motion's contact schedule and foot wrenches"
    return None


def run_simulation(db, simulation_id: str, *, write_lock=None) -> tuple[str, str]:
    """Simulate the stored motion of simulation ``simulation_id`` and store its report and files
    (``write_lock``: the job's, so its watchdog never cuts a write in half). Returns the
    simulation's final (status, message): ``succeeded`` (also when the character fell: that is a
    result, in the report), or ``failed`` with the reason (e.g. the SimulationError's text)."""
    import contextlib

    lock = write_lock or contextlib.nullcontext()
    with db.read() as s:
        sim = store.get_simulation(s, simulation_id=simulation_id, owner=None)
        if sim is None:
            return "failed", f"simulation {simulation_id} not found"
        row = store.get_motion(s, motion_id=sim.motion_id, owner=None)
        cycles = sim.cycles
        motion = store.load_motion(row)
    with lock, db.write() as s:
        store.set_simulation_status(s, simulation_id=simulation_id, status="running", message="")
    from mjcf.simulate import SimulationError, simulate  # lazy: in the job's process

    try:
        result = simulate(motion, cycles)
    except SimulationError as e:
        status, message = "failed", str(e)[:4000]
        with lock, db.write() as s:
            store.set_simulation_status(s, simulation_id=simulation_id, status=status, message=message)
        return status, message
    with tempfile.TemporaryDirectory(prefix="motionx-sim-") as tmp:
        report = write_simulation(result, motion, Path(tmp))
        files = {name: (Path(tmp) / name).read_bytes() for name in FILES if (Path(tmp) / name).exists()}
    from solver.pipeline import jsonable

    report = jsonable(report)
    plural = "s" if cycles != 1 else ""
    message = (f"fell after {report.get('cycles_walked', 0):.2f} of {cycles} cycle{plural}" if result.fell
               else f"walked {cycles} cycle{plural}")
    with lock, db.write() as s:
        store.finish_simulation(s, simulation_id=simulation_id, report=report, files=files, message=message)
    log.info("simulation %s: %s", simulation_id, message)
    return "succeeded", message
