"""The environment a motion lives in, as a value: gravity vector, friction coefficient and
terrain (stairs: the ground under each successive stance raised by a riser height).

One home for standard gravity (``STANDARD_GRAVITY``) and for reading a motion's environment
from its provenance (:func:`environment_of`): nothing else spells out 9.81 or digs in
``provenance["environment"]``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

#: m/s², the tutor's gravity unless the capture says otherwise
STANDARD_GRAVITY = 9.81
#: the standard gravity vector (world z up)
STANDARD_GRAVITY_VECTOR = (0.0, 0.0, -STANDARD_GRAVITY)
DEFAULT_FRICTION = 1.0


@dataclass(frozen=True)
class Environment:
    """Gravity vector (m/s², world frame), Coulomb friction coefficient of the ground, and the
    terrain: ``step_height_m`` raises the ground under each successive stance by that riser
    height (stairs; negative: down; 0: the flat ground z = 0)."""

    gravity: tuple[float, float, float] = STANDARD_GRAVITY_VECTOR
    friction: float = DEFAULT_FRICTION
    step_height_m: float = 0.0

    def __post_init__(self) -> None:
        g = tuple(float(v) for v in self.gravity)
        if len(g) != 3 or not all(math.isfinite(v) for v in g):
            raise ValueError(f"gravity must be a finite 3-vector, got {self.gravity!r}")
        if not (math.isfinite(self.friction) and self.friction > 0):
            raise ValueError(f"friction must be a positive finite number, got {self.friction!r}")
        object.__setattr__(self, "gravity", g)
        object.__setattr__(self, "friction", float(self.friction))
        if not math.isfinite(self.step_height_m):
            raise ValueError(f"step_height_m must be finite, got {self.step_height_m!r}")
        object.__setattr__(self, "step_height_m", float(self.step_height_m))

    @property
    def gravity_magnitude(self) -> float:
        return math.sqrt(sum(v * v for v in self.gravity))

    def to_dict(self) -> dict:
        out = {"gravity": [float(g) for g in self.gravity], "friction": float(self.friction)}
        if self.step_height_m:
            out["terrain"] = {"step_height_m": float(self.step_height_m)}
        return out

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> Environment:
        if not d:
            return Environment()
        g = tuple(float(x) for x in d.get("gravity", STANDARD_GRAVITY_VECTOR))
        step = float((d.get("terrain") or {}).get("step_height_m", 0.0))
        return Environment(g, float(d.get("friction", DEFAULT_FRICTION)), step)  # type: ignore[arg-type]

    def with_(self, **changes: Any) -> Environment:
        from dataclasses import replace

        return replace(self, **changes)


def environment_of(motion: Any) -> Environment:
    """The typed environment of a motion (its provenance's ``environment``; standard gravity
    and μ = 1 when the motion does not say)."""
    prov = getattr(motion, "provenance", None) or {}
    return Environment.from_dict(prov.get("environment"))


def body_weight(motion: Any) -> float:
    """Body weight (N) in the motion's own environment (standard gravity when it has none)."""
    g = environment_of(motion).gravity_magnitude
    return float(motion.character.total_mass) * (g if g > 0 else STANDARD_GRAVITY)


def stair_heights(foot_contact: np.ndarray, riser: float) -> np.ndarray:
    """(2, T) ground height under each foot per frame on stairs of riser height ``riser``, for a
    cyclic foot schedule (frames T−2, T−1 repeat frames 0, 1): the stances of the cycle, in
    the order they begin, stand on treads 0, 1, …, n−1 (× riser); a stance that began in the
    previous cycle is on tread −1…; frames T−2, T−1 are frames 0, 1 raised by n × riser. A
    swinging foot's ground is the lower of the tread it left and the tread it reaches."""
    B = np.asarray(foot_contact, dtype=bool)
    T = B.shape[1]
    H = np.zeros((2, T))
    if riser == 0.0 or T < 5:
        return H
    P = T - 2
    onsets = sorted((t, f) for f in range(2) for t in range(P) if B[f, t] and not B[f, (t - 1) % P])
    n = len(onsets)
    if n == 0:
        return H
    rank = {o: i for i, o in enumerate(onsets)}

    def tread(f: int, t: int, step: int) -> float | None:
        """Tread of the first stance of foot f met walking from frame t by ``step`` (±1; t may
        leave [0, P): frames of other cycles)."""
        u = t
        for _ in range(P + 1):
            if B[f, u % P]:
                while (u % P, f) not in rank:  # back to that stance's onset
                    u -= 1
                return (rank[(u % P, f)] + n * math.floor(u / P)) * riser
            u += step
        return None

    for f in range(2):
        for t in range(P):
            if B[f, t]:
                H[f, t] = tread(f, t, -1) or 0.0
            else:
                a, b = tread(f, t, -1), tread(f, t, +1)
                vals = [x for x in (a, b) if x is not None]
                H[f, t] = min(vals) if vals else 0.0
    H[:, P:] = H[:, :2] + n * riser
    return H


def stances(foot_contact: np.ndarray) -> list[tuple[int, int, int]]:
    """(foot index, first frame, last frame) of every run of frames a foot is on the ground, in
    the clip's own frames (not wrapped around the cycle), foot by foot."""
    B = np.asarray(foot_contact, dtype=bool)
    out = []
    for f in range(B.shape[0]):
        t = 0
        while t < B.shape[1]:
            if not B[f, t]:
                t += 1
                continue
            a = t
            while t < B.shape[1] and B[f, t]:
                t += 1
            out.append((f, a, t - 1))
    return out


def stair_rise(foot_contact: np.ndarray, riser: float) -> float:
    """Height gained over one cycle on stairs: (stances per cycle) × riser."""
    B = np.asarray(foot_contact, dtype=bool)
    P = B.shape[1] - 2
    n = sum(1 for f in range(2) for t in range(P) if B[f, t] and not B[f, (t - 1) % P])
    return n * float(riser)


def ground_of(motion: Any) -> np.ndarray:
    """(2, T) ground height under each foot per frame of a motion (zeros on flat ground)."""
    env = environment_of(motion)
    if not env.step_height_m or motion.contacts is None:
        return np.zeros((2, motion.T))
    return stair_heights(motion.foot_contact(), env.step_height_m)
