"""``motionx library``: a motion library from one tutor — a grid of targets (slope × curve
× speed scale: the grid axes of solver.axes), one extrapolation per cell, written as one
GLB (one looping animation per cell, the grid in its extras), a JSON clip and a motion file
per cell, and ``manifest.json`` (cell → parameters, status, files, realism figures)."""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

from tqdm import tqdm

from service.cli import CliError, add_command, cancel_on_signals, finite_list, load_motion
from service.config import enable_native_code, get_settings, load_check_modules
from solver import axes as registry
from solver.formats import EXPORT_WORLDS


class _Bar:
    """Cells done and the running cell's λ, on stderr: a tqdm bar on a terminal (a line above
    it per finished cell), else one line per finished cell; nothing with ``--quiet``."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.total, self.done = total, 0
        tty = enabled and sys.stderr.isatty()
        self.lines = enabled and not tty
        self.bar = tqdm(total=total, file=sys.stderr, disable=not tty, ascii=".#", desc=f"0/{total} cells",
                        bar_format="[{bar:24}] {desc} {elapsed}")

    def draw(self, key: str, lam: float) -> None:
        if self.bar.disable:
            return
        self.bar.n = self.done + lam
        self.bar.set_description_str(f"{self.done}/{self.total} cells, {key} λ={lam:.3f}")

    def cell(self, r, i: int, n: int) -> None:
        self.done = i
        warm = (f", warm start λ={r.warm_start.lam:.2f} from {r.warm_start.source_cell}"
                if r.warm_start else "")
        text = (f"cell {i}/{n} {r.cell.key}: {r.status} λ={r.lam_reached:.3f} ({r.solves} solves, "
                f"{r.wall_time_s:.1f} s{warm})")
        if not self.bar.disable:
            self.bar.write(text, file=sys.stderr)
            self.draw("", 0.0)
        elif self.lines:
            sys.stderr.write(text + "\n")

    def close(self) -> None:
        self.bar.close()


def cmd_library(args: argparse.Namespace) -> int:
    # Ctrl-C or SIGTERM cancels: the running cell stops at its next IPOPT iteration, the cells not
    # started are not, the cells solved so far are written with the manifest (status "canceled")
    # and the exit status is 130 / 143
    with cancel_on_signals() as cancel:
        return _library(args, cancel)


def _library(args: argparse.Namespace, cancel: cancel_on_signals) -> int:
    from solver import library as L
    from solver.continuation import StepControl

    enable_native_code(get_settings())
    load_check_modules(get_settings())
    axes = {}
    for name in L.AXES:
        vals = getattr(args, name)
        if vals is not None:
            axes[name] = vals
    if not axes:
        raise CliError("give the grid: --slopes and/or --curves (comma-separated values)")
    try:
        cells = L.grid_cells(axes)
        L.check_cells(cells)
        control = StepControl(method=args.method, delta0=args.delta0, max_iter=args.max_iter, eps=args.eps,
                              max_solves=args.max_solves)
    except ValueError as e:
        raise CliError(str(e)) from None
    tutor = load_motion(args.tutor)
    if tutor.wrenches is None or tutor.contacts is None:
        raise CliError(f"{args.tutor} is not a tutor (it has no contact wrenches or contact schedule); "
                       "run `motionx tutor` first")
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {out} exists and is not a directory")
    if out.is_dir() and any(out.iterdir()) and not args.force:
        raise CliError(f"--out {out} is not empty; choose a new folder, or pass --force to replace the files "
                       "this command writes there")
    bar = _Bar(len(cells), not args.quiet)
    try:
        result = L.solve_library(tutor, cells, control, on_cell=bar.cell,
                                 on_progress=lambda c, r: bar.draw(c.key, r.lam_reached), grid=axes,
                                 should_cancel=cancel)
    finally:
        bar.close()
    result.save(out, tutor_file=str(args.tutor), world=args.world)
    manifest = json.loads((out / "manifest.json").read_text())
    wall = result.wall_time_s
    s = manifest["summary"]
    if args.json:
        print(json.dumps(manifest["summary"]))
    else:
        print(f"{s['cells']} cells in {wall:.1f} s ({s['cells_per_minute']} cells/min): {s['succeeded']} succeeded, "
              f"{s['impasse']} at impasse, {s['failed']} failed\n  wrote {out}/: manifest.json, library.glb, "
              "CELL.motion.json and CELL.clip.json per cell")
    if cancel.exit_status is not None:
        print(f"motionx library: {cancel.reason}: canceled {s['canceled']} of {s['cells']} cells; what the cells "
              f"reached is in {out}/ (manifest.json: status canceled)", file=sys.stderr)
        return cancel.exit_status
    return 0 if all(r.status.ok for r in result.cells) else 1


def register(sub: argparse._SubParsersAction) -> None:
    s = add_command(sub, "library", "a motion library: extrapolate a tutor over a grid of targets", """\
Extrapolate one tutor to every cell of a grid (slopes × curves × speed scales), nearest the
tutor first, each cell warm-started from the stored optimum furthest along its homotopy
(docs/service.md, "Motion libraries"). A cell at an impasse keeps its last realistic motion
and is marked so. Writes into --out: library.glb (one looping animation per cell, the grid in
its extras, game-ready data per animation), per cell CELL.motion.json and CELL.clip.json, and
manifest.json (cell -> parameters, status, files, realism figures). Exit status 0 when every
cell succeeded or reached an impasse; Ctrl-C or SIGTERM stops the running cell at its next
IPOPT iteration, writes the cells reached so far and the manifest (status canceled) and exits
130 (143).""")
    s.add_argument("tutor", metavar="TUTOR.json", help="tutor motion file (from motionx tutor)")
    for ax in registry.axes():  # one flag per grid axis of the registry: --slopes, --curves, --speed-scales
        if ax.grid:
            s.add_argument(ax.cli + "s", dest=ax.name, type=finite_list(ax.cli + "s"), metavar="V1,V2,...",
                           help=f"{ax.doc}: comma-separated values within {ax.bounds_text()} (default: none)")
    s.add_argument("--out", required=True, metavar="DIR", help="output folder (new or empty, unless --force)")
    s.add_argument("--force", action="store_true", help="write into a non-empty --out (replaces this command's files)")
    s.add_argument("--method", choices=["adaptive", "thesis"], default="thesis",
                   help="step control: thesis (default, Algorithm 3) or adaptive")
    s.add_argument("--delta0", type=float, default=0.05, metavar="D", help="first step Δ0 in λ")
    s.add_argument("--eps", type=float, default=0.005, metavar="E", help="smallest step ε in λ before an impasse")
    s.add_argument("--max-iter", type=int, default=200, metavar="K", help="IPOPT iterations per step (k)")
    s.add_argument("--max-solves", type=int, default=400, metavar="N", help="most NLP solves per cell")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.add_argument("--json", action="store_true", help="print the manifest's summary as JSON")
    s.add_argument("--world", choices=tuple(EXPORT_WORLDS), default=next(iter(EXPORT_WORLDS)),
                   help="the world of the written clips and GLBs (as motionx export --world): gravity (default: "
                        "gravity down, each cell on its own ground, a slope cell on its ramp) or ground (the "
                        "solver's level ground)")
    s.set_defaults(func=cmd_library)
