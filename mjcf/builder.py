"""Generate a MuJoCo model from a character with ``mujoco.MjSpec`` (no string templates).

One MuJoCo body per segment, its 1-DOF joints in order inside that body (MuJoCo applies
a body's joints sequentially, exactly like our chains of massless bodies), so MuJoCo's
joints map 1:1 to the character's coordinates and carry the same names. Inertial data
are explicit (mass, centre of mass, full inertia); geoms are visual only (no contacts).

MuJoCo's XML writer prints 6 significant digits; exact comparisons therefore use the
model compiled in memory (:func:`compile_model`), and the XML is for viewing/exchange.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import mujoco
import numpy as np

from solver.character import Character
from solver.dynamics import DEFAULT_GRAVITY

MARKER_PREFIX = "marker_"


def _quat(rot: np.ndarray) -> np.ndarray:
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(rot, dtype=float).reshape(9))
    return q


def _quat_z_to(direction: np.ndarray) -> np.ndarray:
    """Quaternion rotating +z onto ``direction``."""
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    q = np.zeros(4)
    mujoco.mju_quatZ2Vec(q, d)
    return q


#: collision classes of a model with contacts on: soles touch the ground (bit 1), every other
#: segment's geom touches only the ground too (bit 2: a fall), segments never touch each other
_SOLE, _BODY, _GROUND = (1, 0), (2, 0), (1, 3)


@dataclass(frozen=True)
class Tread:
    """A block of ground (world frame): centre, half extents, heading (rad about +z)."""

    center: tuple[float, float, float]
    half: tuple[float, float, float]
    yaw: float = 0.0


@dataclass(frozen=True)
class ContactOptions:
    """What makes a model *performable*: contacts on, an unactuated root, a motor per joint.

    Each foot gets a box sole whose bottom face holds the foot's heel and toe contact points
    (the optimizer's two-point centre-line foot) and spans the foot box's width; the sole is
    turned about the heel-toe line by ``sole_roll[side]`` (rad, right then left) so that it lies
    flat on the ground at the foot's mean stance orientation. Joint limits are off (every
    joint torque is a motor's), the ground is the plane z = 0 plus ``treads``."""

    sole_roll: tuple[float, float] = (0.0, 0.0)
    sole_thickness: float = 0.01
    #: half width of the sole (m); None: the foot box's
    sole_half_width: float | None = None
    #: an actuated inversion hinge in each foot (about the heel-toe line, through the ankle): the
    #: stance leg then has six joints, so the sole can lie flat whatever the pelvis's roll
    inversion: bool = False
    friction: float = 1.0
    timestep: float = 0.001
    treads: tuple[Tread, ...] = ()
    floor: bool = True
    #: contact softness: time constant (s) and damping ratio of the contact spring (MuJoCo solref)
    solref: tuple[float, float] = (0.01, 1.0)
    #: elliptic friction cones, frictional-to-normal impedance ratio (high: little creep)
    impratio: float = 10.0
    #: torsional friction of the soles (m: the radius of the contact patch resisting spin; 0: none)
    torsional_friction: float = 0.0


def sole_corners(character: Character, side: str, roll: float,
                 half_width: float | None = None) -> tuple[str, np.ndarray]:
    """The foot segment and the 4 bottom corners of the sole (segment frame; rows: heel +w,
    heel −w, toe +w, toe −w) turned by ``roll`` (rad) about the heel-toe line: the heel and toe
    contact points are the midpoints of the sole's back and front bottom edges."""
    try:
        sole = character.sole(side)  # the optimizer's, the checks' and the exports' sole
    except ValueError as e:
        raise ValueError(f"a sole needs the foot's two contact points (heel, toe) on one segment: {e}") from None
    return sole.segment, sole.corners(roll, half_width)


def _sole_box(character: Character, side: str, roll: float, thickness: float,
              half_width: float | None) -> tuple[str, np.ndarray, np.ndarray, np.ndarray]:
    seg, corners = sole_corners(character, side, roll, half_width)
    heel, toe = corners[0:2].mean(axis=0), corners[2:4].mean(axis=0)
    axis_x = (toe - heel) / np.linalg.norm(toe - heel)
    axis_y = corners[0] - corners[1]
    axis_y = axis_y - axis_x * float(axis_x @ axis_y)
    axis_y /= np.linalg.norm(axis_y)
    axis_z = np.cross(axis_x, axis_y)
    rot = np.column_stack([axis_x, axis_y, axis_z])
    half = np.array([0.5 * float(np.linalg.norm(toe - heel)), 0.5 * float(np.linalg.norm(corners[0] - corners[1])),
                     0.5 * thickness])
    center = 0.5 * (heel + toe) + axis_z * half[2]
    return seg, center, half, rot


@dataclass(frozen=True)
class ContactParts:
    """The elements of a performable spec (:func:`build_performable`) that simulation code refers
    to, as the spec's own element objects: the model compiled from the spec resolves them to ids
    (``mjcf.performable.ModelGeometry``), so no other module relies on how they are named."""

    root: mujoco.MjsBody  # the root segment's body (the pelvis)
    soles: tuple[mujoco.MjsGeom, ...]  # the box soles, right then left (``solver.motion.FEET``)
    floor: mujoco.MjsGeom | None  # the plane z = 0 when it is part of the ground
    treads: tuple[mujoco.MjsGeom, ...]  # the stairs' blocks of ground
    fall: tuple[mujoco.MjsGeom, ...]  # segment geoms (not the feet's) whose touching the ground is a fall
    inversion: tuple[mujoco.MjsJoint, ...]  # the feet's inversion hinges, right then left, when there are


def build_spec(character: Character, gravity: Sequence[float] = DEFAULT_GRAVITY,
               contacts: ContactOptions | None = None) -> mujoco.MjSpec:
    """The character's model; ``contacts`` turns it into a performable one (see
    :class:`ContactOptions`); without, geoms are visual only and nothing is actuated."""
    return _build(character, gravity, contacts)[0]


def _has_inversion(character: Character, segment: str, axis: np.ndarray) -> bool:
    """The foot segment already turns about the heel-toe line ``axis`` (body frame): one of its own
    hinges is within 30° of it (a capture's 3-DOF ankle, ``ankle_inversion_*``). A second hinge on the same
    body about the same axis through the same point makes the mass matrix singular."""
    seg = next(s for s in character.segments if s.name == segment)
    a = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    near = math.cos(math.radians(30.0))
    return any(d.kind == "hinge" and abs(float(np.dot(d.axis, a))) > near * float(np.linalg.norm(d.axis))
               for d in seg.dofs)


def build_performable(character: Character, gravity: Sequence[float],
                      contacts: ContactOptions) -> tuple[mujoco.MjSpec, ContactParts]:
    """The performable spec (:func:`build_spec` with ``contacts``) and its :class:`ContactParts`."""
    spec, parts = _build(character, gravity, contacts)
    assert parts is not None
    return spec, parts


def _build(character: Character, gravity: Sequence[float],
           contacts: ContactOptions | None) -> tuple[mujoco.MjSpec, ContactParts | None]:
    spec = mujoco.MjSpec()
    spec.modelname = character.name
    spec.compiler.degree = False
    spec.compiler.inertiafromgeom = mujoco.mjtInertiaFromGeom.mjINERTIAFROMGEOM_FALSE
    spec.option.gravity = list(map(float, gravity))
    spec.option.timestep = 1.0 / 240.0

    floor = spec.worldbody.add_geom(
        name="floor", type=mujoco.mjtGeom.mjGEOM_PLANE, size=[10.0, 10.0, 0.1], rgba=[0.8, 0.8, 0.8, 1.0]
    )
    floor.contype = 1
    floor.conaffinity = 1
    root_dofs = {d.name for d in character.segments[0].dofs} if contacts is not None else set()
    treads: list[mujoco.MjsGeom] = []
    fall: list[mujoco.MjsGeom] = []
    soles: list[mujoco.MjsGeom] = []
    inversion_joints: list[mujoco.MjsJoint] = []
    if contacts is not None:
        spec.option.timestep = float(contacts.timestep)
        spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
        spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
        spec.option.impratio = float(contacts.impratio)
        floor.contype, floor.conaffinity = _GROUND
        floor.friction = [float(contacts.friction), 0.005, 0.0001]
        if not contacts.floor:
            floor.contype = floor.conaffinity = 0
        for k, tr in enumerate(contacts.treads):
            g = spec.worldbody.add_geom(name=f"tread_{k}", type=mujoco.mjtGeom.mjGEOM_BOX, size=list(tr.half),
                                        pos=list(tr.center), rgba=[0.7, 0.7, 0.75, 1.0])
            g.quat = [float(np.cos(tr.yaw / 2)), 0.0, 0.0, float(np.sin(tr.yaw / 2))]
            g.contype, g.conaffinity = _GROUND
            g.friction = [float(contacts.friction), 0.005, 0.0001]
            treads.append(g)

    bodies: dict[str, mujoco.MjsBody] = {}
    # the feet and what hangs from them (toes) never count as a fall
    foot_segments = {f.segment for f in character.feet}
    for seg in character.segments:
        if seg.parent in foot_segments:
            foot_segments.add(seg.name)
    for seg in character.segments:
        parent = spec.worldbody if seg.parent is None else bodies[seg.parent]
        body = parent.add_body(name=seg.name, pos=seg.offset.tolist())
        if not np.allclose(seg.orientation, np.eye(3)):
            body.quat = _quat(seg.orientation).tolist()
        body.explicitinertial = True
        body.mass = float(seg.mass)
        body.ipos = seg.com.tolist()
        i = seg.inertia
        if np.allclose(i, np.diag(np.diag(i)), rtol=0, atol=1e-15):
            body.inertia = np.diag(i).tolist()
        else:
            body.fullinertia = [i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]]
        for d in seg.dofs:
            jt = mujoco.mjtJoint.mjJNT_HINGE if d.kind == "hinge" else mujoco.mjtJoint.mjJNT_SLIDE
            joint = body.add_joint(name=d.name, type=jt, axis=d.axis.tolist(), pos=[0.0, 0.0, 0.0])
            if contacts is None and np.isfinite(d.lower) and np.isfinite(d.upper):
                joint.range = [float(d.lower), float(d.upper)]
                joint.limited = mujoco.mjtLimited.mjLIMITED_TRUE
            else:
                joint.limited = mujoco.mjtLimited.mjLIMITED_FALSE
        if seg.length > 0 and seg.radius > 0:
            g = body.add_geom(
                name=f"{seg.name}_geom",
                type=mujoco.mjtGeom.mjGEOM_ELLIPSOID,
                size=[seg.radius, seg.radius, seg.length / 2.0],
                pos=(seg.direction * seg.length / 2.0).tolist(),
                quat=_quat_z_to(seg.direction).tolist(),
                rgba=[0.55, 0.65, 0.85, 1.0],
            )
            g.contype = 0
            g.conaffinity = 0
            if contacts is not None and seg.name not in foot_segments:
                g.contype, g.conaffinity = _BODY
                fall.append(g)
            g.mass = 0.0
        if seg.length > 0:
            body.add_site(name=f"{MARKER_PREFIX}{seg.name}", pos=seg.marker.tolist(), size=[0.008, 0, 0])
        bodies[seg.name] = body

    for foot in character.feet:
        g = bodies[foot.segment].add_geom(
            name=f"footbox_{foot.side}",
            type=mujoco.mjtGeom.mjGEOM_BOX,
            size=foot.half.tolist(),
            pos=foot.center.tolist(),
            rgba=[0.9, 0.5, 0.3, 0.3],
        )
        g.contype = 0
        g.conaffinity = 0
        g.mass = 0.0
    for c in character.contacts:
        bodies[c.segment].add_site(name=c.name, pos=c.position.tolist(), size=[0.01, 0, 0], rgba=[1, 0, 0, 1])
    if contacts is not None:
        for side, roll in zip(("right", "left"), contacts.sole_roll, strict=True):
            seg_name, center, half, rot = _sole_box(character, side, float(roll), contacts.sole_thickness,
                                                    contacts.sole_half_width)
            holder = bodies[seg_name]
            if contacts.inversion and not _has_inversion(character, seg_name, rot[:, 0]):
                inversion_joints.append(holder.add_joint(name=f"inversion_{side}", type=mujoco.mjtJoint.mjJNT_HINGE,
                                                         axis=rot[:, 0].tolist(), pos=[0.0, 0.0, 0.0]))
            g = holder.add_geom(name=f"sole_{side}", type=mujoco.mjtGeom.mjGEOM_BOX, size=half.tolist(),
                                pos=center.tolist(), quat=_quat(rot).tolist(), rgba=[0.3, 0.3, 0.3, 1.0])
            g.contype, g.conaffinity = _SOLE
            g.friction = [float(contacts.friction), float(contacts.torsional_friction), 0.0001]
            g.condim = 4 if contacts.torsional_friction > 0 else 3
            g.solref = list(map(float, contacts.solref))
            g.mass = 0.0
            soles.append(g)
        for joint in inversion_joints:
            a = spec.add_actuator(name=joint.name, target=joint.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
            a.gear = [1.0, 0, 0, 0, 0, 0]
            a.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
        for seg in character.segments:
            for d in seg.dofs:
                if d.name in root_dofs:
                    continue
                a = spec.add_actuator(name=d.name, target=d.name, trntype=mujoco.mjtTrn.mjTRN_JOINT)
                a.gear = [1.0, 0, 0, 0, 0, 0]
                a.ctrllimited = mujoco.mjtLimited.mjLIMITED_FALSE
    if contacts is None:
        return spec, None
    return spec, ContactParts(root=bodies[character.segments[0].name], soles=tuple(soles),
                              floor=floor if contacts.floor else None, treads=tuple(treads), fall=tuple(fall),
                              inversion=tuple(inversion_joints))


def compile_model(character: Character, gravity: Sequence[float] = DEFAULT_GRAVITY) -> mujoco.MjModel:
    return build_spec(character, gravity).compile()


def to_xml(character: Character, gravity: Sequence[float] = DEFAULT_GRAVITY,
           contacts: ContactOptions | None = None) -> str:
    spec = build_spec(character, gravity, contacts)
    spec.compile()
    return spec.to_xml()
