"""A gait cycle the simulated character performs without help, computed offline (:func:`feasible_cycle`),
and the controller that replays it with feedback (:class:`CycleController`).

The cycle starts where :func:`mjcf.simulate.simulate` starts a walk (the reference's state at mid
stance, its contacts preloaded at the stored force) and lasts one period of the motion. Its first
guess is one cycle of the default :class:`~mjcf.tracker.Tracker` with the penalized root residual
(the resync run): MuJoCo is deterministic, so those torques replayed open loop give the same states.
iLQR (Li & Todorov 2004; linearizations by MuJoCo's finite differences, ``mjd_transitionFD``) then
changes the torques so that

* the root residual goes to zero (weighted per body weight², as the resync's QP weighs it): the
  cycle's states are those of the character under its joint motors and the contacts alone;
* the end state comes onto the start state moved by the cycle transform (the turn, the rise of
  stairs; the horizontal position is free): chained, the cycle repeats;
* the states stay near the tracker's (a weak pull, so the cycle stays the motion's).

:class:`CycleController` performs the cycle over any number of periods: the cycle's torques plus
time-varying LQR feedback on the state's difference to the cycle's (gains from the periodic Riccati
recursion on the same linearizations; the horizontal position is not fed back, the heading and
height are compared after the cycle transform). docs/simulation.md, "The offline cycle", gives
what it measures on the shipped tutors.
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import mujoco
import numpy as np

from mjcf.controller import ControllerBase
from mjcf.gains import Gains
from mjcf.performable import ModelGeometry, performable_model
from mjcf.reference import ROOT_Z, Reference, mid_stance_time
from mjcf.rollout import _rollout, _start
from mjcf.simulate import CLOSE_TOLERANCE
from mjcf.tracker import Tracker
from solver.environment import body_weight
from solver.motion import Motion

#: the state's scales in the costs: joint and root angles (rad), pelvis height (m), joint angular
#: velocities (rad/s), root linear velocities (m/s)
ANGLE_SCALE = math.radians(5.0)
HEIGHT_SCALE = 0.02
ANGULAR_VELOCITY_SCALE = math.radians(100.0)
LINEAR_VELOCITY_SCALE = 0.2
#: iLQR's weights: the pull toward the tracker's states per step, the end state's closure, the
#: joint torques' change per (N·m)², the residual per BW² (forces; root torques per BW × 1 m)
TRACK_WEIGHT = 1e-3
CLOSURE_WEIGHT = 100.0
CLOSURE_RAMP = 0.0
TORQUE_WEIGHT = 1e-6
RESIDUAL_WEIGHT = 1e3
#: the first guess: the tracker with this root residual weight (per BW²; the resync runs use 1e6). With
#: cheaper root help it follows the reference closer, and its cycle ends nearer its start: measured on the
#: shipped HalfBoy tutors, iLQR from the 1e6 cycle stalls on two of six (C3D Qualisys, CMU)
FIRST_GUESS_RESIDUAL_WEIGHT = 1e3
#: the feedback's LQR weights: states (× the scales above), and the candidate weights of the joint
#: torques per (N·m)²: the one whose feedback holds the most perturbed starts is kept (``_select_gains``)
LQR_STATE_WEIGHT = 1.0
LQR_TORQUE_WEIGHTS = (1e-2, 1e-1)
#: the perturbed starts the gains are chosen on: joint and root velocities plus normal noise of these
#: standard deviations (rad/s, m/s), three draws each (a fixed seed), each run for two chained cycles
PERTURBATIONS = (0.05, 0.1)
#: the selection's unperturbed run chains this many cycles (the model holds one more cycle of treads)
CHAINED = 3
#: a run of the selection has failed when a joint is this far from the cycle's (rad) or the pelvis this
#: far below it (m)
DIVERGED_JOINT = 0.5
DIVERGED_HEIGHT = 0.1
FD_EPS = 1e-6
LINE_SEARCH = (1.0, 0.5, 0.25, 0.1, 0.03, 0.01)
#: iLQR's regularization of the torques' Hessian, adapted between these (Levenberg–Marquardt, ``feasible_cycle``)
MU_MIN, MU_MAX = 1e-6, 1e2


@dataclass(frozen=True, eq=False)
class FeasibleCycle:
    """One cycle's states and controls in the simulated model (:func:`feasible_cycle`).

    ``states`` (N + 1, 2 nv): qpos and qvel after each of the N steps (row 0: the start);
    ``controls`` (N, len(motor_names)): the joint motors' torques, by name; ``gains`` (N, motors, 2 nv):
    the feedback :class:`CycleController` adds; ``record``: what the optimization reached (residual
    before and after, the end state's distance to the start's under the cycle transform, iterations,
    CPU seconds)."""

    timestep: float
    start_time: float  # the reference's time of the start (mid stance)
    period: float
    transform: CycleTransform  # how the next cycle sits against this one; what the feedback compares
    states: np.ndarray
    controls: np.ndarray
    gains: np.ndarray
    motor_names: tuple[str, ...]
    record: dict[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        for name in ("states", "controls", "gains"):
            a = np.array(getattr(self, name))
            a.setflags(write=False)
            object.__setattr__(self, name, a)

    @property
    def steps(self) -> int:
        return int(self.controls.shape[0])


def _weights(nv: int, geometry: ModelGeometry) -> np.ndarray:
    """Per state entry, 1 / scale² (root x, y: 0, the horizontal position is free)."""
    cq, cd = geometry.coordinate_qpos, geometry.coordinate_dof
    wq = np.full(nv, ANGLE_SCALE**-2)
    wq[cq[:2]] = 0.0
    wq[cq[ROOT_Z]] = HEIGHT_SCALE**-2
    wv = np.full(nv, ANGULAR_VELOCITY_SCALE**-2)
    wv[cd[:3]] = LINEAR_VELOCITY_SCALE**-2
    return np.concatenate([wq, wv])


@dataclass(frozen=True, eq=False)
class CycleTransform:
    """How cycle k of a chain sits against the first: turned by k × ``turn`` about the vertical and
    raised by k × ``rise``; and which state entries are compared (``qpos``/``dof``: the root's and
    joints' addresses). The horizontal position is never compared: the walk may drift. (Compared too,
    on stairs, at 5 cm: the DeepMimic stairs down's cycle then walked 1.98 cycles instead of 3.0.)"""

    turn: float
    rise: float
    nv: int
    qpos: np.ndarray
    dof: np.ndarray

    def _turn_velocity(self, x: np.ndarray, angle: float) -> None:
        ix, iy = self.nv + self.dof[0], self.nv + self.dof[1]
        c, s = math.cos(angle), math.sin(angle)
        x[ix], x[iy] = c * x[ix] - s * x[iy], s * x[ix] + c * x[iy]

    def moved(self, x: np.ndarray, k: int) -> np.ndarray:
        """State ``x`` moved by k cycle transforms: heading + k turn, height + k rise, horizontal velocity
        turned (the horizontal position is left as it is)."""
        y = x.copy()
        y[self.qpos[3]] += k * self.turn
        y[self.qpos[ROOT_Z]] += k * self.rise
        self._turn_velocity(y, k * self.turn)
        return y

    def difference(self, x: np.ndarray, target: np.ndarray) -> np.ndarray:
        e = x - target
        e[self.qpos[:2]] = 0.0
        return e

    def back(self, e: np.ndarray, k: int) -> np.ndarray:
        """A difference in cycle k's frame turned back into the first cycle's (the gains act there)."""
        e = e.copy()
        self._turn_velocity(e, -k * self.turn)
        return e


def _linearize(m: mujoco.MjModel, X: np.ndarray, U: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    nv, nu, N = m.nv, m.nu, U.shape[0]
    A, B = np.zeros((N, 2 * nv, 2 * nv)), np.zeros((N, 2 * nv, nu))
    d = mujoco.MjData(m)
    for s in range(N):
        d.qpos[:], d.qvel[:], d.ctrl[:] = X[s, :nv], X[s, nv:], U[s]
        mujoco.mjd_transitionFD(m, d, FD_EPS, False, A[s], B[s], None, None)
    return A, B


def _rollout_open(m: mujoco.MjModel, x0: np.ndarray, U: np.ndarray, Xn: np.ndarray | None = None,
                  K: np.ndarray | None = None, kff: np.ndarray | None = None, alpha: float = 1.0,
                  tf: CycleTransform | None = None) -> tuple[np.ndarray, np.ndarray]:
    """States from ``x0`` under U (+ α k + K (x − Xn), iLQR's forward pass)."""
    nv, N = m.nv, U.shape[0]
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = x0[:nv], x0[nv:]
    mujoco.mj_forward(m, d)
    X = np.zeros((N + 1, 2 * nv))
    X[0] = x0
    Uo = U.copy()
    for s in range(N):
        if K is not None and kff is not None and Xn is not None and tf is not None:
            Uo[s] = U[s] + alpha * kff[s] + K[s] @ tf.difference(X[s], Xn[s])
        d.ctrl[:] = Uo[s]
        mujoco.mj_step(m, d)
        X[s + 1, :nv], X[s + 1, nv:] = d.qpos, d.qvel
        if not (np.all(np.isfinite(d.qpos)) and np.all(np.isfinite(d.qvel))):
            X[s + 1:] = np.nan
            break
    return X, Uo


def periodic_gains(A: np.ndarray, B: np.ndarray, Q: np.ndarray, R: np.ndarray, sweeps: int = 3) -> np.ndarray:
    """Time-varying LQR gains K_s (u = K_s e) of the periodic Riccati recursion: backward over the
    cycle, the value at its start carried to its end, ``sweeps`` times (it converges in two on the
    tutors: the value at the start changes by < 1e-7 relative)."""
    N = A.shape[0]
    V = Q.copy()
    K = np.zeros((N, B.shape[2], A.shape[1]))
    for _ in range(sweeps):
        for s in range(N - 1, -1, -1):
            Quu = R + B[s].T @ V @ B[s]
            Qux = B[s].T @ V @ A[s]
            K[s] = -np.linalg.solve(Quu, Qux)
            V = Q + A[s].T @ V @ A[s] + K[s].T @ Qux
            V = 0.5 * (V + V.T)
    return K


#: a step's gains more than this times the cycle's median (largest entry) are a contact's
#: switching seen by the finite differences, not the dynamics: replaced by the nearest step's
SPIKE_RATIO = 10.0


def despiked(K: np.ndarray) -> np.ndarray:
    """The gains with the steps where a contact switches within the finite differences' step (their
    largest entry > ``SPIKE_RATIO`` × the median step's: up to 4e5 against 1.5e3 on the DeepMimic
    tutor's cycle, at 32 of 1267 steps) replaced by the nearest other step's. With them, a 1 mm or
    0.1 rad/s difference at such a step asks for kN·m and the run falls within a cycle."""
    size = np.abs(K).max(axis=(1, 2))
    bad = size > SPIKE_RATIO * float(np.median(size))
    good = np.flatnonzero(~bad)
    out = K.copy()
    for s in np.flatnonzero(bad):
        out[s] = K[good[np.argmin(np.abs(good - s))]]
    return out


def _backward(A: np.ndarray, B: np.ndarray, X: np.ndarray, U: np.ndarray, Xt: np.ndarray, Ut: np.ndarray,
              Q: np.ndarray, r: np.ndarray, Qf: np.ndarray, target: np.ndarray, tf: CycleTransform,
              mu: float) -> tuple[np.ndarray, np.ndarray]:
    """iLQR's backward pass: the feedforward steps k and gains K of the quadratic model of the cost
    (states toward Xt, torques toward Ut, the end state toward ``target``) on the linearizations."""
    N, nu, nx = B.shape[0], B.shape[2], A.shape[1]
    R = np.diag(r)
    Vx = Qf @ tf.difference(X[-1], target)
    Vxx = Qf.copy()
    kff, K = np.zeros((N, nu)), np.zeros((N, nu, nx))
    for s in range(N - 1, -1, -1):
        Qx = Q @ tf.difference(X[s], Xt[s]) + A[s].T @ Vx
        Qu = r * (U[s] - Ut[s]) + B[s].T @ Vx
        Qxx = Q + A[s].T @ Vxx @ A[s]
        Quu = R + B[s].T @ Vxx @ B[s] + mu * np.eye(nu)
        Qux = B[s].T @ Vxx @ A[s]
        kff[s] = -np.linalg.solve(Quu, Qu)
        K[s] = -np.linalg.solve(Quu, Qux)
        Vx = Qx + K[s].T @ Quu @ kff[s] + K[s].T @ Qu + Qux.T @ kff[s]
        Vxx = Qxx + K[s].T @ Quu @ K[s] + K[s].T @ Qux + Qux.T @ K[s]
        Vxx = 0.5 * (Vxx + Vxx.T)
    return kff, K


def _step(m: mujoco.MjModel, x0: np.ndarray, problem: tuple, mu: float, cost: Any,
          c0: float) -> tuple[float, float, np.ndarray, np.ndarray]:
    """One iLQR step at regularization ``mu``: the backward pass, then the line search's first step that
    lowers the cost below ``c0``: (cost, step length, states, controls); (inf, 0, …) when none does."""
    A, B, X, U, Xt, Ut, Q, r, Qf, target, tf = problem
    kff, K = _backward(A, B, X, U, Xt, Ut, Q, r, Qf, target, tf, mu)
    for alpha in LINE_SEARCH:
        Xn, Un = _rollout_open(m, x0, U, X, K, kff, alpha, tf)
        cn = cost(Xn, Un)
        if cn < c0:
            return cn, alpha, Xn, Un
    return math.inf, 0.0, X, U


def _chained(m: mujoco.MjModel, X: np.ndarray, U: np.ndarray, K: np.ndarray, motors: np.ndarray, x0: np.ndarray,
             cycles: int, tf: CycleTransform) -> float:
    """Cycles the feedback ``K`` (motors) performs chained from ``x0`` before it diverges (module constants)."""
    nv, N = m.nv, U.shape[0]
    d = mujoco.MjData(m)
    d.qpos[:], d.qvel[:] = x0[:nv], x0[nv:]
    mujoco.mj_forward(m, d)
    for k in range(cycles):
        for s in range(N):
            x = np.concatenate([d.qpos, d.qvel])
            e = tf.difference(x, tf.moved(X[s], k))
            if (not np.all(np.isfinite(e)) or np.abs(e[tf.qpos[6:]]).max() > DIVERGED_JOINT
                    or e[tf.qpos[ROOT_Z]] < -DIVERGED_HEIGHT):
                return k + s / N
            u = U[s].copy()
            u[motors] += K[s] @ tf.back(e, k)
            d.ctrl[:] = u
            mujoco.mj_step(m, d)
    return float(cycles)


def _select_gains(m: mujoco.MjModel, geo: ModelGeometry, X: np.ndarray, U: np.ndarray, w: np.ndarray,
                  tf: CycleTransform) -> tuple[np.ndarray, dict[str, Any]]:
    """The periodic LQR gains (motors only, despiked) for each of ``LQR_TORQUE_WEIGHTS``, and the one
    whose feedback performs the most cycles over the selection's runs: the cycle chained three times from
    its start, and two chained cycles from each perturbed start (``PERTURBATIONS``). The cycle's own
    residual is not applied (the performing model has none)."""
    nv = m.nv
    A, B = _linearize(m, X, U)
    Um = U.copy()
    Um[:, geo.residual] = 0.0
    rng = np.random.default_rng(0)
    starts = [X[0]]
    for sd in PERTURBATIONS:
        for _ in range(3):
            x = X[0].copy()
            x[nv:] += sd * rng.standard_normal(nv)
            starts.append(x)
    best: tuple[float, np.ndarray] | None = None
    scores = {}
    for weight in LQR_TORQUE_WEIGHTS:
        rl = np.zeros(m.nu)
        rl[geo.motors] = weight
        rl[geo.residual] = 1e12  # never used by the feedback
        K = despiked(periodic_gains(A, B, np.diag(w) * LQR_STATE_WEIGHT, np.diag(rl))[:, geo.motors, :])
        score = sum(_chained(m, X, Um, K, geo.motors, x, CHAINED if i == 0 else 2, tf)
                    for i, x in enumerate(starts))
        scores[f"{weight:g}"] = round(score, 3)
        if best is None or score > best[0] + 1e-9:
            best = (score, K)
            chosen = weight
    assert best is not None
    return best[1], {"torque_weight": chosen, "scores": scores, "score_max": 3 + 2 * (len(starts) - 1)}


def feasible_cycle(motion: Motion, gains: Gains | None = None, *, iterations: int = 25,
                   tolerance: float = 1e-4) -> FeasibleCycle:
    """The cycle (module docstring): at most ``iterations`` iLQR iterations, ending early when one
    lowers the cost by less than ``tolerance`` of it."""
    gains = gains or Gains()
    cpu0 = _time.process_time()
    ref = Reference(motion)
    _xml, m, geo = performable_model(motion, CHAINED + 1, ref, gains.sole_half_width, gains.inversion,
                                          root_residual=True)
    nv, nu = m.nv, m.nu
    if m.nq != nv:
        raise ValueError("the offline cycle needs a model of hinges and slides (qpos and qvel of one size)")
    cq, cd = geo.coordinate_qpos, geo.coordinate_dof
    turn, _d, rise = ref.transform(1)
    tf = CycleTransform(turn, rise, nv, cq.copy(), cd.copy())
    names = tuple(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, int(a)) for a in geo.motors)
    t0 = mid_stance_time(motion)
    N = int(round(ref.period / float(m.opt.timestep)))
    bw = body_weight(motion)
    tracker = Tracker(motion, m, geo, ref, replace(gains, residual_weight=FIRST_GUESS_RESIDUAL_WEIGHT))
    d0, _ = _start(m, geo, tracker, ref, t0, gains.preload)
    x0 = np.concatenate([d0.qpos, d0.qvel])
    first = _rollout(m, d0, tracker, ref, geo, t0, N, True)
    if first.fell or len(first.ctrl) < N:
        return FeasibleCycle(float(m.opt.timestep), t0, ref.period, tf, np.zeros((0, 2 * nv)),
                             np.zeros((0, len(names))), np.zeros((0, len(names), 2 * nv)), names,
                             {"status": "failed", "message": f"the tracker's first cycle falls: {first.fall_reason}",
                              "cpu_s": _time.process_time() - cpu0})
    U = first.ctrl.copy()
    X, _ = _rollout_open(m, x0, U)
    target = tf.moved(x0, 1)
    w = _weights(nv, geo)
    Q = np.diag(w) * TRACK_WEIGHT
    r = np.zeros(nu)
    r[geo.motors] = TORQUE_WEIGHT
    r[geo.residual] = RESIDUAL_WEIGHT / bw**2
    Xt, Ut = X.copy(), U.copy()
    Ut[:, geo.residual] = 0.0

    def cost(X: np.ndarray, U: np.ndarray, wf: float) -> float:
        if not np.all(np.isfinite(X)) or np.abs(X).max() > 1e6:  # a diverged rollout
            return math.inf
        e = X[:-1] - Xt[:-1]
        e[:, cq[:2]] = 0.0
        du = U - Ut
        ef = tf.difference(X[-1], target)
        return float(0.5 * np.sum((e**2) @ np.diag(Q)) + 0.5 * np.sum((du**2) @ r) + 0.5 * wf * ef @ (w * ef))

    def residual_rms(U: np.ndarray) -> float:
        res = U[:, geo.residual] / bw
        return float(np.sqrt(np.mean(np.sum(res**2, axis=1))))

    rec: dict[str, Any] = {"steps": N, "residual_rms_bw_before": residual_rms(U),
                           "end_error_before": _end_error(X[-1], target, tf), "log": []}
    mu = MU_MIN
    lin_cpu = 0.0
    it = 0
    for it in range(1, iterations + 1):
        # the closure's weight rises over the first iterations (a homotopy): at its full weight from the
        # start, a cycle that ends far from its start takes only tiny steps
        wf = CLOSURE_WEIGHT * min(1.0, 10.0 ** ((it - 1) / CLOSURE_RAMP - 2.0)) if CLOSURE_RAMP else CLOSURE_WEIGHT
        c = _time.process_time()
        A, B = _linearize(m, X, U)
        lin_cpu += _time.process_time() - c
        c0 = cost(X, U, wf)
        problem = (A, B, X, U, Xt, Ut, Q, r, wf * np.diag(w), target, tf)

        def step(mu: float) -> tuple[float, float, np.ndarray, np.ndarray]:
            return _step(m, x0, problem, mu, lambda Xn, Un: cost(Xn, Un, wf), c0)  # noqa: B023

        # Levenberg–Marquardt on the regularization: a step that needs a short line search is tried
        # again with ten times the regularization, which keeps the better; a full step lowers it
        cn, alpha, Xn, Un = step(mu)
        while alpha < 0.25 and mu < MU_MAX:
            trial = step(mu * 10.0)
            if trial[0] >= cn and alpha > 0.0:
                break
            mu *= 10.0
            cn, alpha, Xn, Un = trial if trial[0] < cn else (cn, alpha, Xn, Un)
        rec["log"].append({"closure_weight": wf, "cost": min(cn, c0), "alpha": alpha, "mu": mu})
        if alpha == 0.0:
            break
        X, U = Xn, Un
        if alpha == 1.0:
            mu = max(MU_MIN, mu / 10.0)
        if wf == CLOSURE_WEIGHT and c0 - cn < tolerance * c0:
            break
    # the feedback: periodic LQR on the final cycle's linearizations, its torque weight chosen on perturbed starts
    Kfb, rec["feedback"] = _select_gains(m, geo, X, U, w, tf)
    end = _end_error(X[-1], target, tf)
    rec.update({"iterations": it, "residual_rms_bw_after": residual_rms(U), "end_error_after": end,
                # the resync's closing tolerance: the next cycle can start where this one ends
                "closes": all(abs(end[k]) <= tol for k, tol in CLOSE_TOLERANCE.items()),
                "linearization_cpu_s": lin_cpu, "cpu_s": _time.process_time() - cpu0, "status": "computed"})
    return FeasibleCycle(float(m.opt.timestep), t0, ref.period, tf, X, U[:, geo.motors], Kfb, names, rec)


def _end_error(x: np.ndarray, target: np.ndarray, tf: CycleTransform) -> dict[str, float]:
    """The end state against the start's under the cycle transform, in the units of
    ``mjcf.simulate.CLOSE_TOLERANCE``."""
    e = tf.difference(x, target)
    nv, cq, cd = tf.nv, tf.qpos, tf.dof
    return {"joint_rms_deg": float(np.degrees(np.sqrt(np.mean(e[cq[6:]] ** 2)))),
            "joint_velocity_rms_deg_s": float(np.degrees(np.sqrt(np.mean(e[nv + cd[6:]] ** 2)))),
            "pelvis_height_m": float(e[cq[ROOT_Z]]),
            "root_attitude_deg": float(np.degrees(np.max(np.abs(e[cq[3:6]])))),
            "root_velocity_m_s": float(np.linalg.norm(e[nv + cd[:3]]))}


class CycleController(ControllerBase):
    """Performs a :class:`FeasibleCycle` period after period: its torques plus its gains times the
    state's difference to its states (moved by the cycle transform; horizontal position not fed
    back). Made by ``partial(CycleController, cycle=...)`` for ``mjcf.simulate.simulate``; the model's
    motors are matched by name, any other actuator (a resync's residual) gets zero."""

    def __init__(self, motion: Motion, model: mujoco.MjModel, geometry: ModelGeometry, ref: Reference,
                 cycle: FeasibleCycle) -> None:
        super().__init__(model, geometry, ref)
        if cycle.steps == 0:
            raise ValueError(f"the cycle was not computed: {cycle.record.get('message', '')}")
        if abs(float(model.opt.timestep) - cycle.timestep) > 1e-12:
            raise ValueError("the cycle was computed at another timestep")
        ids = [mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_ACTUATOR, nm) for nm in cycle.motor_names]
        if min(ids) < 0:
            raise ValueError("the model lacks the cycle's motors")
        self.cycle, self.nu, self.nv = cycle, model.nu, model.nv
        self.act = np.array(ids)
        self.step = 0

    def initialize(self, data: mujoco.MjData, t0: float) -> None:
        super().initialize(data, t0)
        # the steps since the cycle's start: a start whole periods later (a resync run) is cycle k of the chain
        self.step = int(round((t0 - self.cycle.start_time) / self.cycle.timestep))

    def control(self, data: mujoco.MjData, t_ref: float) -> np.ndarray:
        c = self.cycle
        k, s = divmod(self.step, c.steps)
        x = np.concatenate([data.qpos, data.qvel])
        tf = c.transform
        e = tf.back(tf.difference(x, tf.moved(c.states[s], k)), k)  # the gains act in the first cycle's frame
        out = np.zeros(self.nu)
        out[self.act] = c.controls[s] + c.gains[s] @ e
        return out

    def after_step(self, data: mujoco.MjData) -> None:
        self.step += 1


def cycle_controller(cycle: FeasibleCycle) -> Any:
    """The factory ``mjcf.simulate.simulate(..., controller=...)`` takes."""
    return partial(CycleController, cycle=cycle)
