"""The homotopy axes as data: one :class:`Axis` per target quantity, registered in one list.

An axis knows its name, unit, bounds, default (the value that changes nothing, or ``None``
when the λ = 0 value is the tutor's own, as for friction and gravity), its documentation,
and its three effects at a value v along the homotopy:

* ``environment(env, v)``: the :class:`~solver.environment.Environment` of the problem;
* ``guide(q, v)``: the guide motion (the tutor's coordinates transformed);
* ``nlp(v)``: NLP parameters that are not part of the environment (``NLP_EFFECTS``):
  ``frame_interval``, the spline's frame interval h relative to the tutor's (a factor), and
  ``heading_change_deg``, added to the tutor's heading change over the cycle.

Along λ ∈ [0, 1] every axis's value is interpolated linearly: v(λ) = v₀ + λ (v₁ − v₀), v₀
the axis's value at the tutor (its ``default``, or read from the tutor's environment).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterator, Mapping
from dataclasses import dataclass
from typing import Any

import numpy as np

from solver.environment import Environment

#: NLP effects an axis may have: how several axes combine ("*" or "+") and the neutral value
NLP_EFFECTS = {"frame_interval": ("*", 1.0), "heading_change_deg": ("+", 0.0)}


@dataclass(frozen=True)
class Axis:
    name: str  # API field, e.g. "slope_deg"
    unit: str  # "°", "m/s²", "×", "m", ""
    doc: str  # one line: what the value means
    lo: float
    hi: float
    lo_open: bool = False  # bounds excluded
    hi_open: bool = False
    default: float | None = 0.0  # the value that changes nothing; None = the tutor's own
    label: str = ""  # short word for plots and names ("slope")
    cli: str = ""  # CLI flag ("--slope")
    metavar: str = "X"
    #: order of application (guide transforms and environment effects, ascending)
    order: int = 0
    #: library grid axis (a cell's value)
    grid: bool = False
    #: the problem at λ depends on v(λ) only (then target B at λ·t is target v₀ + t (B − v₀) at
    #: λ, and a library's cells share optima along a ray)
    linear: bool = True
    base_value: Callable[[Environment], float] | None = None  # v₀ when default is None
    environment: Callable[[Environment, float], Environment] | None = None
    guide: Callable[[np.ndarray, float], np.ndarray] | None = None
    nlp: Callable[[float], Mapping[str, float]] | None = None
    #: a value is drawn/told as "slope {v}°"
    words: str = "{}"
    #: another axis a target must change for this one to mean anything (the going of stairs needs a rise)
    requires: str | None = None

    def bounds_text(self) -> str:
        return (f"{'(' if self.lo_open else '['}{self.lo:g}, {self.hi:g}{')' if self.hi_open else ']'}"
                + (f" {self.unit}" if self.unit else ""))

    def check(self, value: Any) -> float:
        """The value as a float, or ValueError saying the axis, the bounds and the unit."""
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise ValueError(f"{self.name} must be a number, got {value!r}")
        v = float(value)
        if not math.isfinite(v):
            raise ValueError(f"{self.name} must be finite, got {v}")
        below = v <= self.lo if self.lo_open else v < self.lo
        above = v >= self.hi if self.hi_open else v > self.hi
        if below or above:
            raise ValueError(f"{self.name} must be within {self.bounds_text()}, got {v:g}")
        return v

    def start(self, env0: Environment) -> float:
        """v₀: the value at λ = 0 (the tutor's)."""
        if self.default is not None:
            return float(self.default)
        assert self.base_value is not None, self.name
        return float(self.base_value(env0))

    def changes(self, value: float | None) -> bool:
        """Whether a target value changes the problem (a default-valued field changes nothing)."""
        if value is None:
            return False
        return self.default is None or value != self.default

    def describe(self) -> dict[str, Any]:
        """The axis as JSON (GET /axes)."""
        return {"name": self.name, "unit": self.unit, "doc": self.doc, "label": self.label or self.name,
                "minimum": self.lo, "maximum": self.hi, "exclusive_minimum": self.lo_open,
                "exclusive_maximum": self.hi_open, "default": self.default, "grid": self.grid,
                "linear": self.linear, "cli": self.cli, "words": self.words}


_REGISTRY: dict[str, Axis] = {}


def register(axis: Axis) -> Axis:
    if axis.name in _REGISTRY:
        raise ValueError(f"axis {axis.name!r} is registered twice")
    _REGISTRY[axis.name] = axis
    return axis


def axes() -> tuple[Axis, ...]:
    """Every registered axis, in registration (display) order."""
    return tuple(_REGISTRY.values())


def names() -> tuple[str, ...]:
    return tuple(_REGISTRY)


def axis(name: str) -> Axis:
    try:
        return _REGISTRY[name]
    except KeyError:
        raise ValueError(f"unknown axis {name!r}; the axes are {', '.join(_REGISTRY)}") from None


class Target:
    """The target reached at λ = 1, over registered axes: ``Target(slope_deg=10, speed_scale=1.2)``.

    An axis not given (or ``None``) keeps its default; every value is checked against its
    axis's bounds. Axis values read as attributes (``target.slope_deg``)."""

    __slots__ = ("_values",)

    _values: dict[str, float | None]

    def __init__(self, **values: float | None) -> None:
        out: dict[str, float | None] = {}
        for name, v in values.items():
            ax = axis(name)
            out[name] = None if v is None else ax.check(v)
        for name, v in out.items():
            req = axis(name).requires
            if v is not None and req is not None and not axis(req).changes(out.get(req, axis(req).default)):
                raise ValueError(f"{name} needs {req} too ({axis(name).doc})")
        object.__setattr__(self, "_values", out)

    def __getattr__(self, name: str) -> float | None:
        if name.startswith("_"):
            raise AttributeError(name)
        if name in _REGISTRY:
            return self._values.get(name, _REGISTRY[name].default)
        raise AttributeError(f"Target has no axis {name!r}")

    def __setattr__(self, name: str, value: Any) -> None:
        raise AttributeError("Target is immutable")

    def __eq__(self, other: object) -> bool:
        return isinstance(other, Target) and self.to_dict() == other.to_dict()

    def __hash__(self) -> int:
        return hash(tuple(sorted(self.to_dict().items())))

    def __repr__(self) -> str:
        return "Target(" + ", ".join(f"{k}={v!r}" for k, v in self._values.items() if v is not None) + ")"

    def value(self, name: str) -> float | None:
        return getattr(self, name)

    def active(self) -> Iterator[tuple[Axis, float]]:
        """The axes this target changes, with their target values, in application order."""
        for ax in sorted(axes(), key=lambda a: a.order):
            v = self.value(ax.name)
            if ax.changes(v):
                yield ax, float(v)  # type: ignore[arg-type]

    def is_identity(self) -> bool:
        return not any(True for _ in self.active())

    def to_dict(self) -> dict[str, float | None]:
        """Every registered axis's value (defaults included): the provenance's ``target``."""
        return {ax.name: self.value(ax.name) for ax in axes()}


def values_at(env0: Environment, target: Target, lam: float) -> dict[str, float]:
    """v(λ) of every axis the target changes (in application order)."""
    out = {}
    for ax, v1 in target.active():
        v0 = ax.start(env0)
        out[ax.name] = v0 + lam * (v1 - v0)
    return out


def environment_at(base: Environment, target: Target, lam: float) -> tuple[Environment, dict[str, float]]:
    """The environment at λ and the axes' values there (every registered axis reported: the
    tutor's value for an axis the target does not change)."""
    if base.gravity_magnitude <= 0:
        raise ValueError("the tutor's gravity is zero: nothing to extrapolate from")
    vals = values_at(base, target, lam)
    env = base
    for ax in sorted(axes(), key=lambda a: a.order):
        if ax.name in vals and ax.environment is not None:
            env = ax.environment(env, vals[ax.name])
    report = {ax.name: vals.get(ax.name, ax.start(base)) for ax in axes()}
    return env, report


def guide_at(tutor_q: np.ndarray, target: Target, lam: float, env0: Environment | None = None) -> np.ndarray:
    """The guide at λ: each active axis's transform in application order."""
    q = np.array(tutor_q, dtype=float, copy=True)
    for name, v in values_at(env0 or Environment(), target, lam).items():
        ax = axis(name)
        if ax.guide is not None:
            q = ax.guide(q, v)
    return q


def nlp_at(target: Target, lam: float, env0: Environment | None = None) -> dict[str, float]:
    """NLP parameter effects at λ (``NLP_EFFECTS``: neutral unless an active axis sets them)."""
    out = {k: neutral for k, (_, neutral) in NLP_EFFECTS.items()}
    for name, v in values_at(env0 or Environment(), target, lam).items():
        ax = axis(name)
        if ax.nlp is not None:
            for k, f in ax.nlp(v).items():
                if k not in out:
                    raise ValueError(f"axis {name!r} sets an unknown NLP effect {k!r}")
                out[k] = out[k] * float(f) if NLP_EFFECTS[k][0] == "*" else out[k] + float(f)
    return out
