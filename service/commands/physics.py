"""Physics-core commands: ``mjcf`` and ``check-dynamics``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from service.cli import CliError, add_command, load_motion, reference_character


def cmd_mjcf(args: argparse.Namespace) -> int:
    from mjcf.builder import to_xml

    if (args.character is None) == (args.motion is None):
        raise CliError("give exactly one of --character NAME or --motion MOTION.json")
    if args.motion is not None:
        motion = load_motion(args.motion)
        ch = motion.character

        env = motion.environment.gravity
        xml = to_xml(ch, env)
    else:
        ch = reference_character(args.character)
        xml = to_xml(ch)
    if args.out == "-":
        sys.stdout.write(xml)
    else:
        Path(args.out).write_text(xml)
        print(json.dumps({"character": ch.name, "out": args.out, "nq": ch.n, "total_mass": ch.total_mass}))
    return 0


def cmd_check_dynamics(args: argparse.Namespace) -> int:
    from mjcf.check import check_dynamics

    if args.samples < 1:
        raise CliError("--samples must be >= 1")
    res = check_dynamics(reference_character(args.character), args.samples, args.seed)
    print(json.dumps(res))
    return 0 if res["ok"] else 1


def register(sub: argparse._SubParsersAction) -> None:
    from solver.character import REFERENCE

    s = add_command(sub, "mjcf", "write the MuJoCo model (MJCF XML) of a reference character or of a motion's", """\
Write the MuJoCo model (MJCF, built with mujoco.MjSpec) of a reference character, or of a
motion's character and gravity: the model `motionx validate` replays. Prints a JSON line with
nq and total_mass.""")
    s.add_argument("--character", choices=sorted(REFERENCE), help="a reference character")
    s.add_argument("--motion", metavar="MOTION.json",
                   help="a motion file: the model of its character (the one `validate` replays)")
    s.add_argument("--out", required=True, metavar="FILE.xml", help="output file, or - for stdout")
    s.set_defaults(func=cmd_mjcf)

    s = add_command(sub, "check-dynamics", "compare our inverse dynamics with MuJoCo's mj_inverse", """\
Random configurations, velocities, accelerations, gravity directions and foot wrenches: our
recursive Newton-Euler inverse dynamics against MuJoCo's mj_inverse on the same model.
Prints one JSON object (max_rel_err_joint, max_rel_err_root, ...); exit status 1 when either
exceeds 1e-9.""")
    s.add_argument("--character", required=True, choices=sorted(REFERENCE), help="the reference character to test")
    s.add_argument("--samples", type=int, default=100, metavar="N", help="random states to compare")
    s.add_argument("--seed", type=int, default=0, metavar="S", help="random seed (same seed, same states)")
    s.set_defaults(func=cmd_check_dynamics)
