"""The one low-pass filter of the project: a zero-phase Butterworth (``scipy.signal.sosfiltfilt``).

Used by gait processing (:func:`solver.gait.lowpass`: contact detection, force-plate records)
and by contact estimation (the kinematics before differentiation, the centre of mass's lateral
force). Callers validate their inputs and raise their own error type; this module is the
numerics only.

End effects (``edge``): ``"filter"`` extends the signal by odd reflection over
``3·(2·sections + 1)`` samples (scipy's default length); ``"cutoff"`` over 3 periods of the
cut-off, ``3·fps/cutoff`` samples, after which the filter's transient has died out (scipy's
default leaves a transient that corrupts accelerations near the ends). A ``cyclic`` signal
(last sample = first sample one period later, plus a constant offset) is filtered as the
periodic signal it is.
"""

from __future__ import annotations

import math
from functools import lru_cache
from typing import Literal

import numpy as np


@lru_cache(maxsize=32)
def butter_sos(order: int, cutoff_hz: float, fps: float) -> np.ndarray:
    """Second-order sections of an ``order`` Butterworth low-pass (one way)."""
    from scipy.signal import butter  # scipy.signal costs ~0.3 s to import: only when filtering

    return butter(order, cutoff_hz, btype="low", fs=fps, output="sos")


def zero_phase_lowpass(x: np.ndarray, fps: float, cutoff_hz: float, *, order: int, axis: int = -1,
                       cyclic: bool = False, edge: Literal["filter", "cutoff"] = "cutoff",
                       padlen: int | None = None) -> np.ndarray:
    """``x`` low-passed forwards and backwards along ``axis`` (twice the attenuation of ``order``,
    no phase lag); see the module docstring for ``edge`` and ``cyclic`` (``padlen``: the odd
    extension's length, instead of ``edge``'s)."""
    from scipy.signal import sosfiltfilt  # as above

    sos = butter_sos(int(order), float(cutoff_hz), float(fps))
    x = np.moveaxis(np.asarray(x, dtype=float), axis, -1)
    T = x.shape[-1]
    if cyclic:
        P = T - 1
        offset = x[..., -1:] - x[..., :1]
        reps = max(3, 2 * int(math.ceil(3 * fps / cutoff_hz / P)) + 1)
        k0 = reps // 2
        ext = np.concatenate([x[..., :P] + (k - k0) * offset for k in range(reps)], axis=-1)
        out = sosfiltfilt(sos, ext, axis=-1, padtype=None)
        y = np.concatenate([out[..., k0 * P:(k0 + 1) * P], out[..., k0 * P:k0 * P + 1] + offset], axis=-1)
    else:
        if padlen is not None:
            pass
        elif edge == "filter":
            padlen = min(3 * (2 * len(sos) + 1), T - 1)
        else:
            padlen = min(T - 1, int(math.ceil(3 * fps / cutoff_hz)))
        y = sosfiltfilt(sos, x, axis=-1, padtype="odd", padlen=padlen)
    return np.moveaxis(y, -1, axis)
