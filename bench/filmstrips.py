"""The filmstrips of docs/naturalness.md: on two shared trials, the captured cycle, its tutor (the
default character, or ``--character``) and the λ = 1 optima of slope ±20°, curve 90° and stairs, each
drawn by ``service.plots.filmstrip_png`` (the same figure as ``motionx plot --kind filmstrip``).
docs/img/naturalness/before/ holds the same figures made by the code before the fidelity issue
(HalfBoy at 15 frames/s, its features on bounds).

    python -m bench.filmstrips [--out docs/img/naturalness] [--character fullbody|halfboy]
    python -m bench.filmstrips --motions FOLDER   # the tutors and optima the fidelity bench kept
"""

from __future__ import annotations

import argparse
from pathlib import Path

import numpy as np

from bench.trials import shared_trials
from service.config import enable_native_code, get_settings
from service.plots import filmstrip_png
from solver.continuation import StepControl, Target, extrapolate
from solver.gait import extract_cycle
from solver.io import load_trial
from solver.motion import Motion
from solver.pipeline import DEFAULT_CHARACTER, make_tutor

TRIALS = ("deepmimic_walk", "opensim_overground")
TARGETS = {"uphill_20": Target(slope_deg=20.0), "downhill_20": Target(slope_deg=-20.0),
           "curve_90": Target(curve_deg=90.0), "stairs_up_0.17": Target(step_height_m=0.17, step_going_m=0.28)}


def capture_cycle(capture, fps: float) -> Motion:
    """The captured cycle at the tutor's frame rate, on the capture skeleton, with its plates'
    forces as ground reactions where the plates are complete (for the arrows)."""
    cyc, contacts = extract_cycle(capture, fps, start="auto")
    A = np.array(contacts, dtype=bool)
    A[:, -2:] = A[:, :2]
    W = None
    if cyc.measured is not None:
        F = np.array(cyc.measured.force)
        F[:, :, ~np.asarray(cyc.measured.valid, dtype=bool)] = 0.0
        cop = np.nan_to_num(np.array(cyc.measured.cop))
        moment = np.moveaxis(np.cross(np.moveaxis(cop, 1, 2), np.moveaxis(F, 1, 2)), 2, 1)
        moment[:, 2] += np.nan_to_num(np.array(cyc.measured.free_moment))
        W = np.concatenate([moment, F], axis=1)
    return Motion(capture.character, fps, cyc.q, contacts=A, wrenches=W, cyclic=True,
                  provenance={"step": "capture"})


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--out", default="docs/img/naturalness")
    p.add_argument("--character", default=DEFAULT_CHARACTER, choices=["fullbody", "halfboy"])
    p.add_argument("--motions", default=None,
                   help="a folder of NAME.tutor.json and NAME.TARGET.json (MOTIONX_BENCH_FIDELITY_SAVE): draw "
                        "those, with each trial's captured cycle, instead of solving again")
    args = p.parse_args()
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    enable_native_code(get_settings().model_copy(update={"compiled_derivatives": False}))
    trials = shared_trials()
    if args.motions:
        return from_folder(Path(args.motions), out, trials)
    for name in TRIALS:
        files, opts = trials[name]
        capture = load_trial(files, **opts)
        tutor = make_tutor(capture, character=args.character).motion
        assert tutor is not None, name
        (out / f"{name}.capture.png").write_bytes(
            filmstrip_png(capture_cycle(capture, tutor.fps), title=f"{name}: the captured cycle"))
        (out / f"{name}.tutor.png").write_bytes(filmstrip_png(tutor, title=f"{name}: the tutor"))
        for label, target in TARGETS.items():
            res = extrapolate(tutor, target, StepControl())
            last = res.steps[-1].motion
            title = f"{name}: {label} ({res.status}, λ = {res.lam_reached:.3g})"
            (out / f"{name}.{label}.png").write_bytes(filmstrip_png(last, title=title))
            print(f"[filmstrips] {name} {label}: {res.status} λ = {res.lam_reached:.3f}")
    return 0


def from_folder(folder: Path, out: Path, trials: dict) -> int:
    """The filmstrips of the motions a fidelity bench run kept (bench/fidelity.py)."""
    for tutor_file in sorted(folder.glob("*.tutor.json")):
        name = tutor_file.name.removesuffix(".tutor.json")
        tutor = Motion.load(tutor_file)
        files, opts = trials[name]
        (out / f"{name}.capture.png").write_bytes(
            filmstrip_png(capture_cycle(load_trial(files, **opts), tutor.fps), title=f"{name}: the captured cycle"))
        (out / f"{name}.tutor.png").write_bytes(filmstrip_png(tutor, title=f"{name}: the tutor"))
        for f in sorted(folder.glob(f"{name}.*.json")):
            label = f.name.removeprefix(f"{name}.").removesuffix(".json")
            if label == "tutor":
                continue
            status = f.with_suffix(".status")
            title = f"{name}: {label}" + (f" ({status.read_text()})" if status.exists() else "")
            (out / f"{name}.{label}.png").write_bytes(filmstrip_png(Motion.load(f), title=title))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
