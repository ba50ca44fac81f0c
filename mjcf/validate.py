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
from solver.environment import environment_of
from solver.motion import FEET, Motion
from solver.plausibility import Tolerances, about_root, report, root_residual
from solver.trajectory import dynamics_samples


def mujoco_residual(motion: Motion) -> np.ndarray:
    """(6, S) residual root wrench from MuJoCo at the dynamics samples, moment about the root position."""
    ch = motion.character
    replay = MujocoReplay.create(ch, environment_of(motion).gravity)
    s = dynamics_samples(motion)
    fext = None
    if s.wrenches is not None:
        fext = {ch.foot(side).segment: s.wrenches[k] for k, side in enumerate(FEET)}
    _, h0 = replay.inverse(s.q, s.qd, s.qdd, fext)
    return about_root(h0, s.q)


@register_check(section="mujoco_replay", verdict="plausible", flags="all", nested=False, optional=True, order=30)
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


def validate(motion: Motion, tol: Tolerances = Tolerances()) -> dict[str, Any]:
    """Our plausibility report with the MuJoCo replay section; ``plausible`` requires both."""
    return report(motion, tol, include=("mujoco_replay",))
