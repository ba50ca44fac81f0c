"""The motion a simulation tracks, as a function of time over any number of gait cycles.

:class:`Reference` loops the motion over cycles under the cycle transform (turn and translation,
the rise of stairs) of ``solver.trajectory``; :func:`mid_stance_time` is where a walk starts
without impact. A motion that cannot be simulated is refused with :class:`SimulationError`.
"""

from __future__ import annotations

import math

import numpy as np

from solver.environment import ground_of
from solver.motion import FEET, Motion
from solver.trajectory import ROOT_XY, ROOT_YAW, cycle_turn, spline_velocities

ROOT_Z = 2


class SimulationError(ValueError):
    """A motion cannot be simulated (no contact schedule, no wrenches, not a gait cycle...)."""


def _rot2(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def _rotz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class Reference:
    """The motion as a function of time over any number of cycles: the C² spline through its
    frames (q, q̇, q̈), the stored foot wrenches (linear between frames) and the contact
    schedule, cycle k moved by k times the cycle transform."""

    def __init__(self, motion: Motion) -> None:
        if not motion.cyclic or motion.T < 5:
            raise SimulationError("simulation needs a gait cycle (a cyclic motion: frames T−2, T−1 repeat 0, 1)")
        if motion.contacts is None or motion.wrenches is None:
            raise SimulationError("simulation needs the motion's contact schedule and foot wrenches")
        self.motion = motion
        self.q = np.asarray(motion.q, dtype=float)
        self.dt = float(motion.dt)
        self.P = motion.T - 2
        self.period = self.P * self.dt
        if motion.interpolation == "cubic-spline":
            self.v = spline_velocities(self.q, self.dt)
        else:
            self.v = np.gradient(self.q, self.dt, axis=1)
        self.turn = cycle_turn(self.q)
        xy = self.q[list(ROOT_XY)]
        self.shift_xy = xy[:, self.P] - _rot2(self.turn) @ xy[:, 0]
        self.rise = float(self.q[ROOT_Z, self.P] - self.q[ROOT_Z, 0])
        self.contacts = np.asarray(motion.contacts, dtype=bool)
        self.wrenches = np.asarray(motion.wrenches, dtype=float)
        self.ground = ground_of(motion)

    def transform(self, k: int) -> tuple[float, np.ndarray, float]:
        """Cycle k's turn (rad), horizontal translation (2,) and rise (m): x ↦ R x + d."""
        R2 = _rot2(self.turn)
        d = np.zeros(2)
        for _ in range(k):
            d = R2 @ d + self.shift_xy
        return k * self.turn, d, k * self.rise

    def _split(self, t: float) -> tuple[int, int, float]:
        k = math.floor(t / self.period)
        s = (t - k * self.period) / self.dt
        i = min(int(math.floor(s)), self.P - 1)
        return k, i, s - i

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, q̇, q̈ at time t (s from frame 0 of cycle 0)."""
        k, i, u = self._split(t)
        h = self.dt
        q0, q1, v0, v1 = self.q[:, i], self.q[:, i + 1], self.v[:, i], self.v[:, i + 1]
        q = (2 * u**3 - 3 * u**2 + 1) * q0 + (u**3 - 2 * u**2 + u) * h * v0 + (-2 * u**3 + 3 * u**2) * q1 \
            + (u**3 - u**2) * h * v1
        qd = ((6 * u**2 - 6 * u) * q0 + (3 * u**2 - 4 * u + 1) * h * v0 + (-6 * u**2 + 6 * u) * q1
              + (3 * u**2 - 2 * u) * h * v1) / h
        qdd = ((12 * u - 6) * q0 + (6 * u - 4) * h * v0 + (-12 * u + 6) * q1 + (6 * u - 2) * h * v1) / h**2
        if k:
            turn, d, rise = self.transform(k)
            R2 = _rot2(turn)
            xy = list(ROOT_XY)
            q[xy] = R2 @ q[xy] + d
            qd[xy] = R2 @ qd[xy]
            qdd[xy] = R2 @ qdd[xy]
            q[ROOT_YAW] += turn
            q[ROOT_Z] += rise
        return q, qd, qdd

    def wrench(self, t: float) -> np.ndarray:
        """(2, 6) stored foot wrenches at t (world; moment about the origin; force)."""
        k, i, u = self._split(t)
        w = (1 - u) * self.wrenches[:, :, i] + u * self.wrenches[:, :, i + 1]
        if k:
            turn, d, rise = self.transform(k)
            R = _rotz(turn)
            p = np.array([d[0], d[1], rise])
            f = w[:, 3:] @ R.T
            m = w[:, :3] @ R.T + np.cross(p, f)
            w = np.concatenate([m, f], axis=1)
        return w

    def swing_progress(self, t: float, points: list[int] | np.ndarray) -> float | None:
        """Where t is within the swing of the foot owning ``points`` (0 at the last contact frame,
        1 at the next), or None when the foot is in contact at the frame before or after t."""
        _, i, u = self._split(t)
        c: np.ndarray = np.asarray(self.contacts[points].any(axis=0))[: self.P]
        if c[i] or c[(i + 1) % self.P] or not c.any():
            return None
        a = i
        while not c[a % self.P]:
            a -= 1
        b = i + 1
        while not c[b % self.P]:
            b += 1
        return (i + u - a) / (b - a)

    def active(self, t: float) -> np.ndarray:
        """(P,) contact points in contact at the frame before or after t (the stored wrench
        between them may be non-zero)."""
        _, i, u = self._split(t)
        if u == 0.0:
            return self.contacts[:, i].copy()
        return self.contacts[:, i] | self.contacts[:, i + 1]


def mid_stance_time(motion: Motion) -> float:
    """Middle of the longest single support with the whole stance foot (heel and toe) down,
    else of the longest double support: a start without impact."""
    ch = motion.character
    P = motion.T - 2
    C = np.asarray(motion.contacts, dtype=bool)[:, :P]
    full = np.zeros((2, P), dtype=bool)
    anyc = np.zeros((2, P), dtype=bool)
    for f, side in enumerate(FEET):
        idx = [i for i, c in enumerate(ch.contacts) if c.side == side]
        full[f] = C[idx].all(axis=0)
        anyc[f] = C[idx].any(axis=0)
    single = (full[0] & ~anyc[1]) | (full[1] & ~anyc[0])
    mask = single if single.any() else (anyc[0] & anyc[1])
    if not mask.any():
        raise SimulationError("the contact schedule has neither single nor double support")
    best, best_len = 0, 0
    for start in range(P):  # longest cyclic run
        if mask[start] and not mask[(start - 1) % P]:
            n = 0
            while n < P and mask[(start + n) % P]:
                n += 1
            if n > best_len:
                best, best_len = start, n
    if best_len == 0:  # the whole cycle
        best, best_len = 0, P
    return ((best + (best_len - 1) / 2.0) % P) * motion.dt
