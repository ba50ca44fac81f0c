"""``motionx`` command line: a thin shell over ``solver``/``mjcf`` (commands in service.commands).

Conventions every command follows (tests/test_cli_conventions.py checks them):

- a user mistake (bad argument, unreadable or wrong file, impossible request) is one line
  ``motionx: error: …`` on stderr and exit status 2 (:class:`CliError`);
- output piped into a reader that stops early (``motionx validate … | head``) ends quietly
  with status 141, as a process killed by SIGPIPE; Ctrl-C ends with one line and status 130
  (SIGTERM: 143, for commands that clean up after themselves, e.g. ``demo``);
- every command has a description, every option a help line that states its default.
"""

from __future__ import annotations

import argparse
import importlib
import json
import logging
import math
import os
import select
import signal
import sys
import threading
from importlib.metadata import PackageNotFoundError
from importlib.metadata import version as dist_version
from pathlib import Path
from typing import ClassVar

from solver.formats import BVH_UNITS, reader_suffixes

log = logging.getLogger("motionx")

#: the files of a captured trial (what `motionx tutor` reads), by suffix: the readers' registry
#: (solver.formats) but .txt/.json/.xml, which may be a motion file too
TRIAL_SUFFIXES = {s: kind for s, kind in reader_suffixes().items() if s not in (".txt", ".json", ".xml")}


def _positive_kg(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise CliError(f"--mass must be a mass in kg, got {text!r}") from None
    if not (math.isfinite(v) and v > 0):
        raise CliError(f"--mass must be a positive finite mass in kg, got {text!r}")
    return v


def _belt(text: str) -> float | str:
    if text == "auto":
        return "auto"
    try:
        v = float(text)
    except ValueError:
        raise CliError(f"--belt-speed must be 'auto' or a speed in m/s, got {text!r}") from None
    if not math.isfinite(v):
        raise CliError(f"--belt-speed must be finite, got {text!r}")
    return v


def _unit(text: str) -> str | float:
    try:
        return float(text)
    except ValueError:
        return text


def finite(flag: str, what: str = "a number"):
    """An argparse type: a finite number (``what`` says what the flag takes, in its errors)."""
    def conv(text: str) -> float:
        try:
            v = float(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{flag} takes {what}, got {text!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"{flag} must be finite, got {text!r}")
        return v

    return conv


def finite_list(flag: str):
    """An argparse type: comma-separated finite numbers."""
    one = finite(flag, "comma-separated numbers")
    return lambda text: [one(part.strip()) for part in text.split(",")]


def _joints(text: str) -> dict[str, str]:
    from solver.io.roles import RoleError, parse_joint_mapping  # lazy: only a command given --joints reads it

    try:
        return parse_joint_mapping(text)
    except RoleError as e:
        raise CliError(f"--joints: {e}") from None


#: the importer options whose text is converted (a mistake is one line, exit status 2)
_CONVERT = {"mass": _positive_kg, "belt_speed": _belt, "units": _unit, "joints": _joints}
#: every importer option (``solver.formats.reader_options()``) as a flag: (flag, argparse
#: keywords). Every command that imports a trial offers them all (``add_import_options``); a test
#: checks that each reader option has its flag.
IMPORT_FLAGS: dict[str, tuple[str, dict]] = {
    "mass": ("--mass", {"metavar": "KG",
                        "help": "subject mass in kg (default: from the input; required when the input does not "
                                "state it, e.g. BVH)"}),
    "belt_speed": ("--belt-speed", {"metavar": "auto|V",
                                    "help": "OpenSim treadmill trials: belt speed in m/s, or 'auto' (adds v·t to the "
                                            "root: overground-equivalent; default: none, overground); BVH and glTF "
                                            "in-place clips (no root motion): the walking speed in m/s, 'auto' (the "
                                            "stance foot's) or 0 (not in place; default: detected)"}),
    "markers": ("--markers", {"metavar": "MAP",
                              "help": "C3D: marker mapping for unrecognised marker sets, ROLE=label,... (Plug-in "
                                      "Gait roles, e.g. LASI=L_IAS,RASI=R_IAS) or a file with one ROLE=label per "
                                      "line (docs/c3d.md; default: roles detected from the labels)"}),
    "lower_only": ("--lower-only", {"action": argparse.BooleanOptionalAction,
                                    "help": "fit the lower body only (--no-lower-only: the whole body; default: the "
                                            "whole body when the data allow)"}),
    "units": ("--units", {"metavar": "UNIT",
                          "help": f"BVH: length unit of the file, {', '.join(BVH_UNITS)} or metres per unit "
                                  "(default: auto)"}),
    "up": ("--up", {"choices": ["y", "z"], "help": "BVH: the file's up axis (default: y)"}),
    "joints": ("--joints", {"metavar": "ROLE=NAME,...",
                            "help": "BVH, glTF: joint mapping for unrecognised joint names, ROLE=NAME,... (roles hips, "
                                    "hip_l, knee_l, ankle_l, mtp_l, …, e.g. hip_l=Thigh_L,knee_l=Shin_L) or a file "
                                    "with one ROLE=NAME per line (docs/import.md; default: roles detected from the "
                                    "names and the hierarchy)"}),
    "animation": ("--animation", {"metavar": "NAME|INDEX",
                                  "help": "glTF: the animation to read, by name or index (default: the first)"}),
    "in_degrees": ("--in-degrees", {"action": argparse.BooleanOptionalAction,
                                    "help": "OpenSim: the coordinates file is in degrees (--no-in-degrees: radians; "
                                            "default: its header says)"}),
}
#: importer parameters (``solver.errors.InputError.parameter``) -> the flag that sets them
PARAMETER_FLAGS = {name: f"{flag} {spec.get('metavar', '')}".strip() for name, (flag, spec) in IMPORT_FLAGS.items()}


def add_import_options(parser: argparse.ArgumentParser) -> None:
    """The importer options (``IMPORT_FLAGS``) on a command that imports a trial."""
    g = parser.add_argument_group("import options (each for the formats that take it; see docs/import.md)")
    for name, (flag, spec) in IMPORT_FLAGS.items():
        g.add_argument(flag, dest=name, default=None, **spec)


def import_options(args: argparse.Namespace) -> dict:
    """The importer options given on the command line, as ``load_trial`` keywords."""
    given = {name: getattr(args, name) for name in IMPORT_FLAGS if getattr(args, name, None) is not None}
    return {name: _CONVERT[name](v) if name in _CONVERT else v for name, v in given.items()}


class CliError(Exception):
    """A user-facing error: printed as one line, exit status 2."""


class Terminated(BaseException):
    """SIGTERM arrived (a command that installs :func:`stop_on_signals`): unwinds like
    Ctrl-C, so ``finally`` blocks stop child processes; exit status 143."""


def _raise_terminated(signum, frame):
    raise Terminated()


class stop_on_signals:
    """Within ``with stop_on_signals() as guard:`` SIGTERM raises :class:`Terminated` (SIGINT
    raises KeyboardInterrupt already), so that ``finally`` blocks run: child processes are
    stopped, temporary folders removed. ``guard.shield()`` then ignores both signals while
    that bounded cleanup runs; leaving the block restores the previous handlers. Outside the
    main thread (where handlers cannot be set) it does nothing."""

    def __enter__(self) -> stop_on_signals:
        self._active = threading.current_thread() is threading.main_thread()
        if self._active:
            self._old = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
            signal.signal(signal.SIGTERM, _raise_terminated)
        return self

    def shield(self) -> None:
        if self._active:
            for sig in self._old:
                signal.signal(sig, signal.SIG_IGN)

    def __exit__(self, *exc) -> None:
        if self._active:
            for sig, handler in self._old.items():
                signal.signal(sig, handler)


class cancel_on_signals:
    """Within ``with cancel_on_signals() as cancel:`` Ctrl-C (SIGINT) and SIGTERM do not raise:
    they set ``cancel.signal`` and ``cancel()`` turns true, so a long solve given ``cancel`` as its
    ``should_cancel`` stops at its next IPOPT iteration and returns "canceled" with what it has
    (an exception raised inside IPOPT's callbacks would be swallowed by CasADi and the solve go
    on). ``cancel.exit_status`` is 130 or 143 after a signal. Outside the main thread it does
    nothing and ``cancel()`` stays false."""

    STATUS: ClassVar[dict[int, int]] = {signal.SIGINT: 130, signal.SIGTERM: 143}

    def __enter__(self) -> cancel_on_signals:
        self.signal: int | None = None
        self._active = threading.current_thread() is threading.main_thread()
        if self._active:
            self._old = {sig: signal.getsignal(sig) for sig in self.STATUS}
            for sig in self.STATUS:
                signal.signal(sig, self._note)
        return self

    def _note(self, signum, frame) -> None:
        if self.signal is None:
            self.signal = signum

    def __call__(self) -> bool:
        return self.signal is not None

    @property
    def exit_status(self) -> int | None:
        return None if self.signal is None else self.STATUS[signal.Signals(self.signal)]

    @property
    def reason(self) -> str:
        return {signal.SIGINT: "interrupted (Ctrl-C)", signal.SIGTERM: "terminated (SIGTERM)"}.get(
            signal.Signals(self.signal), "") if self.signal is not None else ""

    def __exit__(self, *exc) -> None:
        if self._active:
            for sig, handler in self._old.items():
                signal.signal(sig, handler)


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
    from solver.character import CharacterError, reference  # lazy: command-line start-up time (motionx --help, 0.75 s)

    try:
        return reference(name)
    except CharacterError as e:
        raise CliError(str(e)) from None


def _not_a_motion(path: Path, why: str) -> CliError:
    return CliError(f"{path} is not a motion file ({why}); motion files are the JSON that `motionx tutor` and "
                    "`motionx extrapolate` write")


def _a_capture(path: Path, what: str) -> CliError:
    return CliError(f"{path} is a captured trial ({what}), not a motion file: run `motionx tutor` first "
                    f"(motionx tutor {path}{' CHARACTER.txt' if 'DeepMimic' in what else ''} --out TUTOR.json)")


def load_motion(path: str | Path):
    """A motion file (v2; v1 read too), or a :class:`CliError` that says what the file is instead (binary,
    not JSON, a captured trial, a motion file with errors)."""
    from solver.motion import Motion, MotionError  # lazy: command-line start-up time (motionx --help, 0.75 s)

    p = Path(path)
    if not p.exists():
        raise CliError(f"motion file not found: {p}")
    if p.is_dir():
        raise CliError(f"{p} is a directory, not a motion file")
    kind = TRIAL_SUFFIXES.get(p.suffix.lower())
    if kind:
        raise _a_capture(p, f"a {kind} file")
    try:
        text = p.read_bytes().decode("utf-8")
    except UnicodeDecodeError:
        raise _not_a_motion(p, "binary data, not JSON text") from None
    except OSError as e:
        raise CliError(f"cannot read {p}: {e.strerror or e}") from None
    try:
        data = json.loads(text)
    except json.JSONDecodeError as e:
        raise _not_a_motion(p, f"not JSON: {e.msg} at line {e.lineno}") from None
    except RecursionError:
        raise _not_a_motion(p, "JSON nested too deeply") from None
    if isinstance(data, dict) and "format" not in data:
        if "Frames" in data:
            raise _a_capture(p, "a DeepMimic motion clip")
        if "Skeleton" in data:
            raise _a_capture(p, "a DeepMimic character")
    try:
        return Motion.from_dict(data)
    except MotionError as e:
        raise CliError(f"{p}: {e}") from None


# --- help texts ---------------------------------------------------------------------------------


def _text(v) -> str:
    """A default or choice as a user writes it: 15, not 15.0."""
    if isinstance(v, float):
        return f"{v:g}"
    if isinstance(v, (list, tuple)):
        return " ".join(_text(x) for x in v)
    return str(v)


class HelpFormatter(argparse.RawDescriptionHelpFormatter):
    """Choices as the user types them (``{15,30}``, listed ``15, 30`` in the help line) and
    every option's default in its help line."""

    def _metavar_formatter(self, action, default_metavar):
        if action.metavar is None and action.choices is not None and not isinstance(action.choices, dict):
            text = "{" + ",".join(_text(c) for c in action.choices) + "}"
            return lambda n: (text,) * n
        return super()._metavar_formatter(action, default_metavar)

    def _get_help_string(self, action) -> str:
        text = action.help or ""
        extra = []
        if action.choices is not None and not isinstance(action.choices, dict):
            extra.append("choices: " + ", ".join(_text(c) for c in action.choices))
        d = action.default
        if (action.option_strings and d is not None and d is not False and d is not argparse.SUPPRESS
                and d != "" and "default" not in text and action.nargs != 0):
            extra.append(f"default: {_text(d)}".replace("%", "%%"))
        return f"{text} ({'; '.join(extra)})" if extra else text


def add_command(sub: argparse._SubParsersAction, name: str, summary: str, description: str | None = None,
                **kw) -> argparse.ArgumentParser:
    """A subcommand with its one-line summary (the command list) and its description (its
    own ``--help``)."""
    return sub.add_parser(name, help=summary, description=description or (summary[:1].upper() + summary[1:] + "."),
                          formatter_class=HelpFormatter, allow_abbrev=False, **kw)


def version() -> str:
    try:
        return dist_version("motionx")
    except PackageNotFoundError:  # pragma: no cover - a source tree without an install
        return "unknown"


def build_parser() -> argparse.ArgumentParser:
    from service.commands import MODULES  # lazy: import cycle (the command modules import this one)

    # no abbreviations: "--slop" is an error, not "--slope"
    p = argparse.ArgumentParser(prog="motionx", formatter_class=HelpFormatter, allow_abbrev=False, description="""\
Turn one captured human walk into physically plausible walks on new ground: make the capture
plausible (the tutor), then extrapolate it to a slope, a curve, another friction or gravity,
keeping every intermediate motion.""", epilog="""\
the main job:
  motionx tutor TRIAL_FILE... --out tutor.json
  motionx extrapolate tutor.json --slope -11.25 --out downhill/

`motionx COMMAND --help` describes each command.""")
    p.add_argument("--version", action="version", version=f"motionx {version()}")
    p.add_argument("-v", "--verbose", action="store_true", help="log progress to stderr")
    sub = p.add_subparsers(dest="command", required=True, metavar="COMMAND", title="commands")
    for name in MODULES:
        importlib.import_module(name).register(sub)
    return p


def _stdout_is_broken() -> bool:
    """True when stdout is a pipe whose reader has gone (``| head`` after its lines)."""
    try:
        fd = sys.stdout.fileno()
        poller = select.poll()
        poller.register(fd, select.POLLOUT)
        return any(ev & (select.POLLERR | select.POLLHUP) for _, ev in poller.poll(0))
    except (OSError, ValueError, AttributeError):
        return False


def _main(argv: list[str] | None) -> int:
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
    except SystemExit:  # --help, --version, a usage error: their text must reach a closed pipe too
        sys.stdout.flush()
        raise
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(message)s")
    try:
        code = args.func(args)
        sys.stdout.flush()  # a closed pipe shows here, not as an error at exit
        return code
    except CliError as e:
        print(f"motionx: error: {e}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("motionx: interrupted", file=sys.stderr)
        return 130
    except Terminated:
        print("motionx: terminated", file=sys.stderr)
        return 143


def main(argv: list[str] | None = None) -> int:
    try:
        return _main(argv)
    except BrokenPipeError:
        if not _stdout_is_broken():
            raise
        # the reader stopped early: end quietly (no flush error at exit), as SIGPIPE would
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
