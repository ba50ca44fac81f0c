"""Trials: low-pass the kinematics, take the contact schedule, estimate."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from solver.character import Character
from solver.contact.common import ContactError, ContactEstimate
from solver.contact.estimator import estimate_contact_wrenches
from solver.filtering import zero_phase_lowpass
from solver.gait import contacts_from_plates, detect_contacts
from solver.gait.base import unwrap_hinges
from solver.motion import foot_schedule_of

log = logging.getLogger("solver.contact")

# --- trials: filter, schedule, estimate -----------------------------------------------------

DEFAULT_CUTOFF_HZ = 6.0  # Winter, Biomechanics and Motor Control of Human Movement: gait kinematics
# the centre of mass across the walk (the lateral force), solver.contact.lateral; docs/grf.md: 3-5 Hz all
# lower the lateral error on the three trials whose 6 Hz lateral force rings, 4 Hz the most over the four
DEFAULT_LATERAL_HZ = 4.0
CONTACT_SOURCES = ("auto", "kinematics", "plates")


def lowpass_kinematics(character: Character, q: np.ndarray, fps: float, cutoff_hz: float = DEFAULT_CUTOFF_HZ,
                       *, cyclic: bool = False, order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth low-pass of every coordinate before differentiation.

    Hinge angles are unwrapped first. ``order`` 2 run forwards and backwards gives the
    classic 4th-order zero-lag filter of gait biomechanics. End effects: the signal is
    extended by odd reflection over 3 periods of the cut-off (``3·fps/cutoff`` samples,
    the filter's transient has died out by then; scipy's default of a few samples leaves
    a transient that corrupts accelerations near the ends). A cyclic motion (last frame =
    first frame one period later) is filtered as the periodic signal it is.
    """
    if not (math.isfinite(cutoff_hz) and 0 < cutoff_hz < fps / 2):
        raise ContactError(f"low-pass cut-off {cutoff_hz} Hz must lie in (0, fps/2 = {fps / 2:g} Hz)")
    return zero_phase_lowpass(unwrap_hinges(character, q), fps, cutoff_hz, order=order, axis=1, cyclic=cyclic)


def foot_schedule(contacts: np.ndarray, character: Character) -> np.ndarray:
    """(P, T) contact-point schedule -> (2, T) foot schedule (right, left): any point of the foot."""
    c = np.asarray(contacts, dtype=bool)
    if c.ndim != 2 or c.shape[0] != len(character.contacts):
        raise ContactError(f"contact schedule must have one row per contact point "
                           f"({len(character.contacts)}), got shape {c.shape}")
    return foot_schedule_of(character, c)


@dataclass(frozen=True, eq=False)
class TrialEstimate:
    """A capture's estimated ground reactions with what produced them."""

    estimate: ContactEstimate
    times: np.ndarray  # (T,) the capture's times (s)
    q: np.ndarray  # (n, T) the filtered coordinates that were differentiated
    contacts: np.ndarray  # (P, T) contact-point schedule used
    contacts_from: str  # "plates", "importer", "kinematics", "given"
    cutoff_hz: float | None


def estimate_capture(
    capture: Any,
    *,
    cutoff_hz: float | None = DEFAULT_CUTOFF_HZ,
    contacts: str | np.ndarray = "auto",
    cyclic: bool | None = None,
    smoothing_hz: float | str | None = "cutoff",
    project_cop: bool = True,
    lateral_hz: float | str | None = "default",
    **options: Any,
) -> TrialEstimate:
    """Filter a capture's kinematics, get its contact schedule, estimate its ground reactions.

    ``cutoff_hz``: low-pass cut-off (6 Hz, the same for every trial; ``None`` = no filter).
    ``smoothing_hz``: the temporal prior on the double-support split
    (:func:`estimate_contact_wrenches`); ``"cutoff"`` (default) = the kinematics' own
    cut-off — the split gets no frequency the filtered kinematics do not have — with
    ``method="qp"``, none with the nested reference form or without a filter; ``None`` = one
    QP per frame (the thesis). ``project_cop``: single-support CoPs outside the foot's
    contact polygon moved into it (default; ``False``: the foot takes c exactly, the thesis).
    ``contacts``: ``"kinematics"`` (:func:`solver.gait.detect_contacts` on the
    filtered motion), ``"plates"`` (force-plate loading, kinematics where the plates are
    incomplete; needs ``capture.measured``), ``"auto"`` (the importer's schedule when it has
    one — from plates —, else the plates, else kinematics) or a (P, T) array.
    ``lateral_hz``: the total's lateral force taken from the centre of mass low-passed at this cut-off
    (:mod:`solver.contact.lateral`); ``"default"`` = ``DEFAULT_LATERAL_HZ`` (4 Hz) when it lies below the
    kinematics' cut-off (none without a filter or with a cut-off at or under it); ``None`` = off.
    ``cyclic``: ``None`` = the capture's ``source["loop"] == "wrap"``. Other options go to
    :func:`estimate_contact_wrenches`.
    """
    ch = capture.character
    q, fps = np.asarray(capture.q, dtype=float), float(capture.fps)
    if q.shape[0] != ch.n:
        raise ContactError(f"model/motion mismatch: character {ch.name!r} has {ch.n} coordinates, "
                           f"the motion has {q.shape[0]} rows")
    bad = ~np.isfinite(q)
    if bad.any():
        i, t = np.argwhere(bad)[0]
        raise ContactError(f"coordinate {ch.coordinate_names[i]!r} is not finite (NaN/inf) at frame {t}")
    if cyclic is None:
        cyclic = capture.source.get("loop") == "wrap"
    dt = np.diff(capture.times)
    if capture.T > 2 and np.max(np.abs(dt - np.median(dt))) > 0.01 * np.median(dt):
        raise ContactError("the capture is not uniformly sampled; resample it first (solver.gait.resample)")
    qf = q if cutoff_hz is None else lowpass_kinematics(ch, q, fps, cutoff_hz, cyclic=cyclic)
    if isinstance(contacts, str):
        if contacts not in CONTACT_SOURCES:
            raise ContactError(f"contacts must be one of {CONTACT_SOURCES} or an array, got {contacts!r}")
        how = contacts
        if how == "auto":
            how = "importer" if capture.contacts is not None else ("plates" if capture.measured is not None
                                                                     else "kinematics")
        if how == "importer":
            sched = np.asarray(capture.contacts, dtype=bool)
        elif how == "plates":
            if capture.measured is None:
                raise ContactError("contacts='plates' but the capture has no measured ground reactions")
            sched = contacts_from_plates(capture.measured, character=ch, q=qf, fps=fps)
        else:
            sched = detect_contacts(ch, qf, fps)
    else:
        how, sched = "given", np.asarray(contacts, dtype=bool)
    if sched.shape != (len(ch.contacts), capture.T):
        raise ContactError(f"contact schedule must have shape ({len(ch.contacts)}, T={capture.T}), got {sched.shape}")
    if isinstance(smoothing_hz, str):
        if smoothing_hz != "cutoff":
            raise ContactError(f"smoothing_hz must be a frequency (Hz), 'cutoff' or None, got {smoothing_hz!r}")
        smoothing_hz = cutoff_hz if options.get("method", "qp") == "qp" else None
    if isinstance(lateral_hz, str):
        if lateral_hz != "default":
            raise ContactError(f"lateral_hz must be a frequency (Hz), 'default' or None, got {lateral_hz!r}")
        lateral_hz = DEFAULT_LATERAL_HZ if cutoff_hz is not None and cutoff_hz > DEFAULT_LATERAL_HZ else None
    est = estimate_contact_wrenches(ch, qf, fps, foot_schedule(sched, ch), cyclic=cyclic, smoothing_hz=smoothing_hz,
                                    project_cop=project_cop, lateral_hz=lateral_hz, **options)
    return TrialEstimate(estimate=est, times=np.asarray(capture.times, dtype=float), q=qf, contacts=sched,
                         contacts_from=how, cutoff_hz=cutoff_hz)

