"""The MuJoCo model a motion is simulated on (:func:`performable_model`).

The model is the character's (``mjcf.builder``) with contacts on: box soles under the
optimizer's heel and toe points, flat at the foot's mean stance orientation, the environment's
gravity, friction and treads, an unactuated 6-DOF root (the character's three slides and three
hinges) and one motor per joint; timestep 1 ms. The only forces on the bodies are gravity, the
motors (through the joints) and the contacts. On request, also a residual motor on each root
coordinate (the resync runs of ``mjcf.simulate``).
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from mjcf.builder import ContactOptions, Tread, build_spec, sole_corners
from mjcf.reference import Reference
from solver.motion import FEET, Motion
from solver.stairs import flight_of

#: the root residual's actuators are named this followed by the root coordinate
RESIDUAL_PREFIX = "residual_"


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
