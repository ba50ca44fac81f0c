"""Stairs: the rise (m, + up) and the going (tread depth, m) of a flight of stairs along the
walker's direction of travel, one tread per step (``solver.environment.stair_flight``).

``step_height_m`` v: the ground under each successive stance raised by v
(``Environment.step_height_m``; ``solver.environment.stair_heights``: the stances of a cycle stand
on treads 0, 1, …, so a cycle of two steps climbs 2 v). The NLP holds each contact at its tread's
height (a per-contact, per-frame ground parameter), takes the wrenches about reference points on
the treads, lets root z gain the cycle's rise (the problem is built with ``rising=True``), keeps
each stance foot on its tread and each swinging foot clear of the nosings it passes
(``solver.spacetime.stairs``). Guide: the root raised along a ramp of the cycle's rise.

``step_going_m`` g: the treads' depth. Its value at the tutor is the walker's own step (the
root's travel per cycle over the steps of the cycle: treads as far apart as level steps), so along
λ the going shortens linearly from the level step to g; the guide's stride follows (the root's
travel along the direction of travel scaled to one going per step) and the NLP holds the cycle's
travel to exactly (steps per cycle) × going along the flight. A stairs target without a going
gets ``DEFAULT_GOING_M`` (0.28 m, building codes: 0.25–0.30 m).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from solver.axes.base import Axis, Target, register
from solver.environment import DEFAULT_GOING_M, Environment, walker_going

#: steps per gait cycle assumed by the guide's ramp and stride (a cycle is a stride: two steps)
STEPS_PER_CYCLE = 2


def raise_root(q: np.ndarray, riser: float) -> np.ndarray:
    """The guide with its root z raised linearly by STEPS_PER_CYCLE × riser over the cycle
    (frames 0 … T−2), continuing into the overlap frame T−1."""
    out = np.array(q, dtype=float, copy=True)
    T = out.shape[1]
    out[2] += STEPS_PER_CYCLE * riser * np.arange(T) / (T - 2)
    return out


def shorten_stride(q: np.ndarray, going: float) -> np.ndarray:
    """The guide with its root's travel along the cycle's direction of travel (the chord from frame
    0 to frame T−2) scaled so that a cycle travels STEPS_PER_CYCLE × ``going``; the sway across
    the direction of travel, heights and rotations unchanged."""
    out = np.array(q, dtype=float, copy=True)
    T = out.shape[1]
    chord = out[:2, T - 2] - out[:2, 0]
    length = float(np.linalg.norm(chord))
    if length < 1e-9:
        raise ValueError("the guide does not travel: a flight of stairs needs a walk along a direction")
    u = chord / length
    d = out[:2] - out[:2, :1]
    along = u @ d
    out[:2] += np.outer(u, (STEPS_PER_CYCLE * going / length - 1.0) * along)
    return out


STEP_HEIGHT = register(Axis(
    name="step_height_m", unit="m", doc="stairs: riser height under each successive stance, positive = up (m)",
    lo=-0.3, hi=0.3, default=0.0, label="step", cli="--step-height", metavar="M", order=5, grid=False,
    environment=lambda env, v: env.with_(step_height_m=v), guide=raise_root, words="step {} m"))

STEP_GOING = register(Axis(
    name="step_going_m", unit="m",
    doc=f"stairs: going (tread depth along the walk) of each step, one tread per step (m; with a rise; "
        f"default {DEFAULT_GOING_M:g}, building codes 0.25-0.30)",
    lo=0.2, hi=1.0, default=None, label="going", cli="--step-going", metavar="M", order=4, grid=False,
    base_value=lambda env: env.step_going_m, environment=lambda env, v: env.with_(step_going_m=v),
    guide=lambda q, v: shorten_stride(q, v), words="going {} m", requires="step_height_m"))


def stairs_target(target: Target) -> Target:
    """The target with the stairs' default going (``DEFAULT_GOING_M``) when it has a rise and no
    going (a going without a rise is refused by ``Target`` itself: ``Axis.requires``)."""
    values: dict[str, Any] = {k: v for k, v in target.to_dict().items() if v is not None}
    if not target.step_height_m:
        return target
    if target.step_going_m is None:
        values["step_going_m"] = DEFAULT_GOING_M
    return Target(**values)


def stairs_base(env0: Environment, q: np.ndarray, foot_contact: np.ndarray) -> Environment:
    """The tutor's environment with its going: the walker's own step unless it already has one
    (the value the going axis starts from at λ = 0)."""
    if env0.step_going_m:
        return env0
    going = walker_going(q, foot_contact)
    return env0.with_(step_going_m=going) if math.isfinite(going) and going > 0 else env0
