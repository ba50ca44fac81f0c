"""Gait processing's shared pieces: its error, the validated low-pass, resampling.

Gait processing (this package) is domain logic on a :class:`solver.capture.Capture`: contact
detection and gait events (:mod:`solver.gait.contacts`), cycle extraction
(:mod:`solver.gait.cycles`). Readers (solver/io/) call it; it never reads files.
"""

from __future__ import annotations

import numpy as np

from solver.capture import Capture, MeasuredGRF
from solver.character import Character
from solver.errors import InputError
from solver.filtering import zero_phase_lowpass


class GaitError(InputError):
    """A trial cannot be processed as asked (too short, a foot never on the ground, ...); the
    message says why."""



def lowpass(x: np.ndarray, fps: float, cutoff_hz: float, *, order: int = 4, axis: int = -1) -> np.ndarray:
    """Zero-phase Butterworth low-pass (:func:`solver.filtering.zero_phase_lowpass`, scipy's
    default edge padding).

    ``order`` is the order of the one-way filter (the zero-phase result has twice the
    attenuation, no phase lag). NaN is refused (fill gaps first).
    """
    x = np.asarray(x, dtype=float)
    if not (np.isfinite(fps) and fps > 0):
        raise GaitError(f"lowpass: fps must be positive, got {fps}")
    if not (np.isfinite(cutoff_hz) and 0 < cutoff_hz < fps / 2):
        raise GaitError(f"lowpass: cutoff {cutoff_hz} Hz must lie in (0, fps/2 = {fps / 2} Hz)")
    if np.any(~np.isfinite(x)):
        raise GaitError("lowpass: the signal contains NaN/inf (fill the gaps first)")
    if x.shape[axis] < 4:
        raise GaitError(f"lowpass: at least 4 samples are needed, got {x.shape[axis]}")
    return zero_phase_lowpass(x, fps, cutoff_hz, order=order, axis=axis, edge="filter")


def unwrap_hinges(character: Character, q: np.ndarray) -> np.ndarray:
    """A copy of ``q`` (n, T) with every hinge angle made continuous (no 2π jumps)."""
    q = np.array(q, dtype=float, copy=True)
    for i, k in enumerate(character.dof_kinds):
        if k == "hinge":
            q[i] = np.unwrap(q[i])
    return q


def resample(capture: Capture, fps: float, *, start: float | None = None) -> Capture:
    """The capture sampled at ``fps`` from its first time (or ``start``, a time within the
    capture) to its last (cubic spline).

    Hinge angles are unwrapped first (continuous), so values at times common to both grids
    are preserved exactly. Contact schedules take the nearest sample; measured GRF is
    interpolated linearly (``valid`` where both neighbours are valid).
    """
    from scipy.interpolate import CubicSpline  # lazy: scipy.interpolate costs ~0.4 s to import

    if not (np.isfinite(fps) and fps > 0):
        raise GaitError(f"resample: fps must be a positive number, got {fps}")
    t = capture.times
    if capture.T < 2:
        raise GaitError("resample: the capture has fewer than 2 frames")
    t_first = t[0] if start is None else float(start)
    if not (t[0] - 1e-9 <= t_first <= t[-1]):
        raise GaitError(f"resample: start {t_first} s is outside the capture ({t[0]:.3f} .. {t[-1]:.3f} s)")
    n = int(np.floor((t[-1] - t_first) * fps + 0.01)) + 1  # a last frame within 1 % of a step is kept
    if n < 2:
        raise GaitError(f"resample: {t[-1] - t_first:.3f} s at {fps} fps gives fewer than 2 frames")
    tn = t_first + np.arange(n) / fps
    tn = np.minimum(tn, t[-1])
    q = unwrap_hinges(capture.character, capture.q)
    qn = CubicSpline(t, q, axis=1)(tn) if capture.T >= 4 else np.stack([np.interp(tn, t, r) for r in q])
    contacts = None
    idx = np.clip(np.searchsorted(t, tn), 1, len(t) - 1)
    nearest = np.where(np.abs(t[idx - 1] - tn) <= np.abs(t[idx] - tn), idx - 1, idx)
    if capture.contacts is not None:
        contacts = capture.contacts[:, nearest]
    measured = None
    if capture.measured is not None:
        m = capture.measured

        def li(a: np.ndarray) -> np.ndarray:
            flat = a.reshape(-1, a.shape[-1])
            return np.stack([np.interp(tn, t, r) for r in flat]).reshape(a.shape[:-1] + (n,))

        lo = np.clip(np.searchsorted(t, tn, side="right") - 1, 0, len(t) - 1)
        hi = np.clip(lo + 1, 0, len(t) - 1)
        exact = np.isclose(t[lo], tn, atol=1e-9)
        valid = m.valid[lo] & (exact | m.valid[hi])
        measured = MeasuredGRF(force=li(m.force), cop=li(m.cop), free_moment=li(m.free_moment), valid=valid,
                               source=m.source)
    src = dict(capture.source)
    src["resampled_fps"] = float(fps)
    return capture.evolve(q=qn, times=tn, contacts=contacts, measured=measured, source=src)

