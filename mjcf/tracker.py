"""The balancing QP tracking controller (:class:`Tracker`, a ``mjcf.controller.Controller``) and
its gains (:class:`Gains`).

Every control step the controller solves one quadratic program (``quadprog``, dense) over the
generalized accelerations q̈, the contact forces at the stance sole corners (each a non-negative
combination β of the four edges of a pyramidal friction cone) and, on a resync model, the root
residual r. Constraints (:meth:`Tracker._solve`): the six unactuated root rows of the equations
of motion, M q̈ + h = Jᵀf (+ r) there (only the contacts can move the root), β ≥ 0, and the joint
torque limits on τ = (M q̈ + h − Jᵀf)_actuated, which are the motors' controls. The cost is a
weighted sum of tasks ‖A x − b‖², each a method named after it:

=====================  ========  ===========================================================
task                   weight    target
=====================  ========  ===========================================================
``_stance_task``       1000      each loaded sole corner moves as the reference's heel / toe
``_root_task``         100       the root's reference pose in the world, PD
``_sole_flat_task``    100       a stance sole flat on the ground
``_swing_task``        5         the swing sole's reference position + foot placement
``_joint_task``        1         the joints' reference accelerations, PD
``_inversion_task``    1         the feet's inversion hinges at 0, PD
``_wrench_task``       30, 3     the stored foot forces (per BW²) and moments (per (0.1 BW·m)²)
``_torque_task``       10⁻⁶      small torques (normalized by their limits)
``_residual_task``     10⁶       no root residual (per BW²; resync runs only)
=====================  ========  ===========================================================

What the weights trade: the stance corners (1000) hold the contact model's assumption (a loaded
sole neither slips nor lifts), so no other task buys its error with a sliding foot; the root pose
and a flat sole (100) are the balance and come before the joints' tracking (1); the swing foot (5)
places the foot ahead of the leg's joint angles, i.e. the character steps to recover; the stored
wrenches only share the load among the corners, where the other tasks leave it free; the torques'
term (10⁻⁶) only breaks ties, and the residual (10⁶) pays only where nothing else can.

The formulation follows the QP controllers of physics-based character animation:

* Abe, da Silva & Popović 2007, "Multiobjective control with frictional contacts" (SCA): one QP
  over accelerations and contact forces on the edges of a linearized friction cone, a weighted
  sum of tracking objectives, the equations of motion as constraints.
* de Lasa, Mordatch & Hertzmann 2010, "Feature-based locomotion controllers" (SIGGRAPH): the
  same unknowns and constraints with tasks on features (end effectors, root); there solved by
  strict priority, here by weights.
* Yin, Loken & van de Panne 2007, "SIMBICON" (SIGGRAPH): balance by foot placement,
  Δ = c_d d + c_v v on the centre of mass's position and velocity errors; here added to the
  swing foot's target position rather than the swing hip's angle.
* Lee, Kim & Lee 2010, "Data-driven biped control" (SIGGRAPH): tracking a captured motion whose
  reference follows the simulation; here re-anchored on each planted foot (:meth:`_reanchor`)
  and its clock synchronized with the simulated touchdowns (:meth:`clock_rate`).

Not in it: a momentum task (Macchietto, Zordan & Shelton 2009), ZMP preview control (Kajita et
al. 2003), a planned centre-of-mass trajectory (Mordatch, de Lasa & Hertzmann 2010); the stored
moment task asks the centre of pressure to be where the stored one is on the foot, nothing more.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, NamedTuple

import mujoco
import numpy as np
import quadprog

from mjcf.controller import ControllerBase
from mjcf.gains import Gains, motor_peaks
from mjcf.performable import ModelGeometry, Sole
from mjcf.reference import Reference
from solver.environment import body_weight
from solver.motion import Motion
from solver.trajectory import ROOT_XY


class _Corner(NamedTuple):
    """A loaded sole corner: its foot, Jacobian, J̇q̇, velocity and position (world)."""

    foot: int
    J: np.ndarray
    jdq: np.ndarray
    v: np.ndarray
    p: np.ndarray


@dataclass
class _Stance:
    """Which feet bear load and the rows their tasks are made of (:meth:`Tracker._stance`)."""

    corners: list[_Corner] = field(default_factory=list)  # the loaded corners: the contact forces' points
    points: list[tuple[np.ndarray, ...]] = field(default_factory=list)  # (J, J̇q̇, v, reference acc., vel.)
    flat: list[tuple[np.ndarray, np.ndarray]] = field(default_factory=list)  # (angular J, target ω̇)
    swing: list[Sole] = field(default_factory=list)  # feet without a loaded corner


class _Tasks:
    """The QP's cost: weighted least-squares rows, w ‖A x − b‖² each."""

    def __init__(self, nx: int) -> None:
        self.nx = nx
        self.A: list[np.ndarray] = []
        self.b: list[np.ndarray] = []
        self.w: list[float] = []

    def add(self, A: np.ndarray, b: np.ndarray, w: float) -> None:
        self.A.append(np.atleast_2d(A))
        self.b.append(np.atleast_1d(b))
        self.w.append(w)

    def on_qacc(self, J: np.ndarray, b: np.ndarray, w: float) -> None:
        """A task on the accelerations only: J q̈ ≈ b."""
        A = np.zeros((J.shape[0], self.nx))
        A[:, :J.shape[1]] = J
        self.add(A, b, w)

    def selection(self, columns: np.ndarray, b: np.ndarray, w: float) -> None:
        """A task on single variables: x[columns] ≈ b."""
        A = np.zeros((len(columns), self.nx))
        A[np.arange(len(columns)), columns] = 1.0
        self.add(A, b, w)

    def normal(self) -> tuple[np.ndarray, np.ndarray]:
        """Aᵀ A and Aᵀ b of the weighted rows."""
        Amat = np.vstack([a * math.sqrt(w) for a, w in zip(self.A, self.w, strict=True)])
        bvec = np.concatenate([b * math.sqrt(w) for b, w in zip(self.b, self.w, strict=True)])
        return Amat.T @ Amat, Amat.T @ bvec


class Tracker(ControllerBase):
    """The balancing QP tracking controller (module docstring); a ``mjcf.controller.Controller``
    whose termination is the default fall."""

    def __init__(self, motion: Motion, model: mujoco.MjModel, geometry: ModelGeometry, ref: Reference,
                 gains: Gains | None = None) -> None:
        super().__init__(model, geometry, ref)
        gains = gains or Gains()
        self.m, self.geometry, self.ref, self.g = model, geometry, ref, gains
        self.control_period = gains.control_period
        self.nv = model.nv
        self.qadr, self.vadr = geometry.coordinate_qpos, geometry.coordinate_dof
        self.root_v = self.vadr[:6]
        self.joint_v = self.vadr[6:]
        self.motor, self.residual = geometry.motors, geometry.residual
        self.act_v = np.array([model.jnt_dofadr[model.actuator_trnid[a, 0]] for a in self.motor])
        self.mu = motion.environment.friction * gains.friction_margin
        self.bw = body_weight(motion)
        self.ref_data = mujoco.MjData(model)
        s = 1.0 / math.sqrt(1 + self.mu**2)
        self.edges = np.array([[self.mu * s, 0, s], [-self.mu * s, 0, s], [0, self.mu * s, s], [0, -self.mu * s, s]]).T
        self.inv_q, self.inv_v = geometry.inversion_qpos, geometry.inversion_dof
        self.peaks = motor_peaks(motion, model, geometry)
        # |τ| ≤ scale × the motion's inverse-dynamics peak, at least floor × the largest peak
        self.tau_limit = np.maximum(gains.torque_limit_scale * self.peaks,
                                    gains.torque_limit_floor * float(self.peaks.max()))
        self.torque_limit = self.tau_limit
        self.com_body = int(model.body_rootid[geometry.pelvis])
        self._M = np.zeros((self.nv, self.nv))
        self.treads = bool(geometry.treads)
        self._reset()

    def _reset(self) -> None:
        """The state carried from step to step, as at a run's start."""
        self.predicted = np.zeros((2, 3))  # the QP's contact force per foot (world)
        self.n_corners = [0, 0]  # loaded corners per foot
        # horizontal shift of the reference: re-planted at every touchdown on the actual foot
        self.anchor = np.zeros(2)
        self.anchor_target = np.zeros(2)
        self.was_down = [True, True]
        self.airborne = [False, False]
        self.waited = [0.0, 0.0]

    def initialize(self, data: mujoco.MjData, t0: float) -> None:
        """A run's start: no re-anchoring yet, the clock unsynchronized, the fall detection started."""
        self._reset()
        super().initialize(data, t0)

    def measures(self, data: mujoco.MjData) -> dict[str, Any]:
        """The QP's contact force per foot (``foot_force_qp``), its loaded corners per foot
        (``stance_corners``) and the reference's horizontal shift (``anchor``)."""
        return {"foot_force_qp": self.predicted.copy(), "stance_corners": list(self.n_corners),
                "anchor": self.anchor.copy()}

    def _touching(self, d: mujoco.MjData, sole: Sole) -> bool:
        return any(sole.geom in (d.contact[i].geom1, d.contact[i].geom2) for i in range(d.ncon))

    def _reanchor(self, d: mujoco.MjData, qr: np.ndarray, active: np.ndarray) -> None:
        """When a foot is planted (the reference has it in stance and the simulated sole touches
        the ground, whichever comes last), move the reference horizontally so that its foot is
        where the simulated foot is; blend the shift in over ``anchor_time``. The root task then
        acts relative to the support (Lee, Kim & Lee 2010)."""
        g = self.g
        for f, sole in enumerate(self.geometry.soles):
            bid, centre = sole.body, sole.centre
            down = bool(active[sole.points].any()) and self._touching(d, sole)
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
        data-driven tracking (Lee, Kim & Lee 2010): the reference hurries (``sync_fast``) to its
        touchdown while the simulated foot is already down, and waits (``sync_slow``, at most
        ``sync_max_wait`` s per touchdown) for a late foot."""
        g = self.g
        if not g.synchronize:
            return 1.0
        rate = 1.0
        for f, sole in enumerate(self.geometry.soles):
            touching = self._touching(d, sole)
            sp = self.ref.swing_progress(t_ref, sole.points)
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
        return self.geometry.ground_height(d, p) if self.treads else 0.0

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
        """Joint torques (actuator order) for the state in ``d`` (after mj_forward): the tasks
        at reference time ``t_ref`` (re-anchored), solved in one QP."""
        m, g, ref = self.m, self.g, self.ref
        qr, qdr, qddr = ref.state(t_ref)
        q = d.qpos[self.qadr]
        qd = d.qvel[self.vadr]
        active = ref.active(t_ref)
        if g.reanchor:
            self._reanchor(d, qr, active)
            qr = qr.copy()
            qr[list(ROOT_XY)] += self.anchor
        rd, qacc_r = self._reference(qr, qdr, qddr)
        com, vcom = self._com(d, d.qvel)
        com_r, vcom_r = self._com(rd, rd.qvel)
        mujoco.mj_fullM(m, d, self._M)
        M = self._M
        h = d.qfrc_bias
        st = self._stance(d, rd, active, qacc_r)
        nb = 4 * len(st.corners)
        # f_c = E β_c; generalized force of contacts: Σ J_cᵀ E β_c = Jf β
        Jf = np.zeros((self.nv, nb))
        for i, c in enumerate(st.corners):
            Jf[:, i * 4:(i + 1) * 4] = c.J.T @ self.edges
        tasks = _Tasks(self.nv + nb + len(self.residual))
        self._joint_task(tasks, q, qd, qr, qdr, qddr)
        self._inversion_task(tasks, d)
        self._root_task(tasks, q, qd, qr, qdr, qddr)
        self._stance_task(tasks, st)
        self._sole_flat_task(tasks, st)
        self._swing_task(tasks, d, rd, t_ref, st, qacc_r, (com, vcom, com_r, vcom_r))
        self._wrench_task(tasks, d, rd, st, ref.wrench(t_ref))
        At, bt = self._torque_task(tasks, M, h, Jf)
        self._residual_task(tasks)
        x = self._solve(tasks, M, h, Jf, At, bt)
        nv = self.nv
        tau = np.zeros(m.nu)
        tau[self.motor] = At @ x + bt
        tau[self.residual] = x[nv + nb:]
        pred = np.zeros((2, 3))
        for i, c in enumerate(st.corners):
            pred[c.foot] += self.edges @ x[nv + 4 * i:nv + 4 * i + 4]
        self.predicted = pred
        self.n_corners = [sum(1 for c in st.corners if c.foot == f) for f in range(2)]
        return tau

    def _reference(self, qr: np.ndarray, qdr: np.ndarray, qddr: np.ndarray) -> tuple[mujoco.MjData, np.ndarray]:
        """The reference's kinematics (bodies, centre of mass, their velocities) in ``ref_data``,
        and its generalized accelerations in MuJoCo's dof order."""
        m, rd = self.m, self.ref_data
        rd.qpos[self.qadr] = qr
        rd.qvel[self.vadr] = qdr
        mujoco.mj_kinematics(m, rd)
        mujoco.mj_comPos(m, rd)
        mujoco.mj_comVel(m, rd)
        qacc_r = np.zeros(self.nv)
        qacc_r[self.vadr] = qddr
        return rd, qacc_r

    def _stance(self, d: mujoco.MjData, rd: mujoco.MjData, active: np.ndarray, qacc_r: np.ndarray) -> _Stance:
        """Which sole corners bear load: those the schedule has in contact (``Reference.active``)
        where MuJoCo has a contact within ``contact_distance`` of the corner or, on a foot already
        touching, the corner is within ``contact_height`` of the ground. Each loaded corner is to
        move as the reference's heel or toe point (with ``flat_stance``; else the sole's mid-edge
        points near a contact do); a foot with no loaded corner swings."""
        g = self.g
        st = _Stance()
        for f, sole in enumerate(self.geometry.soles):
            gid, bid, corners, owner = sole.geom, sole.body, sole.corners, sole.owner
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
                        used.append(_Corner(f, J, jdq, v, p))
                        if g.flat_stance:  # the sole stays flat: its corners move as the reference's point
                            st.points.append((J, jdq, v, *edge_ref[c - c % 2]))
            if not used:
                st.swing.append(sole)
            elif g.sole_flat_weight > 0 and (len(self.inv_v) or (active[owner[0]] and active[owner[2]])):
                st.flat.append(self._sole_flat_row(d, rd, sole, bool(active[owner[0]] and active[owner[2]])))
            st.corners.extend(used)
            half_w = 0.5 * float(np.linalg.norm(corners[0] - corners[1]))
            # the optimizer's contact points (mid-edges of the sole) move as the reference's
            for e in edge_ref if not g.flat_stance else ():
                p, v, J, jdq = self._point(d, bid, 0.5 * (corners[e] + corners[e + 1]))
                if any(np.linalg.norm(p - x) < g.contact_distance + half_w for x in touching):
                    st.points.append((J, jdq, v, *edge_ref[e]))
        return st

    def _sole_flat_row(self, d: mujoco.MjData, rd: mujoco.MjData, sole: Sole,
                       both: bool) -> tuple[np.ndarray, np.ndarray]:
        """The stance sole's angular acceleration toward lying flat on the ground: its normal to
        the vertical by PD (``sole_flat_freq``), roll always, pitch too when heel and toe are both
        scheduled (else the foot rocks on heel or toe at the reference's pitch rate), no spin."""
        m, g, nv = self.m, self.g, self.nv
        gid, bid = sole.geom, sole.body
        R = d.geom_xmat[gid].reshape(3, 3)
        nrm = R[:, 2]
        err = np.cross(nrm, np.array([0.0, 0.0, 1.0]))
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
        return jr, kp * err + kd * (wdes - w) - jdr @ d.qvel

    def _joint_task(self, tasks: _Tasks, q: np.ndarray, qd: np.ndarray, qr: np.ndarray, qdr: np.ndarray,
                    qddr: np.ndarray) -> None:
        """Joints (weight 1): the reference's accelerations plus critically damped PD feedback
        (ω = ``joint_freq``) toward its angles and velocities: computed-torque tracking."""
        g = self.g
        kpj, kdj = g.joint_freq**2, 2 * g.joint_freq
        tasks.selection(self.joint_v, qddr[6:] + kpj * (qr[6:] - q[6:]) + kdj * (qdr[6:] - qd[6:]), 1.0)

    def _inversion_task(self, tasks: _Tasks, d: mujoco.MjData) -> None:
        """The feet's inversion hinges (``inversion_weight``): toward 0 (the motion has no such
        coordinate) with the joints' PD; in stance the sole-flat task rules them."""
        if len(self.inv_v):
            g = self.g
            kpj, kdj = g.joint_freq**2, 2 * g.joint_freq
            tasks.selection(self.inv_v, -kpj * d.qpos[self.inv_q] - kdj * d.qvel[self.inv_v], g.inversion_weight)

    def _root_task(self, tasks: _Tasks, q: np.ndarray, qd: np.ndarray, qr: np.ndarray, qdr: np.ndarray,
                   qddr: np.ndarray) -> None:
        """The root's pose in the world (``root_weight``): the reference's accelerations plus PD
        (ω = ``root_freq``). What balances: only the contact forces can supply these accelerations
        (the root rows' equality). The horizontal position is weak (ω = ``root_xy_freq``) and its
        error saturated at ``root_xy_saturation``: foot placement keeps the balance, and a large
        position error would ask for accelerations no contact force can give."""
        g = self.g
        kpr, kdr = np.full(6, g.root_freq**2), np.full(6, 2 * g.root_freq)
        kpr[list(ROOT_XY)], kdr[list(ROOT_XY)] = g.root_xy_freq**2, 2 * g.root_xy_freq
        err = qr[:6] - q[:6]
        err[list(ROOT_XY)] = np.clip(err[list(ROOT_XY)], -g.root_xy_saturation, g.root_xy_saturation)
        tasks.selection(self.root_v, qddr[:6] + kpr * err + kdr * (qdr[:6] - qd[:6]), g.root_weight)

    def _stance_task(self, tasks: _Tasks, st: _Stance) -> None:
        """The loaded sole corners (``contact_weight``): each accelerates as the reference's heel
        or toe point, with damping (``contact_damping``) toward its velocity: the stance foot
        rolls as the reference's and does not slip."""
        g = self.g
        for J, jdq, v, ar, vr in st.points:
            tasks.on_qacc(J, ar - jdq + g.contact_damping * (vr - v), g.contact_weight)

    def _sole_flat_task(self, tasks: _Tasks, st: _Stance) -> None:
        """A stance sole lies flat on the ground (``sole_flat_weight``; :meth:`_sole_flat_row`)."""
        for jr_, b in st.flat:
            tasks.on_qacc(jr_, b, self.g.sole_flat_weight)

    def _swing_task(self, tasks: _Tasks, d: mujoco.MjData, rd: mujoco.MjData, t_ref: float, st: _Stance,
                    qacc_r: np.ndarray, coms: tuple[np.ndarray, ...]) -> None:
        """The swing sole's centre (``swing_weight``): the reference's acceleration plus PD
        (ω = ``swing_freq``) toward the reference's position raised by ``swing_lift`` × sin(π s)
        over the swing (clearance) and moved by SIMBICON's foot-placement feedback (Yin, Loken &
        van de Panne 2007): Δ = c_d (c − c_ref) + c_v (ċ − ċ_ref), horizontal centre-of-mass errors,
        c_d = ``placement_position``, c_v = ``placement_velocity``. With
        ``swing_orientation_weight``, the swing foot also turns as the reference's."""
        m, g, nv = self.m, self.g, self.nv
        com, vcom, com_r, vcom_r = coms
        dxy = g.placement_position * (com - com_r)[:2] + g.placement_velocity * (vcom - vcom_r)[:2]
        kps, kds = g.swing_freq**2, 2 * g.swing_freq
        for sole in st.swing:
            bid, centre = sole.body, sole.centre
            p, v, J, jdq = self._point(d, bid, centre)
            pr = rd.xpos[bid] + rd.xmat[bid].reshape(3, 3) @ centre
            jr_, jdr_ = np.zeros((3, nv)), np.zeros((3, nv))
            mujoco.mj_jac(m, rd, jr_, None, pr, bid)
            mujoco.mj_jacDot(m, rd, jdr_, None, pr, bid)
            vr = jr_ @ rd.qvel
            ar = jr_ @ qacc_r + jdr_ @ rd.qvel
            lift = 0.0
            sp = self.ref.swing_progress(t_ref, sole.points) if g.swing_lift else None
            if sp is not None:  # clearance: the reference's swing raised by up to swing_lift mid-swing
                lift = g.swing_lift * math.sin(math.pi * sp)
            target = pr + np.array([dxy[0], dxy[1], lift])
            tasks.on_qacc(J, ar + kps * (target - p) + kds * (vr - v) - jdq, g.swing_weight)
            if g.swing_orientation_weight > 0:
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
                tasks.on_qacc(jr_s, alpha_r + kps * rot + kds * (jr_r @ rd.qvel - jr_s @ d.qvel) - jdr_s @ d.qvel,
                              g.swing_orientation_weight)

    def _wrench_task(self, tasks: _Tasks, d: mujoco.MjData, rd: mujoco.MjData, st: _Stance, W: np.ndarray) -> None:
        """The motion's stored foot wrenches (regularization; ``force_weight`` per BW²,
        ``moment_weight`` per (0.1 BW·m)²): per stance foot the force, and the moment about the
        simulated sole's centre against the stored moment about the reference's sole centre
        (before re-anchoring: the wrench was stored there), so the centre of pressure is asked
        where the stored one is on its foot wherever the foot is (``local_moments``; else both
        about the world origin, where a force error far from it weighs as a moment error)."""
        g, nv, nx = self.g, self.nv, tasks.nx
        if not st.corners:
            return
        for f in range(2):
            cols = [i for i, c in enumerate(st.corners) if c.foot == f]
            if not cols:
                continue
            Af = np.zeros((3, nx))
            Am = np.zeros((3, nx))
            bid, centre = self.geometry.soles[f].body, self.geometry.soles[f].centre
            if g.local_moments:
                c_sim = d.xpos[bid] + d.xmat[bid].reshape(3, 3) @ centre
                c_ref = rd.xpos[bid] + rd.xmat[bid].reshape(3, 3) @ centre
                if g.reanchor:
                    c_ref[:2] -= self.anchor
            else:
                c_sim = c_ref = np.zeros(3)
            for i in cols:
                p = st.corners[i].p
                Af[:, nv + 4 * i:nv + 4 * i + 4] = self.edges
                Am[:, nv + 4 * i:nv + 4 * i + 4] = np.cross(p - c_sim, self.edges.T).T
            m_ref = W[f, :3] - np.cross(c_ref, W[f, 3:])
            tasks.add(Af / self.bw, W[f, 3:] / self.bw, g.force_weight)
            tasks.add(Am / (0.1 * self.bw), m_ref / (0.1 * self.bw), g.moment_weight)

    def _torque_task(self, tasks: _Tasks, M: np.ndarray, h: np.ndarray,
                     Jf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Small torques (``torque_weight``, each normalized by its limit): τ = At x + bt, the
        actuated rows of M q̈ + h − Jᵀf; returns (At, bt)."""
        nv, nb = self.nv, Jf.shape[1]
        At = np.zeros((len(self.motor), tasks.nx))
        At[:, :nv] = M[self.act_v]
        At[:, nv:nv + nb] = -Jf[self.act_v]
        bt = h[self.act_v]
        tasks.add(At / self.tau_limit[:, None], -bt / self.tau_limit, self.g.torque_weight)
        return At, bt

    def _residual_task(self, tasks: _Tasks) -> None:
        """No root residual (``residual_weight``; a resync model's only): in body weights (the root
        hinges' torques per BW × 1 m), so it is used only where nothing else can do (a Moco-style
        residual actuator: Dembia et al. 2020, OpenSim Moco)."""
        nr = len(self.residual)
        if nr:
            A = np.zeros((nr, tasks.nx))
            A[np.arange(nr), tasks.nx - nr + np.arange(nr)] = 1.0 / self.bw
            tasks.add(A, np.zeros(nr), self.g.residual_weight)

    def _solve(self, tasks: _Tasks, M: np.ndarray, h: np.ndarray, Jf: np.ndarray, At: np.ndarray,
               bt: np.ndarray) -> np.ndarray:
        """The QP's solution x = (q̈, β, r): the tasks' least squares (regularized: 10⁻⁸ on every
        variable, 10⁻⁶ more on β) subject to the root rows of the equations of motion (equalities),
        β ≥ 0 and |τ| ≤ the torque limits; without the limits when infeasible."""
        nv, nb, nx = self.nv, Jf.shape[1], tasks.nx
        nr = len(self.residual)
        G, a = tasks.normal()
        G = G + 1e-8 * np.eye(nx)
        G[nv:nv + nb, nv:nv + nb] += 1e-6 * np.eye(nb)
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
            return quadprog.solve_qp(G, a, C.T, b, 6)[0]
        except ValueError:
            # infeasible within the torque limits (should not happen: q̈ is free): drop them
            return quadprog.solve_qp(G, a, np.vstack([Ceq, np.eye(nx)[nv:nv + nb]]).T,
                                     np.concatenate([beq, np.zeros(nb)]), 6)[0]
