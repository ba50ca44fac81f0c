"""The body mass force plates imply, and the check against the mass a trial states.

Over a whole gait cycle of steady walking the body's vertical momentum comes back to its
value, so the mean total vertical ground force over the cycle is the body weight:

    m = ∫_cycle (F_z,right + F_z,left) dt / (T_cycle g)

* **Continuous plates** (a treadmill, or a walkway where every stance lands on a plate): the
  mean total vertical force over the longest run of consecutive whole cycles (heel strike to
  heel strike of one foot) that each hold exactly one stance of the other foot, stances
  lasting within 25 % of their foot's median (a foot half on a plate does not count) and
  cycles within 25 % of the median stride.
* **One complete stance per foot** (an overground trial with two plates): over one cycle each
  foot has exactly one stance, so ``m = (J_right + J_left) / (T_cycle g)`` with J the stances'
  impulses; T_cycle is the stride time of the kinematics when the caller knows it, else twice
  the mean of the two step times the plates show (strike to strike and off to off: a
  symmetric gait), which is less precise (≈ 2 % on the shared trials, see docs/import.md).

A stance is a run of vertical force above ``threshold`` (20 N) lasting at least 0.1 s that
starts and ends inside the record (unloaded before and after). Without either configuration
the plates imply nothing (None).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from solver.environment import STANDARD_GRAVITY

G = STANDARD_GRAVITY
#: relative difference between the stated and the implied mass above which we warn
MASS_TOLERANCE = 0.05
MIN_STANCE_S = 0.1


@dataclass(frozen=True)
class ImpliedMass:
    kg: float
    method: str  # "whole cycles" | "one stance per foot"
    cycle_s: float  # the stride time used
    cycles: float  # how many cycles the figure averages
    window_s: tuple[float, float]  # the plate record used (s)
    stride_from: str  # "plates" | "kinematics" | "plates (2 x step)"

    def as_dict(self) -> dict[str, Any]:
        return {"kg": round(self.kg, 2), "method": self.method, "cycle_s": round(self.cycle_s, 4),
                "cycles": round(self.cycles, 2), "window_s": [round(w, 4) for w in self.window_s],
                "stride_from": self.stride_from}


def stances(t: np.ndarray, f: np.ndarray, threshold: float = 20.0) -> list[tuple[int, int]]:
    """Complete stances of one foot: (first, last) sample indices of each loaded run that has
    an unloaded sample before and after it and lasts at least ``MIN_STANCE_S``."""
    on = np.asarray(f) > threshold
    d = np.diff(on.astype(int))
    starts = list(np.flatnonzero(d == 1) + 1)
    ends = list(np.flatnonzero(d == -1))
    if on[0]:
        ends = ends[1:] if ends and ends[0] < (starts[0] if starts else len(on)) else ends
    out = []
    for s in starts:
        e = next((e for e in ends if e >= s), None)
        if e is None:
            break  # loaded to the end of the record: incomplete
        if t[e] - t[s] >= MIN_STANCE_S:
            out.append((int(s), int(e)))
    return out


def _regular(t: np.ndarray, st: list[tuple[int, int]]) -> list[tuple[int, int]]:
    """The stances lasting within 25 % of the foot's median stance (all of them when < 3)."""
    if len(st) < 3:
        return st
    d = np.array([t[b] - t[a] for a, b in st])
    med = float(np.median(d))
    return [s for s, x in zip(st, d) if abs(x / med - 1) <= 0.25]


def _trapz(f: np.ndarray, t: np.ndarray) -> float:
    return float(np.sum(0.5 * (f[1:] + f[:-1]) * np.diff(t)))


def _integral(t: np.ndarray, f: np.ndarray, a: int, b: int) -> float:
    """∫ f dt over samples a-1 .. b+1 (the unloaded samples around a stance included)."""
    lo, hi = max(a - 1, 0), min(b + 1, len(t) - 1)
    return _trapz(f[lo:hi + 1], t[lo:hi + 1])


def implied_mass(t: np.ndarray, fz: np.ndarray, *, threshold: float = 20.0, stride_s: float | None = None,
                 g: float = G) -> ImpliedMass | None:
    """Body mass (kg) implied by per-foot vertical forces ``fz`` (2, N) (right, left; N,
    positive up) sampled at ``t`` (N,): see the module doc. None when the plates cannot tell."""
    t = np.asarray(t, dtype=float)
    fz = np.nan_to_num(np.asarray(fz, dtype=float), nan=0.0)
    if fz.ndim != 2 or fz.shape[0] != 2 or fz.shape[1] != t.size or t.size < 3:
        raise ValueError(f"implied_mass: fz must be (2, N={t.size}), got {fz.shape}")
    st = [stances(t, fz[k], threshold) for k in range(2)]
    total = fz.sum(axis=0)
    # whole cycles: consecutive strikes of one foot, each cycle holding exactly one stance of the
    # other foot; stances much shorter or longer than the foot's median (a foot half on a plate)
    # do not count; the longest run of such cycles wins
    regular = [_regular(t, s) for s in st]
    best = None
    for k in range(2):
        strikes = [t[a] for a, _ in regular[k]]
        other = [t[a] for a, _ in regular[1 - k]]
        ok = [sum(strikes[i] <= s < strikes[i + 1] for s in other) == 1 for i in range(len(strikes) - 1)]
        if len(strikes) > 2:
            period = np.median(np.diff(strikes))
            ok = [o and abs((strikes[i + 1] - strikes[i]) / period - 1) <= 0.25 for i, o in enumerate(ok)]
        i = 0
        while i < len(ok):
            if not ok[i]:
                i += 1
                continue
            j = i
            while j < len(ok) and ok[j]:
                j += 1
            if best is None or j - i > best[2]:
                best = (regular[k][i][0], regular[k][j][0], j - i)
            i = j
    if best is not None:
        a, b, n_cyc = best
        T = float(t[b] - t[a])
        mean_f = _trapz(total[a:b + 1], t[a:b + 1]) / T
        return ImpliedMass(float(mean_f / g), "whole cycles", T / n_cyc, float(n_cyc), (float(t[a]), float(t[b])),
                           "plates")
    # one complete stance per foot, consecutive
    pairs = []
    for r in st[0]:
        for lf in st[1]:
            first, second = (r, lf) if r[0] <= lf[0] else (lf, r)
            if second[0] <= first[1] + int(0.6 * (first[1] - first[0])) and second[0] > first[0]:
                pairs.append((r, lf, first, second))
    if not pairs:
        return None
    r, lf, first, second = pairs[0]
    J = _integral(t, fz[0], *r) + _integral(t, fz[1], *lf)
    T, how = (t[second[0]] - t[first[0]]) + (t[second[1]] - t[first[1]]), "plates (2 x step)"
    # the kinematics' stride is more precise, unless it is off the plates' by more than a
    # quarter (a missed or extra strike)
    if stride_s is not None and math.isfinite(stride_s) and abs(stride_s - T) <= 0.25 * T:
        T, how = float(stride_s), "kinematics"
    return ImpliedMass(float(J / (T * g)), "one stance per foot", float(T), 1.0,
                       (float(t[first[0]]), float(t[second[1]])), how)


def mass_warning(mass: float | None, implied: ImpliedMass | float | None, *,
                 tolerance: float = MASS_TOLERANCE) -> str | None:
    """A one-line warning when the trial's mass and the plates' implied mass (kg, or an
    :class:`ImpliedMass`) differ by more than ``tolerance`` (relative to the implied mass)."""
    kg = implied.kg if isinstance(implied, ImpliedMass) else implied
    if mass is None or kg is None or not kg > 0:
        return None
    rel = (mass - kg) / kg
    if abs(rel) <= tolerance:
        return None
    return (f"the subject mass {mass:.1f} kg differs from the {kg:.1f} kg the force plates imply "
            f"({100 * rel:+.0f} %): estimated ground reactions scale with the mass")


def stride_from_events(events: dict[str, list[float]]) -> float | None:
    """Median same-foot heel-strike interval (s) of ``solver.gait.gait_events``, or None."""
    d = [b - a for side in ("right", "left") for a, b in zip(events.get(f"{side}_heel_strike", [])[:-1],
                                                            events.get(f"{side}_heel_strike", [])[1:])]
    return float(np.median(d)) if d else None
