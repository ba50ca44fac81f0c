"""``motionx grf`` (estimate ground reactions from kinematics) and ``motionx grf-compare``.

``grf`` imports a trial (OpenSim model + coordinates, C3D, or any format ``load_trial``
reads), low-passes its kinematics, takes its contact schedule, estimates each foot's
ground reaction (``solver.contact``) and writes them **in the input's own ground frame and
units** as CSV: ``time, side, fx, fy, fz, cop_x, cop_y, cop_z, tz``.

``grf-compare`` compares such a CSV with the trial's force plates (OpenSim GRF .mot or the
C3D's plates) and prints the thesis's Table 4.1 metrics; ``--plot`` writes a PNG.
"""

from __future__ import annotations

import argparse
import json
import logging
import math
import time
from pathlib import Path

import numpy as np

from service.cli import CliError, add_command, add_import_options, import_message, import_options, warn_input

log = logging.getLogger("motionx")


def _user_errors() -> tuple[type[Exception], ...]:
    """Exceptions that describe bad input (their message is the user-facing error): every reader's,
    gait processing's and the force files' (one base, solver.errors.InputError), and the contact
    estimator's option checks."""
    from solver.contact import ContactError
    from solver.errors import InputError

    return (InputError, ContactError)


def _exists(path: str | None, flag: str) -> None:
    if path is not None and not Path(path).is_file():
        raise CliError(f"{flag}: file not found: {path}")


def _files(args: argparse.Namespace) -> list[str]:
    """The trial files given positionally (as for `motionx tutor`) or with --input."""
    return [*(args.inputs or []), *(args.input or [])]


def _load(args: argparse.Namespace):
    """The capture named by the inputs: trial files (positional, as `motionx tutor` takes them,
    or --input), or the older flags --osim MODEL --coordinates IK.mot, --c3d FILE."""
    files = _files(args)
    kinds = [k for k in ("osim", "c3d") if getattr(args, k)] + (["files"] if files else [])
    if len(kinds) != 1:
        raise CliError("give the trial once: its files (MODEL.osim IK.mot|MARKERS.trc [GRF.mot X.xml] | FILE.c3d "
                       "| FILE.bvh | DeepMimic CLIP.txt CHARACTER.txt), or --osim MODEL --coordinates IK.mot, "
                       "or --c3d FILE")
    options = import_options(args)
    belt = options.get("belt_speed")
    from solver.io import load_trial

    if kinds[0] == "osim":
        if not args.coordinates:
            raise CliError("--osim needs --coordinates IK.mot (the model's coordinates over time)")
        _exists(args.osim, "--osim")
        _exists(args.coordinates, "--coordinates")
        _exists(args.grf, "--grf")
        _exists(args.external_loads, "--external-loads")
        return load_trial([p for p in (args.osim, args.coordinates, args.grf, args.external_loads) if p], **options)
    if args.coordinates:
        raise CliError("--coordinates goes with --osim (or list the model and its coordinates as files)")
    if kinds[0] == "c3d":
        if args.grf or args.external_loads:
            raise CliError("--grf and --external-loads are OpenSim force plates; a C3D has its own")
        if belt is not None:
            raise CliError("--belt-speed applies to OpenSim treadmill trials")
        _exists(args.c3d, "--c3d")
        return load_trial([args.c3d], **options)
    for p in files:
        _exists(p, "input")
    extra = [p for p in (args.grf, args.external_loads) if p]
    if extra and not any(Path(p).suffix.lower() == ".osim" for p in files):
        raise CliError("--grf and --external-loads go with an OpenSim trial (MODEL.osim IK.mot)")
    _exists(args.grf, "--grf")
    _exists(args.external_loads, "--external-loads")
    return load_trial([*files, *extra], **options)


def cmd_grf(args: argparse.Namespace) -> int:
    from solver.contact import estimate_capture
    from solver.grf_compare import from_estimate, to_input_frame, write_csv

    errors = _user_errors()
    if args.cutoff is not None and args.cutoff < 0:
        raise CliError(f"--cutoff must be >= 0 Hz (0 = no filter), got {args.cutoff}")
    if args.smoothing is not None and not (math.isfinite(args.smoothing) and args.smoothing >= 0):
        raise CliError(f"--smoothing must be >= 0 Hz (0 = one QP per frame), got {args.smoothing}")
    if args.smoothing and args.method != "qp":  # told before the trial is read (it can take tens of seconds)
        raise CliError(f"--smoothing goes with --method qp (--method {args.method} is the thesis's per-frame "
                       "reference form); drop --smoothing or pass --smoothing 0")
    smoothing = "cutoff" if args.smoothing is None else (args.smoothing or None)
    if args.lateral is not None and not (math.isfinite(args.lateral) and args.lateral >= 0):
        raise CliError(f"--lateral must be >= 0 Hz (0 = the inverse dynamics' own lateral force), "
                       f"got {args.lateral}")
    lateral = "default" if args.lateral is None else (args.lateral or None)
    t0 = time.perf_counter()
    try:
        cap = _load(args)
        t1 = time.perf_counter()
        tr = estimate_capture(cap, cutoff_hz=args.cutoff or None, contacts=args.contacts, method=args.method,
                              cyclic=True if args.cyclic else None, smoothing_hz=smoothing,
                              project_cop=not args.exact_single_support, lateral_hz=lateral)
    except errors as e:
        msg = import_message(e)
        c3d = args.c3d or any(Path(p).suffix.lower() == ".c3d" for p in _files(args))
        if ("double support" in msg or "never" in msg) and args.belt_speed is None and not c3d:
            msg += " (on a treadmill the stance foot moves with the belt: pass --belt-speed auto or the speed)"
        raise CliError(msg) from None
    t2 = time.perf_counter()
    est = tr.estimate
    gr = to_input_frame(from_estimate(est, tr.times), cap.frame)
    try:
        rows = write_csv(args.out, gr)
    except OSError as e:
        raise CliError(f"cannot write {args.out}: {e.strerror or e}") from None
    summary = {k: v for k, v in est.summary().items() if v not in (0, None)}
    from solver.io.summary import describe
    from solver.pipeline import jsonable

    described = jsonable(describe(cap, contacts=tr.contacts, contacts_from=tr.contacts_from))
    warn_input(described)
    print(json.dumps({
        "out": args.out, "rows": rows, "character": cap.character.name, "mass_kg": round(cap.character.total_mass, 3),
        "fps": round(cap.fps, 6), "frame": cap.frame.axes, "length_unit_m": cap.frame.unit_m,
        "contacts_from": tr.contacts_from, "cutoff_hz": tr.cutoff_hz, **summary,
        "free_moment": "not reported (tz = nan): its error exceeds predicting zero on every trial with plates "
                       "(docs/grf.md)",
        "import_s": round(t1 - t0, 3), "estimate_s": round(t2 - t1, 4), "input": described,
    }))
    return 0


# --- grf-compare -------------------------------------------------------------------------------


def cmd_grf_compare(args: argparse.Namespace) -> int:
    from solver.capture import GroundFrame
    from solver.grf_compare import (
        GroundReactions,
        compare,
        feet_on_plates,
        format_table,
        from_input_frame,
        from_measured,
        per_foot,
        plates_complete,
        plot,
        read_csv,
    )

    errors = _user_errors()
    if bool(args.grf) == bool(args.c3d):
        raise CliError("give the measurement: --grf GRF.mot [--external-loads X.xml] or --c3d FILE.c3d")
    if args.external_loads and not args.grf:
        raise CliError("--external-loads goes with --grf")
    _exists(args.estimate, "--estimate")
    off_plates = 0
    try:
        est_in = read_csv(args.estimate)
        times = est_in.times
        if args.grf:
            _exists(args.grf, "--grf")
            _exists(args.external_loads, "--external-loads")
            from solver.io.opensim import C_OSIM, read_opensim_grf

            # compare in the plates' own (treadmill-fixed) frame, with our axis names
            frame = GroundFrame(R=C_OSIM.T, axes="OpenSim ground: x forward, y up, z right")
            est = from_input_frame(est_in, frame)
            contacts = _contacts_of(est)
            meas = from_measured(read_opensim_grf(args.grf, args.external_loads, times=times, frame=frame,
                                                  contacts=contacts), times)
        else:
            _exists(args.c3d, "--c3d")
            from solver.io.c3d import read_c3d_trial

            opts = import_options(args)
            trial = read_c3d_trial(args.c3d, mass=opts.get("mass"), markers=opts.get("markers"))
            track = trial.track
            if track.measured is None:
                raise CliError(f"{args.c3d}: no force plates to compare with")
            frame = track.frame
            est = from_input_frame(est_in, frame)
            meas = from_measured(track.measured, track.times).resample(times)
            # a frame counts only when every loaded foot (plates or estimate) stands on a plate
            lm = {k: np.stack([np.interp(times, track.times, x) for x in track.landmarks[k]])
                  for k in ("heel_r", "mtp_r", "toe_r", "heel_l", "mtp_l", "toe_l")}
            on = feet_on_plates(lm, [p.corners for p in trial.plates])
            ok = plates_complete(est, meas, on)
            off_plates = int(np.sum(meas.valid & est.valid & ~ok))
            meas = GroundReactions(meas.times, meas.force, meas.cop, meas.free_moment, meas.valid & ok)
    except errors as e:
        raise CliError(import_message(e)) from None
    # both in our axes (x forward, y left, z up), SI: CoPs in metres
    try:
        all_frames, ds = compare(est, meas)
        feet = per_foot(est, meas)
    except ValueError as e:
        raise CliError(str(e)) from None
    if off_plates:
        print(f"{off_plates} frames left out: a loaded foot stands off the plates")
    print(format_table(all_frames))
    if ds is not None:
        print()
        print(format_table(ds))
    print()
    print("per foot (all frames): " + "; ".join(
        f"{side} " + ", ".join(_cell(a.row(c)) for c in ("fx", "fy", "fz", "cop")) for side, (a, *_) in feet.items()))
    if args.json:
        Path(args.json).write_text(json.dumps({
            "all": all_frames.as_dict(), "double_support": ds and ds.as_dict(), "frames_off_plates": off_plates,
            "per_foot": {side: {"all": a.as_dict(), "double_support": d and d.as_dict(),
                                "single_support": ss and ss.as_dict()} for side, (a, d, ss) in feet.items()},
        }, indent=2, allow_nan=True))
    if args.plot:
        from solver.grf_compare import to_input_frame

        both = est.valid & meas.valid
        thr = 0.05 * float(np.nanmax(np.where(both, meas.force[:, 2].sum(0), np.nan)))
        # drawn in the CSV's frame and units (the input's), named as the input names its axes
        names, vertical, unit = input_axes(frame)
        plot(args.plot, est_in, to_input_frame(meas, frame), axis_names=names, vertical=vertical, length_unit=unit,
             double_support=np.all(meas.force[:, 2] > thr, axis=0),
             title=f"{Path(args.estimate).name} ({frame.axes})")
    return 0


def _cell(row) -> str:
    if row.component == "cop":
        return f"cop {row.rms:.2f} cm"
    return f"{row.component} {100 * row.rel_rms:.1f} %"


#: our world axes (x forward, y left, z up): the direction each way along them
_DIRECTIONS = (("forward", "backward"), ("left", "right"), ("up", "down"))


def input_axes(frame) -> tuple[tuple[str, str, str], int, str]:
    """The input frame's axis names as the CSV's columns mean them ('x (forward)', 'y (up)',
    'z (right)' for OpenSim), the index of its vertical axis, and its length unit.

    ``frame`` is a :class:`solver.capture.GroundFrame` (p_input = R p_ours): row k of R is
    input axis k in our axes. An axis that is not along one of ours is named by letter only."""
    R = np.asarray(frame.R, dtype=float)
    names = []
    for k, letter in enumerate("xyz"):
        j = int(np.argmax(np.abs(R[k])))
        if abs(R[k, j]) > 1 - 1e-6:
            names.append(f"{letter} ({_DIRECTIONS[j][0 if R[k, j] > 0 else 1]})")
        else:
            names.append(letter)
    vertical = int(np.argmax(np.abs(R[:, 2])))
    unit = {1.0: "m", 0.01: "cm", 0.001: "mm"}.get(round(float(frame.unit_m), 12), f"× {frame.unit_m:g} m")
    return (names[0], names[1], names[2]), vertical, unit


def _contacts_of(gr) -> np.ndarray:
    """(4, T) contact rows (heel, toe per foot) from an estimate: a foot is on when it carries load."""
    on = np.abs(gr.force[:, 2]) > 0.0
    return np.stack([on[0], on[0], on[1], on[1]])


def register(sub: argparse._SubParsersAction) -> None:
    from solver.contact import CONTACT_SOURCES, DEFAULT_CUTOFF_HZ, METHODS

    s = add_command(sub, "grf", "estimate each foot's ground reaction from a trial's kinematics (CSV)", """\
Estimate each foot's ground reaction force, centre of pressure and free moment from the
kinematics alone (docs/method.md (M4): the total external wrench of inverse dynamics, split between the
feet by one convex QP per double-support frame) and write them as CSV in the input's own
ground frame and units: time, side, fx, fy, fz, cop_x, cop_y, cop_z, tz.
The trial is given as for `motionx tutor` (its files); --osim/--coordinates, --c3d and
--input are the older spellings.""")
    s.add_argument("inputs", nargs="*", metavar="INPUT",
                   help="trial files: MODEL.osim COORDS.mot|MARKERS.trc [GRF.mot X.xml] | FILE.c3d | FILE.bvh | "
                        "DeepMimic CLIP.txt CHARACTER.txt")
    g = s.add_argument_group("older input flags (instead of the files)")
    g.add_argument("--osim", metavar="MODEL.osim", help="OpenSim model; with --coordinates")
    g.add_argument("--coordinates", metavar="IK.mot", help="OpenSim coordinates over time (IK result), or the "
                   "markers (.trc) whose inverse kinematics OpenSim solves with the model's marker set")
    g.add_argument("--c3d", metavar="FILE.c3d", help="C3D trial (markers; plates give the contact timing)")
    g.add_argument("--input", nargs="+", metavar="FILE", help="trial files, as the positional INPUT")
    add_import_options(s)
    s.add_argument("--grf", metavar="GRF.mot", help="OpenSim force-plate file: contact timing from the plates "
                   "(--contacts auto|plates) and the belt-speed estimate (default: none)")
    s.add_argument("--external-loads", metavar="X.xml",
                   help="OpenSim ExternalLoads file assigning --grf to feet (default: none)")
    s.add_argument("--contacts", choices=CONTACT_SOURCES, default="auto",
                   help="contact schedule: plates (when the input has them) or kinematics (auto: plates if "
                        "available, else kinematic detection)")
    s.add_argument("--cutoff", type=float, default=DEFAULT_CUTOFF_HZ, metavar="HZ",
                   help="low-pass cut-off before differentiation in Hz; 0 = none")
    s.add_argument("--method", choices=METHODS, default="qp",
                   help="qp: one 6-variable QP per double-support frame; nested: the thesis's form (slow)")
    s.add_argument("--smoothing", type=float, default=None, metavar="HZ",
                   help="temporal prior on the double-support split, as a cut-off (default: the --cutoff; "
                        "0 = one QP per frame, the thesis; qp method only)")
    s.add_argument("--lateral", type=float, default=None, metavar="HZ",
                   help="the total's lateral force from the centre of mass low-passed at this cut-off (default: "
                        "4 Hz when under --cutoff; 0 = the inverse dynamics' own, the thesis)")
    s.add_argument("--exact-single-support", action="store_true",
                   help="the foot takes the total wrench exactly even when its CoP falls outside the foot "
                        "(the thesis); default: a total no foot can take is corrected by the least force through "
                        "the centre of mass")
    s.add_argument("--cyclic", action="store_true",
                   help="the clip is one cycle whose last frame closes it (automatic for DeepMimic loops)")
    s.add_argument("--out", required=True, metavar="EST.csv", help="output CSV")
    s.set_defaults(func=cmd_grf)

    s = add_command(sub, "grf-compare", "compare a grf estimate with measured force plates (Table 4.1)", """\
Compare a `motionx grf` estimate with the trial's force plates (an OpenSim GRF .mot or the
C3D's plates): the thesis's Table 4.1 (RMS, max and relative RMS of fx, fy, fz, the free
moment, CoP distance) over every frame with complete plates and over double support. The
plot shows the curves in the CSV's frame and units (the input's).""")
    s.add_argument("--estimate", required=True, metavar="EST.csv", help="CSV written by motionx grf")
    s.add_argument("--grf", metavar="GRF.mot", help="OpenSim force-plate file (or --c3d)")
    s.add_argument("--external-loads", metavar="X.xml",
                   help="OpenSim ExternalLoads file for --grf (default: feet from the column names)")
    s.add_argument("--c3d", metavar="FILE.c3d", help="C3D trial with force plates (or --grf)")
    s.add_argument("--mass", type=float, default=None, metavar="KG",
                   help="subject mass in kg for a C3D that does not state it (default: from the file)")
    s.add_argument("--markers", metavar="MAP", default=None,
                   help="C3D marker mapping, as for motionx grf (default: roles detected from the labels)")
    s.add_argument("--plot", metavar="OUT.png", help="write estimated vs measured curves (default: no plot)")
    s.add_argument("--json", metavar="OUT.json", help="write the metrics as JSON (default: tables on stdout only)")
    s.set_defaults(func=cmd_grf_compare)
