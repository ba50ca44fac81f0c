"""Heading change over one cycle (°, + left): the guide's root path bent onto an arc
(Φ(Q, v)) and the cycle's yaw change constrained to the tutor's + v."""

from __future__ import annotations

import math

from solver.axes.base import Axis, register
from solver.transforms import curve

CURVE = register(Axis(
    name="curve_deg", unit="°", doc="heading change over one cycle, positive = turning left (degrees)",
    lo=-720.0, hi=720.0, default=0.0, label="curve", cli="--curve", metavar="DEG", order=10, grid=True,
    guide=lambda q, v: curve(q, math.radians(v)), nlp=lambda v: {"heading_change_deg": v}, words="curve {}°"))
