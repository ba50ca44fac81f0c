"""``motionx simulate``: perform a motion in MuJoCo with contacts on under the balancing QP
tracking controller (``mjcf.simulate``) and write what was simulated (service.simulation)."""

from __future__ import annotations

import argparse
import json
from dataclasses import replace
from pathlib import Path

from service.cli import CliError, add_command, load_motion


def cmd_simulate(args: argparse.Namespace) -> int:
    from mjcf.simulate import SimulationError, simulate
    from service.simulation import SUMMARY_KEYS, write_simulation

    if args.cycles < 1:
        raise CliError("--cycles must be >= 1")
    motion = load_motion(args.motion)
    try:
        controller, offline = None, None
        if args.controller == "cycle":
            from mjcf.cycle import cycle_controller, feasible_cycle

            cycle = feasible_cycle(motion)
            offline = {k: v for k, v in cycle.record.items() if k != "log"}
            if offline["status"] != "computed":
                raise CliError(f"no offline cycle: {offline.get('message', '')}")
            controller = cycle_controller(cycle)
        res = simulate(motion, args.cycles, controller=controller, resync=not args.no_resync)
    except (SimulationError, ValueError) as e:  # a motion this model or the offline cycle cannot take
        raise CliError(str(e)) from e
    if offline is not None:
        res = replace(res, report={**res.report, "offline_cycle": offline})
    out = Path(args.out)
    report = write_simulation(res, motion, out)
    summary = {k: report[k] for k in SUMMARY_KEYS}
    if "resync" in report:
        summary["resync"] = {k: report["resync"][k] for k in ("cycles", "completed", "residual_root_wrench_rms_bw")}
    print(json.dumps(summary | {"out": str(out)}))
    return 0 if not res.fell else 1


def register(sub: argparse._SubParsersAction) -> None:
    s = add_command(sub, "simulate", "perform a motion in MuJoCo with contacts on, under a balancing controller",
                    """\
Simulate MOTION.json in MuJoCo (contacts on, an unactuated root, a motor per joint, 1 ms steps)
for --cycles gait cycles under a balancing QP tracking controller, starting in mid stance with
the reference's velocities. Writes DIR/model.xml (the model simulated), DIR/rollout.npz
(timestep, qpos0, qvel0 and per step time, ctrl in actuator order, qpos), DIR/report.json
(cycles walked, fall, tracking, drift, forces, torques; the start's contact force, the
sole's agreement with the stored wrenches; "resync": each cycle also started afresh from the
reference's state and tracked to its end with a penalized residual wrench at the root, its
RMS in body weights), DIR/simulation.png and DIR/simulated.glb. Exit status 1 when the
character fell in the continuous run.""")
    s.add_argument("motion", metavar="MOTION.json", help="a cyclic motion file with contacts and wrenches")
    s.add_argument("--cycles", type=int, default=10, help="gait cycles to simulate (default 10)")
    s.add_argument("--no-resync", action="store_true",
                   help="skip the per-cycle runs from the reference state (report.json's resync; about as long as "
                        "the continuous run)")
    s.add_argument("--controller", choices=("tracker", "cycle"), default="tracker",
                   help="tracker (default): the balancing QP tracking the motion; cycle: first compute offline a "
                        "cycle the character performs with its joint motors alone, closing onto its start, and "
                        "perform it with periodic LQR feedback (mjcf.cycle; 15-40 CPU-s more for HalfBoy; "
                        "report.json's offline_cycle)")
    s.add_argument("--out", required=True, metavar="DIR", help="output folder")
    s.set_defaults(func=cmd_simulate)
