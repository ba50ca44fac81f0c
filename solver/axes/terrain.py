"""Stairs (m, + up): the ground under each successive stance raised by the riser height v
(``Environment.step_height_m``; ``solver.environment.stair_heights``: the stances of a cycle
stand on treads 0, 1, …, so a cycle of two steps climbs 2 v). The NLP holds each contact at
its tread's height (a per-contact, per-frame ground parameter), takes the wrenches about
reference points on the treads, and lets root z gain the cycle's rise (the problem is built
with ``rising=True``). Guide: the root raised along a ramp of the cycle's rise (two steps)."""

from __future__ import annotations

import numpy as np

from solver.axes.base import Axis, register

#: steps per gait cycle assumed by the guide's ramp (a cycle is a stride: two steps)
STEPS_PER_CYCLE = 2


def raise_root(q: np.ndarray, riser: float) -> np.ndarray:
    """The guide with its root z raised linearly by STEPS_PER_CYCLE × riser over the cycle
    (frames 0 … T−2), continuing into the overlap frame T−1."""
    out = np.array(q, dtype=float, copy=True)
    T = out.shape[1]
    out[2] += STEPS_PER_CYCLE * riser * np.arange(T) / (T - 2)
    return out


STEP_HEIGHT = register(Axis(
    name="step_height_m", unit="m", doc="stairs: riser height under each successive stance, positive = up (m)",
    lo=-0.3, hi=0.3, default=0.0, label="step", cli="--step-height", metavar="M", order=5, grid=False,
    environment=lambda env, v: env.with_(step_height_m=v), guide=raise_root, words="step {} m"))
