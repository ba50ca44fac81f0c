"""Physics-core commands: ``mjcf`` and ``check-dynamics``."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from service.cli import CliError, reference_character


def cmd_mjcf(args: argparse.Namespace) -> int:
    from mjcf.builder import to_xml

    if (args.character is None) == (args.motion is None):
        raise CliError("give exactly one of --character NAME or --motion MOTION.json")
    if args.motion is not None:
        from solver.motion import Motion, MotionError

        try:
            motion = Motion.load(args.motion)
        except MotionError as e:
            raise CliError(str(e)) from None
        ch = motion.character
        env = (motion.provenance.get("environment") or {}).get("gravity", (0.0, 0.0, -9.81))
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

    s = sub.add_parser("mjcf", help="write the MuJoCo model (MJCF XML) of a reference character or of a motion's")
    s.add_argument("--character", choices=sorted(REFERENCE), help="a reference character")
    s.add_argument("--motion", help="a motion file: the model of its character (the one `validate` replays)")
    s.add_argument("--out", required=True, help="output file, or - for stdout")
    s.set_defaults(func=cmd_mjcf)

    s = sub.add_parser("check-dynamics", help="compare our inverse dynamics with MuJoCo's mj_inverse")
    s.add_argument("--character", required=True, choices=sorted(REFERENCE))
    s.add_argument("--samples", type=int, default=100)
    s.add_argument("--seed", type=int, default=0)
    s.set_defaults(func=cmd_check_dynamics)
