"""The format-independent result of reading a trial, before fitting our capture skeleton.

Every reader (OpenSim, C3D, BVH, DeepMimic) extracts a :class:`SkeletonTrack`: world
positions of anatomical landmarks (joint centres, segment tips) and, when the source has
them, world orientations of segments, all already in OUR world frame (Z up, X forward,
Y left, metres) — the reader owns the axis/unit conversion and records it in a
:class:`~solver.capture.GroundFrame`. One fitting step (``solver.io.fit``) then builds the
canonical capture character from the track (segment lengths from the data) and solves
inverse kinematics, whatever the format.

Landmark names (a reader provides what its source has; lower body is required):

    pelvis (mid-point of the hip joint centres), hip_r, knee_r, ankle_r, heel_r, mtp_r, toe_r
    (and _l), lumbar, neck (base of the head), head_top, sternum, shoulder_r, elbow_r,
    wrist_r, hand_r (and _l)

Markers (optional, readers of marker data: C3D) are the file's own markers, each with the
segment it sits on (:class:`TrackMarker`); the fit registers them on the fitted skeleton and
reports how closely it follows them (``solver.io.fit_quality``).

Segment orientations (optional) use our segment axes (x forward, y left, z up when the
subject stands in the neutral pose), keyed by our segment names: pelvis, thigh_r, shank_r,
foot_r, toes_r, abdomen, thorax, head, clavicle_r, upper_arm_r, forearm_r, hand_r, ...
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from solver.capture import GroundFrame, MeasuredGRF

LOWER_LANDMARKS = tuple(
    f"{j}_{s}" for s in ("r", "l") for j in ("hip", "knee", "ankle", "heel", "mtp", "toe")
) + ("pelvis",)
UPPER_LANDMARKS = ("lumbar", "neck", "head_top", "sternum") + tuple(
    f"{j}_{s}" for s in ("r", "l") for j in ("shoulder", "elbow", "wrist", "hand")
)


@dataclass(frozen=True, eq=False)
class TrackMarker:
    """One of the file's markers: the segment it sits on (our segment name), its trajectory (3, T)
    in our world frame (metres, NaN where it is not seen) and the role it plays (``"LKNE"``; empty
    for a marker no role names)."""

    segment: str
    xyz: np.ndarray
    role: str = ""


@dataclass(frozen=True, eq=False)
class SkeletonTrack:
    times: np.ndarray  # (T,) s
    landmarks: Mapping[str, np.ndarray]  # name -> (3, T), our world frame, metres
    orientations: Mapping[str, np.ndarray] = field(default_factory=dict)  # segment -> (3, 3, T) world <- segment
    frame: GroundFrame = field(default_factory=GroundFrame)
    mass: float | None = None  # subject mass (kg) when the source states it
    height: float | None = None  # subject height (m) when known
    segment_masses: Mapping[str, float] | None = None  # our segment name -> kg (from a source model)
    measured: MeasuredGRF | None = None
    contacts: np.ndarray | None = None  # (4, T) heel_r, toe_r, heel_l, toe_l when plates tell
    source: Mapping[str, Any] = field(default_factory=dict)
    markers: Mapping[str, TrackMarker] = field(default_factory=dict)  # file label -> marker

    def __post_init__(self) -> None:
        t = np.asarray(self.times, dtype=float)
        T = t.shape[0]
        for name, p in self.landmarks.items():
            if np.asarray(p).shape != (3, T):
                raise ValueError(f"landmark {name!r} must be (3, T={T}), got {np.asarray(p).shape}")
        for name, r in self.orientations.items():
            if np.asarray(r).shape != (3, 3, T):
                raise ValueError(f"orientation {name!r} must be (3, 3, T={T}), got {np.asarray(r).shape}")
        for name, m in self.markers.items():
            if np.asarray(m.xyz).shape != (3, T):
                raise ValueError(f"marker {name!r} must be (3, T={T}), got {np.asarray(m.xyz).shape}")
        missing = [n for n in LOWER_LANDMARKS if n not in self.landmarks]
        if missing:
            raise ValueError(f"track lacks lower-body landmarks {missing}")

    @property
    def has_upper_body(self) -> bool:
        return all(n in self.landmarks for n in UPPER_LANDMARKS)

    def evolve(self, *, source_update: Mapping[str, Any] | None = None, **changes: Any) -> SkeletonTrack:
        """A copy with ``changes`` (fields) and ``source_update`` merged into the source."""
        if source_update:
            changes["source"] = {**dict(changes.get("source", self.source)), **source_update}
        return replace(self, **changes)


# --- stages every reader shares ------------------------------------------------------------


def add_pelvis(lm: dict[str, np.ndarray]) -> None:
    """The ``pelvis`` landmark: the mid-point of the hip joint centres."""
    lm["pelvis"] = 0.5 * (lm["hip_r"] + lm["hip_l"])


def shift_ground(track: SkeletonTrack, speed: float, how: str, note: str) -> SkeletonTrack:
    """The track of a walk on a moving ground — a treadmill's belt, or an in-place clip (a game
    library's walk with its root motion taken out) — as the same walk overground: every landmark
    gets ``speed·t`` along x (a constant-speed ground is an inertial frame: same forces), and
    ``GroundFrame.velocity`` records it so that results map back onto the moving ground (an
    in-place clip's exports walk in place again). ``how``: where the speed came from; ``note``:
    what the frame's axes say of it."""
    t = np.asarray(track.times, dtype=float)
    shift = np.stack([speed * t, np.zeros_like(t), np.zeros_like(t)])
    lm = {k: np.asarray(p) + shift for k, p in track.landmarks.items()}
    f = track.frame
    frame = GroundFrame(R=f.R, offset=f.offset, unit_m=f.unit_m, velocity=np.array([speed, 0.0, 0.0]),
                        axes=f"{f.axes}; {note}")
    return track.evolve(landmarks=lm, frame=frame, source_update={"belt_speed_m_s": speed, "belt_speed_from": how})


def feet_points(track: SkeletonTrack) -> dict[str, np.ndarray]:
    """Per side (``"r"``, ``"l"``) the mid-point of the heel and the metatarsal heads (3, T)."""
    return {s: 0.5 * (np.asarray(track.landmarks[f"heel_{s}"]) + np.asarray(track.landmarks[f"mtp_{s}"]))
            for s in "rl"}


def split_mass(mass: float, ratios: Mapping[str, float], into: dict[str, float] | None = None) -> dict[str, float]:
    """A source body's ``mass`` shared between our segments in the given ratios (added to
    ``into`` when given): one trunk body -> abdomen, thorax, head, clavicles (Winter)."""
    out = {} if into is None else into
    w = sum(ratios.values())
    for k, v in ratios.items():
        out[k] = out.get(k, 0.0) + mass * v / w
    return out


def rescaled_masses(segment_masses: Mapping[str, float], total: float,
                    mass: float) -> tuple[dict[str, float], float]:
    """A source model's segment masses scaled to the subject's ``mass`` (kg) and the new total."""
    return {k: v * mass / total for k, v in segment_masses.items()}, float(mass)
