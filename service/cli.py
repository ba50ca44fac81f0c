"""``motionx`` command line."""

from __future__ import annotations

import argparse
import json
import logging
import sys
from pathlib import Path

log = logging.getLogger("motionx")


class CliError(Exception):
    """A user-facing error: printed as one line, exit status 2."""


def _character(name: str):
    from solver.character import CharacterError, reference

    try:
        return reference(name)
    except CharacterError as e:
        raise CliError(str(e)) from None


def cmd_mjcf(args: argparse.Namespace) -> int:
    from mjcf.builder import to_xml

    ch = _character(args.character)
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
    res = check_dynamics(_character(args.character), args.samples, args.seed)
    print(json.dumps(res))
    return 0 if res["ok"] else 1


def build_parser() -> argparse.ArgumentParser:
    from solver.character import REFERENCE

    p = argparse.ArgumentParser(prog="motionx", description="Physically plausible walk extrapolation.")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress to stderr")
    sub = p.add_subparsers(dest="command", required=True)

    s = sub.add_parser("mjcf", help="write the MuJoCo model (MJCF XML) of a reference character")
    s.add_argument("--character", required=True, choices=sorted(REFERENCE))
    s.add_argument("--out", required=True, help="output file, or - for stdout")
    s.set_defaults(func=cmd_mjcf)

    s = sub.add_parser("check-dynamics", help="compare our inverse dynamics with MuJoCo's mj_inverse")
    s.add_argument("--character", required=True, choices=sorted(REFERENCE))
    s.add_argument("--samples", type=int, default=100)
    s.add_argument("--seed", type=int, default=0)
    s.set_defaults(func=cmd_check_dynamics)
    return p


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    try:
        return args.func(args)
    except CliError as e:
        print(f"motionx: error: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
