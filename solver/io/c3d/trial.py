"""The C3D reader: a trial's track (landmarks, plates, contacts) and the fitted capture."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from solver.capture import Capture, GroundFrame
from solver.io.c3d.axes import _axes_text, _detect_axes
from solver.io.c3d.events import _feet_and_plates
from solver.io.c3d.landmarks import _height_estimate, _landmarks
from solver.io.c3d.markers import _Markers, parse_mapping, required_markers, role_segment
from solver.io.c3d.plates import PlateSignal, _plate_signals, _plate_specs
from solver.io.c3d.reader import FEET, C3DError, G, _mid, _param, _read_raw, _strings, _subject_params, fill_gaps
from solver.io.fit import fit_track
from solver.io.mass import implied_mass, mass_warning
from solver.io.readers import one_file
from solver.io.track import SkeletonTrack, TrackMarker

log = logging.getLogger("solver.io.c3d")


# ----------------------------------------------------------------------------------------
# the reader


@dataclass(frozen=True, eq=False)
class C3DTrial:
    """Everything read from a C3D file: the track and the plates' analog-rate signals."""

    track: SkeletonTrack
    plates: tuple[PlateSignal, ...]


def read_c3d_trial(path: str | Path, *, mass: float | None = None, require_plates: bool = True,
                   max_gap_s: float = 0.1, fz_threshold: float = 20.0,
                   markers: str | Path | Mapping[str, str] | None = None) -> C3DTrial:
    """Read a C3D trial: see the module docstring. ``max_gap_s``: longest marker gap filled;
    ``markers``: a mapping from Plug-in Gait roles to the file's labels (a dict, ``"LASI=a,RASI=b"``
    or a mapping file; :func:`solver.io.c3d.markers.parse_mapping`) for marker sets the reader
    does not recognise."""
    path = Path(path)
    raw = _read_raw(path)
    name = path.name
    T_all = raw.points.shape[2]
    if T_all < 10:
        raise C3DError(f"{name}: only {T_all} marker frames")
    mk = _Markers(raw, parse_mapping(markers))
    required = required_markers(mk)
    sp = _subject_params(raw.params)
    specs = _plate_specs(raw)
    if not specs and require_plates:
        raise C3DError(f"{name}: no force plates (FORCE_PLATFORM:USED is 0 or missing); "
                       "pass require_plates=False to read the kinematics alone")
    # pelvis markers first: they decide the walking direction
    roles = {}
    for role in ("ASI", "PSI"):
        right, left = (mk.find(role, s) for s in ("R", "L"))
        if right and left:
            roles[role] = _mid(mk.get(right), mk.get(left))
    if "PSI" not in roles and mk.find("SACR") is not None:
        roles["PSI"] = mk.get(mk.find("SACR"))  # type: ignore[arg-type]
    R, floor, axes_info = _detect_axes(raw, mk, specs, roles)
    # frames where every required lower-body marker is seen (after short-gap filling)
    max_gap = max(int(round(max_gap_s * raw.point_rate)), 1)
    good = np.ones(T_all, dtype=bool)
    for lbl in required:
        x, gaps = fill_gaps(mk.get(lbl), max_gap)
        interior = [(a, b) for a, b in gaps if a > 0 and b < T_all]
        if interior:
            a, b = interior[0]
            raise C3DError(f"{name}: marker {lbl} has a gap of {b - a} frames ({(b - a) / raw.point_rate:.2f} s "
                           f"> {max_gap_s} s) at {a / raw.point_rate:.2f}-{(b - 1) / raw.point_rate:.2f} s")
        good &= np.isfinite(x).all(axis=0)
    if not good.any():
        raise C3DError(f"{name}: the required markers are never all visible together")
    idx = np.nonzero(good)[0]
    first, last = int(idx[0]), int(idx[-1]) + 1
    if (last - first) / raw.point_rate < 0.5:
        raise C3DError(f"{name}: only {(last - first) / raw.point_rate:.2f} s with every required marker")
    if first > 0 or last < T_all:
        log.warning("%s: frames %d-%d kept (required markers missing at the ends)", name, first, last - 1)
    frames = slice(first, last)
    times = np.arange(first, last) / raw.point_rate
    # height estimate (only for defaults when the file has none)
    height_est = _height_estimate(mk, R, floor, sp)
    built = _landmarks(mk, R, floor, sp, height_est, frames, max_gap, name, raw.point_rate)
    lm = built.landmarks
    frame = GroundFrame(R=R.T, offset=R[2] * floor, unit_m=raw.unit_m,
                        axes=_axes_text(R))
    source: dict[str, Any] = {
        "format": "c3d", "path": str(path), "first_frame": raw.first_frame + first,
        "point_rate": raw.point_rate, "analog_rate": raw.analog_rate, "point_unit_m": raw.unit_m,
        "frames_kept": (first, last), "axes": axes_info, "floor_m": floor, "markers": built.markers_used,
        "marker_set": mk.marker_set, "upper_body": built.upper_body,
        "notes": mk.notes + built.notes, "height_estimate_m": height_est,
        "manufacturer": _strings(_param(raw.params, "MANUFACTURER", "COMPANY"))[:1],
    }
    measured = contacts = None
    plates: tuple[PlateSignal, ...] = ()
    if specs:
        sigs = _plate_signals(raw, specs, R, floor, fz_threshold)
        feet, assigned = _feet_and_plates(sigs, lm, times, raw.point_rate, raw.analog_rate, name)
        measured, contacts, plates = feet.measured, feet.contacts, tuple(assigned)
        source["plates"] = [
            {"index": s.index, "type": s.type, "peak_vertical_N": s.peak_vertical,
             "periods": [list(p) for p in s.periods], "zero": s.baseline} for s in plates
        ]
        source["gait_events"] = feet.events
        if not any(p[2] in FEET for s in plates for p in s.periods):
            log.warning("%s: no foot lands on a force plate", name)
    # subject mass: argument, file, what the plates imply (solver.io.mass: whole cycles of complete
    # plates, else one whole stance of each foot over the stride time of the gait events)
    implied = None
    if measured is not None:

        strikes = [feet.events[f]["foot_strike"] for f in FEET]
        strides = [b - a for s in strikes for a, b in zip(s[:-1], s[1:])]
        implied = implied_mass(times, measured.force[:, 2], threshold=fz_threshold,
                               stride_s=float(np.median(strides)) if strides else None)
    if mass is not None:
        m, how = float(mass), "argument"
    elif sp.mass is not None:
        m, how = sp.mass, "file"
    elif implied is not None:
        m, how = implied.kg, f"plates: {implied.method} over a {implied.cycle_s:.3f} s stride"
    else:
        raise C3DError(f"{name}: subject mass unknown: the file has no PROCESSING:Bodymass and the plates "
                       "measure neither a whole cycle nor one whole stance of each foot",
                       parameter="mass", unit="kg")
    if not 5.0 <= m <= 400.0:
        raise C3DError(f"{name}: implausible subject mass {m:g} kg")
    source["mass_from"] = how
    if implied is not None:

        source["implied_mass"] = implied.as_dict()
        source["mass_implied_kg"] = round(float(implied.kg), 2)
        source["mass_implied_from"] = implied.method
        warn = mass_warning(m, implied)
        if warn:
            source["mass_warning"] = warn
            log.info("%s: %s (mass from the %s; pass mass=... to choose)", name, warn, how)  # shown by the front ends
    if measured is not None:
        peak = float(np.max(measured.force[:, 2].sum(axis=0)))
        if not 0.5 * m * G < peak < 5.0 * m * G:
            log.warning("%s: peak vertical plate force %.0f N is %.2f body weights", name, peak, peak / (m * G))
    track = SkeletonTrack(
        times=times, landmarks=lm, orientations=built.orientations, frame=frame, mass=m,
        height=sp.height, measured=measured, contacts=contacts, source=source,
        markers={lbl: TrackMarker(role_segment(key), built.marker_xyz[lbl], key)
                 for key, lbl in built.markers_used.items()},
    )
    return C3DTrial(track=track, plates=plates)



def trial_files(paths: list[Path]) -> dict[str, Path]:
    """A C3D trial is one ``.c3d`` file (the reader registry's ``trial_files``)."""
    return {"path": one_file(paths, ".c3d")}


def read_c3d(path: str | Path, *, mass: float | None = None, require_plates: bool = True,
             max_gap_s: float = 0.1, fz_threshold: float = 20.0,
             markers: str | Path | Mapping[str, str] | None = None) -> SkeletonTrack:
    """Landmarks, measured ground reactions and contacts of a C3D trial, in our frame."""
    return read_c3d_trial(path, mass=mass, require_plates=require_plates, max_gap_s=max_gap_s,
                          fz_threshold=fz_threshold, markers=markers).track


def load_c3d(path: str | Path, *, mass: float | None = None, require_plates: bool = True,
             max_gap_s: float = 0.1, fz_threshold: float = 20.0,
             markers: str | Path | Mapping[str, str] | None = None, **fit_options: Any) -> Capture:
    """The capture of a C3D trial: ``fit_track(read_c3d(path, ...), **fit_options)``
    (``fit_options``: e.g. ``lower_only``, ``orientation_weight``; see ``solver.io.fit``)."""

    track = read_c3d(path, mass=mass, require_plates=require_plates, max_gap_s=max_gap_s,
                     fz_threshold=fz_threshold, markers=markers)
    return fit_track(track, **fit_options)

