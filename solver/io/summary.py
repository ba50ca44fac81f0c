"""What an imported trial looks like, in a few numbers a user can check at once.

:func:`describe` (JSON-ready): the subject mass used and where it comes from, the mass the
force plates imply (:mod:`solver.io.mass`) and a warning when the two differ by more than
5 %, the marker fit error (OpenSim inverse kinematics of a ``.trc``; a C3D trial's own markers
registered on the fitted skeleton), the fit's verdict (``solver.io.fit_quality``) and the landmark
fit error of our capture skeleton, and the contact schedule as stance intervals per foot (s).
``motionx grf``, ``motionx tutor`` and the upload response print it.
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from typing import Any

import numpy as np

from solver.gait import detect_contacts, gait_events
from solver.io.mass import implied_mass, mass_warning, stride_from_events

log = logging.getLogger(__name__)


def stance_intervals(contacts: np.ndarray, times: np.ndarray, sides: tuple[str, ...]) -> dict[str, list[list[float]]]:
    """Per foot, the [start, end] times (s) of each run of contact (any of the foot's points).

    ``contacts`` (P, T) with ``sides[i]`` the foot of row i. A run touching the clip's first
    or last frame starts or ends there (its true start/end is not observed)."""
    c = np.asarray(contacts, dtype=bool)
    t = np.asarray(times, dtype=float)
    out: dict[str, list[list[float]]] = {}
    for side in ("right", "left"):
        rows = [i for i, s in enumerate(sides) if s == side]
        foot = np.any(c[rows], axis=0) if rows else np.zeros(t.size, bool)
        d = np.diff(np.concatenate([[0], foot.astype(int), [0]]))
        starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
        out[side] = [[round(float(t[a]), 4), round(float(t[b]), 4)] for a, b in zip(starts, ends)]
    return out


def _round(d: Mapping[str, Any] | None, nd: int = 2) -> dict[str, Any] | None:
    if d is None:
        return None
    return {k: (round(float(v), nd) if isinstance(v, (int, float, np.floating)) else v) for k, v in d.items()}


def describe(capture: Any, *, contacts: np.ndarray | None = None, contacts_from: str | None = None) -> dict[str, Any]:
    """A short description of ``capture`` (see the module doc).

    ``contacts``: the (P, T) contact schedule used downstream (rows = the character's contact
    points); by default the capture's own (plates) or one detected from the kinematics.
    """
    src = dict(capture.source or {})
    fit = dict(src.get("fit") or {})
    ch = capture.character
    sides = tuple(p.side for p in ch.contacts)
    out: dict[str, Any] = {
        "format": src.get("format"),
        "frames": int(capture.T),
        "fps": round(float(capture.fps), 4) if capture.T > 1 else None,
        "duration_s": round(float(capture.times[-1] - capture.times[0]), 4),
        "mass_kg": round(float(ch.total_mass), 2),
        "mass_from": src.get("mass_from") or fit.get("masses_from"),
    }
    if src.get("model_mass_kg") is not None:
        out["model_mass_kg"] = round(float(src["model_mass_kg"]), 2)
    # contact schedule
    how = contacts_from
    if contacts is None:
        if capture.contacts is not None:
            contacts, how = capture.contacts, how or "importer"
        else:
            try:
                contacts, how = detect_contacts(ch, capture.q, capture.fps), "kinematics"
            except ValueError as e:  # e.g. a treadmill walk without its belt speed
                out["stance_error"] = str(e)
    stride = None
    if contacts is not None:
        contacts = np.asarray(contacts, dtype=bool)
        out["contacts_from"] = how
        out["stances"] = stance_intervals(contacts, capture.times, sides)
        rows = [[i for i, s in enumerate(sides) if s == side] for side in ("right", "left")]
        if contacts.shape[0] == len(sides) and all(rows):
            feet = [np.any(contacts[r], axis=0) for r in rows]
            stride = stride_from_events(gait_events(np.stack([feet[0], feet[0], feet[1], feet[1]]), capture.times))
    # implied mass: the reader's (OpenSim: at the plates' own rate; C3D: its own stride/stance
    # figure) or from the measured reactions on the capture's times
    implied: dict | None = src.get("implied_mass")
    if implied is None and src.get("mass_implied_kg") is not None:
        implied = {"kg": float(src["mass_implied_kg"]), "method": src.get("mass_implied_from")}
    if implied is None and capture.measured is not None:
        im = implied_mass(capture.times, np.asarray(capture.measured.force)[:, 2], stride_s=stride)
        implied = im.as_dict() if im is not None else None
    if implied is not None:
        out["mass_implied_kg"] = round(float(implied["kg"]), 2)
        out["mass_implied"] = implied
        warn = src.get("mass_warning") or mass_warning(float(ch.total_mass), float(implied["kg"]))
        if warn:
            out["mass_warning"] = warn
    elif capture.measured is not None:
        out["mass_implied_kg"] = None
        out["mass_implied_note"] = "the plates hold neither a whole cycle nor one complete stance per foot"
    # fit errors
    if src.get("ik"):
        out["marker_fit_error_mm"] = _round(src["ik"].get("marker_error_mm"), 1)
        out["marker_fit"] = "OpenSim inverse kinematics of " + str(src["ik"].get("trc", "the .trc")).rsplit("/", 1)[-1]
    elif src.get("marker_error_mm") is not None:
        out["marker_fit_error_mm"] = _round(src.get("marker_error_mm"), 1)
    elif fit.get("marker_error_mm") is not None:  # C3D: the file's markers on the fitted skeleton
        out["marker_fit_error_mm"] = _round(fit["marker_error_mm"], 1)
        out["marker_fit"] = "the file's markers registered on the fitted skeleton"
    if fit.get("verdict") is not None:
        out["fit_verdict"] = dict(fit["verdict"])
    if fit.get("landmark_error_mm") is not None:
        out["landmark_fit_error_mm"] = _round(fit["landmark_error_mm"], 2)
    if src.get("ignored_columns"):
        out["ignored_columns"] = dict(src["ignored_columns"])
    if isinstance(src.get("marker_set"), Mapping):  # C3D: the marker set detected, the upper body's origin
        out["marker_set"] = src["marker_set"].get("name")
    if src.get("upper_body"):
        out["upper_body"] = dict(src["upper_body"])
    return out
