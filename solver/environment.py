"""The environment a motion lives in, as a value: gravity vector, friction coefficient and
terrain (stairs: treads of a rise and a going along the walker's direction of travel, one per
step; :func:`stair_flight` is the one geometry the optimizer, the checks, the simulation and the
plots read).

One home for standard gravity (``STANDARD_GRAVITY``): nothing else spells out 9.81. A motion
carries its environment in its context (``Motion.environment``, ``solver.motion.MotionContext``).
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
#: m, the going (tread depth) of stairs when a target gives a rise and no going: building codes ask
#: 0.25–0.30 m (rise 0.15–0.19 m; e.g. the UK's Approved Document K, the US IBC 1011.5: going ≥ 0.28 m)
DEFAULT_GOING_M = 0.28


@dataclass(frozen=True)
class Environment:
    """Gravity vector (m/s², world frame), Coulomb friction coefficient of the ground, and the
    terrain: ``step_height_m`` raises the ground under each successive stance by that riser
    height (stairs; negative: down; 0: the flat ground z = 0); ``step_going_m`` the treads' depth
    along the direction of travel (0: the walker's own step); ``stairs_at`` where the flight
    stands: (x, y, heading) of the riser line of tread 0 (None: fitted to the walk's stance feet,
    :func:`stair_flight`)."""

    gravity: tuple[float, float, float] = STANDARD_GRAVITY_VECTOR
    friction: float = DEFAULT_FRICTION
    step_height_m: float = 0.0
    step_going_m: float = 0.0
    stairs_at: tuple[float, float, float] | None = None

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
        if not (math.isfinite(self.step_going_m) and self.step_going_m >= 0):
            raise ValueError(f"step_going_m must be a positive number of metres (0: the walker's own step), "
                             f"got {self.step_going_m!r}")
        object.__setattr__(self, "step_going_m", float(self.step_going_m))
        if self.stairs_at is not None:
            at = tuple(float(v) for v in self.stairs_at)
            if len(at) != 3 or not all(math.isfinite(v) for v in at):
                raise ValueError(f"stairs_at must be a finite (x, y, heading), got {self.stairs_at!r}")
            object.__setattr__(self, "stairs_at", at)

    @property
    def gravity_magnitude(self) -> float:
        return math.sqrt(sum(v * v for v in self.gravity))

    def to_dict(self) -> dict:
        out = {"gravity": [float(g) for g in self.gravity], "friction": float(self.friction)}
        if self.step_height_m:
            terrain: dict[str, Any] = {"step_height_m": float(self.step_height_m)}
            if self.step_going_m:
                terrain["step_going_m"] = float(self.step_going_m)
            if self.stairs_at is not None:
                terrain["stairs_at"] = [float(v) for v in self.stairs_at]
            out["terrain"] = terrain
        return out

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> Environment:
        if not d:
            return Environment()
        g = tuple(float(x) for x in d.get("gravity", STANDARD_GRAVITY_VECTOR))
        terrain = d.get("terrain") or {}
        at = terrain.get("stairs_at")
        return Environment(g, float(d.get("friction", DEFAULT_FRICTION)),  # type: ignore[arg-type]
                           float(terrain.get("step_height_m", 0.0)), float(terrain.get("step_going_m", 0.0)),
                           None if at is None else tuple(at))

    def with_(self, **changes: Any) -> Environment:
        from dataclasses import replace

        return replace(self, **changes)


def body_weight(motion: Any) -> float:
    """Body weight (N) in the motion's own environment (standard gravity when it has none)."""
    g = motion.environment.gravity_magnitude
    return float(motion.character.total_mass) * (g if g > 0 else STANDARD_GRAVITY)


def stair_indices(foot_contact: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """The treads of a cyclic foot schedule (frames T−2, T−1 repeat frames 0, 1), one per step
    (step-over-step): the stances of the cycle, in the order they begin, stand on treads 0, 1, …,
    n−1; a stance that began in the previous cycle on tread −1, …; frames T−2, T−1 are frames 0,
    1 on treads n up. Returns (left, reached, n): (2, T) integer arrays — in contact both the
    foot's tread, swinging the tread it left and the one it reaches — and n, the stances per
    cycle. Without a stance (or fewer than 5 frames): zeros and n = 0."""
    B = np.asarray(foot_contact, dtype=bool)
    T = B.shape[1]
    left, reached = np.zeros((2, T), dtype=int), np.zeros((2, T), dtype=int)
    if T < 5:
        return left, reached, 0
    P = T - 2
    onsets = sorted((t, f) for f in range(2) for t in range(P) if B[f, t] and not B[f, (t - 1) % P])
    n = len(onsets)
    if n == 0:
        return left, reached, 0
    rank = {o: i for i, o in enumerate(onsets)}

    def tread(f: int, t: int, step: int) -> int | None:
        """Tread of the first stance of foot f met walking from frame t by ``step`` (±1; t may
        leave [0, P): frames of other cycles)."""
        u = t
        for _ in range(P + 1):
            if B[f, u % P]:
                while (u % P, f) not in rank:  # back to that stance's onset
                    u -= 1
                return rank[(u % P, f)] + n * math.floor(u / P)
            u += step
        return None

    for f in range(2):
        for t in range(P):
            a = tread(f, t, -1)
            b = a if B[f, t] else tread(f, t, +1)
            a = b if a is None else a
            b = a if b is None else b
            left[f, t], reached[f, t] = a or 0, b or 0
    left[:, P:], reached[:, P:] = left[:, :2] + n, reached[:, :2] + n
    return left, reached, n


def stair_heights(foot_contact: np.ndarray, riser: float) -> np.ndarray:
    """(2, T) ground height under each foot per frame on stairs of riser height ``riser``, for a
    cyclic foot schedule (:func:`stair_indices`): tread k stands at k × riser; a swinging foot's
    ground is the lower of the tread it left and the tread it reaches."""
    B = np.asarray(foot_contact, dtype=bool)
    if riser == 0.0 or B.shape[1] < 5:
        return np.zeros(B.shape)
    left, reached, _ = stair_indices(B)
    return np.minimum(left * riser, reached * riser).astype(float)


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
    return stair_indices(foot_contact)[2] * float(riser)


def walker_going(q: np.ndarray, foot_contact: np.ndarray) -> float:
    """The walker's own step (m): the root's horizontal travel over a cycle of frames T−2 per
    stance of the cycle (the going of treads one level step apart)."""
    q = np.asarray(q, dtype=float)
    n = stair_indices(foot_contact)[2]
    return float(np.linalg.norm(q[:2, q.shape[1] - 2] - q[:2, 0])) / max(n, 1)


@dataclass(frozen=True)
class Flight:
    """A straight flight of stairs along the walker's direction of travel (step-over-step: one
    tread per step). Along s (m, from ``origin`` along ``heading``), tread k spans
    [k·going, (k+1)·going] at height k·rise; the riser between treads k−1 and k stands at
    s = k·going, and its top edge, the **nosing**, at the higher of the two heights (going up:
    the front edge of tread k; going down: the front edge of tread k−1). ``left``/``reached``
    (2, T): each foot's tread per frame (:func:`stair_indices`), ``n`` treads per cycle."""

    rise: float
    going: float
    origin: tuple[float, float]
    heading: float
    left: np.ndarray
    reached: np.ndarray
    n: int

    @property
    def direction(self) -> np.ndarray:
        return np.array([math.cos(self.heading), math.sin(self.heading)])

    @property
    def at(self) -> tuple[float, float, float]:
        """(x, y, heading): ``Environment.stairs_at``."""
        return (float(self.origin[0]), float(self.origin[1]), float(self.heading))

    def along(self, xy: np.ndarray) -> np.ndarray:
        """s of points (2, ...) along the flight."""
        xy = np.asarray(xy, dtype=float)
        d = xy - np.asarray(self.origin, dtype=float).reshape((2,) + (1,) * (xy.ndim - 1))
        return np.cos(self.heading) * d[0] + np.sin(self.heading) * d[1]

    def height(self, k: Any) -> Any:
        return np.asarray(k) * self.rise

    def nosing(self, k: Any) -> tuple[Any, Any]:
        """(s, height) of the nosing of riser k (between treads k−1 and k)."""
        k = np.asarray(k)
        return k * self.going, np.maximum((k - 1) * self.rise, k * self.rise)

    def ground(self, s: Any) -> Any:
        """Height of the tread under the points at s."""
        return np.floor(np.asarray(s, dtype=float) / self.going) * self.rise

    def treads(self, first: int, last: int) -> list[dict[str, Any]]:
        """Treads ``first`` … ``last`` as drawable boxes: index, the back and front edge along s and
        their world (x, y), the height."""
        u = self.direction
        o = np.asarray(self.origin, dtype=float)
        return [{"index": k, "s": [k * self.going, (k + 1) * self.going], "height": float(k * self.rise),
                 "back_xy": (o + k * self.going * u).tolist(), "front_xy": (o + (k + 1) * self.going * u).tolist()}
                for k in range(first, last + 1)]


def stair_flight(feet_xy: np.ndarray | None, foot_contact: np.ndarray, rise: float, going: float,
                 at: tuple[float, float, float] | None = None, q: np.ndarray | None = None) -> Flight:
    """The stairs a walk climbs: treads ``going`` deep and ``rise`` high along the walk, each
    stance of the foot schedule on its own tread (:func:`stair_indices`). ``at``: where the flight
    stands (``Environment.stairs_at``); None: along the root's travel over the cycle (``q``
    required), shifted so that the stance feet's centres (``feet_xy`` (2, 2, T): each foot's
    mean contact point) stand, on average, in the middle of their treads."""
    if not (math.isfinite(going) and going > 0):
        raise ValueError(f"the going of stairs must be a positive number of metres, got {going!r}")
    B = np.asarray(foot_contact, dtype=bool)
    left, reached, n = stair_indices(B)
    if at is not None:
        return Flight(float(rise), float(going), (float(at[0]), float(at[1])), float(at[2]), left, reached, n)
    if q is None:
        raise ValueError("placing a flight of stairs needs the walk's root path (q)")
    q = np.asarray(q, dtype=float)
    T = q.shape[1]
    chord = q[:2, T - 2] - q[:2, 0]
    heading = math.atan2(chord[1], chord[0]) if np.linalg.norm(chord) > 1e-9 else float(q[3, 0])
    flight = Flight(float(rise), float(going), (float(q[0, 0]), float(q[1, 0])), heading, left, reached, n)
    sel = B[:, : T - 2]
    if feet_xy is None or not sel.any():
        return flight
    xy = np.asarray(feet_xy, dtype=float)
    s = flight.along(np.moveaxis(xy[:, :, : T - 2], 1, 0))  # (2, T−2)
    shift = float(np.mean(s[sel] - (left[:, : T - 2][sel] + 0.5) * going))
    o = np.asarray(flight.origin) + shift * flight.direction
    return Flight(float(rise), float(going), (float(o[0]), float(o[1])), heading, left, reached, n)


def ground_of(motion: Any) -> np.ndarray:
    """(2, T) ground height under each foot per frame of a motion (zeros on flat ground)."""
    env = motion.environment
    if not env.step_height_m or motion.contacts is None:
        return np.zeros((2, motion.T))
    return stair_heights(motion.foot_contact(), env.step_height_m)

