"""Landmarks of a character skeleton's joints (the BVH and the skinned glTF importers' shared stage).

Public API::

    JointPose(parents, R_rest, P_rest, R, P, end_sites, up_v)   # joints at rest and along the clip
    ground_landmarks(pose, roles, scale, floor_height, path, error) -> Grounded

An importer that reads a skeleton animation (joint names, hierarchy, a rest pose and the joints'
world rotations and positions along the clip, in its own axes and length unit) hands them to
:class:`JointPose` and :func:`ground_landmarks`, which place our landmarks:

- **legs** (:meth:`JointPose.feet`): hip, knee, ankle joints; the toes joint's position (else
  the metatarsal heads at 72 % heel -> toe, 2 cm above the sole); the heel, placed in the rest
  pose behind and below the ankle — 25 % of the ankle -> toe-tip horizontal length behind it,
  at the sole (the rest pose's lowest toe point) — and carried by the foot joint; the toe tip
  moved to the sole the same way; pelvis = mid-point of the hips.
- **upper body** (:meth:`JointPose.upper_body`, all or nothing): lumbar joint, neck = the head
  joint (base of the head), head top = the head's tip, sternum = mid-point of the clavicle
  joints (else the neck joint, else the mid-point of the shoulders), shoulders, elbows, wrists
  and hand tips.

A joint's *tip* is its End Site, else its first child, in the rest pose; an End Site or child
at the joint itself (a zero-length End Site, as some game exporters write them) is no tip. A
head, hand or toes joint without a tip gets one placed by proportion along its bone (the
parent -> joint direction; the toes: ahead of the metatarsal heads along the foot): a head
0.27 × the rest leg (hip -> knee -> ankle) long, a hand 0.22 ×, toes 0.35 × the ankle ->
toes joint distance (Winter's segment lengths); ``Grounded.estimated`` names them.

**In-place clips** (:func:`walk_in_place`): a game library's walk usually has its root motion
taken out — the hips stay over the origin and the feet slide back under them. Such a clip is
a walk on a treadmill whose belt runs at the walking speed: the stance foot moves backwards at
that speed. Unless told otherwise the clip is taken as in place when its pelvis travels less
than 0.15 m/s while its stance foot slides back faster than 0.3 m/s; the speed is then the
stance foot's median backward speed, or the ``belt_speed`` given (m/s), and every landmark is
shifted by speed × t (:func:`solver.io.track.shift_ground`): the walk overground, with the
same forces. ``GroundFrame.velocity`` keeps the speed, so results written on the input's own
rig walk in place again, as the input did.

**Axes** (:func:`ground_landmarks`): our X is the subject's facing direction (horizontal,
perpendicular to the right -> left hip line, averaged over the clip), Y left, Z up (``up_v``,
the input's up direction, a unit vector in its axes); the floor (our z = 0) is
``floor_height`` (input units, along ``up_v``) or the 2nd percentile of the sole points'
heights over the clip; ``scale`` is metres per input unit.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from solver.errors import InputError
from solver.io.track import SkeletonTrack, add_pelvis, feet_points, shift_ground

__all__ = ["Grounded", "JointPose", "ground_landmarks", "walk_in_place"]

#: a tip closer than this to its joint (input units × metres per unit: 1 mm) is no tip
TIP_MIN_M = 1e-3
#: segment lengths placed by proportion, as fractions of the rest leg (hip -> knee -> ankle):
#: Winter's head (0.130 H) and hand (0.108 H) over his leg (0.491 H)
HEAD_OF_LEG, HAND_OF_LEG = 0.27, 0.22
#: the toes beyond the metatarsal heads, as a fraction of the ankle -> toes joint distance
TOES_OF_FOOT = 0.35
#: in place: the pelvis travels less than this (m/s) while the stance foot slides back faster
#: than ``IN_PLACE_FOOT_M_S``
IN_PLACE_PELVIS_M_S, IN_PLACE_FOOT_M_S = 0.15, 0.3


class JointPose:
    """A skeleton's joints along a clip and in its rest pose, in the input's axes and units.

    ``R_rest`` (J, 3, 3), ``P_rest`` (J, 3): world rotations and positions at rest; ``R``
    (J, T, 3, 3), ``P`` (J, T, 3) along the clip; ``end_sites``: joint -> End Site offset in
    the joint's frame; ``up_v``: the input's up direction (unit); ``error``: the importer's
    :class:`InputError` subclass for what the skeleton lacks."""

    def __init__(self, parents: tuple[int, ...] | list[int], R_rest: np.ndarray, P_rest: np.ndarray, R: np.ndarray,
                 P: np.ndarray, end_sites: Mapping[int, np.ndarray], up_v: np.ndarray,
                 error: type[InputError] = InputError) -> None:
        self.parents = tuple(int(p) for p in parents)
        self.R_rest, self.P_rest = np.asarray(R_rest, dtype=float), np.asarray(P_rest, dtype=float)
        self.R, self.P = np.asarray(R, dtype=float), np.asarray(P, dtype=float)
        self.end_sites = {int(j): np.asarray(v, dtype=float) for j, v in end_sites.items()}
        self.up_v = np.asarray(up_v, dtype=float)
        self.error = error
        self.children = {j: [c for c, p in enumerate(self.parents) if p == j] for j in range(len(self.parents))}
        self.min_tip = 0.0  # input units: set by ground_landmarks from the metres per unit
        self.estimated: list[str] = []  # the tips placed by proportion

    def tip(self, j: int) -> np.ndarray | None:
        """Rest-pose position of a joint's tip: its End Site or its first child, whichever is
        first away from the joint (a zero-length End Site is no tip)."""
        cands = []
        if j in self.end_sites:
            cands.append(self.P_rest[j] + self.R_rest[j] @ self.end_sites[j])
        cands += [self.P_rest[c] for c in self.children[j]]
        return next((c for c in cands if np.linalg.norm(c - self.P_rest[j]) > self.min_tip), None)

    def leg_length(self, roles: Mapping[str, int]) -> float:
        """The rest legs' mean hip -> knee -> ankle length (input units)."""
        P = self.P_rest
        return float(np.mean([np.linalg.norm(P[roles[f"hip_{s}"]] - P[roles[f"knee_{s}"]])
                              + np.linalg.norm(P[roles[f"knee_{s}"]] - P[roles[f"ankle_{s}"]]) for s in "rl"]))

    def tip_or_estimate(self, j: int, length: float, what: str) -> np.ndarray | None:
        """A joint's tip, else a point ``length`` along its bone (parent -> joint) from it, named
        ``what`` in :attr:`estimated`; None when the bone has no direction either."""
        t = self.tip(j)
        if t is not None:
            return t
        p = self.parents[j]
        d = self.P_rest[j] - self.P_rest[p] if p >= 0 else self.up_v
        if np.linalg.norm(d) <= self.min_tip:
            return None
        self.estimated.append(what)
        return self.P_rest[j] + length * d / np.linalg.norm(d)

    def world(self, j: int, local: np.ndarray) -> np.ndarray:
        """A point fixed in joint j's frame (``local``) along the clip, (T, 3)."""
        return self.P[j] + np.einsum("tij,j->ti", self.R[j], local)

    def attached(self, j: int, rest_point: np.ndarray) -> np.ndarray:
        """A rest-pose point carried by joint j along the clip."""
        return self.world(j, self.R_rest[j].T @ (rest_point - self.P_rest[j]))

    def feet(self, roles: Mapping[str, int], scale: float, path: str | Path) -> dict[str, np.ndarray]:
        """Leg joints, heel and toe on the sole (and the metatarsal heads of a foot without a toes
        joint), (T, 3) each, input axes and units; the pelvis between the hips."""
        P_rest, R_rest, up_v = self.P_rest, self.R_rest, self.up_v
        raw: dict[str, np.ndarray] = {}
        for s in "rl":
            for r in ("hip", "knee", "ankle"):
                raw[f"{r}_{s}"] = self.P[roles[f"{r}_{s}"]]
            a = roles[f"ankle_{s}"]
            mtp_j = roles.get(f"mtp_{s}")
            toe_rest = self.tip(mtp_j) if mtp_j is not None else self.tip(a)
            if toe_rest is None and mtp_j is not None:  # a toes joint without a tip: the toes ahead of it
                fwd_m = P_rest[mtp_j] - P_rest[a]
                fwd_m = fwd_m - (fwd_m @ up_v) * up_v
                if np.linalg.norm(fwd_m) > self.min_tip:
                    toe_rest = P_rest[mtp_j] + TOES_OF_FOOT * fwd_m
                    self.estimated.append(f"toe_{s}")
            if toe_rest is None:
                raise self.error(f"{path}: the {'right' if s == 'r' else 'left'} foot has no toe joint nor End "
                                 "Site: cannot place the toes")
            ank = P_rest[a]
            sole_h = min(float(toe_rest @ up_v), float(P_rest[mtp_j] @ up_v) if mtp_j is not None else np.inf)
            fwd = (toe_rest - ank) - ((toe_rest - ank) @ up_v) * up_v
            heel = ank - 0.25 * fwd + (sole_h - ank @ up_v) * up_v
            toe_sole = toe_rest + (sole_h - toe_rest @ up_v) * up_v
            body = mtp_j if mtp_j is not None else a
            if mtp_j is None:  # no toes joint: metatarsal heads at 72 % heel -> toe, 2 cm (scaled) above the sole
                m = heel + 0.72 * (toe_sole - heel) + (0.02 / scale) * up_v
                raw[f"mtp_{s}"] = self.world(a, R_rest[a].T @ (m - ank))
            else:
                raw[f"mtp_{s}"] = self.P[mtp_j]
            raw[f"heel_{s}"] = self.world(a, R_rest[a].T @ (heel - ank))
            raw[f"toe_{s}"] = self.world(body, R_rest[body].T @ (toe_sole - P_rest[body]))
        add_pelvis(raw)
        return raw

    def upper_body(self, roles: Mapping[str, int]) -> dict[str, np.ndarray]:
        """Lumbar, neck, head top, sternum, arms; a KeyError naming what the skeleton lacks."""
        P = self.P
        upper: dict[str, np.ndarray] = {}
        # lumbar: the first spine joint clearly above the hips (CMU's LowerBack sits on the root)
        if "lumbar" not in roles:
            raise KeyError("spine joint above the hips")
        upper["lumbar"] = P[roles["lumbar"]]
        head = roles["head"]
        upper["neck"] = P[head]
        leg = self.leg_length(roles)
        ht = self.tip_or_estimate(head, HEAD_OF_LEG * leg, "head_top")
        if ht is None:
            raise KeyError("head top")
        upper["head_top"] = self.attached(head, ht)
        if "clavicle_r" in roles and "clavicle_l" in roles:
            upper["sternum"] = 0.5 * (P[roles["clavicle_r"]] + P[roles["clavicle_l"]])
        elif "neck" in roles:
            upper["sternum"] = P[roles["neck"]]
        else:
            upper["sternum"] = 0.5 * (P[roles["shoulder_r"]] + P[roles["shoulder_l"]])
        for s in "rl":
            upper[f"shoulder_{s}"] = P[roles[f"shoulder_{s}"]]
            upper[f"elbow_{s}"] = P[roles[f"elbow_{s}"]]
            w = roles[f"wrist_{s}"]
            upper[f"wrist_{s}"] = P[w]
            ht = self.tip_or_estimate(w, HAND_OF_LEG * leg, f"hand_{s}")
            if ht is None:
                raise KeyError(f"hand tip {s}")
            upper[f"hand_{s}"] = self.attached(w, ht)
        return upper


@dataclass(frozen=True, eq=False)
class Grounded:
    """Landmarks in our frame and how the input's axes map onto it."""

    landmarks: dict[str, np.ndarray]  # name -> (3, T), our axes, metres
    R: np.ndarray  # rows: our axes in input coordinates (ours = R @ input); GroundFrame.R is its transpose
    offset: np.ndarray  # the floor's origin in input coordinates (input units)
    facing: np.ndarray  # our X (the facing direction) in input coordinates
    floor_height: float  # input units, along up_v
    upper_body: bool  # whether the upper landmarks could all be placed
    missing_upper: str | None  # what the upper body lacks, when it could not be placed
    estimated: tuple[str, ...] = ()  # landmarks whose tips were placed by proportion (no End Site, no child)


def ground_landmarks(pose: JointPose, roles: Mapping[str, int], scale: float, floor_height: float | None,
                     path: str | Path) -> Grounded:
    """Our landmarks from the joints (see the module doc): the facing direction from the hip line
    averaged over the clip, the floor from the soles unless ``floor_height`` is given."""
    up_v = pose.up_v
    pose.min_tip = TIP_MIN_M / scale
    pose.estimated = []
    hl = pose.P[roles["hip_l"]] - pose.P[roles["hip_r"]]  # (T, 3)
    hl = hl - np.outer(hl @ up_v, up_v)
    norms = np.linalg.norm(hl, axis=1, keepdims=True)
    if not np.all(norms > 1e-12):
        raise pose.error(f"{path}: the hip joints coincide (zero-length hip line): cannot tell the facing direction")
    mean = np.mean(hl / norms, axis=0)
    if np.linalg.norm(mean) < 1e-12:
        raise pose.error(f"{path}: degenerate skeleton geometry (the hip line turns all the way round)")
    y_dir = mean / np.linalg.norm(mean)
    x_dir = np.cross(y_dir, up_v)
    A = np.stack([x_dir, y_dir, up_v])  # rows: our axes in input coordinates -> ours = A @ input
    raw = pose.feet(roles, scale, path)
    missing = None
    try:  # upper body (all or nothing)
        raw.update(pose.upper_body(roles))
    except KeyError as e:
        missing = str(e)
    if floor_height is None:
        soles = np.concatenate([raw[f"{k}_{s}"] @ up_v for k in ("heel", "toe") for s in "rl"])
        floor_height = float(np.percentile(soles, 2))
    offset = floor_height * up_v
    lm = {k: ((v - offset) @ A.T * scale).T for k, v in raw.items()}
    return Grounded(lm, A, offset, x_dir, float(floor_height), missing is None, missing, tuple(pose.estimated))


def walk_in_place(track: SkeletonTrack, belt_speed: float | str | None, error: type[InputError],
                  path: str | Path) -> SkeletonTrack:
    """An in-place clip's track as the walk overground (see the module doc): ``belt_speed`` None
    detects it, ``"auto"`` takes the stance foot's speed, a number (m/s) is the walking speed, 0
    leaves the track as it is. The track's source records ``in_place`` and the speed."""
    from solver.gait.base import GaitError
    from solver.gait.belt import belt_speed as stance_speed

    if belt_speed is not None and not isinstance(belt_speed, str):
        v = float(belt_speed)
        if not (np.isfinite(v) and abs(v) <= 10.0):
            raise error(f"{path}: belt_speed {belt_speed!r} m/s is not a walking speed", parameter="belt_speed")
        if v == 0.0:
            return track
        return shift_ground(track, v, "given", "an in-place clip: its ground moving at -velocity")
    if belt_speed is not None and belt_speed != "auto":
        raise error(f"{path}: belt_speed must be a speed (m/s) or 'auto', got {belt_speed!r}", parameter="belt_speed")
    t = np.asarray(track.times, dtype=float)
    duration = float(t[-1] - t[0]) if t.size > 1 else 0.0
    try:
        v = stance_speed(t, feet_points(track))
    except GaitError:
        if belt_speed == "auto":
            raise error(f"{path}: no stance foot to measure the walking speed on; pass belt_speed=... (m/s)",
                        parameter="belt_speed") from None
        return track
    pelvis = np.asarray(track.landmarks["pelvis"])
    travel = float(np.linalg.norm(pelvis[:2, -1] - pelvis[:2, 0]) / duration) if duration > 0 else 0.0
    if belt_speed is None and not (travel < IN_PLACE_PELVIS_M_S and v > IN_PLACE_FOOT_M_S):
        return track
    out = shift_ground(track, v, "the stance foot's backward speed (an in-place clip)",
                       "an in-place clip: its ground moving at -velocity")
    return out.evolve(source_update={"in_place": {"pelvis_travel_m_s": round(travel, 4), "speed_m_s": round(v, 4),
                                                  "detected": belt_speed is None}})
