"""The environment a motion lives in, as a value: gravity vector and friction coefficient.

One home for standard gravity (``STANDARD_GRAVITY``) and for reading a motion's environment
from its provenance (:func:`environment_of`): nothing else spells out 9.81 or digs in
``provenance["environment"]``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Mapping

#: m/s², the tutor's gravity unless the capture says otherwise
STANDARD_GRAVITY = 9.81
#: the standard gravity vector (world z up)
STANDARD_GRAVITY_VECTOR = (0.0, 0.0, -STANDARD_GRAVITY)
DEFAULT_FRICTION = 1.0


@dataclass(frozen=True)
class Environment:
    """Gravity vector (m/s², world frame) and Coulomb friction coefficient of the ground."""

    gravity: tuple[float, float, float] = STANDARD_GRAVITY_VECTOR
    friction: float = DEFAULT_FRICTION

    def __post_init__(self) -> None:
        g = tuple(float(v) for v in self.gravity)
        if len(g) != 3 or not all(math.isfinite(v) for v in g):
            raise ValueError(f"gravity must be a finite 3-vector, got {self.gravity!r}")
        if not (math.isfinite(self.friction) and self.friction > 0):
            raise ValueError(f"friction must be a positive finite number, got {self.friction!r}")
        object.__setattr__(self, "gravity", g)
        object.__setattr__(self, "friction", float(self.friction))

    @property
    def gravity_magnitude(self) -> float:
        return math.sqrt(sum(v * v for v in self.gravity))

    def to_dict(self) -> dict:
        return {"gravity": [float(g) for g in self.gravity], "friction": float(self.friction)}

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> "Environment":
        if not d:
            return Environment()
        g = tuple(float(x) for x in d.get("gravity", STANDARD_GRAVITY_VECTOR))
        return Environment(g, float(d.get("friction", DEFAULT_FRICTION)))  # type: ignore[arg-type]


def environment_of(motion: Any) -> Environment:
    """The typed environment of a motion (its provenance's ``environment``; standard gravity
    and μ = 1 when the motion does not say)."""
    prov = getattr(motion, "provenance", None) or {}
    return Environment.from_dict(prov.get("environment"))


def body_weight(motion: Any) -> float:
    """Body weight (N) in the motion's own environment (standard gravity when it has none)."""
    g = environment_of(motion).gravity_magnitude
    return float(motion.character.total_mass) * (g if g > 0 else STANDARD_GRAVITY)
