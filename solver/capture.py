"""What an importer returns: a capture skeleton, its motion, and how to go back to the input.

Importers (``solver.io``) turn a trial of any format into a :class:`Capture`:

* ``character``: a *capture* skeleton with the canonical topology and coordinate names of
  ``capture-full`` (or ``capture-lower`` when the source has no upper body), with the
  subject's dimensions (segment lengths from the data) and masses (from the source model
  when it has them, otherwise Winter's table),
* ``q`` (n, T): its coordinates at the source's sampling times ``times`` (s), in **our**
  world frame (Z up, X forward, Y left, metres),
* ``frame``: the map from our world frame back to the input's ground frame and units,
  so estimates can be written where the input's force plates are,
* optional measured ground reactions (force plates) and the contact schedule they imply.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any

import numpy as np

from solver.character import Character

if TYPE_CHECKING:
    from solver.retargeting import Rig


def _frozen(a: np.ndarray, dtype=float) -> np.ndarray:
    a = np.array(a, dtype=dtype, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class GroundFrame:
    """Our world (Z up, metres) -> the input's ground frame and length unit.

    p_input = (R @ (p - velocity * t) + offset) / unit_m
    ``R`` rotates our axes onto the input's; ``unit_m`` is metres per input length unit
    (0.001 for mm); ``velocity`` (our frame, m/s) is the motion of the input frame
    relative to ours — a treadmill trial made overground-equivalent has the belt velocity
    here, so results map back onto the treadmill's plates.
    """

    R: np.ndarray = field(default_factory=lambda: np.eye(3))
    offset: np.ndarray = field(default_factory=lambda: np.zeros(3))
    unit_m: float = 1.0
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(3))
    axes: str = "x forward, y left, z up"

    def __post_init__(self) -> None:
        r = np.asarray(self.R, dtype=float).reshape(3, 3)
        if not np.allclose(r @ r.T, np.eye(3), atol=1e-9) or np.linalg.det(r) < 0:
            raise ValueError("GroundFrame.R must be a rotation")
        object.__setattr__(self, "R", _frozen(r))
        object.__setattr__(self, "offset", _frozen(np.asarray(self.offset, dtype=float).reshape(3)))
        object.__setattr__(self, "velocity", _frozen(np.asarray(self.velocity, dtype=float).reshape(3)))
        if not self.unit_m > 0:
            raise ValueError("GroundFrame.unit_m must be positive")

    def point_to_input(self, p: np.ndarray, t: np.ndarray | float = 0.0) -> np.ndarray:
        """Points (..., 3) at times t (broadcast over leading axes) -> input coordinates."""
        p = np.asarray(p, dtype=float)
        t = np.asarray(t, dtype=float)[..., None]
        return ((p - self.velocity * t) @ self.R.T + self.offset) / self.unit_m

    def point_from_input(self, p: np.ndarray, t: np.ndarray | float = 0.0) -> np.ndarray:
        p = np.asarray(p, dtype=float)
        t = np.asarray(t, dtype=float)[..., None]
        return (p * self.unit_m - self.offset) @ self.R + self.velocity * t

    def vector_to_input(self, v: np.ndarray) -> np.ndarray:
        """Free vectors (forces, moments) (..., 3): rotated only (SI units kept)."""
        return np.asarray(v, dtype=float) @ self.R.T

    def vector_from_input(self, v: np.ndarray) -> np.ndarray:
        return np.asarray(v, dtype=float) @ self.R

    def to_dict(self) -> dict:
        return {"R": self.R.tolist(), "offset": self.offset.tolist(), "unit_m": float(self.unit_m),
                "velocity": self.velocity.tolist(), "axes": self.axes}

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> GroundFrame:
        if not d:
            return GroundFrame()
        return GroundFrame(R=np.asarray(d["R"], dtype=float), offset=np.asarray(d["offset"], dtype=float),
                           unit_m=float(d["unit_m"]), velocity=np.asarray(d.get("velocity", [0, 0, 0]), dtype=float),
                           axes=str(d.get("axes", "")))


@dataclass(frozen=True, eq=False)
class MeasuredGRF:
    """Force-plate ground reactions per foot, resampled on the capture's times, OUR frame.

    ``force`` (2, 3, T) N, ``cop`` (2, 3, T) m (on the ground), ``free_moment`` (2, T) N·m
    about the vertical at the CoP; feet ordered (right, left). ``valid`` (T,) marks frames
    where every loaded foot is on a plate (the ground reaction is complete).
    """

    force: np.ndarray
    cop: np.ndarray
    free_moment: np.ndarray
    valid: np.ndarray
    source: str = ""

    def __post_init__(self) -> None:
        for name in ("force", "cop", "free_moment"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        object.__setattr__(self, "valid", _frozen(self.valid, dtype=bool))


@dataclass(frozen=True, eq=False)
class Capture:
    character: Character
    q: np.ndarray  # (n, T), our world frame
    times: np.ndarray  # (T,) seconds
    frame: GroundFrame = field(default_factory=GroundFrame)
    source: Mapping[str, Any] = field(default_factory=dict)
    contacts: np.ndarray | None = None  # (P, T) bool, character.contacts order (e.g. from plates)
    measured: MeasuredGRF | None = None
    #: the input's own rig (:class:`solver.retargeting.Rig`), when it has one: a BVH, skinned glTF
    #: or DeepMimic skeleton and its animation at ``times``, an OpenSim trial's model: what results
    #: are written back onto
    rig: Rig | None = None
    #: a gait cycle cut from a longer trial: (n, W) the captured frames just before its first and
    #: (n, W) just after its last, at its rate (``solver.gait.extract_cycle``): what closes its loop
    #: (``solver.gait.close_loop``)
    lead_in: np.ndarray | None = None
    lead_out: np.ndarray | None = None

    def __post_init__(self) -> None:
        q = np.asarray(self.q, dtype=float)
        t = np.asarray(self.times, dtype=float)
        if q.ndim != 2 or q.shape[0] != self.character.n:
            raise ValueError(f"capture q must be (n={self.character.n}, T), got {q.shape}")
        if t.shape != (q.shape[1],):
            raise ValueError(f"capture times must be (T={q.shape[1]},), got {t.shape}")
        if q.shape[1] >= 2 and not np.all(np.diff(t) > 0):
            raise ValueError("capture times must increase strictly")
        object.__setattr__(self, "q", _frozen(q))
        object.__setattr__(self, "times", _frozen(t))
        if self.contacts is not None:
            object.__setattr__(self, "contacts", _frozen(self.contacts, dtype=bool))
        for name in ("lead_in", "lead_out"):
            lead = getattr(self, name)
            if lead is not None:
                lead = np.asarray(lead, dtype=float)
                if lead.ndim != 2 or lead.shape[0] != self.character.n:
                    raise ValueError(f"capture {name} must be (n={self.character.n}, W), got {lead.shape}")
                object.__setattr__(self, name, _frozen(lead))
        object.__setattr__(self, "source", dict(self.source))

    @property
    def T(self) -> int:
        return int(self.q.shape[1])

    @property
    def fps(self) -> float:
        """Sampling rate (uniform sampling is assumed: median step)."""
        return float(1.0 / np.median(np.diff(self.times)))

    def evolve(self, **changes: Any) -> Capture:
        return replace(self, **changes)
