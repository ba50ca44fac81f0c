"""A skeleton rig's calibration (:class:`RotationCalibration`, fitted against the simplified
motion), a motion put back on the rig through it (:func:`retarget`, :func:`follow`), and how well
the rig follows it.

At each output time the gait phase picks the calibrated rig time; driving joints take the
motion's segment rotations through their calibration, other joints their captured rotations,
the root its place from the pelvis; each leg is then closed by a two-bone IK onto where the
motion's foot carries the ankle joint, with the feet pinned where they touched down
(:func:`foot_pins`). :func:`feet_report` and :func:`locked_joint_rms` measure the result from the
rig's own forward kinematics. ``solver.rig`` describes the method.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
from scipy.spatial.transform import Rotation, Slerp

from solver.kinematics import contact_points, segment_frames
from solver.retargeting import Calibration
from solver.rig_skeleton import (
    LEG_SEGMENTS,
    RIGID_PREFIXES,
    RigError,
    RigPose,
    SkeletonRig,
    cycle_frames,
    cycle_of,
    matrices_to_quats,
    quats_to_matrices,
)
from solver.trajectory import sample

if TYPE_CHECKING:
    from solver.motion import Motion


def _frozen(a: Any) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


def _round(a: np.ndarray, nd: int = 6) -> list:
    return np.round(np.asarray(a, dtype=float), nd).tolist()


@dataclass(frozen=True, eq=False)
class RotationCalibration(Calibration[SkeletonRig, RigPose]):
    """The rig at the cycle's frames, relative to the simplified motion (see ``solver.rig``):
    interpolated between those frames by slerp (:meth:`at`)."""

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

    @classmethod
    def fit(cls, rig: SkeletonRig, reference: Motion) -> RotationCalibration:
        """At every rig frame of the captured cycle, each driving joint's world rotation in its
        segment's frame in ``reference`` (the simplified motion, a gait cycle; its context's frame
        is the capture's ground frame), the root joint's position in the pelvis frame and each
        ankle joint's position in its foot frame (see ``solver.rig``)."""
        t_start, period = cycle_of(reference)
        idx = cycle_frames(rig, t_start, period)
        t = rig.times[idx]
        local, root = rig.local[idx], rig.root[idx]
        pos = rig.positions()
        pos = None if pos is None else pos[idx]
        frame = reference.frame
        W, P = rig.forward(local, root, pos)
        Wo = np.einsum("ji,fkjl->fkil", frame.R, W)  # Rᵀ W: the rig in our world
        Po = frame.point_from_input(P, t[:, None])
        q, fps, character = reference.q, reference.fps, reference.character
        duration = (q.shape[1] - 2) / fps
        tm = np.clip((t - t_start) / period, 0.0, 1.0) * duration
        qs = sample(q, fps, tm, cyclic=True, interpolation=reference.interpolation)
        Rs, Ps = segment_frames(character, qs)  # (S, 3, 3, F), (S, 3, F)
        seg = {s.name: i for i, s in enumerate(character.segments)}
        C = np.broadcast_to(np.eye(3), Wo.shape).copy()
        for s, j in rig.roles.items():
            if s in seg:
                Rseg = np.moveaxis(Rs[seg[s]], -1, 0)
                C[:, j] = np.einsum("fji,fjk->fik", Rseg, Wo[:, j])
        for s, j in rig.roles.items():  # feet rigid on the motion's feet: they stay planted where it is
            if s in seg and s.startswith(RIGID_PREFIXES):
                C[:, j] = Rotation.from_matrix(C[:, j]).mean().as_matrix()
        pel = seg.get("pelvis", 0)
        Rp, Pp = np.moveaxis(Rs[pel], -1, 0), Ps[pel].T
        anchor = rig.roles.get("pelvis", 0)
        root_in_pelvis = np.einsum("fji,fj->fi", Rp, Po[:, anchor] - Pp)
        ankles = np.zeros((t.size, 2, 3))
        for k, side in enumerate("rl"):
            foot = LEG_SEGMENTS[side][2]
            if foot in seg and foot in rig.roles:
                Rf, Pf = np.moveaxis(Rs[seg[foot]], -1, 0), Ps[seg[foot]].T
                ankles[:, k] = np.einsum("fji,fj->fi", Rf, Po[:, rig.roles[foot]] - Pf).mean(axis=0)
        return cls(float(t_start), float(period), t, local, root, C, root_in_pelvis, ankles)

    def pose(self, motion: Motion, rig: SkeletonRig, times: np.ndarray, q: np.ndarray, duration: float) -> RigPose:
        """The joints' local rotations and the root's translation (:func:`follow`)."""
        return follow(self, motion, rig, times, q, duration)

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

    @classmethod
    def from_dict(cls, d: Mapping[str, Any]) -> RotationCalibration:
        return cls(float(d["t_start"]), float(d["period"]), np.asarray(d["times"], dtype=float),
                   quats_to_matrices(np.asarray(d["local"], dtype=float)), np.asarray(d["root"], dtype=float),
                   quats_to_matrices(np.asarray(d["joint_in_segment"], dtype=float)),
                   np.asarray(d["root_in_pelvis"], dtype=float), np.asarray(d["ankle_in_foot"], dtype=float))




def _rotation_between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Smallest rotation taking direction a (3,) to direction b (3,)."""
    a = a / np.linalg.norm(a)
    b = b / np.linalg.norm(b)
    v = np.cross(a, b)
    c = float(np.dot(a, b))
    s = float(np.linalg.norm(v))
    if s < 1e-12:
        if c > 0:
            return np.eye(3)
        perp = np.cross(a, [1.0, 0.0, 0.0])
        if np.linalg.norm(perp) < 1e-6:
            perp = np.cross(a, [0.0, 1.0, 0.0])
        return Rotation.from_rotvec(np.pi * perp / np.linalg.norm(perp)).as_matrix()
    return Rotation.from_rotvec(v / s * math.atan2(s, c)).as_matrix()


def _path(parents: Sequence[int], ancestor: int, joint: int) -> list[int]:
    """Joints from ``ancestor`` (included) down to ``joint`` (excluded)."""
    out = []
    j = parents[joint]
    while j >= 0 and j != ancestor:
        out.append(j)
        j = parents[j]
    if j != ancestor:
        return []
    return [ancestor, *reversed(out)]


def _two_bone(W: np.ndarray, P: np.ndarray, parents: Sequence[int], hip: int, knee: int, ankle: int,
              target: np.ndarray, bend: np.ndarray, *, hinge: bool = False) -> None:
    """Turn the hip -> knee and knee -> ankle chains (world rotations ``W`` (J, 3, 3), positions
    ``P`` (J, 3), one frame, edited in place for the chain's joints) so the ankle reaches ``target``;
    ``bend`` is the knee's flexion axis used when the leg is straight."""
    H, K, A = P[hip], P[knee], P[ankle]
    l1, l2 = np.linalg.norm(K - H), np.linalg.norm(A - K)
    d = float(np.clip(np.linalg.norm(target - H), abs(l1 - l2) + 1e-6, l1 + l2 - 1e-6))
    n = np.cross(K - H, A - K)
    n = n / np.linalg.norm(n) if np.linalg.norm(n) > 1e-4 * l1 * l2 and not hinge else bend / np.linalg.norm(bend)
    cur = float(np.clip((l1**2 + l2**2 - np.linalg.norm(A - H) ** 2) / (2 * l1 * l2), -1, 1))
    want = float(np.clip((l1**2 + l2**2 - d**2) / (2 * l1 * l2), -1, 1))
    delta = math.acos(want) - math.acos(cur)  # interior angle change
    best = None
    for sgn in (1.0, -1.0):
        Rk = Rotation.from_rotvec(sgn * delta * n).as_matrix()
        err = abs(np.linalg.norm(K + Rk @ (A - K) - H) - d)
        if best is None or err < best[0]:
            best = (err, Rk)
    assert best is not None
    Rk = best[1]
    A1 = K + Rk @ (A - K)
    Rh = _rotation_between(A1 - H, target - H)
    for j in _path(parents, hip, knee):
        W[j] = Rh @ W[j]
    for j in _path(parents, knee, ankle):
        W[j] = Rh @ Rk @ W[j]


def hinge_axes(rig: SkeletonRig) -> dict[int, np.ndarray]:
    """Joints with exactly one rotation channel (a BVH joint with one ``…rotation`` channel, a
    DeepMimic revolute joint) -> that axis (unit, joint frame)."""
    out = {}
    for j, ch in enumerate(rig.channels):
        rots = [c for c in ch if c.lower().endswith("rotation")]
        if j > 0 and len(rots) == 1 and "quaternion" not in ch:
            out[j] = np.eye(3)["XYZ".index(rots[0][0].upper())]
    return out


def _twist(R: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """The part of rotations R (F, 3, 3) about ``axis`` (swing-twist decomposition)."""
    q = Rotation.from_matrix(R).as_quat()  # x, y, z, w
    ang = 2.0 * np.arctan2(q[:, :3] @ axis, q[:, 3])
    return Rotation.from_rotvec(ang[:, None] * axis[None, :]).as_matrix()


def _locals(parents: Sequence[int], W: np.ndarray) -> np.ndarray:
    local = np.empty_like(W)
    for j, p in enumerate(parents):
        local[:, j] = W[:, j] if p < 0 else np.einsum("fji,fjk->fik", W[:, p], W[:, j])
    return local


def _worlds(parents: Sequence[int], local: np.ndarray) -> np.ndarray:
    W = np.empty_like(local)
    for j, p in enumerate(parents):
        W[:, j] = local[:, j] if p < 0 else W[:, p] @ local[:, j]
    return W


#: after a foot leaves the ground, how long its pinning correction takes to fade out (s)
PIN_RELEASE_S = 0.15


def foot_pins(motion: Any, q: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(F, 2, 3) m: per output time and foot (right, left), the translation that keeps the
    motion's ground contact points where they touched down (foot-skate clean-up).

    The optimizer holds a contact point still at the motion's frames; between frames the
    interpolated joints let it drift a few millimetres (up to ~1 cm in tight turns at 15 fps).
    At dense output times each foot is moved so that its contact point that has been down
    longest stays at its anchor (a point's anchor: where the corrected foot put it when it
    touched down, so the correction never jumps when a second point lands), and the
    correction fades out over :data:`PIN_RELEASE_S` once the foot is in the air. A frame counts
    as in contact when both motion frames around it are."""
    F = t.size
    out = np.zeros((F, 2, 3))
    if motion.contacts is None or not motion.character.contacts:
        return out
    P = len(motion.character.contacts)
    cp = np.asarray(contact_points(motion.character, q), dtype=float).reshape(P, 3, F)
    s = t * motion.fps
    lo = np.clip(np.floor(s + 1e-9).astype(int), 0, motion.T - 1)
    hi = np.clip(np.ceil(s - 1e-9).astype(int), 0, motion.T - 1)
    on = motion.contacts[:, lo] & motion.contacts[:, hi]
    dt = float(t[1] - t[0]) if F > 1 else 1.0
    for k, side in enumerate(("r", "l")):
        pts = [i for i, c in enumerate(motion.character.contacts) if c.side[0] == side]
        anchor: dict[int, np.ndarray] = {}
        corr = np.zeros(3)
        released, since = np.zeros(3), 0.0
        holder = None
        for f in range(F):
            for i in pts:
                if on[i, f] and i not in anchor:
                    anchor[i] = cp[i, :, f] + corr
                elif not on[i, f]:
                    anchor.pop(i, None)
            if anchor:  # the point down longest holds the foot (dicts keep insertion order)
                first = next(iter(anchor))
                if holder is not None and first != holder:  # the holder lifted: take over without a jump
                    anchor[first] = cp[first, :, f] + corr
                holder = first
                corr = anchor[first] - cp[first, :, f]
                released, since = corr, 0.0
            else:
                since += dt
                corr = released * max(0.0, 1.0 - since / PIN_RELEASE_S)
                holder = None
            out[f, k] = corr
    return out


def output_times(motion: Any, frame_time: float) -> tuple[np.ndarray, float]:
    """One gait cycle of ``motion`` sampled near ``frame_time``: (times from 0 to the cycle's
    duration D included, D)."""
    D = (motion.T - 2) / motion.fps if motion.cyclic else (motion.T - 1) / motion.fps
    n = max(int(round(D / frame_time)), 2)
    return np.linspace(0.0, D, n + 1), D


def retarget(motion: Any, rig: SkeletonRig, *, frame_time: float | None = None) -> RigPose:
    """``motion`` (of the character the rig was calibrated on) on the rig, one cycle at the rig's
    frame rate (or ``frame_time``), through its calibration (:meth:`RotationCalibration.pose`)."""
    cal = rig.calibration
    if cal is None:
        raise RigError("the source rig was never calibrated against a tutor (it is a capture's rig): "
                       "make a tutor first")
    t, D = output_times(motion, frame_time or rig.frame_time)
    q = sample(motion.q, motion.fps, t, cyclic=motion.cyclic, interpolation=motion.interpolation)
    return cal.pose(motion, rig, t, q, D)


def follow(cal: RotationCalibration, motion: Any, rig: SkeletonRig, t: np.ndarray, q: np.ndarray,
           D: float) -> RigPose:
    """``motion`` on ``rig`` through its calibration ``cal`` at times ``t`` (s from the cycle's
    start, ``D`` the motion's cycle), ``q`` (n, F) its coordinates there (see ``solver.rig``)."""
    ch = motion.character
    seg = {s.name: i for i, s in enumerate(ch.segments)}
    if "pelvis" not in seg:
        raise RigError("the motion's character has no pelvis segment")
    frame = motion.frame
    tc = cal.t_start + t / D * cal.period
    local_c, root_c, C, root_in_pelvis, ankle_in_foot = cal.at(tc)
    positions = None
    pos = rig.positions()
    if pos is not None:
        positions = np.stack([np.stack([np.interp(tc, cal.times, pos[:, j, c]) for c in range(3)], -1)
                              for j in range(rig.J)], 1)
    Rs, Ps = segment_frames(ch, q)
    Rs, Ps = np.moveaxis(Rs, -1, 1), np.moveaxis(Ps, -1, 1)  # (S, F, 3, 3), (S, F, 3)
    driven = {j: s for s, j in rig.roles.items() if s in seg}
    hinges = hinge_axes(rig)
    F = t.size
    Wo = np.empty((F, rig.J, 3, 3))
    for j, p in enumerate(rig.parents):
        if j in driven:
            Wo[:, j] = Rs[seg[driven[j]]] @ C[:, j]
        elif p < 0:  # a root above the pelvis (Unreal's "root"): as captured
            Wo[:, j] = np.einsum("ji,fjk->fik", frame.R, local_c[:, j])
        else:
            Wo[:, j] = Wo[:, p] @ local_c[:, j]
    pelvis_pos = Ps[seg["pelvis"]] + np.einsum("fij,fj->fi", Rs[seg["pelvis"]], root_in_pelvis)
    anchor = rig.roles.get("pelvis", 0)
    if anchor == 0:
        root_pos = pelvis_pos
    else:  # the pelvis joint is placed through its own position channels
        if positions is None:
            raise RigError(f"the joint that moves the pelvis ({rig.names[anchor]}) is not the root and has no "
                           "position channels: the rig cannot follow the motion's pelvis")
        root_pos = frame.point_from_input(root_c, tc)
    unit = rig.frame.unit_m

    def fk(Wo: np.ndarray) -> np.ndarray:
        P = np.empty((F, rig.J, 3))
        P[:, 0] = root_pos
        for j, p in enumerate(rig.parents):
            if p < 0:
                continue
            if j == anchor and positions is not None:
                positions[:, j] = np.einsum("fji,fj->fi", Wo[:, p], pelvis_pos - P[:, p]) / unit
            off = rig.offsets[j] if positions is None else positions[:, j]
            P[:, j] = P[:, p] + unit * np.einsum("fij,fj->fi", Wo[:, p], np.broadcast_to(off, (F, 3)))
        return P

    Po = fk(Wo)
    pins = foot_pins(motion, q, t)
    targets = np.full((F, 2, 3), np.nan)
    for k, side in enumerate("rl"):
        thigh, shank, foot = LEG_SEGMENTS[side]
        if not all(s in rig.roles and s in seg for s in (thigh, shank, foot)):
            continue
        hip, knee, ankle = rig.roles[thigh], rig.roles[shank], rig.roles[foot]
        if not (_path(rig.parents, hip, knee) and _path(rig.parents, knee, ankle)):
            continue
        targets[:, k] = Ps[seg[foot]] + np.einsum("fij,fj->fi", Rs[seg[foot]], ankle_in_foot[:, k]) + pins[:, k]
        if knee in hinges:  # a hinge knee bends about its own axis
            bend = np.einsum("fij,j->fi", Wo[:, rig.parents[knee]], hinges[knee])
        else:
            bend = Rs[seg[shank]][:, :, 1]  # our knees flex about the shank's y axis
        for f in range(F):
            _two_bone(Wo[f], Po[f], rig.parents, hip, knee, ankle, targets[f, k], bend[f], hinge=knee in hinges)
        Po = fk(Wo)
    local = _locals(rig.parents, Wo)
    if hinges:  # joints turning about one axis only: keep that part, then aim the legs again
        saved = Wo.copy()
        for j, axis in hinges.items():
            local[:, j] = _twist(local[:, j], axis)
        Wo = _worlds(rig.parents, local)
        for k, side in enumerate("rl"):
            thigh, shank, foot = LEG_SEGMENTS[side]
            if np.isnan(targets[:, k]).all():
                continue
            hip, ankle = rig.roles[thigh], rig.roles[foot]
            chain = _path(rig.parents, hip, ankle)
            Po = fk(Wo)
            for f in range(F):
                Rh = _rotation_between(Po[f, ankle] - Po[f, hip], targets[f, k] - Po[f, hip])
                for j in chain:
                    Wo[f, j] = Rh @ Wo[f, j]
            for j in chain:
                p = rig.parents[j]
                local[:, j] = np.einsum("fji,fjk->fik", Wo[:, p], Wo[:, j])
            if ankle not in hinges:  # the foot keeps the motion's orientation
                local[:, ankle] = np.einsum("fji,fjk->fik", Wo[:, chain[-1]], saved[:, ankle])
            Wo = _worlds(rig.parents, local)
    # local rotations: unchanged by the choice of world axes (Wo = Rᵀ W_input)
    local = _locals(rig.parents, Wo)
    local[:, 0] = np.einsum("ij,fjk->fik", frame.R, Wo[:, 0])  # the root's rotation in input axes
    t_frame = tc  # the frame's time dependence (treadmill belt) follows the capture's clock
    root_in = root_c if anchor else frame.point_to_input(root_pos, t_frame)
    return RigPose(t, local, root_in, positions, tc, targets, tuple(sorted(driven.values())))


def feet_report(motion: Any, rig: SkeletonRig, pose: RigPose) -> dict[str, Any]:
    """How well the rig's feet follow the motion, from the rig's own forward kinematics.

    Per side: ``ankle_error_m``, the largest distance over stance frames between the rig's
    ankle joint and where the motion's foot frame carries it; ``slide_m``, the largest
    horizontal drift, over one contact interval of one of the motion's contact points (heel,
    toe), of the point of the rig's foot (ankle joint's frame for a heel point, toe joint's
    for a toe point) that lies on that contact point when the interval starts: a foot bone
    that stays pinned where the motion's foot is on the ground does not slide. A frame
    counts as in contact when both motion frames around it are."""
    if motion.contacts is None:
        return {}
    frame = motion.frame
    W, P = rig.forward(pose.local, pose.root, pose.positions)
    Wo = np.einsum("ji,fkjl->fkil", frame.R, W)
    Po = frame.point_from_input(P, pose.capture_time[:, None])
    s = pose.times * motion.fps
    lo = np.clip(np.floor(s + 1e-9).astype(int), 0, motion.T - 1)
    hi = np.clip(np.ceil(s - 1e-9).astype(int), 0, motion.T - 1)
    active = motion.contacts[:, lo] & motion.contacts[:, hi]  # (points, F)
    q = sample(motion.q, motion.fps, pose.times, cyclic=motion.cyclic, interpolation=motion.interpolation)
    cp = np.asarray(contact_points(motion.character, q)).reshape(len(motion.character.contacts), 3, -1)
    feet = motion.foot_contact()
    out: dict[str, Any] = {}
    for k, side in enumerate(("right", "left")):
        foot = LEG_SEGMENTS[side[0]][2]
        if foot not in rig.roles or np.isnan(pose.ankle_target[:, k]).all():
            continue
        a = rig.roles[foot]
        toe = rig.roles.get(f"toes_{side[0]}", a)
        stance = feet[k][lo] & feet[k][hi]
        err = np.linalg.norm(Po[:, a] - pose.ankle_target[:, k], axis=1)
        slides = []
        for i, c in enumerate(motion.character.contacts):
            if c.side != side[0] and c.side != side:
                continue
            j = toe if "toe" in c.name else a
            edges = np.flatnonzero(np.diff(np.concatenate([[0], active[i].astype(int), [0]])))
            for s0, s1 in zip(edges[::2], edges[1::2]):
                if s1 - s0 < 2:
                    continue
                local = Wo[s0, j].T @ (cp[i, :, s0] - Po[s0, j])
                pts = Po[s0:s1, j] + np.einsum("fij,j->fi", Wo[s0:s1, j], local)
                slides.append(float(np.max(np.linalg.norm(pts[:, :2] - pts[0, :2], axis=1))))
        out[side] = {"ankle_error_m": float(err[stance].max()) if stance.any() else 0.0,
                     "slide_m": max(slides) if slides else 0.0, "contact_intervals": len(slides)}
    return out


def locked_joint_rms(rig: SkeletonRig, pose: RigPose) -> dict[str, float]:
    """RMS (degrees) of the rotation between each joint the motion does not drive and the
    capture's own local rotation at the same gait phase, and the amplitude ratio (exported
    range of motion over captured) of those joints."""
    cal = rig.calibration
    if not isinstance(cal, RotationCalibration):
        return {}
    local_c, *_ = cal.at(pose.capture_time)
    driven = {rig.roles[s] for s in pose.driven if s in rig.roles}
    legs = set()
    for side in "rl":
        thigh, shank, foot = LEG_SEGMENTS[side]
        if all(s in rig.roles for s in (thigh, shank, foot)):
            legs.update(_path(rig.parents, rig.roles[thigh], rig.roles[shank]))
            legs.update(_path(rig.parents, rig.roles[shank], rig.roles[foot]))
    free = [j for j in range(1, rig.J) if j not in driven and j not in legs]
    if not free:
        return {"rms_deg": 0.0, "joints": 0}
    rel = np.einsum("fjik,fjil->fjkl", local_c[:, free], pose.local[:, free])
    ang = Rotation.from_matrix(rel.reshape(-1, 3, 3)).magnitude().reshape(rel.shape[:2])
    return {"rms_deg": float(np.degrees(np.sqrt(np.mean(ang**2)))), "max_deg": float(np.degrees(ang.max())),
            "joints": len(free)}
