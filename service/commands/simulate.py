"""``motionx simulate``: perform a motion in MuJoCo with contacts on under the balancing QP
tracking controller (``mjcf.simulate``) and write what was simulated."""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from service.cli import CliError, add_command, load_motion


def _plot(result, motion, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import numpy as np

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
    _ = np


def cmd_simulate(args: argparse.Namespace) -> int:
    import numpy as np

    from mjcf.simulate import SimulationError, simulate
    from solver.export import export_motion
    from solver.motion import Motion

    if args.cycles < 1:
        raise CliError("--cycles must be >= 1")
    motion = load_motion(args.motion)
    try:
        res = simulate(motion, args.cycles)
    except SimulationError as e:
        raise CliError(str(e)) from e
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "model.xml").write_text(res.xml)
    np.savez_compressed(out / "rollout.npz", timestep=res.timestep, qpos0=res.qpos0, qvel0=res.qvel0,
                        time=res.time, ctrl=res.ctrl, qpos=res.qpos,
                        actuators=np.array(res.actuator_names))
    report = dict(res.report)
    report["files"] = {"model": "model.xml", "rollout": "rollout.npz", "plot": "simulation.png", "glb": "simulated.glb"}
    (out / "report.json").write_text(json.dumps(report, indent=1))
    _plot(res, motion, out / "simulation.png")
    # the simulated walk, resampled at the motion's rate, on the motion's character
    step = max(1, int(round(1.0 / (motion.fps * res.timestep))))
    q = res.qpos[step - 1::step][:, res.coordinate_qpos].T
    if q.shape[1] >= 2:
        env = dict(motion.provenance.get("environment") or {})
        sim = Motion(motion.character, motion.fps, q, provenance={"source": "mujoco simulation", "environment": env})
        export_motion(sim, "gltf", out / "simulated.glb")
    keys = ("cycles_walked", "fell", "joint_tracking_rms_deg", "foot_force_rms_bw", "peak_torque_ratio_max",
            "realtime_factor")
    print(json.dumps({k: report[k] for k in keys} | {"out": str(out)}))
    return 0 if not res.fell else 1


def register(sub: argparse._SubParsersAction) -> None:
    s = add_command(sub, "simulate", "perform a motion in MuJoCo with contacts on, under a balancing controller",
                    """\
Simulate MOTION.json in MuJoCo (contacts on, an unactuated root, a motor per joint, 1 ms steps)
for --cycles gait cycles under a balancing QP tracking controller, starting in mid stance with
the reference's velocities. Writes DIR/model.xml (the model simulated), DIR/rollout.npz
(timestep, qpos0, qvel0 and per step time, ctrl in actuator order, qpos), DIR/report.json
(cycles walked, fall, tracking, drift, forces, torques), DIR/simulation.png and
DIR/simulated.glb. Exit status 1 when the character fell.""")
    s.add_argument("motion", metavar="MOTION.json", help="a cyclic motion file with contacts and wrenches")
    s.add_argument("--cycles", type=int, default=10, help="gait cycles to simulate (default 10)")
    s.add_argument("--out", required=True, metavar="DIR", help="output folder")
    s.set_defaults(func=cmd_simulate)
