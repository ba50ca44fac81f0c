"""``motionx library``: a motion library from one tutor — a grid of targets (slope × curve
× speed scale: the grid axes of solver.axes), one extrapolation per cell, written as one
GLB (one looping animation per cell, the grid in its extras), a JSON clip and a motion file
per cell, and ``manifest.json`` (cell → parameters, status, files, realism figures)."""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from pathlib import Path

from service.cli import CliError, add_command, load_motion
from service.config import enable_native_code, get_settings
from solver import axes as registry

#: what a library folder holds besides the per-cell files
LIBRARY_FILES = ("manifest.json", "library.glb")
CELL_KINDS = ("motion.json", "clip.json")


def _values(flag: str):
    def conv(text: str) -> list[float]:
        out = []
        for part in text.split(","):
            part = part.strip()
            try:
                v = float(part)
            except ValueError:
                raise argparse.ArgumentTypeError(f"{flag} takes comma-separated numbers, got {part!r}") from None
            if not math.isfinite(v):
                raise argparse.ArgumentTypeError(f"{flag} values must be finite, got {part!r}")
            out.append(v)
        return out

    return conv


class _Bar:
    """Cells done and the running cell's λ, on stderr: redrawn in place on a terminal, else one
    line per finished cell; nothing with ``--quiet``."""

    def __init__(self, total: int, enabled: bool) -> None:
        self.total, self.done = total, 0
        self.tty = enabled and sys.stderr.isatty()
        self.lines = enabled and not self.tty
        self.t0 = time.perf_counter()

    def draw(self, key: str, lam: float) -> None:
        if not self.tty:
            return
        width = 24
        frac = (self.done + lam) / self.total
        fill = int(round(width * frac))
        sys.stderr.write(f"\r[{'#' * fill}{'.' * (width - fill)}] {self.done}/{self.total} cells, "
                         f"{key} λ={lam:.3f} {time.perf_counter() - self.t0:6.1f}s   ")
        sys.stderr.flush()

    def cell(self, r, i: int, n: int) -> None:
        self.done = i
        warm = (f", warm start λ={r.warm_start.lam:.2f} from {r.warm_start.source_cell}"
                if r.warm_start else "")
        text = (f"cell {i}/{n} {r.cell.key}: {r.status} λ={r.lam_reached:.3f} ({r.solves} solves, "
                f"{r.wall_time_s:.1f} s{warm})")
        if self.tty:
            sys.stderr.write("\r" + text + " " * 20 + "\n")
            self.draw("", 0.0)
        elif self.lines:
            sys.stderr.write(text + "\n")

    def close(self) -> None:
        if self.tty:
            sys.stderr.write("\n")


def cmd_library(args: argparse.Namespace) -> int:
    from solver import library as L
    from solver.continuation import StepControl
    from solver.export import game
    from solver.export.clip import to_clip_json
    from solver.export.gltf import to_library_glb

    enable_native_code(get_settings())
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
    out.mkdir(parents=True, exist_ok=True)
    for p in [*(out / n for n in LIBRARY_FILES), *(p for k in CELL_KINDS for p in out.glob(f"*.{k}"))]:
        if p.is_file():
            p.unlink()
    bar = _Bar(len(cells), not args.quiet)
    t0 = time.perf_counter()
    try:
        results = L.solve_library(tutor, cells, control, on_cell=bar.cell,
                                  on_progress=lambda c, r: bar.draw(c.key, r.lam_reached))
    finally:
        bar.close()
    wall = time.perf_counter() - t0
    entries, clips = [], []
    for r in results:
        files = {}
        if r.motion is not None:
            files = {"motion": f"{r.cell.key}.motion.json", "clip": f"{r.cell.key}.clip.json",
                     "glb": "library.glb", "animation": r.cell.key}
            r.motion.save(out / files["motion"])
            (out / files["clip"]).write_text(to_clip_json(r.motion))
            clips.append((r.cell.key, r.motion))
        entries.append(L.cell_entry(r.cell, status=r.status, lam_reached=r.lam_reached, message=r.message,
                                    motion=r.motion, clip_lam=r.clip_lam, files=files, warm_start=r.warm_start,
                                    solves=r.solves, wall_time_s=r.wall_time_s))
    grid = {"axes": {k: list(v) for k, v in axes.items()}, "cells": [c.key for c in cells]}
    if clips:
        (out / "library.glb").write_bytes(to_library_glb(clips, extras={**grid, "manifest": "manifest.json"}))
    manifest = {
        "format": L.FORMAT, "version": L.VERSION,
        "tutor": {"file": str(args.tutor), "character": tutor.character.name, "frames": tutor.T,
                  "fps": float(tutor.fps), "loop_frames": game.loop_frames(tutor)},
        "grid": grid,
        "control": {"method": control.method, "delta0": control.delta0, "eps": control.eps,
                    "max_iter": control.max_iter, "max_solves": control.max_solves},
        "cells": entries,
        "summary": {**L.summary(entries), "wall_time_s": round(wall, 3),
                    "cells_per_minute": round(60.0 * len(cells) / wall, 2) if wall > 0 else None},
        "files": {"glb": "library.glb" if clips else None},
    }
    (out / "manifest.json").write_text(json.dumps(manifest, indent=1, allow_nan=False))
    s = manifest["summary"]
    if args.json:
        print(json.dumps(manifest["summary"]))
    else:
        print(f"{s['cells']} cells in {wall:.1f} s ({s['cells_per_minute']} cells/min): {s['succeeded']} succeeded, "
              f"{s['impasse']} at impasse, {s['failed']} failed\n  wrote {out}/: manifest.json, library.glb, "
              "CELL.motion.json and CELL.clip.json per cell")
    return 0 if all(e["status"] in ("succeeded", "impasse") for e in entries) else 1


def register(sub: argparse._SubParsersAction) -> None:
    s = add_command(sub, "library", "a motion library: extrapolate a tutor over a grid of targets", """\
Extrapolate one tutor to every cell of a grid (slopes × curves × speed scales), nearest the
tutor first, each cell warm-started from the stored optimum furthest along its homotopy
(docs/service.md, "Motion libraries"). A cell at an impasse keeps its last realistic motion
and is marked so. Writes into --out: library.glb (one looping animation per cell, the grid in
its extras, game-ready data per animation), per cell CELL.motion.json and CELL.clip.json, and
manifest.json (cell -> parameters, status, files, realism figures). Exit status 0 when every
cell succeeded or reached an impasse.""")
    s.add_argument("tutor", metavar="TUTOR.json", help="tutor motion file (from motionx tutor)")
    for ax in registry.axes():  # one flag per grid axis of the registry: --slopes, --curves, --speed-scales
        if ax.grid:
            s.add_argument(ax.cli + "s", dest=ax.name, type=_values(ax.cli + "s"), metavar="V1,V2,...",
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
    s.set_defaults(func=cmd_library)
