"""Forward simulation of a motion in MuJoCo with contacts on, tracked by a balancing QP controller.

The model (:func:`performable_model`) is the character's (``mjcf.builder``) with contacts on:
box soles under the optimizer's heel and toe points, flat at the foot's mean stance
orientation, the environment's gravity, friction and treads, an unactuated 6-DOF root (the
character's three slides and three hinges) and one motor per joint; timestep 1 ms. The only
forces on the bodies are gravity, the motors (through the joints) and the contacts.

The controller (:class:`Tracker`) solves, every control step, one quadratic program
(``quadprog``) over the generalized accelerations q̈ and the contact forces at the stance
sole corners (non-negative combinations of the edges of a pyramidal friction cone), subject to
the equations of motion's unactuated root rows (M q̈ + h = Jᵀf there: the contact forces must
move the root) and joint torque limits; the torques follow from the actuated rows,
τ = (M q̈ + h − Jᵀf)_joints, and are what the motors apply. Its costs track

* the joints' reference accelerations with PD feedback,
* the root's reference pose in the world with PD feedback (what balances: only the contact
  forces can supply it),
* zero acceleration (with velocity damping) of the stance sole corners,
* the swing foot's reference position shifted by SIMBICON-style foot-placement feedback
  (centre-of-mass position and velocity errors), i.e. stepping to recover balance,
* the motion's stored foot forces and moments (regularization), and small torques.

The reference loops over cycles under the cycle transform (turn and translation, the rise of
stairs) of ``solver.trajectory``; the walk starts in mid single support with the reference's
velocities (no impact), its contacts preloaded at the stored vertical force (:func:`_start`).

Beside this continuous run, :func:`simulate` starts every cycle afresh from the reference's state
and tracks it to its end with a penalized residual wrench at the root (:func:`_resync`: the
report's ``resync``), and measures the model's agreement with the motion (``mjcf.agreement``).
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field, replace
from typing import Any

import mujoco
import numpy as np
import quadprog

from mjcf.agreement import agreement, ground_height
from mjcf.builder import ContactOptions, Tread, build_spec, sole_corners
from solver.environment import body_weight, ground_of
from solver.motion import FEET, Motion
from solver.stairs import flight_of
from solver.trajectory import ROOT_XY, ROOT_YAW, cycle_turn, dynamics_samples, spline_velocities

ROOT_Z = 2
#: the root residual's actuators are named this followed by the root coordinate
RESIDUAL_PREFIX = "residual_"


class SimulationError(ValueError):
    """A motion cannot be simulated (no contact schedule, no wrenches, not a gait cycle...)."""


def _rot2(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s], [s, c]])


def _rotz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


class Reference:
    """The motion as a function of time over any number of cycles: the C² spline through its
    frames (q, q̇, q̈), the stored foot wrenches (linear between frames) and the contact
    schedule, cycle k moved by k times the cycle transform."""

    def __init__(self, motion: Motion) -> None:
        if not motion.cyclic or motion.T < 5:
            raise SimulationError("simulation needs a gait cycle (a cyclic motion: frames T−2, T−1 repeat 0, 1)")
        if motion.contacts is None or motion.wrenches is None:
            raise SimulationError("simulation needs the motion's contact schedule and foot wrenches")
        self.motion = motion
        self.q = np.asarray(motion.q, dtype=float)
        self.dt = float(motion.dt)
        self.P = motion.T - 2
        self.period = self.P * self.dt
        if motion.interpolation == "cubic-spline":
            self.v = spline_velocities(self.q, self.dt)
        else:
            self.v = np.gradient(self.q, self.dt, axis=1)
        self.turn = cycle_turn(self.q)
        xy = self.q[list(ROOT_XY)]
        self.shift_xy = xy[:, self.P] - _rot2(self.turn) @ xy[:, 0]
        self.rise = float(self.q[ROOT_Z, self.P] - self.q[ROOT_Z, 0])
        self.contacts = np.asarray(motion.contacts, dtype=bool)
        self.wrenches = np.asarray(motion.wrenches, dtype=float)
        self.ground = ground_of(motion)

    def transform(self, k: int) -> tuple[float, np.ndarray, float]:
        """Cycle k's turn (rad), horizontal translation (2,) and rise (m): x ↦ R x + d."""
        R2 = _rot2(self.turn)
        d = np.zeros(2)
        for _ in range(k):
            d = R2 @ d + self.shift_xy
        return k * self.turn, d, k * self.rise

    def _split(self, t: float) -> tuple[int, int, float]:
        k = math.floor(t / self.period)
        s = (t - k * self.period) / self.dt
        i = min(int(math.floor(s)), self.P - 1)
        return k, i, s - i

    def state(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """q, q̇, q̈ at time t (s from frame 0 of cycle 0)."""
        k, i, u = self._split(t)
        h = self.dt
        q0, q1, v0, v1 = self.q[:, i], self.q[:, i + 1], self.v[:, i], self.v[:, i + 1]
        q = (2 * u**3 - 3 * u**2 + 1) * q0 + (u**3 - 2 * u**2 + u) * h * v0 + (-2 * u**3 + 3 * u**2) * q1 \
            + (u**3 - u**2) * h * v1
        qd = ((6 * u**2 - 6 * u) * q0 + (3 * u**2 - 4 * u + 1) * h * v0 + (-6 * u**2 + 6 * u) * q1
              + (3 * u**2 - 2 * u) * h * v1) / h
        qdd = ((12 * u - 6) * q0 + (6 * u - 4) * h * v0 + (-12 * u + 6) * q1 + (6 * u - 2) * h * v1) / h**2
        if k:
            turn, d, rise = self.transform(k)
            R2 = _rot2(turn)
            xy = list(ROOT_XY)
            q[xy] = R2 @ q[xy] + d
            qd[xy] = R2 @ qd[xy]
            qdd[xy] = R2 @ qdd[xy]
            q[ROOT_YAW] += turn
            q[ROOT_Z] += rise
        return q, qd, qdd

    def wrench(self, t: float) -> np.ndarray:
        """(2, 6) stored foot wrenches at t (world; moment about the origin; force)."""
        k, i, u = self._split(t)
        w = (1 - u) * self.wrenches[:, :, i] + u * self.wrenches[:, :, i + 1]
        if k:
            turn, d, rise = self.transform(k)
            R = _rotz(turn)
            p = np.array([d[0], d[1], rise])
            f = w[:, 3:] @ R.T
            m = w[:, :3] @ R.T + np.cross(p, f)
            w = np.concatenate([m, f], axis=1)
        return w

    def swing_progress(self, t: float, points: list[int]) -> float | None:
        """Where t is within the swing of the foot owning ``points`` (0 at the last contact frame,
        1 at the next), or None when the foot is in contact at the frame before or after t."""
        _, i, u = self._split(t)
        c: np.ndarray = np.asarray(self.contacts[points].any(axis=0))[: self.P]
        if c[i] or c[(i + 1) % self.P] or not c.any():
            return None
        a = i
        while not c[a % self.P]:
            a -= 1
        b = i + 1
        while not c[b % self.P]:
            b += 1
        return (i + u - a) / (b - a)

    def active(self, t: float) -> np.ndarray:
        """(P,) contact points in contact at the frame before or after t (the stored wrench
        between them may be non-zero)."""
        _, i, u = self._split(t)
        if u == 0.0:
            return self.contacts[:, i].copy()
        return self.contacts[:, i] | self.contacts[:, i + 1]


def mid_stance_time(motion: Motion) -> float:
    """Middle of the longest single support with the whole stance foot (heel and toe) down,
    else of the longest double support: a start without impact."""
    ch = motion.character
    P = motion.T - 2
    C = np.asarray(motion.contacts, dtype=bool)[:, :P]
    full = np.zeros((2, P), dtype=bool)
    anyc = np.zeros((2, P), dtype=bool)
    for f, side in enumerate(FEET):
        idx = [i for i, c in enumerate(ch.contacts) if c.side == side]
        full[f] = C[idx].all(axis=0)
        anyc[f] = C[idx].any(axis=0)
    single = (full[0] & ~anyc[1]) | (full[1] & ~anyc[0])
    mask = single if single.any() else (anyc[0] & anyc[1])
    if not mask.any():
        raise SimulationError("the contact schedule has neither single nor double support")
    best, best_len = 0, 0
    for start in range(P):  # longest cyclic run
        if mask[start] and not mask[(start - 1) % P]:
            n = 0
            while n < P and mask[(start + n) % P]:
                n += 1
            if n > best_len:
                best, best_len = start, n
    if best_len == 0:  # the whole cycle
        best, best_len = 0, P
    return ((best + (best_len - 1) / 2.0) % P) * motion.dt


def _mean_stance_roll(motion: Motion, model: mujoco.MjModel, qpos_index: np.ndarray) -> tuple[float, float]:
    """Per foot, the roll about the heel-toe line that makes the sole flat on the ground, averaged
    over the frames where the whole foot is down."""
    ch = motion.character
    d = mujoco.MjData(model)
    out = []
    P = motion.T - 2
    C = np.asarray(motion.contacts, dtype=bool)
    for side in FEET:
        seg, corners = sole_corners(ch, side, 0.0)
        ax = corners[2] - corners[0]
        ax /= np.linalg.norm(ax)
        y0 = corners[0] - corners[1]
        y0 /= np.linalg.norm(y0)
        bid = mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_BODY, seg)
        idx = [i for i, c in enumerate(ch.contacts) if c.side == side]
        frames = [t for t in range(P) if C[idx, t].all()] or [t for t in range(P) if C[idx, t].any()]
        rolls = []
        for t in frames:
            d.qpos[qpos_index] = motion.q[:, t]
            mujoco.mj_kinematics(model, d)
            R = d.xmat[bid].reshape(3, 3)
            # y(a) = y0 cos a + (ax × y0) sin a, in world; want its vertical component 0
            a_, b_ = float((R @ y0)[2]), float((R @ np.cross(ax, y0))[2])
            rolls.append(math.atan2(-a_, b_))
        out.append(float(np.mean(rolls)) if rolls else 0.0)
    return out[0], out[1]


def _treads(motion: Motion, cycles: int) -> tuple[Tread, ...]:
    """Stairs: one block per tread of the motion's flight (``solver.stairs.flight_of``: the
    geometry the optimizer and the checks used), its top at the tread's height, as deep as the
    going along the flight, spanning the width of the walk, from the cycle before the first to the
    cycle after the last simulated one. Its front face is the riser of the next tread."""
    flight = flight_of(motion)
    if flight is None:
        return ()
    first = int(min(flight.left.min(), flight.reached.min())) - flight.n
    last = int(max(flight.left.max(), flight.reached.max())) + flight.n * (cycles + 1)
    depth = 1.0
    u = flight.direction
    out = []
    for tr in flight.treads(first, last):
        mid = 0.5 * (np.asarray(tr["back_xy"]) + np.asarray(tr["front_xy"]))
        out.append(Tread((float(mid[0]), float(mid[1]), tr["height"] - depth), (flight.going / 2.0, 0.6, depth),
                         float(math.atan2(u[1], u[0]))))
    return tuple(out)


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


@dataclass(frozen=True, eq=False)
class SimulationResult:
    """What :func:`simulate` produced: the model it ran (XML), the rollout and the measures."""

    xml: str
    timestep: float
    qpos0: np.ndarray
    qvel0: np.ndarray
    time: np.ndarray  # (S,) s since the start
    ctrl: np.ndarray  # (S, nu) actuator order
    qpos: np.ndarray  # (S, nq) after each step
    actuator_names: tuple[str, ...]
    coordinate_qpos: np.ndarray  # our coordinate i -> qpos address
    t0: float  # reference time of the start
    cycle_duration_s: float
    cycles_requested: int
    fell: bool
    fall_time: float | None
    fall_reason: str | None
    wall_time_s: float
    report: dict[str, Any] = field(default_factory=dict)
    series: dict[str, np.ndarray] = field(default_factory=dict)


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


def performable_model(motion: Motion, cycles: int = 10, ref: Reference | None = None,
                      sole_half_width: float | None = None, inversion: bool = True, *,
                      root_residual: bool = False) -> tuple[str, mujoco.MjModel, tuple[float, float]]:
    """The model XML, the model compiled *from that XML* (so a replay from the file is what
    was simulated) and the soles' roll (rad, right and left) that lays them flat in stance.
    ``root_residual``: also a motor on each of the six root coordinates (``residual_<name>``,
    after the joints' motors): the resync runs' penalized residual wrench."""
    ch = motion.character
    env = motion.environment
    ref = ref or Reference(motion)
    base = build_spec(ch, env.gravity).compile()
    ids = [mujoco.mj_name2id(base, mujoco.mjtObj.mjOBJ_JOINT, nm) for nm in ch.coordinate_names]
    qadr = np.array([base.jnt_qposadr[i] for i in ids])
    roll = _mean_stance_roll(motion, base, qadr)
    treads = _treads(motion, cycles)
    opts = ContactOptions(sole_roll=roll, friction=env.friction, treads=treads, floor=not treads,
                          sole_half_width=sole_half_width, inversion=inversion)
    spec = build_spec(ch, env.gravity, opts)
    if root_residual:
        for nm in ch.coordinate_names[:6]:
            a = spec.add_actuator(name=f"{RESIDUAL_PREFIX}{nm}", target=nm, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            a.gear = [1.0, 0, 0, 0, 0, 0]
            a.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
    spec.compile()
    xml = spec.to_xml()
    return xml, mujoco.MjModel.from_xml_string(xml), roll


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


def _foot_forces(m: mujoco.MjModel, d: mujoco.MjData, sole_geoms: tuple[int, int]) -> np.ndarray:
    """(2, 3) world contact force on each sole."""
    out = np.zeros((2, 3))
    f6 = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        for f, gid in enumerate(sole_geoms):
            if c.geom1 == gid or c.geom2 == gid:
                mujoco.mj_contactForce(m, d, i, f6)
                fw = c.frame.reshape(3, 3).T @ f6[:3]
                out[f] += fw if c.geom2 == gid else -fw
    return out


#: the deepest the preloaded start presses the stance sole into the soft contacts (m)
MAX_PRELOAD_DEPTH = 0.01


def _start(m: mujoco.MjModel, ctl: Tracker, ref: Reference, t0: float,
           preload: bool) -> tuple[mujoco.MjData, dict[str, Any]]:
    """The state the simulation starts from at reference time ``t0``: the reference's pose and
    velocities, the body lowered so the lowest scheduled sole corner touches the ground; with
    ``preload``, lowered further (the soft contacts' penetration) until MuJoCo's vertical contact
    force under the controller's first torques equals the stored one (bisection on the depth). A
    fresh ``MjData`` (a replay from qpos0/qvel0 starts from the same solver state)."""
    d = mujoco.MjData(m)
    qr, qdr, _ = ref.state(t0)
    d.qpos[ctl.qadr] = qr
    d.qvel[ctl.vadr] = qdr
    mujoco.mj_forward(m, d)
    active = ref.active(t0)
    lows = []
    for _gid, bid, corners, owner, _c in ctl.soles:
        for c in range(4):
            if active[owner[c]]:
                p = d.xpos[bid] + d.xmat[bid].reshape(3, 3) @ corners[c]
                lows.append(p[2] - ground_height(m, d, p))
    zadr = int(ctl.qadr[ROOT_Z])
    if lows:
        d.qpos[zadr] -= min(lows) + 2e-4
    stored = float(ref.wrench(t0)[:, 5].sum())
    sole_geoms = (ctl.soles[0][0], ctl.soles[1][0])
    info: dict[str, Any] = {"stored_vertical_force_bw": stored / ctl.bw, "preloaded": bool(preload and lows),
                            "depth_m": 2e-4 if lows else 0.0}

    def force(depth: float) -> float:
        d.qpos[zadr] = z0 - depth
        mujoco.mj_forward(m, d)
        saved = ctl.snapshot()
        d.ctrl[:] = ctl.control(d, t0)
        ctl.restore(saved)
        mujoco.mj_forward(m, d)
        return float(_foot_forces(m, d, sole_geoms)[:, 2].sum())

    if preload and lows:
        z0 = float(d.qpos[zadr]) + 2e-4
        lo, hi = 0.0, MAX_PRELOAD_DEPTH
        if force(hi) < stored:  # the contacts cannot carry it within the depth: the touching start
            info.update(preloaded=False, reason=f"less than the stored force {MAX_PRELOAD_DEPTH * 1e3:g} mm deep")
            lo = hi = 2e-4
        for _ in range(40 if lo < hi else 0):
            mid = 0.5 * (lo + hi)
            if force(mid) < stored:
                lo = mid
            else:
                hi = mid
        # where the force jumps (the controller's loaded corners change with the depth) the deeper side: it
        # carries the stored force over the first 10 ms better than the shallower (measured on the tutors)
        info["t0_vertical_force_bw"] = force(hi) / ctl.bw
        info["depth_m"] = hi
    fresh = mujoco.MjData(m)
    fresh.qpos[:] = d.qpos
    fresh.qvel[:] = d.qvel
    mujoco.mj_forward(m, fresh)
    return fresh, info


#: the first this many seconds of a run are measured every step (the start's vertical force)
START_WINDOW_S = 0.06


@dataclass(eq=False)
class _Run:
    """One rollout: per step time, ctrl and qpos; the series sampled every 10 ms; the fall."""

    time: np.ndarray
    ctrl: np.ndarray
    qpos: np.ndarray
    series: dict[str, np.ndarray]
    fell: bool
    fall_time: float | None
    fall_reason: str | None
    wall: float
    start_force: np.ndarray  # (steps in START_WINDOW_S,) total vertical sole force (N) after each step
    t_ref_end: float = 0.0  # the reference's clock after the last step
    qvel_end: np.ndarray = field(default_factory=lambda: np.zeros(0))


def _rollout(m: mujoco.MjModel, d: mujoco.MjData, ctl: Tracker, ref: Reference, t0: float, steps: int,
             stop_on_fall: bool, pelvis: int) -> _Run:
    """Run the controller from the state in ``d`` (reference time ``t0``) for ``steps`` steps."""
    gains = ctl.g
    dt = float(m.opt.timestep)
    time = np.zeros(steps)
    ctrl = np.zeros((steps, m.nu))
    qpos = np.zeros((steps, m.nq))
    sole_geoms = (ctl.soles[0][0], ctl.soles[1][0])
    body_geoms = {i for i in range(m.ngeom) if m.geom_contype[i] == 2}
    every = max(1, int(round(0.01 / dt)))  # measures every 10 ms
    n_start = int(round(START_WINDOW_S / dt))
    start_force: list[float] = []
    keys = ("foot_force", "foot_force_qp", "stance_corners", "foot_force_ref", "t_ref", "q_ref", "q", "t", "com",
            "anchor")
    S: dict[str, list[Any]] = {k: [] for k in keys}
    qr0 = ref.state(t0)[0]
    t_ref = t0
    pelvis_h0 = float(d.xpos[pelvis][2])
    fell, fall_time, reason = False, None, None
    tau = np.zeros(m.nu)
    wall0 = _time.perf_counter()
    done = steps
    for s in range(steps):
        t = s * dt
        if s % gains.control_period == 0:
            tau = ctl.control(d, t_ref)
        d.ctrl[:] = tau
        if s % every == 0:
            S["foot_force"].append(_foot_forces(m, d, sole_geoms))
            S["foot_force_qp"].append(ctl.predicted.copy())
            S["stance_corners"].append(list(ctl.n_corners))
            S["foot_force_ref"].append(ref.wrench(t_ref)[:, 3:])
            S["t_ref"].append(t_ref)
            S["q_ref"].append(ref.state(t_ref)[0])
            S["q"].append(d.qpos[ctl.qadr].copy())
            S["t"].append(t)
            S["com"].append(d.subtree_com[ctl.com_body].copy())
            S["anchor"].append(ctl.anchor.copy())
        mujoco.mj_step(m, d)
        time[s] = t + dt
        ctrl[s] = d.ctrl
        qpos[s] = d.qpos
        mujoco.mj_forward(m, d)
        if s < n_start:
            start_force.append(float(_foot_forces(m, d, sole_geoms)[:, 2].sum()))
        # a fall: pelvis sunk, or any non-foot body on the ground
        bad = None
        t_ref += dt * ctl.clock_rate(d, t_ref)
        ph = float(d.xpos[pelvis][2]) - float(ref.state(t_ref)[0][ROOT_Z] - qr0[ROOT_Z])
        if ph < 0.6 * pelvis_h0:
            bad = f"pelvis height {ph:.3f} m (start {pelvis_h0:.3f} m)"
        for i in range(d.ncon):
            c = d.contact[i]
            if c.geom1 in body_geoms or c.geom2 in body_geoms:
                gb = c.geom1 if c.geom1 in body_geoms else c.geom2
                bad = f"{mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_GEOM, gb)} touches the ground"
                break
        if not np.all(np.isfinite(d.qpos)):
            bad = "the simulation diverged"
        if bad is not None and not fell:
            fell, fall_time, reason = True, t + dt, bad
            if stop_on_fall:
                done = s + 1
                break
    wall = _time.perf_counter() - wall0
    series = {k: np.array(v) for k, v in S.items()}
    return _Run(time[:done], ctrl[:done], qpos[:done], series, fell, fall_time, reason, wall, np.array(start_force),
                t_ref, d.qvel.copy())


#: a resync cycle *closes* when its end state is this near the reference's (joint RMS °, joint velocity
#: RMS °/s, pelvis height m, root attitude °, root velocity m/s): the next cycle could start from it
CLOSE_TOLERANCE = {"joint_rms_deg": 5.0, "joint_velocity_rms_deg_s": 50.0, "pelvis_height_m": 0.02,
                   "root_attitude_deg": 5.0, "root_velocity_m_s": 0.2}


def _end_error(run: _Run, ctl: Tracker, ref: Reference) -> dict[str, float]:
    """How far the state at a run's end is from the reference's at the reference clock's end time: joint
    angles and velocities (RMS), pelvis height, root attitude (largest of the three angles), root linear
    velocity (the horizontal position is re-anchored on the feet: not compared)."""
    if not len(run.qpos):
        return {}
    qr, qdr, _ = ref.state(run.t_ref_end)
    q = run.qpos[-1][ctl.qadr]
    qd = run.qvel_end[ctl.vadr]
    return {"joint_rms_deg": float(np.degrees(np.sqrt(np.mean((q[6:] - qr[6:]) ** 2)))),
            "joint_velocity_rms_deg_s": float(np.degrees(np.sqrt(np.mean((qd[6:] - qdr[6:]) ** 2)))),
            "pelvis_height_m": float(q[ROOT_Z] - qr[ROOT_Z]),
            "root_attitude_deg": float(np.degrees(np.max(np.abs(_wrap(q[3:6] - qr[3:6]))))),
            "root_velocity_m_s": float(np.linalg.norm(qd[:3] - qdr[:3]))}


def _start_report(run: _Run, info: dict[str, Any], bw: float, dt: float) -> dict[str, Any]:
    """The start's vertical contact force against the stored one (BW): after the first step, its
    mean over the first 10 ms and its RMS and largest difference over the first 60 ms."""
    f = run.start_force / bw
    stored = float(info["stored_vertical_force_bw"])
    n10 = max(1, int(round(0.01 / dt)))
    out = dict(info)
    if len(f):
        out.update({"first_step_vertical_force_bw": float(f[0]),
                    "first_10ms_mean_vertical_force_bw": float(np.mean(f[:n10])),
                    "first_10ms_max_difference_bw": float(np.max(np.abs(f[:n10] - stored))),
                    "first_60ms_rms_difference_bw": float(np.sqrt(np.mean((f - stored) ** 2))),
                    "first_60ms_max_difference_bw": float(np.max(np.abs(f - stored)))})
    return out


def _resync(motion: Motion, ref: Reference, t0: float, cycles: int, gains: Gains) -> dict[str, Any]:
    """Performability per cycle: every cycle started afresh from the reference's state at its start
    (t0 + k × period, preloaded as the continuous run), tracked to its end by the same controller
    with a penalized residual wrench at the root (six motors on the root coordinates, weighted by
    ``gains.residual_weight`` in the QP: a Moco-style residual actuator). A cycle completes when it
    ends without a fall; it *closes* when its end state is also within ``CLOSE_TOLERANCE`` of the
    reference's (``end_error``). The residual's RMS is in body weights: forces / BW and the root hinges'
    torques / (BW × 1 m), over every simulated step."""
    _xml, m, _ = performable_model(motion, cycles, ref, gains.sole_half_width, gains.inversion, root_residual=True)
    ctl = Tracker(motion, m, ref, gains)
    pelvis = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, motion.character.segments[0].name)
    steps = int(round(ref.period / float(m.opt.timestep)))
    fresh = ctl.snapshot()
    scale = np.array([ctl.bw] * 3 + [ctl.bw * 1.0] * 3)
    per_cycle = []
    squares: list[np.ndarray] = []
    cpu = _time.process_time()
    completed = closed = 0
    for k in range(cycles):
        ctl.restore(fresh)
        tk = t0 + k * ref.period
        d, _info = _start(m, ctl, ref, tk, gains.preload)
        run = _rollout(m, d, ctl, ref, tk, steps, True, pelvis)
        r = run.ctrl[:, ctl.residual] / scale
        sq = np.sum(r**2, axis=1)
        squares.append(sq)
        completed += not run.fell
        err = _end_error(run, ctl, ref)
        closes = not run.fell and all(abs(err[key]) <= tol for key, tol in CLOSE_TOLERANCE.items())
        closed += closes
        per_cycle.append({"cycle": k, "completed": not run.fell,
                          "walked": min(1.0, float(run.time[-1] / ref.period)) if len(run.time) else 0.0,
                          "fall_reason": run.fall_reason,
                          "end_error": err, "closes": closes,
                          "residual_root_wrench_rms_bw": float(np.sqrt(np.mean(sq))) if len(sq) else float("nan"),
                          "residual_root_wrench_max_bw": float(np.sqrt(np.max(sq))) if len(sq) else float("nan")})
    cpu = _time.process_time() - cpu
    allsq = np.concatenate(squares) if squares else np.zeros(0)
    return {
        "cycles": cycles,
        "completed": completed,
        "closed": closed,
        "close_tolerance": CLOSE_TOLERANCE,
        "residual_root_wrench_rms_bw": float(np.sqrt(np.mean(allsq))) if len(allsq) else float("nan"),
        "residual_weight": gains.residual_weight,
        "per_cycle": per_cycle,
        "cpu_s": cpu,
    }


def simulate(motion: Motion, cycles: int = 10, gains: Gains | None = None, *,
             stop_on_fall: bool = True, resync: bool = True) -> SimulationResult:
    """Simulate ``cycles`` gait cycles of ``motion`` under the tracking controller, continuously
    from mid stance; with ``resync`` also each cycle from the reference's state at its start with a
    penalized root residual (the report's ``resync``)."""
    if cycles < 1:
        raise SimulationError("cycles must be at least 1")
    gains = gains or Gains()
    ref = Reference(motion)
    t0 = mid_stance_time(motion)
    xml, m, _ = performable_model(motion, cycles, ref, gains.sole_half_width, gains.inversion)
    ctl = Tracker(motion, m, ref, gains)
    d, start_info = _start(m, ctl, ref, t0, gains.preload)
    qpos0, qvel0 = d.qpos.copy(), d.qvel.copy()
    dt = float(m.opt.timestep)
    steps = int(round(cycles * ref.period / dt))
    pelvis = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, motion.character.segments[0].name)
    run = _rollout(m, d, ctl, ref, t0, steps, stop_on_fall, pelvis)
    res = SimulationResult(
        xml=xml, timestep=dt, qpos0=qpos0, qvel0=qvel0, time=run.time, ctrl=run.ctrl, qpos=run.qpos,
        actuator_names=tuple(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in range(m.nu)),
        coordinate_qpos=ctl.qadr, t0=t0, cycle_duration_s=ref.period, cycles_requested=cycles,
        fell=run.fell, fall_time=run.fall_time, fall_reason=run.fall_reason, wall_time_s=run.wall,
        series=run.series,
    )
    report = _report(res, motion, ref, ctl)
    report["start"] = _start_report(run, start_info, ctl.bw, dt)
    report["agreement"] = agreement(motion, m, ref)
    if resync:
        report["resync"] = _resync(motion, ref, t0, cycles, gains)
    return replace(res, report=report)


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _report(res: SimulationResult, motion: Motion, ref: Reference, ctl: Tracker) -> dict[str, Any]:
    S = res.series
    walked_s = float(res.time[-1]) if len(res.time) else 0.0
    cycles_walked = walked_s / ref.period
    q, qr = S["q"], S["q_ref"]
    joint_err = np.degrees(q[:, 6:] - qr[:, 6:]) if len(q) else np.zeros((0, motion.n - 6))
    names = motion.character.coordinate_names
    bw = body_weight(motion)
    ff, fr = S["foot_force"], S["foot_force_ref"]
    force_rms = float(np.sqrt(np.mean(np.sum((ff - fr) ** 2, axis=2)))) / bw if len(ff) else float("nan")
    # per cycle drift at each cycle end (reference time t0 + k period)
    drift = []
    for k in range(1, int(math.floor(cycles_walked + 0.01)) + 1):
        i = min(int(round(k * ref.period / 0.01)), len(q) - 1)
        dxy = q[i, list(ROOT_XY)] - qr[i, list(ROOT_XY)]
        drift.append({"cycle": k, "position_m": float(np.linalg.norm(dxy)),
                      "lateral_m": float(dxy @ np.array([-math.sin(qr[i, ROOT_YAW]), math.cos(qr[i, ROOT_YAW])])),
                      "heading_deg": float(np.degrees(_wrap(q[i, ROOT_YAW] - qr[i, ROOT_YAW]))),
                      "joint_rms_deg": float(np.degrees(np.sqrt(np.mean((q[i, 6:] - qr[i, 6:]) ** 2)))),
                      "pelvis_height_m": float(q[i, ROOT_Z] - qr[i, ROOT_Z])})
    peaks_sim = np.max(np.abs(res.ctrl[:, ctl.motor]), axis=0) if len(res.ctrl) else np.zeros(len(ctl.peaks))
    ratio = peaks_sim / np.maximum(ctl.peaks, 1e-9)
    act = [res.actuator_names[a] for a in ctl.motor]
    return {
        "motion": {"character": motion.character.name, "fps": motion.fps, "frames": motion.T,
                   "environment": motion.environment.to_dict()},
        "cycle_duration_s": ref.period,
        "cycles_requested": res.cycles_requested,
        "cycles_walked": cycles_walked,
        "simulated_s": walked_s,
        "fell": res.fell,
        "fall": None if not res.fell else {"time_s": res.fall_time, "cycle": (res.fall_time or 0.0) / ref.period,
                                           "reason": res.fall_reason},
        "start_reference_time_s": res.t0,
        "reference_clock_offset_s": (float(S["t_ref"][-1] - S["t"][-1] - res.t0) if len(S["t"]) else 0.0),
        "timestep_s": res.timestep,
        "control_period_s": res.timestep * ctl.g.control_period,
        "joint_tracking_rms_deg": float(np.sqrt(np.mean(joint_err**2))) if joint_err.size else float("nan"),
        "joint_tracking_rms_deg_per_joint": {names[6 + j]: float(np.sqrt(np.mean(joint_err[:, j] ** 2)))
                                             for j in range(joint_err.shape[1])} if joint_err.size else {},
        "root_height_rms_m": float(np.sqrt(np.mean((q[:, ROOT_Z] - qr[:, ROOT_Z]) ** 2))) if len(q) else float("nan"),
        "drift_per_cycle": drift,
        "foot_force_rms_bw": force_rms,
        "body_weight_n": bw,
        "peak_torque_nm": {a: float(p) for a, p in zip(act, peaks_sim, strict=True)},
        "id_peak_torque_nm": {a: float(p) for a, p in zip(act, ctl.peaks, strict=True)},
        "peak_torque_ratio": {a: float(r) for a, r in zip(act, ratio, strict=True)},
        "peak_torque_ratio_max": float(ratio.max()) if len(ratio) else float("nan"),
        "torque_limit_nm": {a: float(v) for a, v in zip(act, ctl.tau_limit, strict=True)},
        "wall_time_s": res.wall_time_s,
        "realtime_factor": walked_s / res.wall_time_s if res.wall_time_s > 0 else float("nan"),
    }
