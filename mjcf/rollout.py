"""A run of the tracking controller in MuJoCo: its start and its steps.

:func:`_start` puts the walk at a reference time (mid single support for
:func:`mjcf.simulate.simulate`) with the reference's velocities (no impact), its contacts
preloaded at the stored vertical force; :func:`_rollout` steps the model under the controller,
detects a fall and samples the series the report is made from (:class:`_Run`).
"""

from __future__ import annotations

import time as _time
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from mjcf.agreement import ground_height
from mjcf.reference import ROOT_Z, Reference
from mjcf.tracker import Tracker


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
