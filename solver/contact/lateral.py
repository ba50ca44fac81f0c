"""The lateral force of the total, from the centre of mass low-passed across the walk.

The total ground force is the body's mass times its centre-of-mass acceleration (less gravity).
Across the walking direction that acceleration is a step-frequency sway: on the shared trials
the plates' lateral force has almost no power above ~4 Hz outside the heel-strike transients,
while the lateral acceleration of the kinematics' centre of mass, filtered with the joint angles
at 6 Hz, carries 4-8 Hz oscillation of the pelvis and trunk (skin-marker wobble, the filter's
response to the impacts) that the plates do not show (docs/grf.md). ``lateral_correction`` takes
the centre of mass's lateral coordinate (across the mean progression direction), low-passes it
at ``lateral_hz`` (the kinematics' zero-phase Butterworth), differentiates it as the estimator
differentiates the coordinates, and returns the force that makes the total's lateral force
``M · ÿ_com`` — applied *at the centre of mass* (a pure force there: the angular-momentum part of
the total, and so its free moment and the CoP's forward position, are untouched).
"""

from __future__ import annotations

import numpy as np

from solver.contact.common import _derivatives
from solver.filtering import zero_phase_lowpass


def _lowpass(x: np.ndarray, fps: float, cutoff_hz: float, cyclic: bool) -> np.ndarray:
    """Zero-phase 2nd-order Butterworth forwards and backwards (the kinematics' filter, odd extension over
    3 periods of the cut-off; a cyclic signal x[-1] = x[0] + offset filtered as the periodic signal)."""
    return zero_phase_lowpass(x, fps, cutoff_hz, order=2, cyclic=cyclic)


MAX_TURN_DEG = 30.0  # a walk whose heading turns more than this has no single lateral axis


def heading_change(com: np.ndarray) -> float:
    """Degrees the centre of mass's horizontal heading turns from the clip's first quarter to its last
    (chords over each quarter; 0 when it hardly moves)."""
    T = com.shape[1]
    k = max(1, T // 4)
    a, b = com[:2, k] - com[:2, 0], com[:2, -1] - com[:2, -1 - k]
    if not (np.hypot(*a) > 0.02 and np.hypot(*b) > 0.02):
        return 0.0
    return float(np.degrees(np.arctan2(a[0] * b[1] - a[1] * b[0], a @ b)))


def lateral_axis(com: np.ndarray) -> np.ndarray | None:
    """Unit horizontal vector across the mean progression (z × the mean horizontal COM velocity); world y
    when the centre of mass hardly progresses (in place); None when the walk turns (more than
    ``MAX_TURN_DEG``: no single axis is lateral throughout)."""
    d = np.asarray(com[:2, -1] - com[:2, 0], dtype=float)
    n = float(np.hypot(*d))
    if not n > 0.05:  # < 5 cm over the whole clip: no progression to speak of
        return np.array([0.0, 1.0, 0.0])
    if abs(heading_change(com)) > MAX_TURN_DEG:
        return None
    return np.array([-d[1] / n, d[0] / n, 0.0])


def lateral_correction(com: np.ndarray, total_force: np.ndarray, mass: float, fps: float, lateral_hz: float,
                       cyclic: bool) -> tuple[np.ndarray, np.ndarray] | None:
    """The force (3, N) to add at the centre of mass at the estimator's frames so that the total's lateral
    force is the low-passed centre of mass's, and the lateral axis (3,); None for a turning walk.

    ``com`` (3, T) the centre of mass at every frame of the (filtered) motion, ``total_force`` (3, N) the
    total ground force at the estimator's frames (those of ``_derivatives``)."""
    e = lateral_axis(com)
    if e is None:
        return None
    y = e @ com  # (T,) lateral coordinate
    yf = _lowpass(y, fps, lateral_hz, cyclic)
    _, _, ydd = _derivatives(yf[None, :], 1.0 / fps, cyclic)
    want = mass * ydd[0]  # gravity has no lateral component
    have = e @ total_force
    return np.outer(e, want - have), e
