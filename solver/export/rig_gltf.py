"""glTF 2.0 of a motion on the input's own character or skeleton (``to_glb(motion, rig="source")``).

Public API::

    rig_glb(motion, *, meshes=True, world="gravity") -> bytes         # one animation: the motion
    rig_glb_library(items, *, meshes=True, world="gravity") -> bytes  # one animation per (name, motion)
    rig_gltf_embedded(motion, *, meshes=True, world="gravity") -> str # the .gltf JSON, buffer embedded

The motion is put on its source rig by :func:`solver.rig.retarget` (one gait cycle at the rig's
frame rate, feet planted by the leg IK) and written as one animation: per joint node a
``rotation`` channel (the local rotations as unit quaternions x, y, z, w), a ``translation``
channel for the skeleton's root joint and for every joint whose translation is not its node's
(a pelvis moved under a ``root``), ``LINEAR``, times from 0 to the cycle's duration. The
animation is named after the motion: ``tutor``, or the step with its target and λ
(``extrapolate slope_deg=10 lambda=1.0000``); its ``extras.motionx`` hold the step, λ, the
target and the frame rate.

- **A skinned glTF input** (rig format ``gltf``): the source file as it came in — meshes,
  skins, materials, textures, images, cameras, node names and rest TRS, the nodes above the
  skeleton (Mixamo's ``Armature``) — with its animations replaced by the new one (a joint node
  given by a ``matrix`` is written with the same transform as TRS, which an animated node needs).
- **A BVH or DeepMimic input** (no asset): a GLB of the rig's own skeleton — a node per joint
  with its rest offset (identity rest rotations: the BVH's zero pose, DeepMimic's reference
  pose), under a node ``rig`` that maps the input's axes and length unit onto glTF's (Y up,
  metres, the walk along +Z); with ``meshes``, one skinned mesh: per joint a tapered box from
  the joint to each child and End Site (BVH), or the character's own ``BodyDefs`` shapes
  (DeepMimic: box, sphere, capsule, cylinder at their attach frames, in their colours).

The root is placed in the export's world (``world``, :mod:`solver.export.world`: by default
gravity points down and a slope walk climbs its ramp), and with ``meshes`` the ground the walk
stands on is a node ``ground`` at the scene root (one child per animation in a library).
"""

from __future__ import annotations

import base64
import json
import math
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from solver.export import DEFAULT_WORLD, Y_UP, ExportError, _check_motion, continuous_quaternions
from solver.export import source_rig as _source_rig
from solver.export.gltf_parts import (
    ARRAY_BUFFER,
    ELEMENT_ARRAY_BUFFER,
    FLOAT,
    GROUND_MATERIAL,
    TRIANGLES,
    UNSIGNED_BYTE,
    UNSIGNED_INT,
    UNSIGNED_SHORT,
    Buffer,
    ellipsoid_mesh,
    glb,
    ground_nodes,
    hexahedron,
)
from solver.export.world import check_world, ground_of_motion, world_rig_pose
from solver.motion import Motion
from solver.rig import RIG_FORMATS, RigError, RigPose, SkeletonRig, retarget

__all__ = ["rig_glb", "rig_glb_library", "rig_gltf_embedded"]

#: a translation channel is written for a joint whose translation differs from its node's by
#: more than this fraction of the skeleton's size
_MOVED = 1e-6


def source_rig(motion: Motion) -> SkeletonRig:
    """The motion's source rig (``motion.context.rig``); an :class:`ExportError` saying why not."""
    return _source_rig(motion, RIG_FORMATS,
                       "rig=source needs a motion made from a skinned glTF, BVH or DeepMimic input")


def animation_name(motion: Motion) -> str:
    """``tutor``, or the step with its target and λ (``extrapolate slope_deg=10 lambda=1.0000``)."""
    prov = motion.provenance
    step = str(prov.get("step") or "motion")
    if step in ("tutor", "capture", "simplify"):
        return step
    parts = [step]
    target = prov.get("target")
    if isinstance(target, Mapping):
        parts += [f"{k}={v:g}" if isinstance(v, (int, float)) else f"{k}={v}" for k, v in target.items()
                  if v is not None and not isinstance(v, (Mapping, list))]
    lam = prov.get("lambda")
    if isinstance(lam, (int, float)) and not isinstance(lam, bool):
        parts.append(f"lambda={lam:.4f}")
    return " ".join(parts)


def _quats(local: np.ndarray) -> np.ndarray:
    """(F, 3, 3) -> (F, 4) unit quaternions x, y, z, w, continuous in time."""
    q = Rotation.from_matrix(local).as_quat()
    q = continuous_quaternions(q)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def _poses(items: Sequence[tuple[str, Motion]], world: str) -> tuple[SkeletonRig, list[tuple[str, Motion, RigPose]]]:
    if not items:
        raise ExportError("a rig GLB needs at least one motion")
    names = [n for n, _ in items]
    if len(set(names)) != len(names) or not all(isinstance(n, str) and n for n in names):
        raise ExportError("animation names must be distinct non-empty strings")
    rigs: list[SkeletonRig] = []
    out = []
    for name, m in items:
        _check_motion(m)
        rig = source_rig(m)
        if rigs and not _same_rig(rigs[0], rig):
            raise ExportError(f"{name!r} is on another source rig than {names[0]!r}: one GLB holds one character")
        rigs.append(rig)
        try:
            out.append((name, m, world_rig_pose(m, world, rig, retarget(m, rig))))
        except RigError as e:
            raise ExportError(f"{name}: {e}") from None
    return rigs[0], out


def _same_rig(a: SkeletonRig, b: SkeletonRig) -> bool:
    return (a.format == b.format and a.names == b.names and a.parents == b.parents
            and np.allclose(a.offsets, b.offsets) and a.extra.get("asset") == b.extra.get("asset"))


def _translations(rig: SkeletonRig, pose: RigPose) -> np.ndarray:
    """(F, J, 3) each joint's translation in its parent's frame (the root's: ``pose.root``), input units."""
    F = pose.times.size
    if pose.positions is not None:
        t = np.array(pose.positions, dtype=float)
    else:
        t = np.broadcast_to(rig.offsets, (F, rig.J, 3)).copy()
    t[:, 0] = pose.root
    return t


def _motion_extras(motion: Motion, rig: SkeletonRig, pose: RigPose) -> dict[str, Any]:
    prov = motion.provenance
    out: dict[str, Any] = {"step": prov.get("step"), "fps": float(1.0 / (pose.times[1] - pose.times[0])),
                           "frames": int(pose.times.size), "cycle_duration_s": float(pose.times[-1]),
                           "source_rig": rig.format}
    for key in ("lambda", "target"):
        if key in prov:
            out[key] = prov[key]
    return json.loads(json.dumps(out, allow_nan=False, default=str))


def _animation(buf: Buffer, name: str, motion: Motion, rig: SkeletonRig, pose: RigPose, nodes: Sequence[int],
               rest_translation: np.ndarray, to_node: np.ndarray) -> dict[str, Any]:
    """One animation: rotation channels for every joint node, translation channels for the root
    and the joints whose translation is not their node's. ``to_node`` (J,): input units per node
    unit of each joint's translation (the parent's accumulated scale)."""
    t_acc = buf.add(pose.times, FLOAT, "SCALAR", minmax=True)
    trans = _translations(rig, pose) / to_node[None, :, None]
    size = float(np.max(np.abs(rest_translation))) or 1.0
    samplers: list[dict] = []
    channels: list[dict] = []
    for j, node in enumerate(nodes):
        out = buf.add(_quats(pose.local[:, j]), FLOAT, "VEC4")
        samplers.append({"input": t_acc, "output": out, "interpolation": "LINEAR"})
        channels.append({"sampler": len(samplers) - 1, "target": {"node": int(node), "path": "rotation"}})
        if j == 0 or np.max(np.abs(trans[:, j] - rest_translation[j])) > _MOVED * size:
            out = buf.add(trans[:, j], FLOAT, "VEC3")
            samplers.append({"input": t_acc, "output": out, "interpolation": "LINEAR"})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": int(node), "path": "translation"}})
    return {"name": name, "samplers": samplers, "channels": channels,
            "extras": {"motionx": _motion_extras(motion, rig, pose)}}


# --- a skinned glTF input -------------------------------------------------------------------------

def _source_document(rig: SkeletonRig, poses: list[tuple[str, Motion, RigPose]], meshes: bool,
                     world: str) -> tuple[dict, bytes]:
    from solver.io.gltf import GltfError, parse_gltf
    from solver.io.gltf.nodes import _matrix, node_parents, node_trs

    try:
        asset = parse_gltf(base64.b64decode(str(rig.extra["asset"])), "the source glTF")
        nodes = [int(n) for n in rig.extra["nodes"]]
        scales = np.asarray(rig.extra.get("scales", np.ones(rig.J)), dtype=float)
    except (KeyError, TypeError, ValueError, GltfError) as e:
        raise ExportError(f"the motion's source glTF rig is unreadable ({e})") from None
    doc = asset.doc
    if len(nodes) != rig.J or scales.shape != (rig.J,) or not all(0 <= n < len(doc.get("nodes", [])) for n in nodes):
        raise ExportError("the motion's source glTF rig does not match its asset")
    to_node = np.array([scales[p] if p >= 0 else 1.0 for p in rig.parents])
    rest = np.empty((rig.J, 3))
    for j, n in enumerate(nodes):
        node = doc["nodes"][n]
        t, q, s = node_trs(node, "the source glTF", n)
        if "matrix" in node:  # an animated node is given by TRS
            del node["matrix"]
            node.update(translation=t.tolist(), rotation=q.tolist(), scale=s.tolist())
        rest[j] = t
    buf = Buffer(data=bytearray(asset.bin), views=doc.setdefault("bufferViews", []),
                  accessors=doc.setdefault("accessors", []))
    doc["animations"] = [_animation(buf, name, m, rig, pose, nodes, rest, to_node) for name, m, pose in poses]
    if meshes:  # the ground, in the scene: the nodes above the skeleton (at rest) after the input's frame
        above = np.eye(4)
        parent = node_parents(doc, "the source glTF")
        p = parent[nodes[0]]
        while p >= 0:
            above = _matrix(*node_trs(doc["nodes"][p], "the source glTF", p)) @ above
            p = parent[p]
        _add_ground(doc, buf, poses, above @ _input_matrix(poses[0][1]), world)
    while len(buf.data) % 4:
        buf.data.append(0)
    doc["buffers"] = [{"byteLength": len(buf.data)}]
    return doc, bytes(buf.data)


def _input_matrix(motion: Motion) -> np.ndarray:
    """(4x4) our world (metres) -> the input's axes and units (the motion's ``GroundFrame``; a
    moving frame, a treadmill's, at time 0)."""

    frame = motion.frame
    m = np.eye(4)
    m[:3, :3] = frame.R / frame.unit_m
    m[:3, 3] = frame.offset / frame.unit_m
    return m


def _add_ground(doc: dict[str, Any], buf: Buffer, poses: list[tuple[str, Motion, RigPose]], to_scene: np.ndarray,
                world: str) -> None:
    """The motions' ground (``solver.export.gltf_parts.ground_nodes``) at the root of the document's scene."""
    materials = doc.setdefault("materials", [])
    materials.append(dict(GROUND_MATERIAL))
    meshes = doc.setdefault("meshes", [])
    grounds = [(name, ground_of_motion(m, world)) for name, m, _ in poses]
    node = ground_nodes(buf, grounds, to_scene, len(materials) - 1, meshes, doc["nodes"])
    scenes = doc.setdefault("scenes", [{"nodes": []}])
    scenes[int(doc.get("scene", 0))].setdefault("nodes", []).append(node)


# --- a BVH or DeepMimic input: the rig's own skeleton ---------------------------------------------

def _tapered_box(a: np.ndarray, b: np.ndarray, w0: float, w1: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A box from a to b, square sections of side w0 at a and w1 at b (flat-shaded)."""
    u = (b - a) / np.linalg.norm(b - a)
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    v = ref - (ref @ u) * u
    v /= np.linalg.norm(v)
    w = np.cross(u, v)
    corners = [(-1, -1), (1, -1), (1, 1), (-1, 1)]
    bottom = np.array([a + 0.5 * w0 * (x * v + y * w) for x, y in corners])
    top = np.array([b + 0.5 * w1 * (x * v + y * w) for x, y in corners])
    return hexahedron(np.vstack([bottom, top]))


def capsule_mesh(radius: float, height: float, rings: int = 6, sectors: int = 12
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A capsule along Y centred at the origin: a cylinder of ``height`` between two hemispheres
    of ``radius`` (DeepMimic's capsule; ``height`` 0 gives a sphere)."""
    rows = []
    for i in range(rings, -1, -1):  # the lower cap, from its pole
        phi = 0.5 * math.pi * i / rings
        rows.append((-0.5 * height - radius * math.sin(phi), radius * math.cos(phi), -math.sin(phi), math.cos(phi)))
    for i in range(rings + 1):
        phi = 0.5 * math.pi * i / rings
        rows.append((0.5 * height + radius * math.sin(phi), radius * math.cos(phi), math.sin(phi), math.cos(phi)))
    verts, norms = [], []
    for y, r, ny, nr in rows:
        for j in range(sectors):
            th = 2 * math.pi * j / sectors
            verts.append((r * math.cos(th), y, r * math.sin(th)))
            norms.append((nr * math.cos(th), ny, nr * math.sin(th)))
    tris = []
    for i in range(len(rows) - 1):
        for j in range(sectors):
            a, b = i * sectors + j, i * sectors + (j + 1) % sectors
            c, d = (i + 1) * sectors + j, (i + 1) * sectors + (j + 1) % sectors
            tris += [(a, c, d), (a, d, b)]
    V, N, T = np.array(verts), np.array(norms), np.array(tris)
    p0, p1, p2 = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
    cr = np.cross(p1 - p0, p2 - p0)
    keep = np.linalg.norm(cr, axis=1) > 1e-12 * max(radius, height, 1e-9) ** 2
    inward = np.einsum("ij,ij->i", cr, N[T[:, 0]] + N[T[:, 1]] + N[T[:, 2]]) < 0
    T[inward] = T[inward][:, [0, 2, 1]]
    N = N / np.linalg.norm(N, axis=1, keepdims=True)
    return V, N, T[keep]


def _cylinder_mesh(radius: float, height: float, sectors: int = 12) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A closed cylinder along Y centred at the origin (flat caps)."""
    verts: list[tuple[float, float, float]] = []
    norms: list[tuple[float, float, float]] = []
    tris: list[tuple[int, int, int]] = []
    for y in (-0.5 * height, 0.5 * height):
        for j in range(sectors):
            th = 2 * math.pi * j / sectors
            verts.append((radius * math.cos(th), y, radius * math.sin(th)))
            norms.append((math.cos(th), 0.0, math.sin(th)))
    for j in range(sectors):
        a, b, c, d = j, (j + 1) % sectors, sectors + j, sectors + (j + 1) % sectors
        tris += [(a, c, d), (a, d, b)]
    for sgn in (-1.0, 1.0):
        k = len(verts)
        verts.append((0.0, sgn * 0.5 * height, 0.0))
        norms.append((0.0, sgn, 0.0))
        ring = []
        for j in range(sectors):
            th = 2 * math.pi * j / sectors
            ring.append(len(verts))
            verts.append((radius * math.cos(th), sgn * 0.5 * height, radius * math.sin(th)))
            norms.append((0.0, sgn, 0.0))
        for j in range(sectors):
            tris.append((k, ring[j], ring[(j + 1) % sectors]))
    V, N, T = np.array(verts), np.array(norms), np.array(tris)
    p0, p1, p2 = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
    centroid = (p0 + p1 + p2) / 3.0
    inward = np.einsum("ij,ij->i", np.cross(p1 - p0, p2 - p0), centroid) < 0
    T[inward] = T[inward][:, [0, 2, 1]]
    return V, N, T


def _body_shape(body: Mapping[str, Any]) -> tuple[np.ndarray, np.ndarray, np.ndarray] | None:
    """A DeepMimic ``BodyDefs`` entry's shape in its joint's frame (metres), or None."""
    try:
        shape = str(body.get("Shape", "")).lower()
        p = [float(body.get(f"Param{k}", 0.0)) for k in range(3)]
        at = np.array([float(body.get(f"Attach{a}", 0.0)) for a in "XYZ"])
        theta = [float(body.get(f"AttachTheta{a}", 0.0)) for a in "XYZ"]
    except (TypeError, ValueError):
        return None
    if shape == "box" and min(p) > 0:
        c = np.array([[x, y, z] for z in (-1, 1) for x, y in ((-1, -1), (1, -1), (1, 1), (-1, 1))]) * 0.5 * np.array(p)
        V, N, T = hexahedron(c)
    elif shape == "sphere" and p[0] > 0:
        V, N, T = ellipsoid_mesh(np.zeros(3), np.array([0.0, 1.0, 0.0]), 0.5 * p[0], 0.5 * p[0])
    elif shape == "capsule" and p[0] > 0:
        V, N, T = capsule_mesh(0.5 * p[0], max(p[1], 0.0))
    elif shape == "cylinder" and p[0] > 0 and p[1] > 0:
        V, N, T = _cylinder_mesh(0.5 * p[0], p[1])
    else:
        return None
    R = Rotation.from_euler("XYZ", theta).as_matrix()  # DeepMimic: R = Rx Ry Rz
    return V @ R.T + at, N @ R.T, T


def _skeleton_document(rig: SkeletonRig, poses: list[tuple[str, Motion, RigPose]], meshes: bool,
                       frame: Any, in_world: str) -> tuple[dict, bytes]:
    J = rig.J
    buf = Buffer()
    children: dict[int, list[int]] = {j: [] for j in range(J)}
    for j, p in enumerate(rig.parents):
        if p >= 0:
            children[p].append(j)
    # the "rig" node: input axes and unit -> glTF (Y up, metres; our X forward -> glTF +Z)
    Q = Y_UP @ frame.R.T
    unit = float(frame.unit_m)
    top = np.eye(4)
    top[:3, :3] = Q * unit
    top[:3, 3] = -Q @ frame.offset
    rig_node = 0
    joint_node = [1 + j for j in range(J)]
    nodes: list[dict] = [{"name": "rig", "translation": [float(x) for x in top[:3, 3]],
                          "rotation": [float(x) for x in Rotation.from_matrix(Q).as_quat()],
                          "scale": [unit] * 3, "children": [joint_node[0]]}]
    rest = np.array(rig.offsets, dtype=float)
    rest[0] = poses[0][2].root[0]  # the root at rest where the first animation starts
    world = np.empty((J, 4, 4))
    for j in range(J):
        m = np.eye(4)
        m[:3, 3] = rest[j]
        world[j] = (top if rig.parents[j] < 0 else world[rig.parents[j]]) @ m
        node: dict[str, Any] = {"name": rig.names[j], "translation": [float(x) for x in rest[j]]}
        if children[j]:
            node["children"] = [joint_node[c] for c in children[j]]
        nodes.append(node)
    scene_nodes = [rig_node]
    doc: dict[str, Any] = {"asset": {"version": "2.0", "generator": "motionx",
                                     "extras": {"source_rig": rig.format, "units_m": unit, "axes": frame.axes}},
                           "scene": 0, "nodes": nodes}
    if meshes:
        prims = _skeleton_primitives(rig, world, children, buf)
        if prims:
            ibm = np.linalg.inv(world)
            ibm[:, 3, :] = [0.0, 0.0, 0.0, 1.0]
            ibm_acc = buf.add(np.transpose(ibm, (0, 2, 1)).reshape(J, 16), FLOAT, "MAT4")
            doc["skins"] = [{"name": "rig", "joints": joint_node, "inverseBindMatrices": ibm_acc,
                             "skeleton": joint_node[0]}]
            doc["meshes"] = [{"name": "rig", "primitives": [p for p, _ in prims]}]
            doc["materials"] = [{"name": f"colour {k}", "pbrMetallicRoughness": {
                "baseColorFactor": c, "metallicFactor": 0.0, "roughnessFactor": 0.8}} for k, (_, c) in enumerate(prims)]
            for k, (prim, _) in enumerate(prims):
                prim["material"] = k
            nodes.append({"name": "rig_mesh", "mesh": 0, "skin": 0})
            scene_nodes.append(len(nodes) - 1)
    doc["scenes"] = [{"name": "rig", "nodes": scene_nodes}]
    to_node = np.ones(J)
    doc["animations"] = [_animation(buf, name, m, rig, pose, joint_node, rest, to_node) for name, m, pose in poses]
    if meshes:  # the "rig" node maps the input onto Y_UP · our world
        to_scene = np.eye(4)
        to_scene[:3, :3] = Y_UP
        _add_ground(doc, buf, poses, to_scene, in_world)
    while len(buf.data) % 4:
        buf.data.append(0)
    doc.update(buffers=[{"byteLength": len(buf.data)}], bufferViews=buf.views, accessors=buf.accessors)
    return doc, bytes(buf.data)


def _skeleton_primitives(rig: SkeletonRig, world: np.ndarray, children: Mapping[int, list[int]],
                         buf: Buffer) -> list[tuple[dict, list[float]]]:
    """Mesh primitives (one per colour) of the rig's bones, in the bind pose (scene metres),
    each vertex bound to its joint."""
    J = rig.J
    groups: dict[tuple[float, ...], list[tuple[np.ndarray, np.ndarray, np.ndarray, int]]] = {}
    scale_m = float(np.linalg.norm(world[0, :3, 0]))  # metres per input unit
    bodies = rig.extra.get("body_defs") if rig.format == "deepmimic" else None
    for j in range(J):
        pieces: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        colour: list[float] = [0.75, 0.75, 0.78, 1.0]
        if isinstance(bodies, Mapping):
            body = bodies.get(rig.names[j])
            if isinstance(body, Mapping):
                shape = _body_shape(body)
                if shape is not None:
                    pieces.append(shape)
                    try:
                        colour = [float(body.get(k, d)) for k, d in (("ColorR", 0.75), ("ColorG", 0.75),
                                                                     ("ColorB", 0.78), ("ColorA", 1.0))]
                    except (TypeError, ValueError):
                        pass
        else:
            tips = [rig.offsets[c] for c in children[j]]
            if j in rig.end_sites:
                tips.append(np.asarray(rig.end_sites[j], dtype=float))
            for tip in tips:
                L = float(np.linalg.norm(tip) * scale_m)
                if L < 0.01:
                    continue
                w0 = min(max(0.16 * L, 0.012), 0.07) / scale_m
                pieces.append(_tapered_box(np.zeros(3), np.asarray(tip, dtype=float), w0, 0.55 * w0))
        for V, N, T in pieces:
            Vw = V @ world[j, :3, :3].T + world[j, :3, 3]
            Nw = N @ world[j, :3, :3].T
            Nw /= np.linalg.norm(Nw, axis=1, keepdims=True)
            groups.setdefault(tuple(min(max(c, 0.0), 1.0) for c in colour), []).append((Vw, Nw, T, j))
    prims: list[tuple[dict, list[float]]] = []
    joint_type = UNSIGNED_BYTE if J <= 256 else UNSIGNED_SHORT
    for rgba, parts in groups.items():
        V = np.concatenate([p[0] for p in parts])
        N = np.concatenate([p[1] for p in parts])
        offsets = np.cumsum([0] + [p[0].shape[0] for p in parts[:-1]])
        T = np.concatenate([p[2] + o for p, o in zip(parts, offsets)])
        joints = np.zeros((V.shape[0], 4))
        joints[:, 0] = np.concatenate([np.full(p[0].shape[0], p[3]) for p in parts])
        weights = np.zeros((V.shape[0], 4))
        weights[:, 0] = 1.0
        itype = UNSIGNED_SHORT if V.shape[0] < 65536 else UNSIGNED_INT
        prims.append(({"attributes": {"POSITION": buf.add(V, FLOAT, "VEC3", ARRAY_BUFFER, minmax=True),
                                      "NORMAL": buf.add(N, FLOAT, "VEC3", ARRAY_BUFFER),
                                      "JOINTS_0": buf.add(joints, joint_type, "VEC4", ARRAY_BUFFER),
                                      "WEIGHTS_0": buf.add(weights, FLOAT, "VEC4", ARRAY_BUFFER)},
                       "indices": buf.add(T.reshape(-1), itype, "SCALAR", ELEMENT_ARRAY_BUFFER),
                       "mode": TRIANGLES}, list(rgba)))
    return prims


# --- the front ------------------------------------------------------------------------------------

def _opensim_document(items: Sequence[tuple[str, Motion]], meshes: bool, world: str) -> tuple[dict, bytes]:
    """A motion made from an OpenSim trial on its model's bodies (a look at it: the web page's
    preview): a joint per body under the "rig" node, each body a tapered box from its origin to
    each child body's (a leaf body: to twice its centre of mass), one gait cycle at 30 frames/s
    (:func:`solver.export.opensim.model_bodies`), where gravity points down."""
    from solver.export.opensim import PREVIEW_RATE, OpenSimExportError, model_bodies

    if world != DEFAULT_WORLD:
        raise ExportError(f"the OpenSim model is written where gravity points down (world={DEFAULT_WORLD!r})")
    poses: list[tuple[str, Motion, RigPose]] = []
    rig = None
    for name, m in items:
        _check_motion(m)
        try:
            mb = model_bodies(m)
        except OpenSimExportError as e:
            raise ExportError(str(e)) from None
        bodies, parents = mb["bodies"], mb["parents"]
        order: list[int] = []
        frontier = [i for i, b in enumerate(bodies) if parents.get(b) not in bodies]
        while frontier:  # parents first
            order += frontier
            frontier = [i for i, b in enumerate(bodies) if parents.get(b) in {bodies[k] for k in frontier}]
        if len(order) != len(bodies) or sum(parents.get(bodies[i]) not in bodies for i in order) != 1:
            raise ExportError("the OpenSim model's bodies do not form one tree under the ground")
        idx = {bodies[i]: k for k, i in enumerate(order)}
        par = tuple(idx.get(parents.get(bodies[i]), -1) for i in order)
        R, P = mb["R"][:, order], mb["P"][:, order]
        Rp, Pp = mb["posture"][0][order], mb["posture"][1][order]
        J, F = len(order), R.shape[0]
        offsets = np.array([Rp[p].T @ (Pp[j] - Pp[p]) if p >= 0 else np.zeros(3) for j, p in enumerate(par)])
        local = np.empty_like(R)
        positions = np.zeros((F, J, 3))
        for j, p in enumerate(par):
            local[:, j] = R[:, j] if p < 0 else np.einsum("fji,fjk->fik", R[:, p], R[:, j])
            if p >= 0:
                positions[:, j] = np.einsum("fji,fj->fi", R[:, p], P[:, j] - P[:, p])
        com = mb["com"][order]
        leaves = {j: 2.0 * com[j] for j in range(J) if j not in par and np.linalg.norm(com[j]) > 0}
        # the model's bodies as a skeleton, for the glTF writer
        this = SkeletonRig("opensim", tuple(bodies[i] for i in order), par, offsets,
                           tuple(("Xposition", "Yposition", "Zposition", "quaternion") for _ in range(J)), {},
                           mb["times"], local, P[:, 0], mb["frame"], end_sites=leaves,
                           extra={"frame_time": 1.0 / PREVIEW_RATE})
        rig = rig or this
        if this.names != rig.names:
            raise ExportError(f"{name!r} is on another OpenSim model than {items[0][0]!r}: one GLB holds one model")
        poses.append((name, m, RigPose(mb["times"], local, P[:, 0], positions, mb["times"],
                                       np.full((F, 2, 3), np.nan), ())))
    assert rig is not None
    return _skeleton_document(rig, poses, meshes, rig.frame, world)


def _is_opensim(motion: Motion) -> bool:
    rig = motion.context.rig
    return rig is not None and rig.format == "opensim"


def _document(items: Sequence[tuple[str, Motion]], meshes: bool, world: str) -> tuple[dict, bytes]:
    if not isinstance(meshes, bool):
        raise ExportError(f"meshes must be a boolean, got {meshes!r}")
    check_world(world)
    if items and all(_is_opensim(m) for _, m in items):
        return _opensim_document(items, meshes, world)
    rig, poses = _poses(items, world)
    if rig.format == "gltf":
        return _source_document(rig, poses, meshes, world)

    frame = poses[0][1].frame
    return _skeleton_document(rig, poses, meshes, frame, world)


def rig_glb(motion: Motion, *, meshes: bool = True, world: str = DEFAULT_WORLD) -> bytes:
    """GLB of ``motion`` on its source rig (see the module doc): the input glTF character with
    the motion as its one animation, or the BVH / DeepMimic skeleton (``meshes``: with its bone
    shapes) animated; in ``world``, with its ground when ``meshes``."""
    _check_motion(motion)
    return glb(*_document([(animation_name(motion), motion)], meshes, world))


def rig_glb_library(items: Sequence[tuple[str, Motion]], *, meshes: bool = True, world: str = DEFAULT_WORLD) -> bytes:
    """One GLB of the source character with one animation per (name, motion) — e.g. a library's
    λ optima, one per cell. Every motion must come from the same input rig."""
    if isinstance(items, (str, bytes)) or not isinstance(items, Sequence):
        raise ExportError("items must be a sequence of (name, motion) pairs")
    return glb(*_document(list(items), meshes, world))


def rig_gltf_embedded(motion: Motion, *, meshes: bool = True, world: str = DEFAULT_WORLD) -> str:
    """The ``.gltf`` JSON of :func:`rig_glb` with its buffer embedded as a base64 data URI."""
    _check_motion(motion)
    doc, data = _document([(animation_name(motion), motion)], meshes, world)
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data).decode("ascii")
    return json.dumps(doc, allow_nan=False, separators=(",", ":"), ensure_ascii=False)
