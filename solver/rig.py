"""The input's own skeleton (its *rig*) and how a motion goes back onto it.

A trial read from a BVH, a skinned glTF or a DeepMimic clip has a skeleton of its own: joint
names, hierarchy, offsets, channels, rest pose. The importer keeps it beside the capture as a
:class:`Rig` (the joints' local rotations and the root's translation at the capture's times)
and names, per segment of the capture skeleton, the joint that moves it (its *role*, e.g.
``thigh_r`` → ``RightUpLeg``). Motions carry it in their context (``Motion.context.rig``), so every tutor,
λ optimum and library cell can be written on the user's own skeleton.

**Calibration** (when the tutor is made, :func:`calibrate`). At every rig frame of the
gait cycle, the rigid map between each driving joint's world frame ``W_j`` and its segment's
frame ``R_s`` in the *simplified* motion (the synthesis character fitted to the capture) is
kept: ``C_j = R_sᵀ W_j``; so are the root joint's position in the pelvis frame and each ankle
joint's position in the foot frame. These maps hold what the synthesis character does not
model — its locked degrees of freedom (hip rotation, subtalar, spine, arms…) and the
difference between the fitted segment and the rig's bone — at that gait phase.

**Retargeting** (:func:`retarget`): for a motion of the same character (tutor, λ optimum),
at each output time ``t`` (the rig's own frame rate, one cycle), the gait phase
``φ = t / D`` (``D`` the motion's cycle duration) picks the capture's rig time
``t' = t_start + φ · period`` (time-warped where the speed changed). A driving joint gets the
world rotation ``R_s(t) · C_j(t')``; every other joint (arms, spine, head, fingers of a
HalfBoy motion) its captured local rotation at ``t'``; the root its position from the pelvis.
Then each leg is closed by a two-bone IK (hip and knee joints turned in their plane) so the
rig's ankle joint lands where the motion's foot frame carries it: the feet stay planted on
the rig's own bones even where its bone lengths differ from the fitted segments.

Pure numpy/scipy; rotations stored as unit quaternions (w, x, y, z) in :meth:`Rig.to_dict`.

The rig as a value is in ``solver.rig_skeleton``, the retargeting in ``solver.rig_retarget``;
this module calibrates a rig and names the whole API.
"""

from __future__ import annotations

from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from solver.capture import GroundFrame
from solver.kinematics import segment_frames
from solver.rig_retarget import (
    PIN_RELEASE_S,
    RigPose,
    feet_report,
    foot_pins,
    hinge_axes,
    locked_joint_rms,
    output_times,
    retarget,
)
from solver.rig_skeleton import (
    LEG_SEGMENTS,
    MAX_JOINTS,
    RIG_FORMATS,
    RIGID_PREFIXES,
    ROLE_SEGMENTS,
    Calibration,
    Rig,
    RigError,
    matrices_to_quats,
    quats_to_matrices,
    segment_roles,
)

__all__ = [
    "LEG_SEGMENTS",
    "MAX_JOINTS",
    "PIN_RELEASE_S",
    "RIGID_PREFIXES",
    "RIG_FORMATS",
    "ROLE_SEGMENTS",
    "Calibration",
    "Rig",
    "RigError",
    "RigPose",
    "calibrate",
    "feet_report",
    "foot_pins",
    "hinge_axes",
    "locked_joint_rms",
    "matrices_to_quats",
    "output_times",
    "quats_to_matrices",
    "retarget",
    "segment_roles",
    "unroll",
]


# --- calibration ------------------------------------------------------------------------

def _world_in_ours(rig: Rig, local: np.ndarray, root: np.ndarray, times: np.ndarray,
                   frame: GroundFrame, positions: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (F, J, 3, 3) and positions (F, J, 3) (m) of the rig in our world frame."""
    W, P = rig.forward(local, root, positions)
    Wo = np.einsum("ji,fkjl->fkil", frame.R, W)  # Rᵀ W
    Po = frame.point_from_input(P, times[:, None])
    return Wo, Po


def _cycle_frames(rig: Rig, t_start: float, period: float) -> np.ndarray:
    """Indices of the rig frames covering [t_start, t_start + period] (one frame either side)."""
    t = rig.times
    a = max(int(np.searchsorted(t, t_start, side="right")) - 2, 0)
    b = min(int(np.searchsorted(t, t_start + period, side="left")) + 2, t.size)
    if b - a < 2 or t[a] > t_start + 1e-6 or t[b - 1] < t_start + period - 1e-6:
        raise RigError(f"the source rig's frames ({t[0]:.3f}-{t[-1]:.3f} s) do not cover the gait cycle "
                       f"({t_start:.3f}-{t_start + period:.3f} s)")
    return np.arange(a, b)


def unroll(rig: Rig, repeats: int, displacement: np.ndarray) -> Rig:
    """A looping rig clip (its last frame at the phase of its first) repeated ``repeats`` times,
    the root moved by ``displacement`` (input units) per repetition (as :func:`solver.gait.unroll_loop`)."""
    times, local, root = [rig.times], [rig.local], [rig.root]
    pos = rig.positions()
    poss = None if pos is None else [pos]
    period = rig.times[-1] - rig.times[0]
    for r in range(1, repeats):
        times.append(rig.times[1:] + r * period)
        local.append(rig.local[1:])
        root.append(rig.root[1:] + r * np.asarray(displacement, dtype=float))
        if poss is not None and pos is not None:
            poss.append(pos[1:])
    extra = dict(rig.extra)
    if poss is not None:
        extra["positions"] = np.concatenate(poss).tolist()
    return rig.evolve(times=np.concatenate(times), local=np.concatenate(local), root=np.concatenate(root),
                      extra=extra)


def calibrate(rig: Rig, character: Any, q: np.ndarray, fps: float, *, t_start: float, period: float,
              frame: GroundFrame, interpolation: str = "cubic-spline") -> Rig:
    """The rig calibrated against the simplified motion ``q`` (n, T) of ``character`` (a gait
    cycle at ``fps`` starting at rig time ``t_start``, lasting ``period``; ``frame`` the
    motion's ground frame): see the module docstring."""
    from solver.trajectory import sample

    idx = _cycle_frames(rig, t_start, period)
    t = rig.times[idx]
    local, root = rig.local[idx], rig.root[idx]
    pos = rig.positions()
    pos = None if pos is None else pos[idx]
    Wo, Po = _world_in_ours(rig, local, root, t, frame, pos)
    T = q.shape[1]
    duration = (T - 2) / fps
    tm = np.clip((t - t_start) / period, 0.0, 1.0) * duration
    qs = sample(q, fps, tm, cyclic=True, interpolation=interpolation)
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
        thigh, shank, foot = LEG_SEGMENTS[side]
        if foot in seg and foot in rig.roles:
            Rf, Pf = np.moveaxis(Rs[seg[foot]], -1, 0), Ps[seg[foot]].T
            ankles[:, k] = np.einsum("fji,fj->fi", Rf, Po[:, rig.roles[foot]] - Pf).mean(axis=0)
    cal = Calibration(float(t_start), float(period), t, local, root, C, root_in_pelvis, ankles)
    extra = dict(rig.extra)
    if pos is not None:
        extra["positions"] = pos.tolist()
    extra["calibrated_on"] = sorted(s for s in rig.roles if s in seg)
    return rig.evolve(times=t, local=local, root=root, extra=extra, calibration=cal)
