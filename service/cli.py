"""``motionx`` command line: a thin shell over ``solver``/``mjcf`` (commands in service.commands)."""

from __future__ import annotations

import argparse
import importlib
import logging
import math
import sys

log = logging.getLogger("motionx")


class CliError(Exception):
    """A user-facing error: printed as one line, exit status 2."""


def parse_belt_speed(text: str | None) -> float | str | None:
    """``--belt-speed``: None, "auto", or a finite speed in m/s."""
    if text is None:
        return None
    if text == "auto":
        return "auto"
    try:
        v = float(text)
    except ValueError:
        raise CliError(f"--belt-speed must be 'auto' or a speed in m/s, got {text!r}") from None
    if not math.isfinite(v):
        raise CliError(f"--belt-speed must be finite, got {text!r}")
    return v


#: importer parameters (``solver.io.errors.InputError.parameter``) -> the flag that sets them
PARAMETER_FLAGS = {"mass": "--mass KG", "belt_speed": "--belt-speed auto|V"}


def import_message(e: BaseException) -> str:
    """An importer's error in the command line's words: an error that names a missing
    importer parameter (``e.parameter``, e.g. ``"mass"``) says which flag to pass."""
    param = getattr(e, "parameter", None)
    if param in PARAMETER_FLAGS:
        return f"{getattr(e, 'reason', None) or e}; pass {PARAMETER_FLAGS[param]}"
    return str(e)


def warn_input(summary: dict) -> None:
    """Print what a user must see about an input (e.g. a mass the plates contradict) on stderr."""
    if summary.get("mass_warning"):
        print(f"motionx: warning: {summary['mass_warning']}; pass --mass KG if the trial's mass is wrong",
              file=sys.stderr)


def reference_character(name: str):
    from solver.character import CharacterError, reference

    try:
        return reference(name)
    except CharacterError as e:
        raise CliError(str(e)) from None


def build_parser() -> argparse.ArgumentParser:
    from service.commands import MODULES

    p = argparse.ArgumentParser(prog="motionx", description="Physically plausible walk extrapolation.")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress to stderr")
    sub = p.add_subparsers(dest="command", required=True)
    for name in MODULES:
        importlib.import_module(name).register(sub)
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
