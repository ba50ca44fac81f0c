"""Ground slope along the walking direction (°, + uphill), simulated by gravity: gravity
rotated by R_y(v) and the guide tilted by Ψ(Q, v) (docs/method.md (M7): θ = −slope)."""

from __future__ import annotations

import math

import numpy as np

from solver import spatial as sp
from solver.axes.base import Axis, register
from solver.environment import Environment
from solver.transforms import slope


def _environment(env: Environment, v: float) -> Environment:
    g = sp.rotation_about([0.0, 1.0, 0.0], math.radians(v)) @ np.asarray(env.gravity, dtype=float)
    return env.with_(gravity=tuple(float(c) for c in g))


SLOPE = register(Axis(
    name="slope_deg", unit="°", doc="ground slope along the walking direction, positive = uphill (degrees)",
    lo=-89.0, hi=89.0, lo_open=True, hi_open=True, default=0.0, label="slope", cli="--slope", metavar="DEG",
    order=20, grid=True, environment=_environment, guide=lambda q, v: slope(q, math.radians(v)),
    words="slope {}°"))
