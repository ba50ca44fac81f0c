"""Plausibility of a motion, with the root residual recomputed independently by MuJoCo.

MuJoCo replay: the motion's coordinates, velocities and accelerations at its dynamics samples
(``solver.trajectory``: frames and midpoints of its spline, or central differences) go through
``mj_inverse`` on the MJCF generated from the motion's character, with the contact wrenches applied
to the feet (``mj_applyFT``). What the six root joints still need is the residual wrench; it must
vanish, and agree with ours.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mjcf.replay import MujocoReplay
from solver.checks import Check, Context, SectionResult, register_check
from solver.motion import FEET, Motion
from solver.plausibility import Tolerances, about_root, report, root_residual
from solver.trajectory import dynamics_samples


def mujoco_residual(motion: Motion) -> np.ndarray:
    """(6, S) residual root wrench from MuJoCo at the dynamics samples, moment about the root position."""
    ch = motion.character
    replay = MujocoReplay.create(ch, motion.environment.gravity)
    s = dynamics_samples(motion)
    fext = None
    if s.wrenches is not None:
        fext = {ch.foot(side).segment: s.wrenches[k] for k, side in enumerate(FEET)}
    _, h0 = replay.inverse(s.q, s.qd, s.qdd, fext)
    return about_root(h0, s.q)


@register_check(section="mujoco_replay", verdict="plausible", flags="all", optional=True, order=30,
                title="MuJoCo replay")
def replay_checks(ctx: Context) -> SectionResult:
    """The MuJoCo replay's figures and its two checks: its root residual vanishes
    (``mujoco_root``) and agrees with ours (``mujoco_agrees``), within the residual tolerance."""
    motion, tol, weight, leg = ctx.motion, ctx.tolerances, ctx.weight, ctx.leg
    ours = root_residual(motion, ctx.gravity)
    mj = mujoco_residual(motion)
    diff = mj - ours
    mjr: dict[str, Any] = {
        "max_force_N": float(np.abs(mj[3:]).max()),
        "max_moment_Nm": float(np.abs(mj[:3]).max()),
        "max_force_rel_weight": float(np.abs(mj[3:]).max() / weight),
        "max_moment_rel_weight_leg": float(np.abs(mj[:3]).max() / (weight * leg)),
        "agreement_force_rel_weight": float(np.abs(diff[3:]).max() / weight),
        "agreement_moment_rel_weight_leg": float(np.abs(diff[:3]).max() / (weight * leg)),
        "model": "MJCF generated from the motion's character (mujoco.MjSpec), mj_inverse + mj_applyFT",
    }
    checks = (
        Check.measure("mujoco_root", max(mjr["max_force_rel_weight"], mjr["max_moment_rel_weight_leg"]),
                      tol.residual, "BW, BW·leg", "MuJoCo's root residual force / weight and moment / (weight × leg)"),
        Check.measure("mujoco_agrees",
                      max(mjr["agreement_force_rel_weight"], mjr["agreement_moment_rel_weight_leg"]), tol.residual,
                      "BW, BW·leg", "MuJoCo's root residual less ours, force / weight and moment / (weight × leg)"),
    )
    return SectionResult(checks, mjr)


#: gait cycles the ``simulation`` section performs, and the figures it holds a walk to
SIMULATION_CYCLES = 10
SIMULATION_LIMITS = {"joint_tracking_rms_deg": 5.0, "foot_force_rms_bw": 0.15, "peak_torque_ratio_max": 1.5}


@register_check(section="simulation", verdict="plausible", optional=True, order=40)
def simulation_checks(ctx: Context) -> SectionResult:
    """The motion performed in MuJoCo with contacts on (``mjcf.simulate``) for
    :data:`SIMULATION_CYCLES` cycles. Its checks are warnings: they never decide ``plausible``,
    since a fall measures the tracking controller as much as the motion (docs/simulation.md)."""
    from mjcf.simulate import SimulationError, simulate

    try:
        res = simulate(ctx.motion, SIMULATION_CYCLES, resync=False)
    except SimulationError as e:
        return SectionResult((), {"error": str(e)}, checked=False, unchecked=None)
    r = res.report
    lim = SIMULATION_LIMITS
    checks = (
        Check.measure("cycles_walked", r["cycles_walked"], float(SIMULATION_CYCLES), "cycles",
                      "gait cycles walked in MuJoCo forward simulation before a fall", warning=True, at_least=True),
        Check.measure("joint_tracking_rms", r["joint_tracking_rms_deg"], lim["joint_tracking_rms_deg"], "deg",
                      "RMS of the simulated joint angles less the motion's", warning=True),
        Check.measure("foot_force_rms", r["foot_force_rms_bw"], lim["foot_force_rms_bw"], "BW",
                      "RMS of the simulated foot forces less the stored ones", warning=True),
        Check.measure("peak_torque_ratio", r["peak_torque_ratio_max"], lim["peak_torque_ratio_max"], "",
                      "largest simulated joint torque peak over the motion's own inverse-dynamics peak", warning=True),
    )
    extra = {k: r[k] for k in ("cycles_requested", "cycle_duration_s", "fell", "fall", "drift_per_cycle",
                               "root_height_rms_m", "realtime_factor")}
    extra["controller"] = "balancing QP tracking controller, contacts on, unactuated root (mjcf.simulate)"
    return SectionResult(checks, extra)


def validate(motion: Motion, tol: Tolerances = Tolerances(), *, simulate: bool = False) -> dict[str, Any]:
    """Our plausibility report with the MuJoCo replay section; ``plausible`` requires both.
    ``simulate``: also the ``simulation`` section (the motion performed in MuJoCo forward
    simulation; reported, never deciding ``plausible``)."""
    return report(motion, tol, include=("mujoco_replay", "simulation") if simulate else ("mujoco_replay",))
