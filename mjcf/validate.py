"""Plausibility of a motion, with the root residual recomputed independently by MuJoCo.

MuJoCo replay: the motion's coordinates (velocities and accelerations by the same central
differences) go through ``mj_inverse`` on the MJCF generated from the motion's character,
with the contact wrenches applied to the feet (``mj_applyFT``). What the six root joints
still need is the residual wrench; it must vanish, and agree with ours.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from mjcf.replay import MujocoReplay
from solver.kinematics import finite_differences
from solver.motion import FEET, Motion
from solver.plausibility import Tolerances, about_root, environment_of, report, root_residual


def mujoco_residual(motion: Motion) -> np.ndarray:
    """(6, T-2) residual root wrench from MuJoCo, moment about the root position."""
    env = environment_of(motion)
    ch = motion.character
    replay = MujocoReplay.create(ch, env["gravity"])
    q = motion.q
    qd, qdd = finite_differences(q, motion.dt)
    fext = None
    if motion.wrenches is not None:
        fext = {ch.foot(side).segment: motion.wrenches[k][:, 1:-1] for k, side in enumerate(FEET)}
    _, h0 = replay.inverse(q[:, 1:-1], qd, qdd, fext)
    return about_root(h0, q[:, 1:-1])


def validate(motion: Motion, tol: Tolerances = Tolerances()) -> dict[str, Any]:
    """Our plausibility report plus the MuJoCo replay; ``plausible`` requires both."""
    rep = report(motion, tol)
    weight, leg = rep["body_weight_N"], rep["leg_length_m"]
    ours = root_residual(motion, environment_of(motion)["gravity"])
    mj = mujoco_residual(motion)
    diff = mj - ours
    mjr = {
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
