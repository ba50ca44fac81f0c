"""The input's own skeleton as a value: :class:`Rig` (joints, hierarchy, offsets, channels, the
captured animation, the joint that moves each capture segment) and its :class:`Calibration`
against a simplified motion, both to and from the JSON a motion's context carries.

Also the rig's vocabulary: the formats whose rigs are :class:`Rig` values, importer joint roles
→ capture segments, each leg's segments, and unit quaternions (w, x, y, z) ↔ rotation matrices.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from solver.capture import GroundFrame
from solver.errors import InputError

#: the formats whose rigs are :class:`Rig` values (others, e.g. OpenSim's, are their exporter's own mapping)
RIG_FORMATS = ("bvh", "gltf", "deepmimic")
#: at most this many joints in a rig (a full-body rig with fingers and face has ~70–150): it bounds
#: what every motion of the capture carries
MAX_JOINTS = 256
#: importer joint role -> the capture segment that joint moves (the joint at its proximal end)
ROLE_SEGMENTS = {"hips": "pelvis", "lumbar": "abdomen", "head": "head",
                 **{f"{role}_{s}": f"{seg}_{s}" for s in "rl" for role, seg in (
                     ("hip", "thigh"), ("knee", "shank"), ("ankle", "foot"), ("mtp", "toes"),
                     ("clavicle", "clavicle"), ("shoulder", "upper_arm"), ("elbow", "forearm"),
                     ("wrist", "hand"))}}
#: segments whose joints keep one calibration over the cycle (the rig's foot bones move rigidly
#: with the motion's feet, so a planted foot stays planted on the rig)
RIGID_PREFIXES = ("foot_", "toes_")
#: per side, the leg segments whose driving joints the two-bone IK turns
LEG_SEGMENTS = {"r": ("thigh_r", "shank_r", "foot_r"), "l": ("thigh_l", "shank_l", "foot_l")}


class RigError(InputError):
    """A motion cannot be written on its source rig; the message says why."""


def _frozen(a: Any, dtype: Any = float) -> np.ndarray:
    a = np.array(a, dtype=dtype, copy=True)
    a.setflags(write=False)
    return a


def quats_to_matrices(q: np.ndarray) -> np.ndarray:
    """(..., 4) unit quaternions (w, x, y, z) -> (..., 3, 3)."""
    q = np.asarray(q, dtype=float)
    return Rotation.from_quat(q.reshape(-1, 4), scalar_first=True).as_matrix().reshape(q.shape[:-1] + (3, 3))


def matrices_to_quats(R: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> (..., 4) (w, x, y, z), continuous along the first axis (sign flips removed)."""
    R = np.asarray(R, dtype=float)
    q = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat(scalar_first=True).reshape(R.shape[:-2] + (4,))
    if q.ndim >= 2:
        for k in range(1, q.shape[0]):
            flip = np.sum(q[k] * q[k - 1], axis=-1) < 0
            q[k][flip] *= -1
    return q


@dataclass(frozen=True, eq=False)
class Calibration:
    """The rig at the cycle's frames, relative to the simplified motion (see ``solver.rig``)."""

    t_start: float  # s, the cycle's start in the rig's times
    period: float  # s, the capture cycle's duration
    times: np.ndarray  # (F,) rig times covering [t_start, t_start + period]
    local: np.ndarray  # (F, J, 3, 3) captured local rotations
    root: np.ndarray  # (F, 3) captured root translation (input units)
    joint_in_segment: np.ndarray  # (F, J, 3, 3): C_j for driving joints, identity elsewhere
    root_in_pelvis: np.ndarray  # (F, 3) m, the root joint's position in the pelvis frame
    ankle_in_foot: np.ndarray  # (F, 2, 3) m, ankle joints (right, left) in the foot frames

    def __post_init__(self) -> None:
        for name in ("times", "local", "root", "joint_in_segment", "root_in_pelvis", "ankle_in_foot"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))

    def at(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Interpolated (local, root, joint_in_segment, root_in_pelvis, ankle_in_foot) at rig
        times ``t`` (slerp for rotations, linear otherwise)."""
        t = np.clip(np.asarray(t, dtype=float), self.times[0], self.times[-1])

        def rot(a: np.ndarray) -> np.ndarray:
            J = a.shape[1]
            out = np.empty((t.size, J, 3, 3))
            for j in range(J):
                out[:, j] = Slerp(self.times, Rotation.from_matrix(a[:, j]))(t).as_matrix()
            return out

        def lin(a: np.ndarray) -> np.ndarray:
            flat = a.reshape(a.shape[0], -1)
            return np.stack([np.interp(t, self.times, flat[:, c]) for c in range(flat.shape[1])], axis=-1).reshape(
                (t.size,) + a.shape[1:])

        return rot(self.local), lin(self.root), rot(self.joint_in_segment), lin(self.root_in_pelvis), \
            lin(self.ankle_in_foot)

    def to_dict(self) -> dict[str, Any]:
        r6 = _round
        return {"t_start": self.t_start, "period": self.period, "times": r6(self.times),
                "local": r6(matrices_to_quats(self.local)), "root": r6(self.root),
                "joint_in_segment": r6(matrices_to_quats(self.joint_in_segment)),
                "root_in_pelvis": r6(self.root_in_pelvis), "ankle_in_foot": r6(self.ankle_in_foot)}

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> Calibration:
        return Calibration(float(d["t_start"]), float(d["period"]), np.asarray(d["times"], dtype=float),
                           quats_to_matrices(np.asarray(d["local"], dtype=float)),
                           np.asarray(d["root"], dtype=float),
                           quats_to_matrices(np.asarray(d["joint_in_segment"], dtype=float)),
                           np.asarray(d["root_in_pelvis"], dtype=float), np.asarray(d["ankle_in_foot"], dtype=float))


def _round(a: np.ndarray, nd: int = 6) -> list:
    return np.round(np.asarray(a, dtype=float), nd).tolist()


@dataclass(frozen=True, eq=False)
class Rig:
    """A source skeleton and its captured animation (input axes and length units).

    ``local`` (F, J, 3, 3) is each joint's full local rotation (rest rotation included) at
    ``times``; ``root`` (F, 3) the root joint's local translation. Child joints sit at their
    ``offsets`` in the parent frame (plus, for BVH joints with position channels, the
    captured ``extra["positions"]``). ``roles``: capture segment -> index of the joint that
    moves it (the joint at the segment's proximal end). ``channels``: per joint, the BVH
    channel names (or ``("quaternion",)`` / ``("Zrotation",)`` for DeepMimic's spherical /
    revolute joints, ``()`` for a fixed joint). ``frame`` maps our world onto the input's axes
    and units. ``extra``: what the writer of that format needs besides (JSON-able).
    """

    format: str
    names: tuple[str, ...]
    parents: tuple[int, ...]
    offsets: np.ndarray  # (J, 3)
    channels: tuple[tuple[str, ...], ...]
    roles: Mapping[str, int]
    times: np.ndarray  # (F,)
    local: np.ndarray  # (F, J, 3, 3)
    root: np.ndarray  # (F, 3)
    frame: GroundFrame = field(default_factory=GroundFrame)
    end_sites: Mapping[int, np.ndarray] = field(default_factory=dict)
    extra: Mapping[str, Any] = field(default_factory=dict)
    calibration: Calibration | None = None

    def __post_init__(self) -> None:
        J = len(self.names)
        if J > MAX_JOINTS:
            raise RigError(f"the input's skeleton has {J} joints; at most {MAX_JOINTS} are supported")
        if len(self.parents) != J or len(self.channels) != J:
            raise RigError("rig: names, parents and channels must have one entry per joint")
        if J == 0 or self.parents[0] != -1 or any(not -1 < p < j for j, p in enumerate(self.parents) if j):
            raise RigError("rig: joints must be listed parents first, the root first")
        for name in ("offsets", "times", "local", "root"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        F = self.times.shape[0]
        if self.offsets.shape != (J, 3) or self.local.shape != (F, J, 3, 3) or self.root.shape != (F, 3):
            raise RigError(f"rig: expected offsets (J={J}, 3), local (F={F}, J, 3, 3), root (F, 3); got "
                           f"{self.offsets.shape}, {self.local.shape}, {self.root.shape}")
        bad = {s: j for s, j in self.roles.items() if not 0 <= int(j) < J}
        if bad:
            raise RigError(f"rig: roles point at no joint: {bad}")
        object.__setattr__(self, "roles", {str(s): int(j) for s, j in self.roles.items()})
        object.__setattr__(self, "end_sites", {int(j): _frozen(v) for j, v in self.end_sites.items()})
        object.__setattr__(self, "extra", dict(self.extra))

    @property
    def J(self) -> int:
        return len(self.names)

    @property
    def frame_time(self) -> float:
        if self.times.size < 2:
            return float(self.extra.get("frame_time", 1 / 30))
        return float(np.median(np.diff(self.times)))

    def positions(self) -> np.ndarray | None:
        """(F, J, 3) captured local translations of joints with position channels, else None."""
        p = self.extra.get("positions")
        return None if p is None else np.asarray(p, dtype=float)

    def forward(self, local: np.ndarray, root: np.ndarray, positions: np.ndarray | None = None
                ) -> tuple[np.ndarray, np.ndarray]:
        """World rotations (F, J, 3, 3) and positions (F, J, 3) in the input's axes and units."""
        F = local.shape[0]
        W = np.empty_like(local)
        P = np.empty((F, self.J, 3))
        for j, p in enumerate(self.parents):
            if p < 0:
                W[:, j], P[:, j] = local[:, j], root
            else:
                off = self.offsets[j] if positions is None else positions[:, j]
                W[:, j] = W[:, p] @ local[:, j]
                P[:, j] = P[:, p] + np.einsum("fij,fj->fi", W[:, p], np.broadcast_to(off, (F, 3)))
        return W, P

    def evolve(self, **changes: Any) -> Rig:
        return replace(self, **changes)

    # --- JSON (the motion context) -------------------------------------------------------
    def to_dict(self, *, animation: bool = True) -> dict[str, Any]:
        d: dict[str, Any] = {
            "format": self.format, "names": list(self.names), "parents": list(self.parents),
            "offsets": _round(self.offsets), "channels": [list(c) for c in self.channels],
            "roles": dict(self.roles), "frame": self.frame.to_dict(),
            "end_sites": {str(j): _round(v) for j, v in self.end_sites.items()},
            "extra": dict(self.extra), "frame_time": self.frame_time,
        }
        if animation:
            d.update(times=_round(self.times), local=_round(matrices_to_quats(self.local)), root=_round(self.root))
        if self.calibration is not None:
            d["calibration"] = self.calibration.to_dict()
        return d

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> Rig:
        try:
            names = tuple(str(n) for n in d["names"])
            J = len(names)
            cal = d.get("calibration")
            calibration = Calibration.from_dict(cal) if cal else None
            if "times" in d:
                times = np.asarray(d["times"], dtype=float)
                local = quats_to_matrices(np.asarray(d["local"], dtype=float))
                root = np.asarray(d["root"], dtype=float)
            elif calibration is not None:  # a calibrated rig needs no animation of its own
                times, local, root = calibration.times, calibration.local, calibration.root
            else:
                raise KeyError("times")
            extra = dict(d.get("extra") or {})
            extra.setdefault("frame_time", float(d.get("frame_time", 1 / 30)))
            return Rig(str(d["format"]), names, tuple(int(p) for p in d["parents"]),
                       np.asarray(d["offsets"], dtype=float).reshape(J, 3),
                       tuple(tuple(str(c) for c in ch) for ch in d["channels"]),
                       {str(k): int(v) for k, v in dict(d["roles"]).items()}, times, local, root,
                       GroundFrame.from_dict(d.get("frame")),
                       {int(k): np.asarray(v, dtype=float) for k, v in dict(d.get("end_sites") or {}).items()},
                       extra, calibration)
        except (KeyError, TypeError, ValueError) as e:
            raise RigError(f"the motion's source rig is unreadable ({e.__class__.__name__}: {e})") from None


def segment_roles(roles: Mapping[str, int]) -> dict[str, int]:
    """Importer joint roles (``hip_r``, ``knee_r``, ``lumbar``…) -> capture segment -> joint."""
    return {ROLE_SEGMENTS[r]: int(j) for r, j in roles.items() if r in ROLE_SEGMENTS}
