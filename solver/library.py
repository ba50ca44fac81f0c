"""Motion libraries: a grid (or list) of targets, one extrapolation per cell, warm starts
between cells, and the library's manifest (docs/service.md, "Motion libraries").

A *cell* is one extrapolation of the tutor to its target
(:func:`solver.continuation.extrapolate`, called through its public signature only). The
grid's axes are the registered homotopy axes marked ``grid`` (:mod:`solver.axes`: today
``slope_deg``, ``curve_deg``, ``speed_scale``), so a new axis needs no change here.

**Warm starts.** Every axis is interpolated linearly in λ by the homotopy (slope: gravity
tilted by λ·slope and guide Ψ(·, λ·slope); curve: guide Φ(·, λ·curve); speed: the problem is
a function of the speed value 1 + λ (s − 1)), so the problem at λ
for target B is the problem at λ·s for target B/s. Hence a stored optimum of another cell A at
λ_A lies on B's homotopy whenever λ_A·(A − neutral) = t·(B − neutral) with 0 ≤ t < 1: B then
starts at λ = t from it (``extrapolate(..., start=(t, optimum))``) instead of λ = 0. Every
cell's λ = 0 optimum (the base problem: the tutor's own ground) is the same, so a cell never
solves the base problem again once any cell has; a cell whose ray passes through a solved
inner cell (5 × 5: (7.5°, 45°) is half of (15°, 90°)) starts half-way. A neighbour off the
ray would need a homotopy between two targets, which the continuation does not offer: such
cells start from the base optimum.
"""

from __future__ import annotations

import dataclasses
import functools
import itertools
import json
import math
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from solver import axes as registry
from solver.continuation import StepControl, Target, extrapolate
from solver.export import DEFAULT_WORLD, game
from solver.status import Status, combined

#: the grid axes, in the order of names and manifests (the registry's, solver.axes)
AXES = tuple(a.name for a in registry.axes() if a.grid)
#: axis -> the value that changes nothing (λ = 0 of every homotopy)
NEUTRAL: dict[str, float] = {a.name: float(a.default) for a in registry.axes() if a.grid and a.default is not None}
SHORT = {a.name: a.label for a in registry.axes() if a.grid}
#: most cells one library may have
MAX_CELLS = 125
#: axes whose homotopy is linear in λ (checked by tests/test_library.py): only these carry warm
#: starts part-way along a ray; another axis shares only the base problem (λ = 0)
LINEAR_AXES = frozenset(a.name for a in registry.axes() if a.grid and a.linear)
#: two rays are the same when their directions differ by less than this (relative)
RAY_TOLERANCE = 1e-9


class LibraryError(ValueError):
    """A library request the method cannot take (unknown or unsupported axis, too many cells)."""


@dataclass(frozen=True)
class Cell:
    """One target of the library: its axis values (every axis of the library, in AXES order)."""

    params: tuple[tuple[str, float], ...]

    @property
    def values(self) -> dict[str, float]:
        return dict(self.params)

    @property
    def key(self) -> str:
        """A name usable as a file stem and an animation name, e.g. ``slope-5_curve20``."""
        return "_".join(f"{SHORT.get(k, k)}{v:g}" for k, v in self.params)

    def offset(self) -> tuple[float, ...]:
        return tuple(v - NEUTRAL.get(k, 0.0) for k, v in self.params)

    def is_neutral(self) -> bool:
        return all(abs(o) == 0.0 for o in self.offset())

    def target_kwargs(self) -> dict[str, float]:
        return {k: float(v) for k, v in self.params}


def _check_axis(name: str) -> None:
    if name not in AXES:
        raise LibraryError(f"unknown axis {name!r}; the axes are {', '.join(AXES)}")


def _finite(name: str, v: Any) -> float:
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
        raise LibraryError(f"{name}: values must be finite numbers, got {v!r}")
    return float(v)


def grid_cells(axes: Mapping[str, Sequence[float]]) -> list[Cell]:
    """The cells of a grid: the product of the axes' values (each axis: distinct values)."""
    if not axes:
        raise LibraryError(f"a grid needs at least one axis ({', '.join(AXES)})")
    names = [a for a in AXES if a in axes] + [a for a in axes if a not in AXES]
    for a in names:
        _check_axis(a)
        vals = [_finite(a, v) for v in axes[a]]
        if not vals:
            raise LibraryError(f"axis {a!r} has no values")
        if len(set(vals)) != len(vals):
            raise LibraryError(f"axis {a!r} repeats a value")
    n = math.prod(len(axes[a]) for a in names)
    if n > MAX_CELLS:
        raise LibraryError(f"the grid has {n} cells; a library has at most {MAX_CELLS}")
    combos = itertools.product(*(axes[a] for a in names))
    return [Cell(tuple(zip(names, (float(v) for v in combo)))) for combo in combos]


def list_cells(targets: Sequence[Mapping[str, float]]) -> list[Cell]:
    """The cells of an explicit list of targets (every target gets every axis any target uses)."""
    if not targets:
        raise LibraryError("the list of targets is empty")
    if len(targets) > MAX_CELLS:
        raise LibraryError(f"{len(targets)} targets; a library has at most {MAX_CELLS}")
    used = [a for a in AXES if any(a in t for t in targets)]
    if not used:
        raise LibraryError(f"the targets give no axis: each needs one of {', '.join(AXES)}")
    for t in targets:
        for a in t:
            _check_axis(a)
    cells = [Cell(tuple((a, _finite(a, t.get(a, NEUTRAL[a]))) for a in used)) for t in targets]
    if len({c.key for c in cells}) != len(cells):
        raise LibraryError("the list repeats a target")
    return cells


def check_cells(cells: Sequence[Cell]) -> None:
    """Every cell's target must be one the solver accepts (its own checks)."""

    for c in cells:
        try:
            Target(**c.target_kwargs())
        except (TypeError, ValueError) as e:
            raise LibraryError(f"cell {c.key}: {e}") from None


def order(cells: Sequence[Cell]) -> list[Cell]:
    """Dispatch order: nearest the tutor first (largest relative offset over the axes, then their
    sum), so the cells whose rays pass through them find them solved."""
    spans: dict[str, float] = {}
    for c in cells:
        for (k, _), o in zip(c.params, c.offset()):
            spans[k] = max(spans.get(k, 0.0), abs(o))

    def size(c: Cell) -> tuple[float, float, str]:
        rel = [abs(o) / spans[k] if spans[k] else 0.0 for (k, _), o in zip(c.params, c.offset())]
        return max(rel), sum(rel), c.key

    return sorted(cells, key=size)


def on_ray(cell: Cell, other: Cell, lam: float) -> float | None:
    """t in [0, 1) such that ``other``'s problem at λ = ``lam`` is ``cell``'s problem at λ = t,
    or None (different rays, or not below ``cell``'s target)."""
    a, b = cell.offset(), other.offset()
    if [k for k, _ in cell.params] != [k for k, _ in other.params]:
        return None
    if lam == 0.0:
        return 0.0  # the base problem: the same for every target
    if any(k not in LINEAR_AXES and (x != 0.0 or y != 0.0) for (k, _), x, y in zip(cell.params, a, b)):
        return None
    pa = [lam * x for x in b]
    na = math.sqrt(sum(x * x for x in a))
    if na == 0.0:
        return None
    i = max(range(len(a)), key=lambda k: abs(a[k]))  # t from the largest component: exact ratios stay exact
    t = pa[i] / a[i]
    resid = math.sqrt(sum((x - t * y) ** 2 for x, y in zip(pa, a)))
    if resid > RAY_TOLERANCE * max(na, 1.0) or not 0.0 <= t < 1.0 - 1e-12:
        return None
    return t


@dataclass(frozen=True)
class CellStart:
    """A cell's warm start: the stored optimum of another cell (or its own) its homotopy starts from."""

    lam: float  # where this cell's homotopy starts
    source_cell: str  # the cell whose stored optimum it is
    source_lam: float  # that optimum's λ on its own homotopy


def best_start(cell: Cell, stored: Iterable[tuple[Cell, float]]) -> CellStart | None:
    """The stored optimum (cell, λ) furthest along ``cell``'s homotopy, or None."""
    best: CellStart | None = None
    for other, lam in stored:
        t = on_ray(cell, other, lam)
        if t is not None and (best is None or t > best.lam):
            best = CellStart(t, other.key, lam)
    return best


def realism(report: Mapping[str, Any] | None) -> dict[str, Any] | None:
    """The plausibility report's figures for a manifest (None without a report)."""
    if not report:
        return None
    rr = report.get("root_residual") or {}
    out = {
        "plausible": bool(report.get("plausible")),
        "root_residual_rel_weight": rr.get("max_force_rel_weight"),
        "root_moment_rel_weight_leg": rr.get("max_moment_rel_weight_leg"),
        "slip_mm": report.get("slip_mm"),
        "penetration_mm": report.get("penetration_mm"),
        "friction_cone_excess_N": report.get("friction_cone_excess_N"),
        "cop_outside_mm": report.get("cop_outside_mm"),
        "problems": list(report.get("problems") or []),
    }
    mj = report.get("mujoco_replay")
    if isinstance(mj, Mapping):
        out["mujoco_root_residual_rel_weight"] = mj.get("max_force_rel_weight")
    real = report.get("realism")  # the realism validator's section, when the report has one
    if isinstance(real, Mapping) and isinstance(real.get("checks"), Mapping):
        out["realism"] = {
            "passed": real.get("passed"), "failed": list(real.get("failed") or []),
            "warnings": list(real.get("warnings") or []),
            "checks": {k: {f: c.get(f) for f in ("value", "limit", "unit", "passed", "severity")}
                       for k, c in real["checks"].items() if isinstance(c, Mapping)},
        }
    return out


@dataclass
class CellResult:
    cell: Cell
    status: Status  # succeeded | impasse | failed | canceled
    lam_reached: float
    message: str
    motion: Any | None  # the cell's clip: its last realistic optimum (see :func:`last_realistic`)
    steps: list  # (λ, motion) of every optimum of this cell
    solves: int
    wall_time_s: float
    warm_start: CellStart | None
    clip_lam: float | None = None

    def __post_init__(self) -> None:
        self.status = Status(self.status)


#: files a library folder holds besides its cells' CELL.motion.json and CELL.clip.json
LIBRARY_FILES = ("manifest.json", "library.glb", "library.rig.glb")
CELL_KINDS = ("motion.json", "clip.json", "rig.bvh", "deepmimic.txt")
#: source rig format -> (export format, cell file kind) written beside each cell's clip
RIG_FILES = {"bvh": ("bvh", "rig.bvh"), "deepmimic": ("deepmimic", "deepmimic.txt")}


@dataclass(frozen=True)
class LibraryResult:
    """Every cell of a library (in the order given) and how the whole ended."""

    tutor: Any  # the tutor motion
    cells: tuple[CellResult, ...]
    control: StepControl
    wall_time_s: float
    grid: Mapping[str, Sequence[float]] | None = None  # the axes' values when the cells are a grid

    @property
    def status(self) -> Status:
        """failed, canceled or impasse when a cell ended so (in that order), else succeeded."""
        return combined(r.status for r in self.cells)

    def entries(self) -> list[dict[str, Any]]:
        """The manifest's cells (:func:`cell_entry`), with the file names :meth:`save` writes."""
        out = []
        for r in self.cells:
            files = {}
            if r.motion is not None:
                files = {"motion": f"{r.cell.key}.motion.json", "clip": f"{r.cell.key}.clip.json",
                         "glb": "library.glb", "animation": r.cell.key}
            out.append(cell_entry(r.cell, status=r.status, lam_reached=r.lam_reached, message=r.message,
                                  motion=r.motion, clip_lam=r.clip_lam, files=files, warm_start=r.warm_start,
                                  solves=r.solves, wall_time_s=r.wall_time_s))
        return out

    def manifest(self, tutor_file: str | None = None) -> dict[str, Any]:
        """The library's ``manifest.json`` (format ``motionx.library``)."""
        entries = self.entries()
        t, c, wall = self.tutor, self.control, self.wall_time_s
        grid = {"axes": {k: list(v) for k, v in (self.grid or {}).items()}, "cells": [r.cell.key for r in self.cells]}
        return {
            "format": FORMAT, "version": VERSION, "status": str(self.status),
            "tutor": {"file": tutor_file, "character": t.character.name, "frames": t.T, "fps": float(t.fps),
                      "loop_frames": game.loop_frames(t)},
            "grid": grid,
            "control": c.summary(),
            "cells": entries,
            "summary": {**summary(entries), "wall_time_s": round(wall, 3),
                        "cells_per_minute": round(60.0 * len(entries) / wall, 2) if wall > 0 else None},
            "files": {"glb": "library.glb" if any(r.motion is not None for r in self.cells) else None},
        }

    def save(self, folder: str | Path, tutor_file: str | None = None, world: str = DEFAULT_WORLD) -> Path:
        """Write ``manifest.json``, ``library.glb`` (one animation per cell with a clip) and each
        cell's ``CELL.motion.json`` and ``CELL.clip.json`` (and, for a walk from a BVH or a
        DeepMimic clip, the cell on the input's own skeleton: ``CELL.rig.bvh`` /
        ``CELL.deepmimic.txt``; and for any input with a rig, ``library.rig.glb``: the input's
        own character with one animation per cell) into ``folder`` (created when missing;
        earlier files of these names are replaced). The exports are in ``world``
        (:mod:`solver.export.world`: by default gravity points down and each cell stands on its
        own ground — a slope cell on its ramp —, drawn in the GLBs and described in the clips)."""
        from solver.export import export_motion
        from solver.export.clip import to_clip_json
        from solver.export.gltf import to_library_glb
        from solver.export.rig_gltf import rig_glb_library
        from solver.rig import RIG_FORMATS

        out = Path(folder)
        out.mkdir(parents=True, exist_ok=True)
        for p in [*(out / n for n in LIBRARY_FILES), *(p for k in CELL_KINDS for p in out.glob(f"*.{k}"))]:
            if p.is_file():
                p.unlink()
        manifest = self.manifest(tutor_file)
        clips = []
        for r in self.cells:
            if r.motion is not None:
                r.motion.save(out / f"{r.cell.key}.motion.json")
                (out / f"{r.cell.key}.clip.json").write_text(to_clip_json(r.motion, world=world))
                rig = r.motion.context.rig
                if rig is not None and rig.format in RIG_FILES:
                    fmt, kind = RIG_FILES[rig.format]
                    (out / f"{r.cell.key}.{kind}").write_text(str(export_motion(r.motion, fmt, rig="source",
                                                                                world=world)))
                clips.append((r.cell.key, r.motion))
        if clips:
            (out / "library.glb").write_bytes(to_library_glb(clips, extras={**manifest["grid"],
                                                                            "manifest": "manifest.json"},
                                                             world=world))
            rig = clips[0][1].context.rig
            if rig is not None and rig.format in RIG_FORMATS:
                (out / "library.rig.glb").write_bytes(rig_glb_library(clips, world=world))
        (out / "manifest.json").write_text(json.dumps(manifest, indent=1, allow_nan=False))
        return out


def solve_library(tutor, cells: Sequence[Cell], control=None, *,
                  on_cell: Callable[[CellResult, int, int], None] | None = None,
                  on_progress: Callable[[Cell, Any], None] | None = None,
                  should_cancel: Callable[[], bool] | None = None,
                  grid: Mapping[str, Sequence[float]] | None = None) -> LibraryResult:
    """Extrapolate every cell in one process, nearest the tutor first, each warm-started from
    the best stored optimum (:func:`best_start`); the result lists the cells in the order given
    (``grid``: the axes' values the cells come from, for the manifest). The CLI's engine; the
    service runs the same cells as jobs."""


    t_start = time.perf_counter()
    control = control or StepControl()
    check_cells(cells)
    stored: list[tuple[Cell, float, Any]] = []
    results: list[CellResult] = []
    todo = order(cells)
    for i, cell in enumerate(todo):
        t0 = time.perf_counter()
        ws = best_start(cell, ((c, lam) for c, lam, _ in stored))
        start = None
        if ws is not None:
            m = next(m for c, lam, m in stored if c.key == ws.source_cell and lam == ws.source_lam)
            start = (ws.lam, m)
        ctl = dataclasses.replace(control, delta0=1.0) if cell.is_neutral() else control
        steps: list = [] if start is None else [start]

        def on_step(step, cell=cell, steps=steps) -> None:
            steps.append((step.lam, step.motion))
            stored.append((cell, step.lam, step.motion))

        if cancelled := (should_cancel is not None and should_cancel()):
            res = None
        else:
            res = extrapolate(tutor, Target(**cell.target_kwargs()), ctl, start=start, on_step=on_step,
                              should_cancel=should_cancel,
                              on_progress=functools.partial(on_progress, cell) if on_progress else None)
        status = Status.CANCELED if cancelled or res is None else res.status
        lam = (ws.lam if ws else 0.0) if res is None else max(res.lam_reached, ws.lam if ws else 0.0)
        kept = last_realistic(steps)
        motion = kept[1] if kept else None
        r = CellResult(cell, status, lam, "canceled" if res is None else res.message, motion, steps,
                       0 if res is None else res.solves, time.perf_counter() - t0, ws,
                       kept[0] if kept else None)
        results.append(r)
        if on_cell:
            on_cell(r, i + 1, len(todo))
    by_key = {r.cell.key: r for r in results}
    return LibraryResult(tutor, tuple(by_key[c.key] for c in cells), control, time.perf_counter() - t_start,
                         {k: tuple(v) for k, v in grid.items()} if grid is not None else None)


def realistic(motion) -> bool:
    """A motion the realism checks accept: the report's ``realistic`` verdict when it has one
    (the realism validator), else its ``plausible`` verdict."""
    rep = getattr(motion, "report", None) or {}
    return bool(rep.get("realistic", rep.get("plausible", False)))


def last_realistic(steps: Sequence[tuple[float, Any]]) -> tuple[float, Any] | None:
    """The (λ, motion) of the last realistic optimum of a cell, or None."""
    for lam, m in reversed(steps):
        if realistic(m):
            return lam, m
    return None


FORMAT = "motionx.library"
VERSION = 1


def cell_entry(cell: Cell, *, status: str, lam_reached: float, message: str = "", motion=None,
               clip_lam: float | None = None, files: Mapping[str, str] | None = None,
               warm_start: CellStart | Mapping[str, Any] | None = None, solves: int | None = None,
               wall_time_s: float | None = None, report: Mapping[str, Any] | None = None,
               extra: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """One cell of a manifest: parameters, status (an impasse is marked and keeps its last
    realistic λ), files, realism figures (the plausibility report's) and the clip's cycle."""

    entry: dict[str, Any] = {
        "key": cell.key, "parameters": cell.values, "status": status,
        "at_impasse": status == "impasse", "lambda_reached": float(lam_reached),
        "clip_lambda": None if clip_lam is None else float(clip_lam), "message": message,
    }
    if motion is not None:
        rep = report if report is not None else getattr(motion, "report", None)
        entry["realism"] = realism(rep)
        if game.has_free_root(motion):
            g = game.game_json(motion, decimals=6)
            entry["cycle"] = g["cycle"]
            entry["loop"] = {k: g["loop"][k] for k in ("frames", "duration", "seamless", "closure_m")}
    else:
        entry["realism"] = None
    if isinstance(warm_start, CellStart):
        warm_start = dataclasses.asdict(warm_start)
    entry["warm_start"] = dict(warm_start) if warm_start else None
    if solves is not None:
        entry["solves"] = int(solves)
    if wall_time_s is not None:
        entry["wall_time_s"] = round(float(wall_time_s), 3)
    entry["files"] = dict(files or {})
    if extra:
        entry.update(extra)
    return entry


def summary(entries: Sequence[Mapping[str, Any]]) -> dict[str, Any]:
    counts = {s: sum(1 for e in entries if e["status"] == s)
              for s in ("succeeded", "impasse", "failed", "canceled", "queued", "running")}
    done = sum(counts[s] for s in ("succeeded", "impasse", "failed", "canceled"))
    out: dict[str, Any] = {"cells": len(entries), "done": done, **counts}
    times = [e["wall_time_s"] for e in entries if e.get("wall_time_s") is not None]
    if times:
        out["cell_time_s"] = {"total": round(sum(times), 3), "mean": round(sum(times) / len(times), 3),
                              "max": round(max(times), 3)}
    return out
