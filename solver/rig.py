"""The input's own skeleton (its *rig*) and how a motion goes back onto it.

A trial read from a BVH, a skinned glTF or a DeepMimic clip has a skeleton of its own: joint
names, hierarchy, offsets, channels, rest pose. The importer keeps it beside the capture as a
:class:`SkeletonRig` (the joints' local rotations and the root's translation at the capture's
times; a :class:`~solver.retargeting.Rig`, whose interface ``solver.retargeting`` describes)
and names, per segment of the capture skeleton, the joint that moves it (its *role*, e.g.
``thigh_r`` → ``RightUpLeg``). Motions carry it in their context (``Motion.context.rig``), so
every tutor, λ optimum and library cell can be written on the user's own skeleton.

**Calibration** (:class:`RotationCalibration`, fitted when the tutor is made: :func:`calibrate`).
At every rig frame of the gait cycle, the rigid map between each driving joint's world frame ``W_j`` and its segment's
frame ``R_s`` in the *simplified* motion (the synthesis character fitted to the capture) is
kept: ``C_j = R_sᵀ W_j``; so are the root joint's position in the pelvis frame and each ankle
joint's position in the foot frame. These maps hold what the synthesis character does not
model — its locked degrees of freedom (hip rotation, subtalar, spine, arms…) and the
difference between the fitted segment and the rig's bone — at that gait phase.

**Retargeting** (:func:`retarget`, :meth:`RotationCalibration.pose`): for a motion of the same
character (tutor, λ optimum), at each output time ``t`` (the rig's own frame rate, one cycle), the gait phase
``φ = t / D`` (``D`` the motion's cycle duration) picks the capture's rig time
``t' = t_start + φ · period`` (time-warped where the speed changed). A driving joint gets the
world rotation ``R_s(t) · C_j(t')``; every other joint (arms, spine, head, fingers of a
HalfBoy motion) its captured local rotation at ``t'``; the root its position from the pelvis.
Then each leg is closed by a two-bone IK (hip and knee joints turned in their plane) so the
rig's ankle joint lands where the motion's foot frame carries it: the feet stay planted on
the rig's own bones even where its bone lengths differ from the fitted segments.

Pure numpy/scipy; rotations stored as unit quaternions (w, x, y, z) in :meth:`SkeletonRig.to_dict`.

The rig as a value is in ``solver.rig_skeleton``, its calibration (fit, retargeting) in
``solver.rig_retarget``, the interface both implement in ``solver.retargeting``; this module
calibrates a capture's rig and names the whole API.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

from solver.retargeting import Calibration, Rig, calibration_kind, rig_kind
from solver.rig_retarget import (
    PIN_RELEASE_S,
    RotationCalibration,
    feet_report,
    follow,
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
    RigError,
    RigPose,
    SkeletonRig,
    matrices_to_quats,
    quats_to_matrices,
    segment_roles,
)

if TYPE_CHECKING:
    from solver.motion import Motion

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
    "RotationCalibration",
    "SkeletonRig",
    "calibrate",
    "calibration_kind",
    "feet_report",
    "follow",
    "foot_pins",
    "hinge_axes",
    "locked_joint_rms",
    "matrices_to_quats",
    "output_times",
    "quats_to_matrices",
    "retarget",
    "rig_kind",
    "segment_roles",
    "unroll",
]


def unroll(rig: SkeletonRig, repeats: int, displacement: np.ndarray) -> SkeletonRig:
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


def calibrate(rig: Rig, reference: Motion) -> Rig:
    """``rig`` calibrated against ``reference`` (:meth:`Rig.calibrated`; for a skeleton, the
    simplified motion: a gait cycle of the synthesis character over the captured cycle, its
    context's frame the capture's ground frame): see the module docstring."""
    return rig.calibrated(reference)
