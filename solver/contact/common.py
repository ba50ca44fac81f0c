"""Contact estimation: constants, errors, status codes, the estimate, input checks, derivatives."""

from __future__ import annotations

import logging
import math
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any

import numpy as np

from solver.character import Character, CharacterError
from solver.motion import FEET

log = logging.getLogger("solver.contact")


METHODS = ("qp", "nested")
DEFAULT_PENETRATION = 0.01  # m, docs/method.md (M1)
DEFAULT_FRICTION = 1.0  # docs/method.md (M5.7)
DEFAULT_REGULARIZATION = 1e-6
FEASIBILITY_TOL = 1e-9  # relative, on the constraint rows (N·m per N of load)
#: below this vertical load (N) a foot's centre of pressure is undefined (NaN), as force-plate software
#: reports it: a moment of 0.01 N·m over 0.003 N would put the CoP 3 m away
COP_MIN_FZ = 10.0


class ContactError(ValueError):
    """Bad input to contact-force estimation; the message names the problem."""


class Support(IntEnum):
    FLIGHT = 0
    RIGHT = 1
    LEFT = 2
    DOUBLE = 3


class Status(IntEnum):
    UNDEFINED = 0  # accelerations undefined (ends of a non-cyclic motion): NaN
    SINGLE = 1  # single support: the foot on the ground takes c exactly
    OPTIMAL = 2  # double support: least-effort split, every constraint satisfied
    RELAXED = 3  # double support, infeasible: least relaxation, then least effort
    FLIGHT = 4  # no foot on the ground: zero wrenches (c unexplained)
    FAILED = 5  # the QP solver failed: NaN
    PROJECTED = 6  # single support, c's CoP outside the foot: CoP moved into the polygon (project_cop)


def _frozen(a: Any, dtype: Any = float) -> np.ndarray:
    a = np.array(a, dtype=dtype, copy=True)
    a.setflags(write=False)
    return a


def cop_and_free_moment(wrenches: np.ndarray, min_fz: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """CoP on the ground z = 0 and free moment about the vertical at the CoP.

    ``wrenches`` (..., 6, T): world frame about the origin (moment; force). Returns CoP
    (..., 3, T) (NaN where f_z ≤ ``min_fz``) and the free moment (..., T) (0 there).
    """
    w = np.asarray(wrenches, dtype=float)
    mx, my, mz, fx, fy, fz = (w[..., k, :] for k in range(6))
    loaded = fz > min_fz
    with np.errstate(divide="ignore", invalid="ignore"):
        px = np.where(loaded, -my / fz, np.nan)
        py = np.where(loaded, mx / fz, np.nan)
    cop = np.stack([px, py, np.where(loaded, 0.0, np.nan)], axis=-2)
    tz = np.where(loaded, mz - (px * fy - py * fx), 0.0)
    return cop, tz


@dataclass(frozen=True, eq=False)
class ContactEstimate:
    """Estimated ground reaction of each foot at every frame (our world frame, SI).

    ``wrenches`` (2, 6, T): feet (right, left), world frame, (moment about the world
    origin; force) — the :class:`~solver.motion.Motion` convention. ``total`` (6, T) is
    c = h0 (with ``lateral_hz``: its lateral force from the low-passed centre of mass, the difference
    a force through the centre of mass). ``support`` and ``status`` hold :class:`Support` / :class:`Status` codes per
    frame. ``cop`` (2, 3, T) on the ground (NaN for a foot carrying less than ``COP_MIN_FZ``),
    ``free_moment`` (2, T) about the vertical at the CoP (0 there), ``cop_violation`` (2, T)
    metres outside the contact polygon (0 inside; NaN where undefined). The free moment is the
    wrench's own (what the dynamics use) but not a reliable estimate of the plates' free moment:
    on every shared trial its error exceeds that of predicting zero, so the reports leave it out
    (docs/grf.md).
    """

    wrenches: np.ndarray
    total: np.ndarray
    support: np.ndarray
    status: np.ndarray
    cop_violation: np.ndarray
    fps: float
    method: str
    cyclic: bool = False
    smoothing_hz: float | None = None
    lateral_hz: float | None = None  # the total's lateral force from the centre of mass low-passed here
    cop: np.ndarray = field(init=False)
    free_moment: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        for name in ("wrenches", "total", "cop_violation"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        object.__setattr__(self, "support", _frozen(self.support, np.int8))
        object.__setattr__(self, "status", _frozen(self.status, np.int8))
        cop, tz = cop_and_free_moment(self.wrenches, COP_MIN_FZ)
        object.__setattr__(self, "cop", _frozen(cop))
        object.__setattr__(self, "free_moment", _frozen(tz))

    @property
    def T(self) -> int:
        return int(self.wrenches.shape[-1])

    @property
    def force(self) -> np.ndarray:
        return self.wrenches[:, 3:, :]

    @property
    def defined(self) -> np.ndarray:
        return np.isin(self.status, (Status.SINGLE, Status.PROJECTED, Status.OPTIMAL, Status.RELAXED, Status.FLIGHT))

    @property
    def double_support(self) -> np.ndarray:
        return (self.support == Support.DOUBLE) & self.defined

    def summary(self) -> dict:
        return {
            "frames": self.T,
            "method": self.method,
            "smoothing_hz": self.smoothing_hz,
            "lateral_hz": self.lateral_hz,
            **{f"support_{s.name.lower()}": int(np.sum(self.support == s)) for s in Support},
            **{f"status_{s.name.lower()}": int(np.sum(self.status == s)) for s in Status},
            "max_cop_violation_m": float(np.nanmax(self.cop_violation)) if np.any(self.defined) else None,
        }


# --- input checks ------------------------------------------------------------------------


def _check_inputs(character: Character, q: Any, fps: float, foot_contact: Any, gravity: Any) -> tuple:
    q = np.asarray(q, dtype=float)
    n = character.n
    if q.ndim != 2:
        raise ContactError(f"the motion must be a (coordinates, frames) array, got shape {q.shape}")
    if q.shape[0] != n:
        raise ContactError(
            f"model/motion mismatch: character {character.name!r} has {n} coordinates, "
            f"the motion has {q.shape[0]} rows"
        )
    T = q.shape[1]
    if T < 3:
        raise ContactError(f"accelerations need at least 3 frames, got {T}")
    bad = ~np.isfinite(q)
    if bad.any():
        i, t = np.argwhere(bad)[0]
        raise ContactError(
            f"coordinate {character.coordinate_names[i]!r} is not finite (NaN/inf) at frame {t} "
            f"({int(bad.sum())} bad values)"
        )
    if not (isinstance(fps, (int, float, np.floating)) and math.isfinite(fps) and fps > 0):
        raise ContactError(f"fps must be a positive finite number, got {fps!r}")
    fc = np.asarray(foot_contact)
    if fc.shape != (2, T):
        raise ContactError(f"foot_contact must have shape (2 feet (right, left), T={T}), got {fc.shape}")
    if fc.dtype != bool:
        if not np.all(np.isin(fc, (0, 1))):
            raise ContactError("foot_contact must be boolean (or 0/1)")
        fc = fc.astype(bool)
    g = np.asarray(gravity, dtype=float).reshape(-1)
    if g.shape != (3,) or not np.all(np.isfinite(g)):
        raise ContactError(f"gravity must be a finite 3-vector, got {gravity!r}")
    for side in FEET:
        try:
            character.foot(side)
        except CharacterError as e:
            raise ContactError(str(e)) from None
    return q, fc, g


def _check_schedule(fc: np.ndarray, defined: np.ndarray) -> None:
    for i, side in enumerate(FEET):
        if not fc[i].any():
            raise ContactError(f"the {side} foot is never on the ground in the contact schedule")
    ds = fc[0] & fc[1]
    if not ds.any():
        raise ContactError("the contact schedule has no double support (no frame with both feet on the ground)")
    if not (ds & defined).any():
        raise ContactError(
            "double support only at frames where accelerations are undefined (first/last frame); "
            "give more frames or cyclic=True"
        )


# --- derivatives ---------------------------------------------------------------------------


def _derivatives(q: np.ndarray, dt: float, cyclic: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Central differences (docs/method.md (M2.2)): (frames where defined, q̇, q̈) at those frames."""
    T = q.shape[1]
    if not cyclic:
        qd = (q[:, 2:] - q[:, :-2]) / (2.0 * dt)
        qdd = (q[:, 2:] - 2.0 * q[:, 1:-1] + q[:, :-2]) / (dt * dt)
        return np.arange(1, T - 1), qd, qdd
    # the last frame closes the cycle: q[T-1] = q[0] + offset (offset: root advance)
    offset = q[:, -1] - q[:, 0]
    P = T - 1
    ext = np.concatenate([q[:, P - 1 : P] - offset[:, None], q[:, :P], q[:, :1] + offset[:, None]], axis=1)
    qd = (ext[:, 2:] - ext[:, :-2]) / (2.0 * dt)
    qdd = (ext[:, 2:] - 2.0 * ext[:, 1:-1] + ext[:, :-2]) / (dt * dt)
    # frame T-1 is frame 0 one period later: same velocity and acceleration
    return np.arange(T), np.concatenate([qd, qd[:, :1]], axis=1), np.concatenate([qdd, qdd[:, :1]], axis=1)


