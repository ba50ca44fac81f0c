"""Gravity magnitude (m/s²): the gravity vector scaled to |g| = v, its direction kept
(the slope axis turns it afterwards). v₀ = the tutor's |g|."""

from __future__ import annotations

from solver.axes.base import Axis, register
from solver.environment import Environment


def _environment(env: Environment, v: float) -> Environment:
    g0 = env.gravity_magnitude
    return env.with_(gravity=tuple(c * v / g0 for c in env.gravity))


GRAVITY = register(Axis(
    name="gravity", unit="m/s²", doc="target gravity magnitude (Moon 1.62; default: the tutor's)",
    lo=0.0, hi=100.0, lo_open=True, default=None, label="|g|", cli="--gravity", metavar="G", order=0,
    base_value=lambda env: env.gravity_magnitude, environment=_environment, words="|g|={} m/s²"))
