"""A run of a controller (``mjcf.controller.Controller``) in MuJoCo: its start and its steps.

:func:`_start` puts the walk at a reference time (mid single support for
:func:`mjcf.simulate.simulate`) with the reference's velocities (no impact), its contacts
preloaded at the stored vertical force; :func:`_rollout` steps the model under the controller's
hooks, ends at its termination (by default a fall) and samples the series the report is made from
(:class:`_Run`).
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from mjcf.controller import Controller
from mjcf.performable import ModelGeometry
from mjcf.reference import ROOT_Z, Reference
from solver.environment import body_weight


def _foot_forces(m: mujoco.MjModel, d: mujoco.MjData, geometry: ModelGeometry) -> np.ndarray:
    """(2, 3) world contact force on each sole."""
    out = np.zeros((2, 3))
    f6 = np.zeros(6)
    for i in range(d.ncon):
        c = d.contact[i]
        for f, gid in enumerate(sole.geom for sole in geometry.soles):
            if c.geom1 == gid or c.geom2 == gid:
                mujoco.mj_contactForce(m, d, i, f6)
                fw = c.frame.reshape(3, 3).T @ f6[:3]
                out[f] += fw if c.geom2 == gid else -fw
    return out


#: the deepest the preloaded start presses the stance sole into the soft contacts (m)
MAX_PRELOAD_DEPTH = 0.01


def _start(m: mujoco.MjModel, geometry: ModelGeometry, ctl: Controller, ref: Reference, t0: float,
           preload: bool) -> tuple[mujoco.MjData, dict[str, Any]]:
    """The state the simulation starts from at reference time ``t0``: the reference's pose and
    velocities, the body lowered so the lowest scheduled sole corner touches the ground; with
    ``preload``, lowered further (the soft contacts' penetration) until MuJoCo's vertical contact
    force under the controller's first controls (``initialize`` then ``control`` at each depth)
    equals the stored one (bisection on the depth). A fresh ``MjData`` (a replay from qpos0/qvel0
    starts from the same solver state)."""
    d = mujoco.MjData(m)
    qr, qdr, _ = ref.state(t0)
    d.qpos[geometry.coordinate_qpos] = qr
    d.qvel[geometry.coordinate_dof] = qdr
    mujoco.mj_forward(m, d)
    active = ref.active(t0)
    lows = []
    for sole in geometry.soles:
        bid = sole.body
        for c in range(4):
            if active[sole.owner[c]]:
                p = d.xpos[bid] + d.xmat[bid].reshape(3, 3) @ sole.corners[c]
                lows.append(p[2] - geometry.ground_height(d, p))
    zadr = int(geometry.coordinate_qpos[ROOT_Z])
    if lows:
        d.qpos[zadr] -= min(lows) + 2e-4
    stored = float(ref.wrench(t0)[:, 5].sum())
    bw = body_weight(ref.motion)
    info: dict[str, Any] = {"stored_vertical_force_bw": stored / bw, "preloaded": bool(preload and lows),
                            "depth_m": 2e-4 if lows else 0.0}

    def force(depth: float) -> float:
        d.qpos[zadr] = z0 - depth
        mujoco.mj_forward(m, d)
        ctl.initialize(d, t0)
        d.ctrl[:] = ctl.control(d, t0)
        mujoco.mj_forward(m, d)
        return float(_foot_forces(m, d, geometry)[:, 2].sum())

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
        info["t0_vertical_force_bw"] = force(hi) / bw
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
    """One rollout: per step time, ctrl and qpos; the series sampled every 10 ms; the fall (the
    controller's termination: its time and reason)."""

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


#: the series the run samples itself (a controller's ``measures`` add others)
RUN_SERIES = ("foot_force", "foot_force_ref", "t_ref", "q_ref", "q", "t", "com")


def _rollout(m: mujoco.MjModel, d: mujoco.MjData, ctl: Controller, ref: Reference, geometry: ModelGeometry,
             t0: float, steps: int, stop_on_fall: bool) -> _Run:
    """Run the controller from the state in ``d`` (reference time ``t0``) for ``steps`` steps, or
    until its termination (with ``stop_on_fall``); the hooks in the order ``mjcf.controller`` gives."""
    dt = float(m.opt.timestep)
    time = np.zeros(steps)
    ctrl = np.zeros((steps, m.nu))
    qpos = np.zeros((steps, m.nq))
    every = max(1, int(round(0.01 / dt)))  # measures every 10 ms
    n_start = int(round(START_WINDOW_S / dt))
    start_force: list[float] = []
    S: dict[str, list[Any]] = {k: [] for k in RUN_SERIES}
    com_body = int(m.body_rootid[geometry.pelvis])
    t_ref = t0
    ctl.initialize(d, t0)
    fell, fall_time, reason = False, None, None
    tau = np.zeros(m.nu)
    wall0 = _time.perf_counter()
    done = steps
    for s in range(steps):
        t = s * dt
        if s % ctl.control_period == 0:
            tau = ctl.control(d, t_ref)
        d.ctrl[:] = tau
        if s % every == 0:
            S["foot_force"].append(_foot_forces(m, d, geometry))
            S["foot_force_ref"].append(ref.wrench(t_ref)[:, 3:])
            S["t_ref"].append(t_ref)
            S["q_ref"].append(ref.state(t_ref)[0])
            S["q"].append(d.qpos[geometry.coordinate_qpos].copy())
            S["t"].append(t)
            S["com"].append(d.subtree_com[com_body].copy())
            for k, v in ctl.measures(d).items():
                if k in RUN_SERIES:
                    raise ValueError(f"a controller's measure is named as the run's own series: {k}")
                S.setdefault(k, []).append(v)
        mujoco.mj_step(m, d)
        time[s] = t + dt
        ctrl[s] = d.ctrl
        qpos[s] = d.qpos
        mujoco.mj_forward(m, d)
        if s < n_start:
            start_force.append(float(_foot_forces(m, d, geometry)[:, 2].sum()))
        ctl.after_step(d)
        t_ref += dt * ctl.clock_rate(d, t_ref)
        bad = ctl.termination(d, t_ref)
        if bad is not None and not fell:
            fell, fall_time, reason = True, t + dt, bad
            if stop_on_fall:
                done = s + 1
                break
    wall = _time.perf_counter() - wall0
    series = {k: np.array(v) for k, v in S.items()}
    return _Run(time[:done], ctrl[:done], qpos[:done], series, fell, fall_time, reason, wall, np.array(start_force),
                t_ref, d.qvel.copy())
