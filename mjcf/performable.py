"""The MuJoCo model a motion is simulated on (:func:`performable_model`).

The model is the character's (``mjcf.builder``) with contacts on: box soles under the
optimizer's heel and toe points, flat at the foot's mean stance orientation, the environment's
gravity, friction and treads, an unactuated 6-DOF root (the character's three slides and three
hinges) and one motor per joint; timestep 1 ms. The only forces on the bodies are gravity, the
motors (through the joints) and the contacts. On request, also a residual motor on each root
coordinate (the resync runs of ``mjcf.simulate``).

:class:`ModelGeometry` is what the simulation's other modules know of the model: the ids and
addresses of the builder's parts (``mjcf.builder.ContactParts``: soles, ground, the geoms that mean
a fall, inversion hinges) and of the motion's coordinates and motors in the compiled model.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import mujoco
import numpy as np

from mjcf.builder import ContactOptions, ContactParts, Tread, build_performable, build_spec, sole_corners
from mjcf.reference import Reference
from solver.motion import FEET, Motion
from solver.stairs import flight_of

#: the root residual's actuators are named this followed by the root coordinate
RESIDUAL_PREFIX = "residual_"


def _frozen(a: np.ndarray | list[int]) -> np.ndarray:
    out = np.array(a)
    out.setflags(write=False)
    return out


@dataclass(frozen=True, eq=False)
class Sole:
    """A foot's box sole in the compiled model."""

    side: str  # "right" or "left"
    geom: int
    body: int  # the foot segment's body
    corners: np.ndarray  # (4, 3) bottom corners in the body's frame: heel +w, heel −w, toe +w, toe −w
    centre: np.ndarray  # (3,) the bottom face's centre in the body's frame
    owner: tuple[int, int, int, int]  # per corner, the motion's contact point it belongs to (heel, heel, toe, toe)
    points: np.ndarray  # the motion's contact points on this foot (indices into ``Character.contacts``)
    roll: float  # rad about the heel-toe line: flat at the foot's mean stance orientation


@dataclass(frozen=True, eq=False)
class ModelGeometry:
    """The parts of a performable model the simulation refers to, by id in the compiled model
    (:func:`performable_model`): the soles, the ground (floor, treads), the segment geoms whose
    contact with the ground is a fall, the pelvis, the motion's coordinates and the actuators."""

    soles: tuple[Sole, ...]  # right, left (``solver.motion.FEET``)
    floor: bool  # the plane z = 0 is ground (else the treads alone are)
    treads: tuple[int, ...]  # the stairs' box geoms
    tread_half: np.ndarray  # (len(treads), 3) their half extents
    fall_geoms: frozenset[int]  # segment geoms (not the feet's) that touch only the ground: a fall
    pelvis: int  # the root segment's body
    coordinate_qpos: np.ndarray  # motion coordinate i -> qpos address
    coordinate_dof: np.ndarray  # motion coordinate i -> dof address
    inversion_qpos: np.ndarray  # the feet's inversion hinges (right, left; none without): qpos addresses
    inversion_dof: np.ndarray  # ... and dof addresses
    motors: np.ndarray  # the joints' and inversion hinges' actuators, in actuator order
    residual: np.ndarray  # the root residual's actuators, in root coordinate order (empty without)

    def ground_height(self, d: mujoco.MjData, p: np.ndarray) -> float:
        """Height of the ground (the floor or the tread below) at a world point."""
        best = 0.0 if self.floor else -math.inf
        for i, hs in zip(self.treads, self.tread_half, strict=True):
            R = d.geom_xmat[i].reshape(3, 3)
            loc = R.T @ (p - d.geom_xpos[i])
            if abs(loc[0]) <= hs[0] and abs(loc[1]) <= hs[1]:
                best = max(best, float(d.geom_xpos[i][2] + hs[2]))
        return best if np.isfinite(best) else 0.0


def _sole(motion: Motion, model: mujoco.MjModel, side: str, gid: int, roll: float) -> Sole:
    ch = motion.character
    size = model.geom_size[gid]
    R9 = np.zeros(9)
    mujoco.mju_quat2Mat(R9, model.geom_quat[gid])
    R = R9.reshape(3, 3)
    pos = model.geom_pos[gid]
    corners = np.array([pos + R @ np.array([sx * size[0], sy * size[1], -size[2]])
                        for sx in (-1, 1) for sy in (1, -1)])  # heel ±, toe ±
    heel, toe = ch.sole_indices(side)  # the sole's heel and toe contact points
    return Sole(side=side, geom=gid, body=int(model.geom_bodyid[gid]), corners=_frozen(corners),
                centre=_frozen(R @ np.array([0, 0, -1.0]) * size[2] + pos), owner=(heel, heel, toe, toe),
                points=_frozen([i for i, c in enumerate(ch.contacts) if c.side == side]), roll=roll)


def _geometry(motion: Motion, model: mujoco.MjModel, parts: ContactParts, residual: list[mujoco.MjsActuator],
              roll: tuple[float, float]) -> ModelGeometry:
    """The ids of ``parts`` and ``residual`` in ``model`` (compiled from the XML of their spec)."""
    geom = [model.geom(g.name).id for g in parts.soles]
    joints = [model.joint(nm).id for nm in motion.character.coordinate_names]
    inversion = [model.joint(j.name).id for j in parts.inversion]
    res = [model.actuator(a.name).id for a in residual]
    treads = tuple(model.geom(g.name).id for g in parts.treads)
    return ModelGeometry(
        soles=tuple(_sole(motion, model, side, gid, r) for side, gid, r in zip(FEET, geom, roll, strict=True)),
        floor=parts.floor is not None, treads=treads, tread_half=_frozen(model.geom_size[list(treads)].reshape(-1, 3)),
        fall_geoms=frozenset(model.geom(g.name).id for g in parts.fall), pelvis=model.body(parts.root.name).id,
        coordinate_qpos=_frozen([model.jnt_qposadr[j] for j in joints]),
        coordinate_dof=_frozen([model.jnt_dofadr[j] for j in joints]),
        inversion_qpos=_frozen(np.array([model.jnt_qposadr[j] for j in inversion], dtype=int)),
        inversion_dof=_frozen(np.array([model.jnt_dofadr[j] for j in inversion], dtype=int)),
        motors=_frozen(np.array([a for a in range(model.nu) if a not in res], dtype=int)),
        residual=_frozen(np.array(res, dtype=int)))


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
                      root_residual: bool = False) -> tuple[str, mujoco.MjModel, ModelGeometry]:
    """The model XML, the model compiled *from that XML* (so a replay from the file is what
    was simulated) and its :class:`ModelGeometry` (the soles with the roll that lays them flat in
    stance). ``root_residual``: also a motor on each of the six root coordinates
    (``residual_<name>``, after the joints' motors): the resync runs' penalized residual wrench."""
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
    spec, parts = build_performable(ch, env.gravity, opts)
    residual = []
    if root_residual:
        for nm in ch.coordinate_names[:6]:
            a = spec.add_actuator(name=f"{RESIDUAL_PREFIX}{nm}", target=nm, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            a.gear = [1.0, 0, 0, 0, 0, 0]
            a.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
            residual.append(a)
    spec.compile()
    xml = spec.to_xml()
    model = mujoco.MjModel.from_xml_string(xml)
    return xml, model, _geometry(motion, model, parts, residual, roll)
