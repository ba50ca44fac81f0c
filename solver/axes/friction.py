"""Ground friction coefficient μ (Coulomb cone and torsional friction of the feet). v₀ = the tutor's μ."""

from __future__ import annotations

from solver.axes.base import Axis, register

FRICTION = register(Axis(
    name="friction", unit="", doc="target friction coefficient μ (default: the tutor's)",
    lo=0.0, hi=10.0, lo_open=True, default=None, label="μ", cli="--friction", metavar="MU", order=0,
    base_value=lambda env: env.friction, environment=lambda env, v: env.with_(friction=v), words="μ={}"))
