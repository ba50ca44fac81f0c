"""``motionx plot``: a motion's ground reaction forces, root residuals and filmstrip as PNG files."""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

from service.cli import CliError, add_command, load_motion

KINDS = ("grf", "residuals", "filmstrip")


def write_motion_plots(motion, out: Path, kinds=KINDS) -> dict[str, str]:
    """Renders every kind first (:class:`service.plots.PlotError` when the motion cannot be
    plotted: nothing is written), then writes ``<kind>.png`` into ``out`` (created if needed);
    returns {kind: file name}."""
    from service.plots import MOTION_PLOTS

    images = {kind: MOTION_PLOTS[kind](motion) for kind in kinds}
    try:
        out.mkdir(parents=True, exist_ok=True)
        for kind, data in images.items():
            (out / f"{kind}.png").write_bytes(data)
    except OSError as e:
        raise CliError(f"cannot write into {out}: {e.strerror or e}") from None
    return {kind: f"{kind}.png" for kind in images}


def cmd_plot(args: argparse.Namespace) -> int:
    from service.plots import PlotError

    motion = load_motion(args.motion)
    kinds = KINDS if args.kind == "all" else (args.kind,)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {out} exists and is not a directory")
    t0 = time.perf_counter()
    try:
        files = write_motion_plots(motion, out, kinds)
    except PlotError as e:
        raise CliError(f"{args.motion}: {e}") from None
    print(json.dumps({"out": str(out), "files": list(files.values()), "frames": motion.T, "fps": motion.fps,
                      "character": motion.character.name, "seconds": round(time.perf_counter() - t0, 3)}))
    return 0


def register(sub: argparse._SubParsersAction) -> None:
    s = add_command(sub, "plot", "plot a motion file: ground reaction forces, root residuals, filmstrip (PNG)", """\
Write PNG plots of a motion with contact wrenches (a tutor or a λ optimum): grf.png, each
foot's ground reaction force against time with its contact phases; residuals.png, the root
residual of the equations of motion per frame, ours and MuJoCo's replay, with the
plausibility tolerance; filmstrip.png, the cycle seen from the side, from behind and from
above (stick figures, the feet's soles as exported, the ground, ground-force arrows: look at
the walk). Prints a JSON line with the files.""")
    s.add_argument("motion", metavar="MOTION.json",
                   help="motion file v2 (JSON) with contact wrenches (a tutor or a λ optimum)")
    s.add_argument("--kind", choices=[*KINDS, "all"], default="all",
                   help="grf: forces per foot with the contact phases; residuals: root residual per frame, "
                        "ours and MuJoCo's replay; filmstrip: side, rear and top views of the cycle (default: all)")
    s.add_argument("--out", required=True, metavar="DIR",
                   help="output directory (grf.png, residuals.png, filmstrip.png)")
    s.set_defaults(func=cmd_plot)
