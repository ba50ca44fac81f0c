"""Generate a MuJoCo model from a character with ``mujoco.MjSpec`` (no string templates).

One MuJoCo body per segment, its 1-DOF joints in order inside that body (MuJoCo applies
a body's joints sequentially, exactly like our chains of massless bodies), so MuJoCo's
joints map 1:1 to the character's coordinates and carry the same names. Inertial data
are explicit (mass, centre of mass, full inertia); geoms are visual only (no contacts).

MuJoCo's XML writer prints 6 significant digits; exact comparisons therefore use the
model compiled in memory (:func:`compile_model`), and the XML is for viewing/exchange.
"""

from __future__ import annotations

from collections.abc import Sequence

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


def build_spec(character: Character, gravity: Sequence[float] = DEFAULT_GRAVITY) -> mujoco.MjSpec:
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

    bodies: dict[str, mujoco.MjsBody] = {}
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
            if np.isfinite(d.lower) and np.isfinite(d.upper):
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
    return spec


def compile_model(character: Character, gravity: Sequence[float] = DEFAULT_GRAVITY) -> mujoco.MjModel:
    return build_spec(character, gravity).compile()


def to_xml(character: Character, gravity: Sequence[float] = DEFAULT_GRAVITY) -> str:
    spec = build_spec(character, gravity)
    spec.compile()
    return spec.to_xml()
