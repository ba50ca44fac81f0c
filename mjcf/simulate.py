"""Forward simulation of a motion in MuJoCo with contacts on, tracked by a balancing QP controller.

:func:`simulate` performs the motion and reports on it (:class:`SimulationResult`). Its parts: the
reference (``mjcf.reference``: the motion over any number of cycles), the model
(``mjcf.performable``: contacts on, an unactuated root, one motor per joint; its
``ModelGeometry``), the controller (any ``mjcf.controller.Controller``; by default
``mjcf.tracker.Tracker``) and the run (``mjcf.rollout``: the start without impact, the steps, the
controller's termination, by default a fall).

The walk runs continuously from mid stance; beside this continuous run, :func:`simulate` starts
every cycle afresh from the reference's state and tracks it to its end with a penalized residual
wrench at the root (:func:`_resync`: the report's ``resync``), and measures the model's agreement
with the motion (``mjcf.agreement``).
"""

from __future__ import annotations

import math
import time as _time
from dataclasses import dataclass, field, replace
from functools import partial
from typing import Any

import mujoco
import numpy as np

from mjcf.agreement import agreement
from mjcf.controller import Controller, ControllerFactory
from mjcf.gains import Gains, motor_peaks
from mjcf.performable import ModelGeometry, performable_model
from mjcf.reference import ROOT_Z, Reference, SimulationError, mid_stance_time
from mjcf.rollout import _rollout, _Run, _start
from mjcf.tracker import Tracker
from solver.environment import body_weight
from solver.motion import Motion
from solver.trajectory import ROOT_XY, ROOT_YAW


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


#: a resync cycle *closes* when its end state is this near the reference's (joint RMS °, joint velocity
#: RMS °/s, pelvis height m, root attitude °, root velocity m/s): the next cycle could start from it
CLOSE_TOLERANCE = {"joint_rms_deg": 5.0, "joint_velocity_rms_deg_s": 50.0, "pelvis_height_m": 0.02,
                   "root_attitude_deg": 5.0, "root_velocity_m_s": 0.2}


def _end_error(run: _Run, geometry: ModelGeometry, ref: Reference) -> dict[str, float]:
    """How far the state at a run's end is from the reference's at the reference clock's end time: joint
    angles and velocities (RMS), pelvis height, root attitude (largest of the three angles), root linear
    velocity (the horizontal position is re-anchored on the feet: not compared)."""
    if not len(run.qpos):
        return {}
    qr, qdr, _ = ref.state(run.t_ref_end)
    q = run.qpos[-1][geometry.coordinate_qpos]
    qd = run.qvel_end[geometry.coordinate_dof]
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


def _resync(motion: Motion, ref: Reference, t0: float, cycles: int, gains: Gains,
            controller: ControllerFactory | None = None) -> dict[str, Any]:
    """Performability per cycle: every cycle started afresh from the reference's state at its start
    (t0 + k × period, preloaded as the continuous run), tracked to its end by the same controller
    (``controller``; by default the :class:`~mjcf.tracker.Tracker` with ``gains``) with a penalized
    residual wrench at the root (six motors on the root coordinates, weighted by
    ``gains.residual_weight`` in the Tracker's QP: a Moco-style residual actuator). A cycle completes when it
    ends without a fall; it *closes* when its end state is also within ``CLOSE_TOLERANCE`` of the
    reference's (``end_error``). The residual's RMS is in body weights: forces / BW and the root hinges'
    torques / (BW × 1 m), over every simulated step."""
    _xml, m, geometry = performable_model(motion, cycles, ref, gains.sole_half_width, gains.inversion,
                                          root_residual=True)
    ctl = (controller or partial(Tracker, gains=gains))(motion, m, geometry, ref)
    steps = int(round(ref.period / float(m.opt.timestep)))
    bw = body_weight(motion)
    scale = np.array([bw] * 3 + [bw * 1.0] * 3)
    per_cycle = []
    squares: list[np.ndarray] = []
    cpu = _time.process_time()
    completed = closed = 0
    for k in range(cycles):
        tk = t0 + k * ref.period
        d, _info = _start(m, geometry, ctl, ref, tk, gains.preload)
        run = _rollout(m, d, ctl, ref, geometry, tk, steps, True)
        r = run.ctrl[:, geometry.residual] / scale
        sq = np.sum(r**2, axis=1)
        squares.append(sq)
        completed += not run.fell
        err = _end_error(run, geometry, ref)
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
             controller: ControllerFactory | None = None, stop_on_fall: bool = True,
             resync: bool = True) -> SimulationResult:
    """Simulate ``cycles`` gait cycles of ``motion`` under a controller, continuously from mid
    stance; with ``resync`` also each cycle from the reference's state at its start with a
    penalized root residual (the report's ``resync``). ``controller`` makes the controller from
    (motion, model, geometry, reference) (``mjcf.controller``); by default the
    :class:`~mjcf.tracker.Tracker` with ``gains``, which also hold the model's options
    (``sole_half_width``, ``inversion``) and the start's (``preload``)."""
    if cycles < 1:
        raise SimulationError("cycles must be at least 1")
    gains = gains or Gains()
    ref = Reference(motion)
    t0 = mid_stance_time(motion)
    xml, m, geometry = performable_model(motion, cycles, ref, gains.sole_half_width, gains.inversion)
    ctl = (controller or partial(Tracker, gains=gains))(motion, m, geometry, ref)
    d, start_info = _start(m, geometry, ctl, ref, t0, gains.preload)
    qpos0, qvel0 = d.qpos.copy(), d.qvel.copy()
    dt = float(m.opt.timestep)
    steps = int(round(cycles * ref.period / dt))
    run = _rollout(m, d, ctl, ref, geometry, t0, steps, stop_on_fall)
    res = SimulationResult(
        xml=xml, timestep=dt, qpos0=qpos0, qvel0=qvel0, time=run.time, ctrl=run.ctrl, qpos=run.qpos,
        actuator_names=tuple(mujoco.mj_id2name(m, mujoco.mjtObj.mjOBJ_ACTUATOR, a) for a in range(m.nu)),
        coordinate_qpos=geometry.coordinate_qpos.copy(), t0=t0, cycle_duration_s=ref.period, cycles_requested=cycles,
        fell=run.fell, fall_time=run.fall_time, fall_reason=run.fall_reason, wall_time_s=run.wall,
        series=run.series,
    )
    report = _report(res, motion, ref, ctl, motor_peaks(motion, m, geometry), geometry.motors)
    report["controller"] = type(ctl).__name__
    report["start"] = _start_report(run, start_info, body_weight(motion), dt)
    report["agreement"] = agreement(motion, m, ref, geometry)
    if resync:
        report["resync"] = _resync(motion, ref, t0, cycles, gains, controller)
    return replace(res, report=report)


def _wrap(a: np.ndarray) -> np.ndarray:
    return (a + np.pi) % (2 * np.pi) - np.pi


def _report(res: SimulationResult, motion: Motion, ref: Reference, ctl: Controller, peaks: np.ndarray,
            motors: np.ndarray) -> dict[str, Any]:
    """The report of a run; ``peaks``: per motor (``motors``) the motion's own inverse-dynamics peak."""
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
    peaks_sim = np.max(np.abs(res.ctrl[:, motors]), axis=0) if len(res.ctrl) else np.zeros(len(peaks))
    ratio = peaks_sim / np.maximum(peaks, 1e-9)
    act = [res.actuator_names[a] for a in motors]
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
        "control_period_s": res.timestep * ctl.control_period,
        "joint_tracking_rms_deg": float(np.sqrt(np.mean(joint_err**2))) if joint_err.size else float("nan"),
        "joint_tracking_rms_deg_per_joint": {names[6 + j]: float(np.sqrt(np.mean(joint_err[:, j] ** 2)))
                                             for j in range(joint_err.shape[1])} if joint_err.size else {},
        "root_height_rms_m": float(np.sqrt(np.mean((q[:, ROOT_Z] - qr[:, ROOT_Z]) ** 2))) if len(q) else float("nan"),
        "drift_per_cycle": drift,
        "foot_force_rms_bw": force_rms,
        "body_weight_n": bw,
        "peak_torque_nm": {a: float(p) for a, p in zip(act, peaks_sim, strict=True)},
        "id_peak_torque_nm": {a: float(p) for a, p in zip(act, peaks, strict=True)},
        "peak_torque_ratio": {a: float(r) for a, r in zip(act, ratio, strict=True)},
        "peak_torque_ratio_max": float(ratio.max()) if len(ratio) else float("nan"),
        "torque_limit_nm": ({a: float(v) for a, v in zip(act, ctl.torque_limit, strict=True)}
                            if ctl.torque_limit is not None else None),
        "wall_time_s": res.wall_time_s,
        "realtime_factor": walked_s / res.wall_time_s if res.wall_time_s > 0 else float("nan"),
    }
