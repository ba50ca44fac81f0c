"""The method's commands: ``tutor``, ``validate`` and ``extrapolate`` (the main job)."""

from __future__ import annotations

import argparse
import csv
import json
import math
import sys
import time
from dataclasses import asdict
from pathlib import Path

from service.cli import CliError, import_message, parse_belt_speed, warn_input


def _load_motion(path: str):
    from solver.motion import Motion, MotionError

    try:
        return Motion.load(path)
    except MotionError as e:
        raise CliError(str(e)) from None


def _write_motion(motion, path: Path, *, with_replay: bool = True) -> dict:
    """Write a motion file with its plausibility report (MuJoCo replay included)."""
    from mjcf.validate import validate

    rep = validate(motion) if with_replay else motion.report
    motion.evolve(report=rep).save(path)
    return rep


# --- tutor --------------------------------------------------------------------------------


def cmd_tutor(args: argparse.Namespace) -> int:
    from solver.io import load_trial
    from solver.pipeline import PipelineError, make_tutor

    t0 = time.perf_counter()
    try:
        capture = load_trial(args.inputs, mass=args.mass, belt_speed=parse_belt_speed(args.belt_speed))
    except (ValueError, FileNotFoundError) as e:
        raise CliError(f"cannot import {' '.join(args.inputs)}: {import_message(e)}") from None
    t_import = time.perf_counter() - t0
    from solver.io.summary import describe
    from solver.pipeline import jsonable

    described = jsonable(describe(capture))
    warn_input(described)
    try:
        res = make_tutor(capture, character=args.character, fps=args.fps, cycle=args.cycle, start=args.start,
                         max_iter=args.max_iter)
    except (PipelineError, ValueError) as e:
        raise CliError(str(e)) from None
    out = {"status": res.status, "message": res.message, "import_s": round(t_import, 3), "input": described,
           "stats": res.stats}
    if res.motion is None:
        print(json.dumps(out))
        return 1
    rep = _write_motion(res.motion, Path(args.out))
    out.update({"out": args.out, "frames": res.motion.T, "coordinates": res.motion.n, "plausible": rep["plausible"],
                "root_residual_rel_weight": rep["root_residual"]["max_force_rel_weight"],
                "mujoco_agreement_rel_weight": rep["mujoco_replay"]["agreement_force_rel_weight"]})
    print(json.dumps(out))
    return 0 if rep["plausible"] else 1


# --- validate -----------------------------------------------------------------------------


def cmd_validate(args: argparse.Namespace) -> int:
    from mjcf.validate import validate
    from solver.plausibility import Tolerances

    motion = _load_motion(args.motion)
    tol = Tolerances(residual=args.residual_tol) if args.residual_tol else Tolerances()
    rep = validate(motion, tol)
    print(json.dumps(rep, indent=2 if args.pretty else None))
    return 0 if rep["plausible"] else 1


# --- extrapolate --------------------------------------------------------------------------


class _ProgressBar:
    """A one-line progress bar on stderr (λ reached, environment, elapsed)."""

    def __init__(self, enabled: bool) -> None:
        self.enabled = enabled and sys.stderr.isatty()
        self.verbose = enabled and not self.enabled

    def __call__(self, rec) -> None:
        env = ", ".join(f"{k}={v:.3g}" for k, v in rec.environment.items())
        mark = "ok" if rec.accepted else "retry"
        if self.enabled:
            width = 30
            fill = int(round(width * rec.lam_reached))
            sys.stderr.write(f"\r[{'#' * fill}{'.' * (width - fill)}] λ={rec.lam_reached:.3f} "
                             f"(tried {rec.lam:.3f} {mark}, {rec.iterations} it) {rec.wall_time:6.1f}s  ")
            sys.stderr.flush()
        elif self.verbose:
            sys.stderr.write(f"λ {rec.lam:.4f} {mark:5s} {rec.iterations:4d} it  reached {rec.lam_reached:.4f}  "
                             f"{rec.wall_time:7.2f}s  {env}\n")

    def close(self) -> None:
        if self.enabled:
            sys.stderr.write("\n")


def write_progress_csv(records, path: Path) -> None:
    keys = ["slope_deg", "curve_deg", "friction", "gravity"]
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["wall_time_s", "lambda", *keys, "iterations", "accepted", "status", "lambda_reached"])
        for r in records:
            w.writerow([f"{r.wall_time:.4f}", f"{r.lam:.6f}", *[f"{r.environment.get(k, float('nan')):.6g}" for k in keys],
                        r.iterations, int(r.accepted), r.status, f"{r.lam_reached:.6f}"])


def plot_progress(records, target, path: Path) -> None:
    """λ (and the environment value) against compute time, like the thesis's Figs. 5.21/5.23/5.28
    (``service.plots.progress_png``, the plot the API serves at ``/jobs/{id}/plots/progress.png``)."""
    from service.plots import progress_png

    path.write_bytes(progress_png([asdict(r) for r in records], asdict(target)))


def cmd_extrapolate(args: argparse.Namespace) -> int:
    from service.commands.plot import write_motion_plots
    from solver.continuation import StepControl, Target, extrapolate

    tutor = _load_motion(args.tutor)
    try:
        target = Target(slope_deg=args.slope or 0.0, curve_deg=args.curve or 0.0, friction=args.friction,
                        gravity=args.gravity)
        control = StepControl(method=args.method, delta0=args.delta0, max_iter=args.max_iter, eps=args.eps,
                              max_solves=args.max_solves)
    except ValueError as e:
        raise CliError(str(e)) from None
    if target.is_identity():
        raise CliError("give a target: --slope DEG, --curve DEG, --friction MU and/or --gravity G")
    if tutor.wrenches is None or tutor.contacts is None:
        raise CliError(f"{args.tutor} is not a tutor (it has no contact wrenches or contact schedule); "
                       "run `motionx tutor` first")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    bar = _ProgressBar(not args.quiet)
    files: list[str] = []

    def on_step(step) -> None:
        name = f"motion_{step.step:03d}_lambda_{step.lam:.4f}.json"
        step.motion.save(out / name)  # our plausibility report inside; MuJoCo replay for the last one
        files.append(name)

    try:
        res = extrapolate(tutor, target, control, on_progress=bar, on_step=on_step)
    except ValueError as e:
        raise CliError(str(e)) from None
    finally:
        bar.close()
    write_progress_csv(res.records, out / "progress.csv")
    plot_progress(res.records, target, out / "progress.png")
    final = None
    if res.steps:
        last = res.steps[-1]
        rep = _write_motion(last.motion, out / files[-1])
        final = {"file": files[-1], "lambda": last.lam, "plausible": rep["plausible"],
                 "root_residual_N": rep["root_residual"]["max_force_N"],
                 "root_residual_rel_weight": rep["root_residual"]["max_force_rel_weight"],
                 "mujoco_root_residual_rel_weight": rep["mujoco_replay"]["max_force_rel_weight"],
                 "mujoco_agreement_rel_weight": rep["mujoco_replay"]["agreement_force_rel_weight"],
                 "environment": last.motion.provenance.get("environment_values"),
                 "plots": list(write_motion_plots(last.motion, out).values())}
    summary = {
        "status": res.status,
        "lambda_reached": res.lam_reached,
        "message": res.message,
        "target": {"slope_deg": target.slope_deg, "curve_deg": target.curve_deg, "friction": target.friction,
                   "gravity": target.gravity},
        "control": {"method": control.method, "delta0": control.delta0, "eps": control.eps,
                    "max_iter": control.max_iter},
        "solves": res.solves,
        "accepted": len(res.steps),
        "wall_time_s": round(res.wall_time, 3),
        "motions": files,
        "final": final,
    }
    (out / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=False))
    print(json.dumps(summary))
    return 0 if res.status in ("succeeded", "impasse") else 1


def _finite(kind: str):
    def conv(s: str) -> float:
        try:
            v = float(s)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{kind} must be a number, got {s!r}") from None
        if not math.isfinite(v):
            raise argparse.ArgumentTypeError(f"{kind} must be finite, got {s!r}")
        return v

    return conv


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("tutor", help="import a trial and make it physically plausible (the tutor motion)")
    s.add_argument("inputs", nargs="+", help="trial files: MODEL.osim COORDS.mot | FILE.c3d | FILE.bvh | "
                                             "DeepMimic CLIP.txt CHARACTER.txt")
    s.add_argument("--character", choices=["halfboy", "fullbody"], default="halfboy")
    s.add_argument("--fps", type=float, choices=[15.0, 30.0], default=15.0)
    s.add_argument("--out", required=True, help="motion file v1 (JSON) to write")
    s.add_argument("--mass", type=_finite("--mass"), help="subject mass (kg) when the input does not state it")
    s.add_argument("--belt-speed", default=None,
                   help="treadmill belt speed in m/s, or 'auto' (adds v·t to the root: overground-equivalent)")
    s.add_argument("--cycle", type=int, default=0, help="which complete gait cycle to use (0 = first)")
    s.add_argument("--start", default="auto", choices=["auto", "right_heel_strike", "left_heel_strike", "best_loop"],
                   help="where the cycle starts (auto: heel strikes, else the best-closing loop)")
    s.add_argument("--max-iter", type=int, default=1000, help="IPOPT iteration limit of the correction")
    s.set_defaults(func=cmd_tutor)

    s = sub.add_parser("validate", help="plausibility report of a motion file (MuJoCo replay included)")
    s.add_argument("motion", help="motion file v1 (JSON)")
    s.add_argument("--residual-tol", type=_finite("--residual-tol"), default=None,
                   help="root residual tolerance relative to body weight (default 1e-6)")
    s.add_argument("--pretty", action="store_true")
    s.set_defaults(func=cmd_validate)

    s = sub.add_parser("extrapolate", help="continuation from a tutor to a new environment (the main job)")
    s.add_argument("tutor", help="tutor motion file (motionx tutor)")
    s.add_argument("--slope", type=_finite("--slope"), help="ground slope in degrees, positive uphill")
    s.add_argument("--curve", type=_finite("--curve"), help="heading change over one cycle in degrees, positive left")
    s.add_argument("--friction", type=_finite("--friction"), help="target friction coefficient")
    s.add_argument("--gravity", type=_finite("--gravity"), help="target gravity magnitude in m/s² (Moon 1.62)")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--method", choices=["adaptive", "thesis"], default="adaptive", help="step control")
    s.add_argument("--delta0", type=float, default=0.05, help="first step Δ0")
    s.add_argument("--eps", type=float, default=0.005, help="smallest step ε before an impasse")
    s.add_argument("--max-iter", type=int, default=200, help="IPOPT iterations per step (k)")
    s.add_argument("--max-solves", type=int, default=400)
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.set_defaults(func=cmd_extrapolate)
