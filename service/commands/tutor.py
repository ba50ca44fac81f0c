"""The method's commands: ``tutor``, ``validate`` and ``extrapolate`` (the main job)."""

from __future__ import annotations

import argparse
import json
import sys
import time
from dataclasses import asdict
from pathlib import Path

from tqdm import tqdm

from service.cli import (
    CliError,
    add_command,
    add_import_options,
    cancel_on_signals,
    finite,
    import_message,
    import_options,
    load_motion,
    warn_input,
)
from service.commands.outputs import prepare_output_dir
from service.config import enable_native_code, get_settings, load_check_modules
from solver import axes as registry
from solver.outputs import progress_csv, step_stem


def _write_motion(motion, path: Path, *, with_replay: bool = True) -> dict:
    """Write a motion file with its plausibility report (MuJoCo replay included)."""
    from mjcf.validate import validate

    rep = validate(motion) if with_replay else motion.report
    motion.evolve(report=rep).save(path)
    return rep


# --- tutor --------------------------------------------------------------------------------


def _input_line(inp: dict | None) -> str | None:
    """The input summary (``solver.io.summary.describe``, the ``input`` key of ``--json``) in one
    short line: format, frames, mass used and the mass the plates imply, fit error, stances."""
    if not inp:
        return None
    mass = f"{inp['mass_kg']:g} kg" + (f" ({inp['mass_from']})" if inp.get("mass_from") else "")
    if inp.get("mass_implied_kg") is not None:
        mass += f", plates imply {inp['mass_implied_kg']:.1f} kg"
    parts = [f"{inp.get('format') or 'trial'}, {inp.get('frames')} frames"
             + (f" at {inp['fps']:g} fps" if inp.get("fps") else ""), mass]
    for key, what in (("marker_fit_error_mm", "marker fit"), ("landmark_fit_error_mm", "landmark fit")):
        if (inp.get(key) or {}).get("max") is not None:
            parts.append(f"{what} <= {inp[key]['max']:.1f} mm")
            break
    if inp.get("stances"):
        parts.append("stances " + ", ".join(f"{side} {len(v)}" for side, v in inp["stances"].items()))
    return "  input: " + "; ".join(parts)


def _tutor_summary(out: dict) -> str:
    """A few lines for a person: what was made, how long it took, whether it is plausible."""
    st = out.get("stats") or {}
    simp, corr = st.get("simplify") or {}, st.get("correct") or {}
    its = sum(a.get("iterations") or 0 for a in corr.get("attempts") or [])
    took = (f"in {out['import_s'] + (st.get('total_s') or 0.0):.1f} s (import {out['import_s']:.1f} s, "
            f"simplification {simp.get('time_s', 0.0):.1f} s, correction {corr.get('time_s', 0.0):.1f} s "
            f"with {its} IPOPT iterations)")
    if out["status"] != "succeeded" or "out" not in out:
        return f"tutor {out['status']} {took}: {out.get('message') or 'no plausible motion'}; nothing written"
    inp = _input_line(out.get("input"))
    lines = [f"tutor {out['status']} {took}", *([inp] if inp else []),
             f"  wrote {out['out']}: {out['character']}, {out['coordinates']} coordinates, {out['frames']} frames "
             f"at {out['fps']:g} fps (one gait cycle)",
             f"  {'plausible' if out['plausible'] else 'NOT plausible'}: root residual "
             f"{out['root_residual_rel_weight']:.1e} x body weight (tolerance 1e-6), MuJoCo's replay agrees to "
             f"{out['mujoco_agreement_rel_weight']:.1e}{_realism_words(out)}"]
    md = st.get("marker_distance_to_capture_mm") or {}
    if md:
        lines.append(f"  distance to the capture: markers {md['mean']:.1f} mm on average, {md['max']:.1f} mm at most")
    lines.append(f"  next: motionx extrapolate {out['out']} --slope DEG (or --curve DEG) --out DIR")
    return "\n".join(lines)


def _realism_words(out: dict) -> str:
    """'; realism passed' or '; realism: N checks failed' (``motionx validate`` shows the figures)."""
    if "realism_failed" not in out:
        return ""
    n = len(out["realism_failed"])
    return "; realism passed" if not n else f"; realism: {n} check{'s' if n > 1 else ''} failed"


def cmd_tutor(args: argparse.Namespace) -> int:
    # Ctrl-C or SIGTERM, from the import on, cancels: the running solve stops at its next IPOPT
    # iteration, nothing is written, the summary says "canceled" and the exit status is 130 / 143
    with cancel_on_signals() as cancel:
        return _tutor(args, cancel)


def _tutor(args: argparse.Namespace, cancel: cancel_on_signals) -> int:
    from solver.io import load_trial
    from solver.pipeline import PipelineError, make_tutor

    enable_native_code(get_settings())
    load_check_modules(get_settings())
    t0 = time.perf_counter()
    try:
        capture = load_trial(args.inputs, **import_options(args))
    except (ValueError, FileNotFoundError) as e:
        raise CliError(f"cannot import {' '.join(args.inputs)}: {import_message(e)}") from None
    t_import = time.perf_counter() - t0
    from solver.io.summary import describe
    from solver.pipeline import jsonable

    described = jsonable(describe(capture))
    warn_input(described)
    if not cancel():
        print("motionx tutor: solving (simplification, then correction with IPOPT)", file=sys.stderr, flush=True)
    try:
        res = make_tutor(capture, character=args.character, fps=args.fps, cycle=args.cycle, start=args.start,
                         max_iter=args.max_iter, should_cancel=cancel)
    except (PipelineError, ValueError) as e:
        raise CliError(import_message(e)) from None  # an input's error names its flag (--belt-speed, …)
    out = {"status": res.status, "message": res.message, "import_s": round(t_import, 3), "input": described,
           "stats": res.stats}
    if res.status == "canceled" and cancel():
        out["message"] = f"{cancel.reason}, {res.message}"
    if res.motion is None:
        print(json.dumps(out) if args.json else _tutor_summary(out))
        return cancel.exit_status or 1
    rep = _write_motion(res.motion, Path(args.out))
    out.update({"out": args.out, "character": res.motion.character.name, "fps": res.motion.fps,
                "frames": res.motion.T, "coordinates": res.motion.n, "plausible": rep["plausible"],
                "root_residual_rel_weight": rep["root_residual"]["max_force_rel_weight"],
                "mujoco_agreement_rel_weight": rep["mujoco_replay"]["agreement_force_rel_weight"],
                "realism_failed": (rep.get("realism") or {}).get("failed", [])})
    print(json.dumps(out) if args.json else _tutor_summary(out))
    if cancel.exit_status is not None:  # the signal came after the tutor was made: it is written
        return cancel.exit_status
    return 0 if rep["plausible"] else 1


# --- validate -----------------------------------------------------------------------------


def cmd_validate(args: argparse.Namespace) -> int:
    from mjcf.validate import validate
    from solver.plausibility import Tolerances

    load_check_modules(get_settings())
    motion = load_motion(args.motion)
    tol = Tolerances(residual=args.residual_tol) if args.residual_tol else Tolerances()
    rep = validate(motion, tol)
    if args.json or args.pretty:
        print(json.dumps(rep, indent=2 if args.pretty else None))
    else:
        print(_validate_summary(rep, args.motion))
    return 0 if rep["plausible"] and rep.get("natural") is not False else 1


def _validate_summary(rep: dict, path) -> str:
    """The plausibility report for a person: the verdicts (plausible, natural), the checks at the
    frames in one line, then every realism and naturalness check with its figure and limit
    (failures first), warnings and notes."""
    r, mj = rep["root_residual"], rep.get("mujoco_replay") or {}
    natural = {True: ", natural", False: ", NOT natural"}.get(rep.get("natural"), "")
    head = (f"{path}: {'plausible' if rep['plausible'] else 'NOT plausible'}{natural} ({rep['character']}, "
            f"{rep['frames']} frames at {rep['fps']:g} fps)")
    frames = [f"root residual {max(r['max_force_rel_weight'], r['max_moment_rel_weight_leg']):.1e} x body weight "
              f"(tolerance {rep['tolerances']['residual']:g})"]
    if mj:
        frames.append(f"MuJoCo's replay agrees to {mj['agreement_force_rel_weight']:.1e}")
    if "slip_mm" in rep:
        frames.append(f"slip {rep['slip_mm']:.2f} mm, penetration {rep['penetration_mm']:.2f} mm")
    other = [k for k, v in rep["checks"].items() if not v and not k.startswith("realism_")]
    frames.append("contact checks ok" if not other else "failed: " + ", ".join(other))
    lines = [head, "  at the frames: " + "; ".join(frames)]
    lines += _section_lines(rep.get("realism") or {}, "realism (between the frames")
    lines += _section_lines(rep.get("naturalness") or {}, "naturalness (the gait's human features")
    return "\n".join(lines)


def _section_lines(sec: dict, title: str) -> list[str]:
    """A report section of checks (``solver.realism``, ``solver.naturalness``): its verdict, then
    every check with its figure and limit (failures first, then warnings), the captured walk's
    figure where the section has one, and its notes."""
    lines = []
    checks = {k: c for k, c in (sec.get("checks") or {}).items() if c.get("applies", True)}
    if checks:
        failed = sec.get("failed") or []
        lines.append(f"  {title}, {1e3 * sec.get('time_s', 0.0):.0f} ms): "
                     + (f"{len(failed)} of {sum(c['severity'] == 'failure' for c in checks.values())} checks failed"
                        if failed else "every check passed"))
        order = sorted(checks.items(), key=lambda kv: (kv[1]["passed"], kv[1]["severity"] != "failure"))
        for name, c in order:
            mark = ("ok  " if c["passed"] else ("FAIL" if c["severity"] == "failure" else "warn"))
            rel = ">=" if c.get("bound") == "min" else "<="
            value = "–" if c["value"] is None else f"{c['value']:.3g}"
            capture = f"; capture {c['capture']:.3g}" if c.get("capture") is not None else ""
            lines.append(f"    {mark} {name:22s} {value:>9s} {c['unit']:6s} (limit {rel} {c['limit']:.3g}{capture}): "
                         f"{c['what']}")
    for note in sec.get("notes") or []:
        lines.append(f"  note: {note}")
    return lines


# --- extrapolate --------------------------------------------------------------------------


class _ProgressBar:
    """Progress on stderr: a tqdm bar of λ reached on a terminal (with the last solve, the
    environment and the elapsed time), else one line per solve; nothing with ``--quiet``."""

    def __init__(self, enabled: bool) -> None:
        tty = enabled and sys.stderr.isatty()
        self.verbose = enabled and not tty
        self.bar = tqdm(total=1.0, file=sys.stderr, disable=not tty, ascii=".#",
                        bar_format="[{bar:30}] λ={n:.3f} {desc}")

    def __call__(self, rec) -> None:
        from service.plots import number_text

        env = ", ".join(f"{k}={number_text(v)}" for k, v in rec.environment.items())
        mark = "ok" if rec.accepted else "retry"
        if not self.bar.disable:
            self.bar.n = rec.lam_reached
            self.bar.set_description_str(f"(tried {rec.lam:.3f} {mark}, {rec.iterations} it) {env} "
                                         f"{rec.wall_time:6.1f}s")
        elif self.verbose:
            sys.stderr.write(f"λ {rec.lam:.4f} {mark:5s} {rec.iterations:4d} it  reached {rec.lam_reached:.4f}  "
                             f"{rec.wall_time:7.2f}s  {env}\n")

    def close(self) -> None:
        self.bar.close()


def plot_progress(records, target, path: Path) -> None:
    """λ (and the environment value) against compute time, like the thesis's Figs. 5.21/5.23/5.28
    (``service.plots.progress_png``, the plot the API serves at ``/jobs/{id}/plots/progress.png``)."""
    from service.plots import progress_png

    path.write_bytes(progress_png([asdict(r) for r in records], target.to_dict()))


def _extrapolate_summary(summary: dict, out: Path) -> str:
    from service.plots import changed_parameters, describe_target

    final = summary["final"]
    head = (f"{summary['status']}: λ = {summary['lambda_reached']:.4f} toward {describe_target(summary['target'])} "
            f"in {summary['wall_time_s']:.1f} s ({summary['solves']} solves, {summary['accepted']} motions kept)")
    lines = [head]
    if summary["message"]:
        lines.append(f"  {summary['message']}")
    if final:
        env = final.get("environment") or {}
        changed = [k for k in changed_parameters(summary["target"]) if env.get(k) is not None]
        reached = f" ({describe_target({k: env[k] for k in changed})})" if changed else ""
        lines.append(f"  final motion {final['file']}: λ = {final['lambda']:.4f}{reached}, "
                     f"{'plausible' if final['plausible'] else 'NOT plausible'} (root residual "
                     f"{final['root_residual_rel_weight']:.1e} x body weight, MuJoCo's replay agrees to "
                     f"{final['mujoco_agreement_rel_weight']:.1e}{_realism_words(final)})")
    lines.append(f"  wrote {out}/: step_NNN_lambda_L.motion.json per λ, progress.csv, progress.png, summary.json"
                 + (", grf.png, residuals.png, filmstrip.png" if final else ""))
    return "\n".join(lines)


def cmd_extrapolate(args: argparse.Namespace) -> int:
    from service.commands.plot import write_motion_plots
    from solver.continuation import StepControl, Target, extrapolate

    enable_native_code(get_settings())
    load_check_modules(get_settings())

    try:  # the target first: a wrong value is told before any file is read
        target = Target(**{ax.name: getattr(args, ax.name) for ax in registry.axes()})
        control = StepControl(method=args.method, delta0=args.delta0, max_iter=args.max_iter, eps=args.eps,
                              max_solves=args.max_solves)
    except ValueError as e:
        raise CliError(str(e)) from None
    if target.is_identity():
        raise CliError("give a target: " + ", ".join(f"{ax.cli} {ax.metavar}" for ax in registry.axes()))
    tutor = load_motion(args.tutor)
    if tutor.wrenches is None or tutor.contacts is None:
        raise CliError(f"{args.tutor} is not a tutor (it has no contact wrenches or contact schedule); "
                       "run `motionx tutor` first")
    out = Path(args.out)
    prepare_output_dir(out, force=args.force)
    bar = _ProgressBar(not args.quiet)
    files: list[str] = []

    def on_step(step) -> None:
        name = f"{step_stem(step.step, step.lam)}.motion.json"
        step.motion.save(out / name)  # our plausibility report inside; MuJoCo replay for the last one
        files.append(name)

    # Ctrl-C or SIGTERM cancels the walk: the motions kept so far, progress and summary are written
    # and the exit status is 130 / 143
    with cancel_on_signals() as cancel:
        try:
            res = extrapolate(tutor, target, control, on_progress=bar, on_step=on_step, should_cancel=cancel)
        except ValueError as e:
            raise CliError(str(e)) from None
        finally:
            bar.close()
    (out / "progress.csv").write_text(progress_csv(asdict(r) for r in res.records))
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
                 "realism_failed": (rep.get("realism") or {}).get("failed", []),
                 "environment": dict(last.motion.context.axis_values) or None,
                 "plots": list(write_motion_plots(last.motion, out).values())}
    summary = {**res.summary(), "control": control.summary(), "final": final}  # motions: the files on_step wrote
    if cancel() and res.status == "canceled":
        summary["message"] = cancel.reason
    (out / "summary.json").write_text(json.dumps(summary, indent=2, allow_nan=False))
    print(json.dumps(summary) if args.json else _extrapolate_summary(summary, out))
    if cancel.exit_status is not None:
        return cancel.exit_status
    return 0 if res.status.ok else 1


def register(sub: argparse._SubParsersAction) -> None:
    s = add_command(sub, "tutor", "import a trial and make it physically plausible (the tutor motion)", """\
Import a captured walk, take one gait cycle, reduce the capture skeleton to the synthesis
character, estimate the contact forces from the kinematics and correct the motion with the
spacetime NLP (IPOPT) until it obeys the equations of motion: the tutor, written as a motion
file v2 with its plausibility report (MuJoCo replay included). It is the input of
`motionx extrapolate`. Exit status 1 when the correction fails (nothing is written); Ctrl-C
or SIGTERM stops the solve at its next IPOPT iteration, writes nothing and exits 130 (143).""")
    s.add_argument("inputs", nargs="+", metavar="INPUT",
                   help="trial files: MODEL.osim COORDS.mot [GRF.mot X.xml] | FILE.c3d | FILE.bvh | "
                        "DeepMimic CLIP.txt CHARACTER.txt")
    # the default: solver.pipeline.DEFAULT_CHARACTER (not imported here: the command line starts without CasADi)
    s.add_argument("--character", choices=["halfboy", "fullbody"], default="fullbody",
                   help="synthesis character: fullbody (the whole skeleton: 43 coordinates and those the capture "
                        "uses of its ankles, knees and forearms; the faithful one) or halfboy (the thesis's: 16 "
                        "coordinates, legs + trunk, head and arms welded to the pelvis)")
    s.add_argument("--fps", type=float, choices=[15.0, 30.0], default=None,
                   help="frames per second of the tutor (default: 30 for fullbody, 15 for halfboy; adjusted so that "
                        "the cycle's frames span the subject's own period)")
    s.add_argument("--out", required=True, metavar="TUTOR.json", help="motion file v2 (JSON) to write")
    s.add_argument("--cycle", type=int, default=0, metavar="N", help="which complete gait cycle to use (0 = first)")
    s.add_argument("--start", default="auto", choices=["auto", "right_heel_strike", "left_heel_strike", "best_loop"],
                   help="where the cycle starts (auto: heel strikes, else the best-closing loop)")
    s.add_argument("--max-iter", type=int, default=1000, metavar="K", help="IPOPT iteration limit of the correction")
    s.add_argument("--json", action="store_true", help="print the result as one JSON object instead of a summary")
    add_import_options(s)
    s.set_defaults(func=cmd_tutor)

    s = add_command(sub, "extrapolate", "continuation from a tutor to a new environment (the main job)", """\
Walk the homotopy λ from 0 (the tutor's ground) to 1 (the target: slope, curve, friction,
gravity, speed, stairs, combinable; the axes of solver.axes), solving the spacetime NLP at each λ
and keeping every plausible and natural optimum as a motion of its own (the walk ends at an
impasse at the last natural λ). Writes into --out, per accepted step,
step_NNN_lambda_L.motion.json, then progress.csv, progress.png, summary.json and the last
motion's grf.png, residuals.png and filmstrip.png. Exit status 0 for `succeeded` and `impasse`.""")
    s.add_argument("tutor", metavar="TUTOR.json", help="tutor motion file (from motionx tutor)")
    for ax in registry.axes():  # one flag per registered homotopy axis
        s.add_argument(ax.cli, dest=ax.name, type=finite(ax.cli), metavar=ax.metavar,
                       help=f"{ax.doc}; within {ax.bounds_text()}"
                            + ("" if ax.default is None else f" (default: {ax.default:g})"))
    s.add_argument("--out", required=True, metavar="DIR", help="output folder (new or empty, unless --force)")
    s.add_argument("--force", "--overwrite", action="store_true",
                   help="write into a non-empty --out: first remove the files an extrapolation writes there "
                        "(step_*, progress.*, summary.json, grf.png, residuals.png), keep the others")
    s.add_argument("--method", choices=["adaptive", "thesis"], default="thesis",
                   help="step control: thesis (default; Algorithm 3: double on success, halve on failure) or "
                        "adaptive (secant predictor, steps from the recent history)")
    s.add_argument("--delta0", type=finite("--delta0"), default=0.05, metavar="D", help="first step Δ0 in λ")
    s.add_argument("--eps", type=finite("--eps"), default=0.005, metavar="E",
                   help="smallest step ε in λ before an impasse")
    s.add_argument("--max-iter", type=int, default=200, metavar="K", help="IPOPT iterations per step (k)")
    s.add_argument("--max-solves", type=int, default=400, metavar="N",
                   help="most NLP solves of the whole continuation (accepted or not)")
    s.add_argument("--quiet", action="store_true", help="no progress bar")
    s.add_argument("--json", action="store_true", help="print summary.json on stdout instead of a summary")
    s.set_defaults(func=cmd_extrapolate)

    s = add_command(sub, "validate", "plausibility report of a motion file (MuJoCo replay included)", """\
Check a motion file against the equations of motion: root residual (ours and MuJoCo's
mj_inverse replay on the motion's MJCF), foot slip, penetration, friction cone, centre of
pressure, and the realism checks that hold between the frames (whole-body Newton-Euler
from positions, inverse dynamics on a 6x finer spline, torsional friction, foot spin,
ground force ranges, heading), and the naturalness checks of its gait (swing clearance, foot
pitch under load, joints at their limits, crossover, shared load at each change of support,
force shape, trunk lean on slopes, pelvis ranges), each beside the captured walk's own
figure. Prints a summary (--json: the report as JSON); exit status 1 when the motion is not
plausible or not natural.""")
    s.add_argument("motion", metavar="MOTION.json", help="motion file v2 (JSON)")
    s.add_argument("--residual-tol", type=finite("--residual-tol"), default=None, metavar="R",
                   help="root residual tolerance relative to body weight (default: 1e-6)")
    s.add_argument("--json", action="store_true", help="print the report as one JSON object instead of a summary")
    s.add_argument("--pretty", action="store_true", help="print the report as indented JSON")
    s.set_defaults(func=cmd_validate)
