"""The balancing QP tracking controller (:class:`Tracker`) and its gains (:class:`Gains`).

The controller solves, every control step, one quadratic program (``quadprog``) over the
generalized accelerations q̈ and the contact forces at the stance sole corners (non-negative
combinations of the edges of a pyramidal friction cone), subject to the equations of motion's
unactuated root rows (M q̈ + h = Jᵀf there: the contact forces must move the root) and joint
torque limits; the torques follow from the actuated rows, τ = (M q̈ + h − Jᵀf)_joints, and are
what the motors apply. Its costs track

* the joints' reference accelerations with PD feedback,
* the root's reference pose in the world with PD feedback (what balances: only the contact
  forces can supply it),
* zero acceleration (with velocity damping) of the stance sole corners,
* the swing foot's reference position shifted by SIMBICON-style foot-placement feedback
  (centre-of-mass position and velocity errors), i.e. stepping to recover balance,
* the motion's stored foot forces and moments (regularization), and small torques.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import mujoco
import numpy as np
import quadprog

from mjcf.agreement import ground_height
from mjcf.performable import RESIDUAL_PREFIX
from mjcf.reference import Reference
from solver.environment import body_weight
from solver.motion import FEET, Motion
from solver.trajectory import ROOT_XY, dynamics_samples


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


class Tracker:
    """The balancing QP tracking controller (module docstring)."""

    def __init__(self, motion: Motion, model: mujoco.MjModel, ref: Reference, gains: Gains) -> None:
        ch = motion.character
        self.m, self.ref, self.g = model, ref, gains
        self.nv = model.nv
        ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, nm) for nm in ch.coordinate_names]
        self.qadr = np.array([model.jnt_qposadr[i] for i in ids])
        self.vadr = np.array([model.jnt_dofadr[i] for i in ids])
        self.root_v = self.vadr[:6]
        self.joint_v = self.vadr[6:]
        # the motors (joints, inversion hinges) and, on a resync model, the root residual's six actuators
        act_names = [mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_ACTUATOR, a) or "" for a in range(model.nu)]
        self.motor = np.array([a for a in range(model.nu) if not act_names[a].startswith(RESIDUAL_PREFIX)], dtype=int)
        by_name = {nm: a for a, nm in enumerate(act_names)}
        self.residual = np.array([by_name[RESIDUAL_PREFIX + nm] for nm in ch.coordinate_names[:6]
                                  if RESIDUAL_PREFIX + nm in by_name], dtype=int)
        self.act_v = np.array([model.jnt_dofadr[model.actuator_trnid[a, 0]] for a in self.motor])
        env = motion.environment
        self.mu = env.friction * gains.friction_margin
        self.bw = body_weight(motion)
        self.ref_data = mujoco.MjData(model)
        # soles: body, corners in body frame, which contact point each corner belongs to (heel/toe)
        self.soles = []
        for side in FEET:
            gid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_GEOM, f"sole_{side}")
            bid = int(model.geom_bodyid[gid])
            size = model.geom_size[gid]
            R9 = np.zeros(9)
            mujoco.mju_quat2Mat(R9, model.geom_quat[gid])
            R = R9.reshape(3, 3)
            pos = model.geom_pos[gid]
            corners = np.array([pos + R @ np.array([sx * size[0], sy * size[1], -size[2]])
                                for sx in (-1, 1) for sy in (1, -1)])  # heel ±, toe ±
            heel, toe = ch.sole_indices(side)  # the sole's heel and toe points, by name
            owner = [heel, heel, toe, toe]
            self.soles.append((gid, bid, corners, owner, R @ np.array([0, 0, -1.0]) * size[2] + pos))
        self.n_edges = 4
        s = 1.0 / math.sqrt(1 + self.mu**2)
        self.edges = np.array([[self.mu * s, 0, s], [-self.mu * s, 0, s], [0, self.mu * s, s], [0, -self.mu * s, s]]).T
        # inversion joints (when the model has them): the motion has none, their reference is 0
        inv = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_JOINT, f"inversion_{side}") for side in FEET]
        self.inv_q = np.array([model.jnt_qposadr[j] for j in inv if j >= 0], dtype=int)
        self.inv_v = np.array([model.jnt_dofadr[j] for j in inv if j >= 0], dtype=int)
        peaks = id_peaks(motion)
        lim = np.maximum(gains.torque_limit_scale * peaks, gains.torque_limit_floor * float(peaks.max()))
        # actuator order; an inversion joint (not a coordinate of the motion) gets its ankle's limit
        names = list(ch.coordinate_names[6:])
        self.act_is_coordinate = np.array([v in set(self.vadr) for v in self.act_v])
        joint_of_act = []
        for a in self.motor:
            nm = act_names[a]
            if nm in names:
                joint_of_act.append(names.index(nm))
            else:
                side = nm.rsplit("_", 1)[-1][0]
                ankle = [i for i, n in enumerate(names) if n.startswith("ankle") and n.endswith("_" + side)]
                joint_of_act.append(ankle[0] if ankle else int(np.argmax(peaks)))
        self.peaks = peaks[joint_of_act]
        self.tau_limit = lim[joint_of_act]
        self.com_body = int(model.body_rootid[mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, ch.segments[0].name)])
        self._jp = np.zeros((3, self.nv))
        self._jr = np.zeros((3, self.nv))
        self._M = np.zeros((self.nv, self.nv))
        self.predicted = np.zeros((2, 3))
        self.n_corners = [0, 0]
        # horizontal shift of the reference: re-planted at every touchdown on the actual foot
        self.anchor = np.zeros(2)
        self.anchor_target = np.zeros(2)
        self.was_down = [True, True]
        self.airborne = [False, False]
        self.waited = [0.0, 0.0]
        self.owner_feet = [[i for i, c in enumerate(ch.contacts) if c.side == side] for side in FEET]
        self.treads = any((mujoco.mj_id2name(model, mujoco.mjtObj.mjOBJ_GEOM, i) or "").startswith("tread_")
                          for i in range(model.ngeom))

    def snapshot(self) -> tuple[Any, ...]:
        """The controller's state (re-anchoring, clock synchronization), for :meth:`restore`."""
        return (self.anchor.copy(), self.anchor_target.copy(), list(self.was_down), list(self.airborne),
                list(self.waited))

    def restore(self, state: tuple[Any, ...]) -> None:
        a, at, wd, ab, wt = state
        self.anchor, self.anchor_target = a.copy(), at.copy()
        self.was_down, self.airborne, self.waited = list(wd), list(ab), list(wt)

    def _reanchor(self, d: mujoco.MjData, qr: np.ndarray, active: np.ndarray) -> None:
        """When a foot is planted (the reference has it in stance and the simulated sole touches
        the ground, whichever comes last), move the reference horizontally so that its foot is
        where the simulated foot is; blend the shift in over ``anchor_time``."""
        g = self.g
        for f, (gid, bid, _corners, _owner, centre) in enumerate(self.soles):
            touching = any(gid in (d.contact[i].geom1, d.contact[i].geom2) for i in range(d.ncon))
            down = bool(active[self.owner_feet[f]].any()) and touching
            if down and not self.was_down[f]:
                rd = self.ref_data
                rd.qpos[self.qadr] = qr
                mujoco.mj_kinematics(self.m, rd)
                p_ref = rd.xpos[bid] + rd.xmat[bid].reshape(3, 3) @ centre
                p_sim = d.xpos[bid] + d.xmat[bid].reshape(3, 3) @ centre
                self.anchor_target = (p_sim - p_ref)[:2]
            self.was_down[f] = down
        a = min(1.0, self.m.opt.timestep * g.control_period / g.anchor_time)
        self.anchor = self.anchor + a * (self.anchor_target - self.anchor)

    def clock_rate(self, d: mujoco.MjData, t_ref: float) -> float:
        """How fast the reference's clock runs for the next step: contact-synchronized, as in
        data-driven tracking (the reference waits for a late touchdown and hurries to an early
        one), at most ``sync_max`` s ahead of or behind real time per step."""
        g = self.g
        if not g.synchronize:
            return 1.0
        rate = 1.0
        for f, (gid, *_rest) in enumerate(self.soles):
            touching = any(gid in (d.contact[i].geom1, d.contact[i].geom2) for i in range(d.ncon))
            sp = self.ref.swing_progress(t_ref, self.owner_feet[f])
            if sp is not None and sp < 0.5 and not touching:
                self.airborne[f] = True
            if touching:
                self.airborne[f] = False
                if sp is not None and sp > 0.5:  # down before the reference: hurry to its touchdown
                    rate = max(rate, g.sync_fast)
            elif sp is None and self.airborne[f] and self.waited[f] < g.sync_max_wait:
                rate = min(rate, g.sync_slow)  # the reference is down, the foot not yet: wait
                self.waited[f] += self.m.opt.timestep * (1.0 - g.sync_slow)
            if sp is not None and sp < 0.5:
                self.waited[f] = 0.0
        return rate

    def ground(self, d: mujoco.MjData, p: np.ndarray) -> float:
        return ground_height(self.m, d, p) if self.treads else 0.0

    def _point(self, d: mujoco.MjData, bid: int,
               local: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """World position, velocity, Jacobian and J̇q̇ of a body point."""
        p = d.xpos[bid] + d.xmat[bid].reshape(3, 3) @ local
        jp, jr = np.zeros((3, self.nv)), np.zeros((3, self.nv))
        mujoco.mj_jac(self.m, d, jp, jr, p, bid)
        jdp, jdr = np.zeros((3, self.nv)), np.zeros((3, self.nv))
        mujoco.mj_jacDot(self.m, d, jdp, jdr, p, bid)
        return p, jp @ d.qvel, jp, jdp @ d.qvel

    def _com(self, d: mujoco.MjData, qvel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        jc = np.zeros((3, self.nv))
        mujoco.mj_jacSubtreeCom(self.m, d, jc, self.com_body)
        return d.subtree_com[self.com_body].copy(), jc @ qvel

    def control(self, d: mujoco.MjData, t_ref: float) -> np.ndarray:
        """Joint torques (actuator order) for the state in ``d`` (after mj_forward)."""
        m, g, ref = self.m, self.g, self.ref
        nv = self.nv
        qr, qdr, qddr = ref.state(t_ref)
        q = d.qpos[self.qadr]
        qd = d.qvel[self.vadr]
        active = ref.active(t_ref)
        if g.reanchor:
            self._reanchor(d, qr, active)
            qr = qr.copy()
            qr[list(ROOT_XY)] += self.anchor
        # reference kinematics (feet, centre of mass)
        rd = self.ref_data
        rd.qpos[self.qadr] = qr
        rd.qvel[self.vadr] = qdr
        mujoco.mj_kinematics(m, rd)
        mujoco.mj_comPos(m, rd)
        mujoco.mj_comVel(m, rd)
        qacc_r = np.zeros(nv)
        qacc_r[self.vadr] = qddr
        com, vcom = self._com(d, d.qvel)
        com_r, vcom_r = self._com(rd, rd.qvel)

        mujoco.mj_fullM(m, d, self._M)
        M = self._M
        h = d.qfrc_bias
        W = ref.wrench(t_ref)

        # stance corners
        corner_rows = []  # (foot, J, Jdqd, vel)
        swing = []
        point_rows = []
        flat_rows: list[tuple[np.ndarray, np.ndarray]] = []
        for f, (gid, bid, corners, owner, centre) in enumerate(self.soles):
            used = []
            touching = [d.contact[i].pos.copy() for i in range(d.ncon)
                        if gid in (d.contact[i].geom1, d.contact[i].geom2) and d.contact[i].dist < 0]
            edge_ref = {}  # reference acceleration and velocity of the heel / toe point
            for e in (0, 2):
                if active[owner[e]] and touching:
                    _, vr, Jr, jdqr = self._point(rd, bid, 0.5 * (corners[e] + corners[e + 1]))
                    edge_ref[e] = (Jr @ qacc_r + jdqr, vr)
            for c in range(4):
                if active[owner[c]]:
                    p, v, J, jdq = self._point(d, bid, corners[c])
                    near = touching and p[2] - self.ground(d, p) < g.contact_height
                    if near or any(np.linalg.norm(p - x) < g.contact_distance for x in touching):
                        used.append((f, J, jdq, v, p))
                        if g.flat_stance:  # the sole stays flat: its corners move as the reference's point
                            point_rows.append((J, jdq, v, *edge_ref[c - c % 2]))
            if not used:
                swing.append((f, bid, centre))
            elif g.sole_flat_weight > 0 and (len(self.inv_v) or (active[owner[0]] and active[owner[2]])):
                # the sole lies flat on the ground: roll (and pitch, with heel and toe both on the
                # ground) to the ground's normal, no spin
                R = d.geom_xmat[gid].reshape(3, 3)
                nrm = R[:, 2]
                err = np.cross(nrm, np.array([0.0, 0.0, 1.0]))
                both = active[owner[0]] and active[owner[2]]
                if not both:
                    err = R[:, 0] * float(R[:, 0] @ err)  # roll only: the foot rocks on heel or toe
                jp, jr = np.zeros((3, nv)), np.zeros((3, nv))
                mujoco.mj_jac(m, d, jp, jr, d.geom_xpos[gid], bid)
                jdp, jdr = np.zeros((3, nv)), np.zeros((3, nv))
                mujoco.mj_jacDot(m, d, jdp, jdr, d.geom_xpos[gid], bid)
                w = jr @ d.qvel
                wdes = np.zeros(3)
                if not both:
                    jr_ref = np.zeros((3, nv))
                    mujoco.mj_jac(m, rd, None, jr_ref, rd.xpos[bid], bid)
                    wr = jr_ref @ rd.qvel
                    wdes = wr - R[:, 0] * float(R[:, 0] @ wr)  # the reference's pitch rate, no roll
                kp, kd = g.sole_flat_freq**2, 2 * g.sole_flat_freq
                flat_rows.append((jr, kp * err + kd * (wdes - w) - jdr @ d.qvel))
            corner_rows.extend(used)
            half_w = 0.5 * float(np.linalg.norm(corners[0] - corners[1]))
            # the optimizer's contact points (mid-edges of the sole) move as the reference's
            for e in edge_ref if not g.flat_stance else ():
                p, v, J, jdq = self._point(d, bid, 0.5 * (corners[e] + corners[e + 1]))
                if any(np.linalg.norm(p - x) < g.contact_distance + half_w for x in touching):
                    point_rows.append((J, jdq, v, *edge_ref[e]))
        nc = len(corner_rows)
        nb = nc * self.n_edges
        nr = len(self.residual)  # the root residual (resync runs): generalized forces on the root's six rows
        nx = nv + nb + nr
        # f_c = E β_c; generalized force of contacts: Σ J_cᵀ E β_c = Jf β
        Jf = np.zeros((nv, nb))
        for i, (_, J, _, _, _) in enumerate(corner_rows):
            Jf[:, i * 4:(i + 1) * 4] = J.T @ self.edges
        A_list: list[np.ndarray] = []
        b_list: list[np.ndarray] = []
        w_list: list[float] = []

        def task(A: np.ndarray, b: np.ndarray, w: float) -> None:
            A_list.append(np.atleast_2d(A))
            b_list.append(np.atleast_1d(b))
            w_list.append(w)

        kpj, kdj = g.joint_freq**2, 2 * g.joint_freq
        acc_j = qddr[6:] + kpj * (qr[6:] - q[6:]) + kdj * (qdr[6:] - qd[6:])
        A = np.zeros((len(self.joint_v), nx))
        A[np.arange(len(self.joint_v)), self.joint_v] = 1.0
        task(A, acc_j, 1.0)
        if len(self.inv_v):
            A = np.zeros((len(self.inv_v), nx))
            A[np.arange(len(self.inv_v)), self.inv_v] = 1.0
            task(A, -kpj * d.qpos[self.inv_q] - kdj * d.qvel[self.inv_v], g.inversion_weight)
        kpr, kdr = np.full(6, g.root_freq**2), np.full(6, 2 * g.root_freq)
        # horizontal position: weak and saturated (foot placement keeps the balance; a large
        # position error would otherwise ask for accelerations no contact force can give)
        kpr[list(ROOT_XY)], kdr[list(ROOT_XY)] = g.root_xy_freq**2, 2 * g.root_xy_freq
        err = qr[:6] - q[:6]
        err[list(ROOT_XY)] = np.clip(err[list(ROOT_XY)], -g.root_xy_saturation, g.root_xy_saturation)
        acc_r = qddr[:6] + kpr * err + kdr * (qdr[:6] - qd[:6])
        A = np.zeros((6, nx))
        A[np.arange(6), self.root_v] = 1.0
        task(A, acc_r, g.root_weight)
        for J, jdq, v, ar, vr in point_rows:
            A = np.zeros((3, nx))
            A[:, :nv] = J
            task(A, ar - jdq + g.contact_damping * (vr - v), g.contact_weight)
        for jr_, b in flat_rows:
            A = np.zeros((3, nx))
            A[:, :nv] = jr_
            task(A, b, g.sole_flat_weight)
        # swing foot placement: the reference position moved by the balance feedback
        dxy = g.placement_position * (com - com_r)[:2] + g.placement_velocity * (vcom - vcom_r)[:2]
        kps, kds = g.swing_freq**2, 2 * g.swing_freq
        for _f, bid, centre in swing:
            p, v, J, jdq = self._point(d, bid, centre)
            pr = rd.xpos[bid] + rd.xmat[bid].reshape(3, 3) @ centre
            jr_, jdr_ = np.zeros((3, nv)), np.zeros((3, nv))
            mujoco.mj_jac(m, rd, jr_, None, pr, bid)
            mujoco.mj_jacDot(m, rd, jdr_, None, pr, bid)
            vr = jr_ @ rd.qvel
            ar = jr_ @ qacc_r + jdr_ @ rd.qvel
            lift = 0.0
            sp = ref.swing_progress(t_ref, self.owner_feet[_f]) if g.swing_lift else None
            if sp is not None:  # clearance: the reference's swing raised by up to swing_lift mid-swing
                lift = g.swing_lift * math.sin(math.pi * sp)
            target = pr + np.array([dxy[0], dxy[1], lift])
            A = np.zeros((3, nx))
            A[:, :nv] = J
            task(A, ar + kps * (target - p) + kds * (vr - v) - jdq, g.swing_weight)
            if g.swing_orientation_weight > 0:  # the swing foot turns as the reference's
                jr_s, jdr_s, jr_r, jdr_r = (np.zeros((3, nv)) for _ in range(4))
                mujoco.mj_jac(m, d, None, jr_s, p, bid)
                mujoco.mj_jacDot(m, d, None, jdr_s, p, bid)
                mujoco.mj_jac(m, rd, None, jr_r, pr, bid)
                mujoco.mj_jacDot(m, rd, None, jdr_r, pr, bid)
                Rs, Rr = d.xmat[bid].reshape(3, 3), rd.xmat[bid].reshape(3, 3)
                qe = np.zeros(4)
                mujoco.mju_mat2Quat(qe, (Rr @ Rs.T).reshape(9))
                rot = np.zeros(3)
                mujoco.mju_quat2Vel(rot, qe, 1.0)
                alpha_r = jr_r @ qacc_r + jdr_r @ rd.qvel
                A = np.zeros((3, nx))
                A[:, :nv] = jr_s
                task(A, alpha_r + kps * rot + kds * (jr_r @ rd.qvel - jr_s @ d.qvel) - jdr_s @ d.qvel,
                     g.swing_orientation_weight)
        # stored foot wrenches (regularization): per foot the force, and the moment about the sole's
        # centre (the stored one about the reference's sole centre, before re-anchoring: the wrench was
        # stored there), so the centre of pressure is asked where the stored one is on its foot, wherever
        # the foot is (about the world origin, a force error far from it weighed as a moment error)
        if nb:
            for f in range(2):
                cols = [i for i, r in enumerate(corner_rows) if r[0] == f]
                if not cols:
                    continue
                Af = np.zeros((3, nx))
                Am = np.zeros((3, nx))
                _gid, bid, _corners, _owner, centre = self.soles[f]
                if g.local_moments:
                    c_sim = d.xpos[bid] + d.xmat[bid].reshape(3, 3) @ centre
                    c_ref = rd.xpos[bid] + rd.xmat[bid].reshape(3, 3) @ centre
                    if g.reanchor:
                        c_ref[:2] -= self.anchor
                else:
                    c_sim = c_ref = np.zeros(3)
                for i in cols:
                    p = corner_rows[i][4]
                    Af[:, nv + 4 * i:nv + 4 * i + 4] = self.edges
                    Am[:, nv + 4 * i:nv + 4 * i + 4] = np.cross(p - c_sim, self.edges.T).T
                m_ref = W[f, :3] - np.cross(c_ref, W[f, 3:])
                task(Af / self.bw, W[f, 3:] / self.bw, g.force_weight)
                task(Am / (0.1 * self.bw), m_ref / (0.1 * self.bw), g.moment_weight)
        # torques: τ = (M q̈ + h − Jf β)_act
        At = np.zeros((len(self.motor), nx))
        At[:, :nv] = M[self.act_v]
        At[:, nv:nv + nb] = -Jf[self.act_v]
        bt = h[self.act_v]
        task(At / self.tau_limit[:, None], -bt / self.tau_limit, g.torque_weight)
        if nr:  # the residual, in body weights (root hinges: per BW × 1 m), used only where it pays
            A = np.zeros((nr, nx))
            A[np.arange(nr), nv + nb + np.arange(nr)] = 1.0 / self.bw
            task(A, np.zeros(nr), g.residual_weight)

        Amat = np.vstack([a * math.sqrt(w) for a, w in zip(A_list, w_list, strict=True)])
        bvec = np.concatenate([b * math.sqrt(w) for b, w in zip(b_list, w_list, strict=True)])
        G = Amat.T @ Amat + 1e-8 * np.eye(nx)
        G[nv:nv + nb, nv:nv + nb] += 1e-6 * np.eye(nb)
        a = Amat.T @ bvec
        # equalities: root rows of the equations of motion; inequalities: β ≥ 0, |τ| ≤ limit
        Ceq = np.zeros((6, nx))
        Ceq[:, :nv] = M[self.root_v]
        Ceq[:, nv:nv + nb] = -Jf[self.root_v]
        if nr:  # M q̈ + h = Jᵀf + r on the root rows
            Ceq[:, nv + nb:] = -np.eye(6)
        beq = -h[self.root_v]
        Cin = [np.eye(nx)[nv:nv + nb], At, -At]
        bin_ = [np.zeros(nb), -self.tau_limit + bt, -self.tau_limit - bt]
        C = np.vstack([Ceq, *Cin])
        b = np.concatenate([beq, *bin_])
        try:
            x = quadprog.solve_qp(G, a, C.T, b, 6)[0]
        except ValueError:
            # infeasible within the torque limits (should not happen: q̈ is free): drop them
            x = quadprog.solve_qp(G, a, np.vstack([Ceq, np.eye(nx)[nv:nv + nb]]).T,
                                  np.concatenate([beq, np.zeros(nb)]), 6)[0]
        tau = np.zeros(m.nu)
        tau[self.motor] = At @ x + bt
        tau[self.residual] = x[nv + nb:]
        pred = np.zeros((2, 3))
        for i, r in enumerate(corner_rows):
            pred[r[0]] += self.edges @ x[nv + 4 * i:nv + 4 * i + 4]
        self.predicted = pred
        self.n_corners = [sum(1 for r in corner_rows if r[0] == f) for f in range(2)]
        return tau
