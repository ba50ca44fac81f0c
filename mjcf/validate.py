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


def validate(motion: Motion, tol: Tolerances = Tolerances()) -> dict[str, Any]:
    """Our plausibility report plus the MuJoCo replay; ``plausible`` requires both."""
    rep = report(motion, tol)
    weight, leg = rep["body_weight_N"], rep["leg_length_m"]
    ours = root_residual(motion, environment_of(motion).gravity)
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
    rep["mujoco_replay"] = mjr
    rep["checks"]["mujoco_root"] = (
        mjr["max_force_rel_weight"] <= tol.residual and mjr["max_moment_rel_weight_leg"] <= tol.residual
    )
    rep["checks"]["mujoco_agrees"] = (
        mjr["agreement_force_rel_weight"] <= tol.residual and mjr["agreement_moment_rel_weight_leg"] <= tol.residual
    )
    for k in ("mujoco_root", "mujoco_agrees"):
        if not rep["checks"][k]:
            rep["problems"].append(f"{k} out of tolerance")
    rep["plausible"] = all(rep["checks"].values())
    return rep
