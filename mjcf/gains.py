"""The tracking controller's gains (:class:`Gains`) and the basis of its torque limits: the
motion's own inverse-dynamics peaks (:func:`id_peaks`), per motor of the simulated model
(:func:`motor_peaks`)."""

from __future__ import annotations

from dataclasses import dataclass

import mujoco
import numpy as np

from mjcf.performable import ModelGeometry
from solver.motion import FEET, Motion
from solver.trajectory import dynamics_samples


@dataclass(frozen=True)
class Gains:
    """Controller gains: natural frequencies (rad/s, critically damped PD) and QP weights."""

    joint_freq: float = 20.0
    root_freq: float = 10.0
    root_weight: float = 100.0
    root_xy_freq: float = 6.0
    root_xy_saturation: float = 0.05  # m
    swing_freq: float = 10.0
    swing_weight: float = 5.0
    swing_orientation_weight: float = 0.0
    synchronize: bool = True  # the reference's clock follows the simulated touchdowns
    sync_fast: float = 3.0  # its rate while a foot is down before the reference's
    sync_slow: float = 0.2  # its rate while the reference waits for a late foot
    sync_max_wait: float = 0.15  # s: the longest a reference waits for one touchdown
    swing_lift: float = 0.02  # m: the swing foot's target raised by this much at mid-swing (clearance)
    contact_weight: float = 1000.0
    contact_damping: float = 20.0
    force_weight: float = 30.0  # per (BW)²
    moment_weight: float = 3.0  # per (BW·m)²... scaled by 1/(BW·0.1 m)²
    torque_weight: float = 1e-6
    placement_position: float = 1.0  # foot-placement feedback: Δ = c_d (com − com_ref) + c_v (v − v_ref)
    placement_velocity: float = 0.3
    friction_margin: float = 0.8
    torque_limit_scale: float = 2.0  # |τ| ≤ scale × the motion's inverse-dynamics peak (per joint)
    torque_limit_floor: float = 0.05  # ... and at least this fraction of the largest peak
    contact_distance: float = 0.005  # a scheduled sole corner bears load when MuJoCo has a contact this near it (m)
    contact_height: float = 0.003  # ... or, on a foot already touching, when this close to the ground (m)
    sole_half_width: float | None = None  # m; None: the foot box's half width
    inversion: bool = True  # an actuated inversion hinge in each foot (ContactOptions.inversion)
    inversion_weight: float = 1.0  # its pull toward 0 (in stance the sole-flat task rules)
    sole_flat_weight: float = 100.0
    sole_flat_freq: float = 20.0
    flat_stance: bool = True  # stance tasks on the sole's corners (else on the heel/toe points only)
    reanchor: bool = True  # re-plant the reference's horizontal position on each touchdown
    anchor_time: float = 0.1  # s
    control_period: int = 1  # control steps every this many simulation steps
    local_moments: bool = True  # the stored moments tracked about the sole's centre (else about the world origin)
    preload: bool = True  # start with the contacts loaded at the stored vertical force (``_start``)
    residual_weight: float = 1e6  # per BW²: the root residual's cost, on a model with one (the resync runs)



def id_peaks(motion: Motion) -> np.ndarray:
    """Per joint coordinate (n − 6), the motion's own inverse-dynamics peak |τ| (N·m), at its
    dynamics samples with its stored foot wrenches."""
    from mjcf.replay import MujocoReplay

    env = motion.environment
    rep = MujocoReplay.create(motion.character, env.gravity)
    s = dynamics_samples(motion)
    fext = {}
    if s.wrenches is not None:
        for f, side in enumerate(FEET):
            seg = motion.character.contact_points(side)[0].segment
            fext[seg] = s.wrenches[f]
    tau, _ = rep.inverse(s.q, s.qd, s.qdd, fext)
    return np.max(np.abs(tau[6:]), axis=1)



def motor_peaks(motion: Motion, model: mujoco.MjModel, geometry: ModelGeometry) -> np.ndarray:
    """Per motor (``geometry.motors``), the motion's own inverse-dynamics peak |τ| of its joint
    (:func:`id_peaks`); an inversion hinge (no coordinate of the motion) gets its ankle's."""
    peaks = id_peaks(motion)
    names = motion.character.coordinate_names[6:]
    joint_dofs = [int(v) for v in geometry.coordinate_dof[6:]]
    inversion_dofs = [int(v) for v in geometry.inversion_dof]
    out = []
    for a in geometry.motors:
        dof = int(model.jnt_dofadr[model.actuator_trnid[a, 0]])
        if dof in joint_dofs:
            out.append(joint_dofs.index(dof))
        else:
            side = FEET[inversion_dofs.index(dof)][0]
            ankle = [i for i, n in enumerate(names) if n.startswith("ankle") and n.endswith("_" + side)]
            out.append(ankle[0] if ankle else int(np.argmax(peaks)))
    return peaks[out]
