"""The input's own skeleton as a rig (:class:`SkeletonRig`: joints, hierarchy, offsets, channels,
the captured animation, the joint that moves each capture segment; its calibration,
:class:`solver.rig_retarget.RotationCalibration`, is the :class:`~solver.retargeting.Calibration`
of BVH, glTF and DeepMimic rigs) and a motion on it (:class:`RigPose`), to and from the plain data
a motion's context carries.

Also the rig's vocabulary: importer joint roles → capture segments, each leg's segments, and unit
quaternions (w, x, y, z) ↔ rotation matrices. ``solver.rig`` describes the method.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial.transform import Rotation

from solver.capture import GroundFrame
from solver.retargeting import RIG_FORMATS, Calibration, Rig, RigError, calibration_kind

if TYPE_CHECKING:
    from solver.motion import Motion

__all__ = ["LEG_SEGMENTS", "MAX_JOINTS", "RIGID_PREFIXES", "RIG_FORMATS", "ROLE_SEGMENTS", "RigError", "RigPose",
           "SkeletonRig", "matrices_to_quats", "quats_to_matrices", "segment_roles"]

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


def _round(a: np.ndarray, nd: int = 6) -> list:
    return np.round(np.asarray(a, dtype=float), nd).tolist()


@dataclass(frozen=True, eq=False)
class RigPose:
    """A motion on the rig: ``local`` (F, J, 3, 3) rotations and ``root`` (F, 3) translation (input
    units) at ``times`` (s from the cycle's start), plus what the feet check needs."""

    times: np.ndarray
    local: np.ndarray
    root: np.ndarray
    positions: np.ndarray | None  # (F, J, 3) local translations of joints with position channels
    capture_time: np.ndarray  # (F,) the rig time of the same gait phase
    ankle_target: np.ndarray  # (F, 2, 3) m, our frame: where the motion's feet carry the ankle joints
    driven: tuple[str, ...]  # segments whose joints the motion drives


def cycle_of(reference: Motion) -> tuple[float, float]:
    """(t_start, period) of the captured cycle a reference motion stands for (its context's)."""
    cyc = reference.context.cycle
    if cyc is None or cyc.t_start is None or cyc.period_s is None:
        raise RigError("the reference motion does not record the captured cycle (its context's cycle)")
    return cyc.t_start, cyc.period_s


def cycle_frames(rig: SkeletonRig, t_start: float, period: float) -> np.ndarray:
    """Indices of the rig frames covering [t_start, t_start + period] (one frame either side)."""
    t = rig.times
    a = max(int(np.searchsorted(t, t_start, side="right")) - 2, 0)
    b = min(int(np.searchsorted(t, t_start + period, side="left")) + 2, t.size)
    if b - a < 2 or t[a] > t_start + 1e-6 or t[b - 1] < t_start + period - 1e-6:
        raise RigError(f"the source rig's frames ({t[0]:.3f}-{t[-1]:.3f} s) do not cover the gait cycle "
                       f"({t_start:.3f}-{t_start + period:.3f} s)")
    return np.arange(a, b)


@dataclass(frozen=True, eq=False)
class SkeletonRig(Rig):
    """A source skeleton and its captured animation (input axes and length units): the rig of a
    BVH, skinned glTF or DeepMimic input (:data:`~solver.retargeting.RIG_FORMATS`).

    ``local`` (F, J, 3, 3) is each joint's full local rotation (rest rotation included) at
    ``times``; ``root`` (F, 3) the root joint's local translation. Child joints sit at their
    ``offsets`` in the parent frame (plus, for BVH joints with position channels, the
    captured ``extra["positions"]``). ``roles``: capture segment -> index of the joint that
    moves it (the joint at the segment's proximal end). ``channels``: per joint, the BVH
    channel names (or ``("quaternion",)`` / ``("Zrotation",)`` for DeepMimic's spherical /
    revolute joints, ``()`` for a fixed joint). ``frame`` maps our world onto the input's axes
    and units. ``extra``: what the writer of that format needs besides (JSON-able).
    ``calibration``: its :class:`~solver.rig_retarget.RotationCalibration` once calibrated
    (:meth:`calibrated`).
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
    calibration: Calibration[Any, Any] | None = None
    file_data: Mapping[str, Any] | None = field(default=None, init=False, repr=False)

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

    def calibrated(self, reference: Motion) -> SkeletonRig:
        """The rig calibrated against ``reference`` (the simplified cycle:
        :meth:`solver.rig_retarget.RotationCalibration.fit`), its animation the frames of the
        captured cycle the calibration holds."""
        cal = calibration_kind(self.format).fit(self, reference)
        idx = cycle_frames(self, *cycle_of(reference))
        extra = dict(self.extra)
        pos = self.positions()
        if pos is not None:
            extra["positions"] = pos[idx].tolist()
        seg = {s.name for s in reference.character.segments}
        extra["calibrated_on"] = sorted(s for s in self.roles if s in seg)
        return self.evolve(times=self.times[idx], local=self.local[idx], root=self.root[idx], extra=extra,
                           calibration=cal)

    # --- plain data (the motion context) ----------------------------------------------------
    def data(self) -> dict[str, Any]:
        """The rig as plain data: its animation left out when its calibration holds the same frames."""
        d: dict[str, Any] = {
            "format": self.format, "names": list(self.names), "parents": list(self.parents),
            "offsets": _round(self.offsets), "channels": [list(c) for c in self.channels],
            "roles": dict(self.roles), "frame": self.frame.to_dict(),
            "end_sites": {str(j): _round(v) for j, v in self.end_sites.items()},
            "extra": dict(self.extra), "frame_time": self.frame_time,
        }
        animation = {"times": _round(self.times), "local": _round(matrices_to_quats(self.local)),
                     "root": _round(self.root)}
        cal = None if self.calibration is None else self.calibration.to_dict()
        if cal is None or any(cal.get(k) != v for k, v in animation.items()):
            d.update(animation)
        if cal is not None:
            d["calibration"] = cal
        return d

    @classmethod
    def read(cls, d: Mapping[str, Any]) -> SkeletonRig:
        names = tuple(str(n) for n in d["names"])
        J = len(names)
        calibration = cls.read_calibration(d)
        held = d if "times" in d else d.get("calibration") or {}  # a calibrated rig's animation: its calibration's
        times = np.asarray(held["times"], dtype=float)
        local = quats_to_matrices(np.asarray(held["local"], dtype=float))
        root = np.asarray(held["root"], dtype=float)
        extra = dict(d.get("extra") or {})
        extra.setdefault("frame_time", float(d.get("frame_time", 1 / 30)))
        return cls(str(d["format"]), names, tuple(int(p) for p in d["parents"]),
                   np.asarray(d["offsets"], dtype=float).reshape(J, 3),
                   tuple(tuple(str(c) for c in ch) for ch in d["channels"]),
                   {str(k): int(v) for k, v in dict(d["roles"]).items()}, times, local, root,
                   GroundFrame.from_dict(d.get("frame")),
                   {int(k): np.asarray(v, dtype=float) for k, v in dict(d.get("end_sites") or {}).items()},
                   extra, calibration)


def segment_roles(roles: Mapping[str, int]) -> dict[str, int]:
    """Importer joint roles (``hip_r``, ``knee_r``, ``lumbar``…) -> capture segment -> joint."""
    return {ROLE_SEGMENTS[r]: int(j) for r, j in roles.items() if r in ROLE_SEGMENTS}
