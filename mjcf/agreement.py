"""Does the simulated model agree with the motion it performs? (docs/simulation.md, "Agreement")

Measured on the reference alone (no controller), with the simulation's performable model and its
geometry (:func:`mjcf.performable.performable_model`):

* **The sole.** The simulated sole is the character's (``Character.sole``: the rectangle whose back
  and front edges have the heel and toe contact points as midpoints, as wide as the foot box), turned
  about its heel–toe line by the foot's mean stance roll. :func:`sole_agreement` checks the model's
  sole geoms are that rectangle, and where each stored foot wrench's centre of pressure lies on it:
  the fraction of stance frames whose centre of pressure is beyond the heel or toe edge, or beyond
  the sides.
* **Swing clearance.** :func:`swing_clearance`: the height above the ground (the floor, or the tread
  below) of the sole's four corners through each foot's swing, on the reference's C² spline.
"""

from __future__ import annotations

from typing import Any

import mujoco
import numpy as np

from mjcf.performable import ModelGeometry
from solver.environment import body_weight
from solver.motion import FEET, Motion

#: a centre of pressure closer than this to the sole's outline counts as on it (m)
COP_TOLERANCE = 1e-3
#: a sole is flat on the ground when its normal is within 2° of the vertical and its corners within 2 mm of it
FLAT_COS, FLAT_HEIGHT = float(np.cos(np.radians(2.0))), 0.002
#: stance frames whose stored vertical force is below this (BW) have no meaningful centre of pressure
COP_MIN_FORCE_BW = 0.02


def sole_agreement(motion: Motion, model: mujoco.MjModel, geometry: ModelGeometry) -> dict[str, Any]:
    """The simulated soles against the character's, and the stored centres of pressure on them.

    ``sole_matches_character``: every sole geom's bottom face has the character's heel and toe
    contact points as the midpoints of its back and front edges and its half width (to 0.1 mm).
    ``cop_outside_fraction`` (per foot and overall): the fraction of the cycle's stance frames (stored
    vertical force ≥ 2 % BW) whose centre of pressure, on the plane of the sole's bottom face at the
    reference's pose, is more than 1 mm beyond the sole's outline; ``beyond_heel_or_toe`` and
    ``beyond_sides`` split it; ``max_beyond_m`` is the largest distance beyond.
    ``cop_outside_fraction_flat``: the same over the frames where the sole lies flat on the ground
    (``flat_stance_frames``; the optimizer's centre of pressure is bounded in the foot's box, whose
    height lets it off the sole's outline when the foot is tilted, at heel strike and push-off)."""
    ch = motion.character
    qadr = geometry.coordinate_qpos
    d = mujoco.MjData(model)
    bw = body_weight(motion)
    P = motion.T - 2
    W = np.asarray(motion.wrenches, dtype=float)
    matches = True
    per_foot: dict[str, Any] = {}
    n_all = n_out_all = n_flat = n_out_flat = 0
    for f, gid in enumerate(s.geom for s in geometry.soles):
        side = FEET[f]
        sole = ch.sole(side)
        half = model.geom_size[gid]
        R9 = np.zeros(9)
        mujoco.mju_quat2Mat(R9, model.geom_quat[gid])
        R = R9.reshape(3, 3)
        bottom = model.geom_pos[gid] - R[:, 2] * half[2]
        back, front = bottom - R[:, 0] * half[0], bottom + R[:, 0] * half[0]
        err = max(float(np.linalg.norm(back - sole.heel.position)), float(np.linalg.norm(front - sole.toe.position)),
                  abs(float(half[1]) - sole.half_width))
        matches = matches and err < 1e-4
        n = out_len = out_wid = 0
        beyond = 0.0
        for t in range(P):
            fw = W[f, 3:, t]
            if fw[2] < COP_MIN_FORCE_BW * bw:
                continue
            d.qpos[qadr] = motion.q[:, t]
            mujoco.mj_kinematics(model, d)
            Rg = d.geom_xmat[gid].reshape(3, 3)
            c = d.geom_xpos[gid] - Rg[:, 2] * half[2]
            m_c = W[f, :3, t] - np.cross(c, fw)
            fl, ml = Rg.T @ fw, Rg.T @ m_c
            if fl[2] <= 0:
                continue
            px, py = -ml[1] / fl[2], ml[0] / fl[2]
            bx, by = abs(px) - half[0], abs(py) - half[1]
            n += 1
            out_len += bx > COP_TOLERANCE
            out_wid += by > COP_TOLERANCE
            outside = bx > COP_TOLERANCE or by > COP_TOLERANCE
            n_out_all += outside
            corners = [c + Rg @ np.array([sx * half[0], sy * half[1], 0.0]) for sx in (-1, 1) for sy in (-1, 1)]
            if Rg[2, 2] > FLAT_COS and max(float(p[2]) - geometry.ground_height(d, p) for p in corners) < FLAT_HEIGHT:
                n_flat += 1
                n_out_flat += outside
            beyond = max(beyond, float(bx), float(by))
        n_all += n
        per_foot[side] = {"stance_frames": n, "beyond_heel_or_toe": float(out_len / n) if n else 0.0,
                          "beyond_sides": float(out_wid / n) if n else 0.0, "max_beyond_m": max(beyond, 0.0)}
    return {"sole_matches_character": bool(matches), "per_foot": per_foot,
            "cop_outside_fraction": float(n_out_all / n_all) if n_all else 0.0, "stance_frames": n_all,
            "flat_stance_frames": n_flat, "cop_outside_fraction_flat": float(n_out_flat / n_flat) if n_flat else 0.0,
            "tolerance_m": COP_TOLERANCE}


def swing_clearance(motion: Motion, model: mujoco.MjModel, geometry: ModelGeometry, ref: Any,
                    step: float = 0.002) -> dict[str, Any]:
    """The reference's sole corners above the ground through each foot's swing (the reference's
    frames before and after without a contact of that foot), sampled every ``step`` s over one cycle
    on the reference's spline (``ref``: the simulation's ``mjcf.reference.Reference``): per foot the
    lowest corner (m), where in the swing it is (0 lift-off, 1 touchdown) and the fraction of the
    swing with a corner below the ground."""
    qadr = geometry.coordinate_qpos
    d = mujoco.MjData(model)
    owners = [s.points for s in geometry.soles]
    sole_corners = [(s.body, s.corners) for s in geometry.soles]
    lows: list[list[tuple[float, float]]] = [[], []]
    for t in np.arange(0.0, ref.period, step):
        sp = [ref.swing_progress(float(t), owners[f]) for f in range(2)]
        if sp[0] is None and sp[1] is None:
            continue
        d.qpos[qadr] = ref.state(float(t))[0]
        mujoco.mj_kinematics(model, d)
        for f, (bid, corners) in enumerate(sole_corners):
            if sp[f] is None:
                continue
            h = min(float(p[2]) - geometry.ground_height(d, p)
                    for p in (d.xpos[bid] + d.xmat[bid].reshape(3, 3) @ c for c in corners))
            lows[f].append((h, float(sp[f] or 0.0)))
    out: dict[str, Any] = {}
    for f, side in enumerate(FEET):
        if not lows[f]:
            out[side] = None
            continue
        hs = np.array([x[0] for x in lows[f]])
        i = int(np.argmin(hs))
        out[side] = {"min_corner_height_m": float(hs[i]), "at_swing_fraction": lows[f][i][1],
                     "fraction_below_ground": float(np.mean(hs < 0.0)),
                     "fraction_below_5mm": float(np.mean(hs < 0.005))}
    mins = [v["min_corner_height_m"] for v in out.values() if v]
    out["min_corner_height_m"] = min(mins) if mins else None
    return out


def agreement(motion: Motion, model: mujoco.MjModel, ref: Any, geometry: ModelGeometry) -> dict[str, Any]:
    """Both measures, as ``report.json``'s ``agreement``."""
    return {"sole": sole_agreement(motion, model, geometry),
            "swing_clearance": swing_clearance(motion, model, geometry, ref)}
