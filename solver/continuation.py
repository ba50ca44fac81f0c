"""Extrapolation by continuation in λ ∈ [0, 1] (SPEC §7, Algorithm 3 and beyond).

Types are frozen values; progress is reported through callbacks so the CLI, a worker or
a test can consume it (crocoddyl's CallbackLogger / mujoco's IterLog habit).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Callable, Mapping

from solver.motion import Motion


@dataclass(frozen=True)
class Target:
    """The target environment, as data (combinable): λ = 1 reaches all of it at once.

    slope_deg: ground slope along the walking direction, positive = uphill (the thesis's
        θ = -slope: gravity rotated by R_y(-λθ), guide Ψ(Q_tut, -λθ)).
    curve_deg: heading change over one cycle, positive = turning left (guide Φ(Q_tut, λθ)).
    friction: target friction coefficient μ₂ (None = keep the tutor's).
    gravity: target gravity magnitude in m/s² (None = keep the tutor's), e.g. 1.62 (Moon).
    """

    slope_deg: float = 0.0
    curve_deg: float = 0.0
    friction: float | None = None
    gravity: float | None = None

    def __post_init__(self) -> None:
        for name in ("slope_deg", "curve_deg"):
            v = getattr(self, name)
            if not math.isfinite(v):
                raise ValueError(f"{name} must be finite")
        if not -89.0 < self.slope_deg < 89.0:
            raise ValueError("slope_deg must be within (-89, 89) degrees")
        if not -720.0 <= self.curve_deg <= 720.0:
            raise ValueError("curve_deg must be within [-720, 720] degrees")
        if self.friction is not None and not (math.isfinite(self.friction) and self.friction > 0):
            raise ValueError("friction must be a positive finite number")
        if self.gravity is not None and not (math.isfinite(self.gravity) and self.gravity > 0):
            raise ValueError("gravity must be a positive finite magnitude (m/s²)")

    def is_identity(self) -> bool:
        return self.slope_deg == 0 and self.curve_deg == 0 and self.friction is None and self.gravity is None


@dataclass(frozen=True)
class StepControl:
    """Step control of the homotopy walk.

    method "thesis": Algorithm 3 (double on success, halve on failure, stop when Δ < ε).
    method "adaptive": step from the recent history of accepted steps, secant predictor
        from the last two optima, warm-started multipliers.
    """

    method: str = "adaptive"
    delta0: float = 0.05
    max_iter: int = 200  # k: solver iterations allowed per step
    eps: float = 0.005  # smallest step before declaring an impasse
    max_solves: int = 400

    def __post_init__(self) -> None:
        if self.method not in ("adaptive", "thesis"):
            raise ValueError("method must be 'adaptive' or 'thesis'")
        if not (0 < self.eps <= self.delta0 <= 1):
            raise ValueError("need 0 < eps <= delta0 <= 1")
        if self.max_iter < 1 or self.max_solves < 1:
            raise ValueError("max_iter and max_solves must be >= 1")


@dataclass(frozen=True)
class ProgressRecord:
    """One solve of the continuation, accepted or not."""

    wall_time: float  # s since the start of the extrapolation
    lam: float  # λ tried
    environment: Mapping[str, float]  # slope_deg, curve_deg, friction, gravity at that λ
    iterations: int
    accepted: bool
    status: str  # solver status text
    lam_reached: float


@dataclass(frozen=True)
class StepResult:
    """An accepted λ: a plausible motion of the continuum."""

    step: int  # 0 = the base problem (λ = 0), then 1, 2, ...
    lam: float
    motion: Motion
    stats: Mapping[str, Any] = field(default_factory=dict)


@dataclass(frozen=True)
class ExtrapolationResult:
    status: str  # "succeeded" | "impasse" | "canceled" | "failed"
    lam_reached: float
    steps: tuple[StepResult, ...]
    records: tuple[ProgressRecord, ...]
    solves: int
    wall_time: float
    message: str = ""


ProgressCallback = Callable[[ProgressRecord], None]
StepCallback = Callable[[StepResult], None]
CancelCheck = Callable[[], bool]
