"""Walking speed relative to the capture's (×): speed = stride length × cadence.

Choice (documented in docs/continuation.md): a speed scale s splits equally between stride
length and cadence, stride ∝ s^0.5 and cadence ∝ s^0.5 — the square-root split of human
gait (stride length and cadence contribute about equally to speed changes around the
preferred speed). The frame count per cycle is kept: the frame interval becomes
h = h_tutor · s^−0.5 (an NLP parameter), the motion's frame rate fps_tutor · s^0.5, and the
guide's root path (x, y from its start, in the horizontal plane) is stretched by s^0.5.
"""

from __future__ import annotations

import numpy as np

from solver.axes.base import Axis, register

#: stride ∝ s^STRIDE_EXPONENT, cadence ∝ s^(1 − STRIDE_EXPONENT)
STRIDE_EXPONENT = 0.5


def stride_factor(s: float) -> float:
    return float(s) ** STRIDE_EXPONENT


def cadence_factor(s: float) -> float:
    return float(s) ** (1.0 - STRIDE_EXPONENT)


def stretch_stride(q: np.ndarray, factor: float) -> np.ndarray:
    """The guide with its root's horizontal displacement from frame 0 scaled by ``factor``
    (stride and lateral sway alike); heights and rotations unchanged."""
    out = np.array(q, dtype=float, copy=True)
    out[:2] = out[:2, :1] + factor * (out[:2] - out[:2, :1])
    return out


SPEED = register(Axis(
    name="speed_scale", unit="×", doc="walking speed relative to the capture's (stride and cadence × √s)",
    lo=0.5, hi=2.0, default=1.0, label="speed", cli="--speed-scale", metavar="S", order=0, grid=True,
    guide=lambda q, s: stretch_stride(q, stride_factor(s)),
    nlp=lambda s: {"frame_interval": 1.0 / cadence_factor(s)}, words="speed ×{}"))
