"""glTF 2.0 export: a skinned, animated character (``.glb`` binary, the default, or ``.gltf``
with an embedded base64 buffer: ``to_gltf(motion, binary=False)``).

- one node per segment, node i = segment i (``character.segments`` order), holding the
  segment's rest transform (translation = rest offset, rotation = rest orientation);
- one skin whose joints are the segment nodes, with inverse bind matrices of the rest
  pose (q = 0, the pose the node transforms describe), present with the meshes;
- one mesh per segment with a non-degenerate ellipsoid (polar semi-axis half the bone
  length along the bone ``direction``, equatorial semi-axis the segment's ``radius``),
  every vertex skinned with weight 1 to its segment, instantiated by a node at the scene
  root that uses the skin;
- one animation: a rotation channel per segment that has hinges and a translation
  channel for the root (and any segment with slides), sampled at the motion's fps,
  LINEAR interpolation;
- with the meshes, the ground the walk stands on (:mod:`solver.export.world`): a node
  ``ground`` at the scene root holding its mesh (a strip along the path, a ramp on a slope,
  treads and risers on stairs), its description in the node's ``extras``.

The motion is written in a *world* (``world="gravity"``, the default: gravity points down and
a slope is a ramp; ``"ground"``: the solver's frame, level ground and tilted gravity).

Axes: glTF is Y up, +Z forward, +X left, metres. The *data* are converted (no extra
root node): every vector v becomes ``Y_UP @ v`` and every rotation R ``Y_UP R Y_UPᵀ``,
so each node's local axes are the glTF axes at rest. World positions in the file are
therefore ``Y_UP @`` our world positions: x_gltf = y, y_gltf = z, z_gltf = x.
"""

from __future__ import annotations

import base64
import json
import logging
from typing import Any

import numpy as np

from solver.export import (
    AXES_Y_UP,
    AXES_Z_UP,
    Y_UP,
    ExportError,
    _check_motion,
    change_axes,
    continuous_quaternions,
    game,
    matrix_to_quaternion,
)
from solver.export.gltf_parts import (
    ARRAY_BUFFER,
    ELEMENT_ARRAY_BUFFER,
    FLOAT,
    GROUND_MATERIAL,
    TRIANGLES,
    UNSIGNED_BYTE,
    UNSIGNED_SHORT,
    Buffer,
    ellipsoid_mesh,
    glb,
    ground_nodes,
    hexahedron,
)
from solver.export.rig_gltf import rig_glb, rig_gltf_embedded
from solver.export.world import DEFAULT_WORLD, check_world, ground_of_motion, world_of, world_transforms
from solver.motion import Motion

log = logging.getLogger(__name__)


def _trs_matrix(rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rot
    m[:3, 3] = pos
    return m


def sole_mesh(bottom: np.ndarray, top: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A shoe-like convex hexahedron (flat-shaded: vertices (24, 3), normals, triangles (12, 3))
    from its bottom and top faces, four corners each ordered (heel-right, heel-left,
    toe-right, toe-left)."""
    return hexahedron(np.vstack([bottom, top]),  # 0-3 bottom, 4-7 top
                      [(0, 2, 3, 1), (4, 5, 7, 6), (0, 1, 5, 4), (2, 6, 7, 3), (0, 4, 6, 2), (1, 3, 7, 5)])


def foot_shape(character, side: str) -> tuple[np.ndarray, np.ndarray]:
    """The drawn foot of a side (foot segment frame): its sole is the rectangle through the heel
    and toe contact points as wide as the foot box (``Character.sole``, ``solver.kinematics.sole_corners``: the foot
    stands on the ground where its contact points do), its top the foot box's top face.
    Returns (bottom (4, 3), top (4, 3)), corners (heel-right, heel-left, toe-right, toe-left)."""
    foot = character.foot(side)
    sole = character.sole(side)
    heel, toe = sole.heel, sole.toe
    w = float(foot.half[1])
    lo_x, hi_x = float(foot.center[0] - foot.half[0]), float(foot.center[0] + foot.half[0])
    top_z = float(foot.center[2] + foot.half[2])
    bottom, top = [], []
    for c, x_top in ((heel, lo_x), (toe, hi_x)):
        for sgn in (-1.0, 1.0):
            bottom.append(np.asarray(c.position) + np.array([0.0, sgn * w, 0.0]))
            top.append(np.array([x_top, float(c.position[1]) + sgn * w, top_z]))
    return np.array(bottom), np.array(top)


def _animation(buf: Buffer, motion: Motion, name: str, *, loop: bool = False, world: str = DEFAULT_WORLD) -> dict:
    """One animation of ``motion`` (frames 0 … P, one cycle, with ``loop``; else every frame) in
    ``world``, with the game-ready data (:mod:`solver.export.game`, Y up) and the world in its
    ``extras``."""

    S = len(motion.character.segments)
    w = world_of(motion, world)
    extras: dict[str, Any] = {}
    frames = motion.T
    if game.has_free_root(motion):
        if loop:
            frames = game.loop_frames(motion) + 1
        extras = game.game_json(motion, axes=Y_UP, frames=frames, world=w)
    lt = world_transforms(motion, w, frames)
    rot, pos = change_axes(lt.rot, lt.pos, True)
    quat = continuous_quaternions(matrix_to_quaternion(rot))  # (S, T, 4)
    times = np.arange(frames, dtype=float) / float(motion.fps)
    t_acc = buf.add(times, FLOAT, "SCALAR", minmax=True)
    samplers: list[dict] = []
    channels: list[dict] = []
    for i in range(S):
        if lt.moving_rot[i]:
            out = buf.add(quat[i], FLOAT, "VEC4", minmax=True)
            samplers.append({"input": t_acc, "output": out, "interpolation": "LINEAR"})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": i, "path": "rotation"}})
        if i == 0 or lt.moving_pos[i]:
            out = buf.add(pos[i], FLOAT, "VEC3", minmax=True)
            samplers.append({"input": t_acc, "output": out, "interpolation": "LINEAR"})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": i, "path": "translation"}})
    anim: dict[str, Any] = {"name": name, "samplers": samplers, "channels": channels}
    if extras:
        extras["frames_in_animation"] = frames
    extras["world"] = w.to_json(Y_UP)
    anim["extras"] = extras
    return anim


def _check_flag(name: str, value: Any) -> None:
    if not isinstance(value, bool):
        raise ExportError(f"{name} must be a boolean, got {value!r}")


def _document(motion: Motion, meshes: bool, loop: bool = False,
              clips: list[tuple[str, Motion]] | None = None, world: str = DEFAULT_WORLD) -> tuple[dict, bytes]:
    """The glTF document and its buffer: the skeleton of ``motion`` and its animation, or (with
    ``clips``) one named animation per (name, motion), all of ``motion``'s character, in
    ``world``; with ``meshes`` the ground of each beside them."""
    _check_motion(motion)
    _check_flag("meshes", meshes)
    _check_flag("loop", loop)
    check_world(world)
    ch = motion.character
    segs = ch.segments
    S, T = len(segs), motion.T
    index = {s.name: i for i, s in enumerate(segs)}
    parents = [index[s.parent] if s.parent is not None else -1 for s in segs]
    buf = Buffer()

    # rest transforms (Y-up) and bind pose
    rest_rot, rest_pos = change_axes(
        np.array([s.orientation for s in segs]), np.array([s.offset for s in segs]), True
    )
    rest_quat = matrix_to_quaternion(rest_rot)
    bind = np.empty((S, 4, 4))
    for i in range(S):
        local = _trs_matrix(rest_rot[i], rest_pos[i])
        bind[i] = local if parents[i] < 0 else bind[parents[i]] @ local
    nodes: list[dict] = []
    for i, s in enumerate(segs):
        node: dict[str, Any] = {"name": s.name}
        if np.any(rest_pos[i]):
            node["translation"] = [float(x) for x in rest_pos[i]]
        if not np.array_equal(rest_quat[i], [0.0, 0.0, 0.0, 1.0]):
            node["rotation"] = [float(x) for x in rest_quat[i]]
        children = [j for j in range(S) if parents[j] == i]
        if children:
            node["children"] = children
        nodes.append(node)

    # skin: glTF stores matrices column-major
    mesh_list: list[dict] = []
    skins: list[dict] = []
    scene_nodes = [0]
    if meshes:
        ibm = np.linalg.inv(bind)
        ibm_acc = buf.add(np.transpose(ibm, (0, 2, 1)).reshape(S, 16), FLOAT, "MAT4")
        skins.append({"name": ch.name, "joints": list(range(S)), "inverseBindMatrices": ibm_acc, "skeleton": 0})
        joint_type = UNSIGNED_BYTE if S <= 256 else UNSIGNED_SHORT
        # feet are drawn standing where their contact points stand (``foot_shape``); a welded toes
        # segment is inside that shape
        foot_of = {f.segment: f.side for f in ch.feet if sum(c.side == f.side for c in ch.contacts) == 2
                   and all(c.segment == f.segment for c in ch.contacts if c.side == f.side)}
        welded = {s.name for s in segs if s.parent in foot_of and not s.dofs}
        for i, s in enumerate(segs):
            if s.name in welded:
                continue
            if s.name in foot_of:
                v, n, f = sole_mesh(*foot_shape(ch, foot_of[s.name]))
            elif s.length > 0 and s.radius > 0:
                v, n, f = ellipsoid_mesh(s.direction * (s.length / 2.0), s.direction, s.length / 2.0, s.radius)
            else:
                continue
            # segment frame (ours) -> segment frame (Y-up) -> bind-pose (mesh) space
            v = (v @ Y_UP.T) @ bind[i, :3, :3].T + bind[i, :3, 3]
            n = (n @ Y_UP.T) @ bind[i, :3, :3].T
            nv = v.shape[0]
            joints = np.zeros((nv, 4))
            joints[:, 0] = i
            weights = np.zeros((nv, 4))
            weights[:, 0] = 1.0
            prim = {
                "attributes": {
                    "POSITION": buf.add(v, FLOAT, "VEC3", ARRAY_BUFFER, minmax=True),
                    "NORMAL": buf.add(n, FLOAT, "VEC3", ARRAY_BUFFER),
                    "JOINTS_0": buf.add(joints, joint_type, "VEC4", ARRAY_BUFFER),
                    "WEIGHTS_0": buf.add(weights, FLOAT, "VEC4", ARRAY_BUFFER),
                },
                "indices": buf.add(f.reshape(-1), UNSIGNED_SHORT, "SCALAR", ELEMENT_ARRAY_BUFFER, minmax=True),
                "material": 0,
                "mode": TRIANGLES,
            }
            mesh_list.append({"name": s.name, "primitives": [prim]})
            nodes.append({"name": f"{s.name}_mesh", "mesh": len(mesh_list) - 1, "skin": 0})
            scene_nodes.append(len(nodes) - 1)

    items = [(str(motion.provenance.get("step", "motion")), motion)] if clips is None else clips
    animations = [_animation(buf, m, name, loop=loop, world=world) for name, m in items]
    if meshes:
        to_scene = np.eye(4)
        to_scene[:3, :3] = Y_UP
        scene_nodes.append(ground_nodes(buf, [(name, ground_of_motion(m, world)) for name, m in items], to_scene,
                                        1, mesh_list, nodes))

    while len(buf.data) % 4:
        buf.data.append(0)
    doc: dict[str, Any] = {
        "asset": {
            "version": "2.0",
            "generator": "motionx",
            "extras": {
                "character": ch.name,
                "fps": float(motion.fps),
                "frame_count": T,
                "axes": dict(AXES_Y_UP),
                "source_axes": dict(AXES_Z_UP),
                "axis_conversion": "data converted: (x, y, z)_gltf = (y, z, x)_motionx",
                "world": world,
            },
        },
        "scene": 0,
        "scenes": [{"name": ch.name, "nodes": scene_nodes}],
        "nodes": nodes,
        "animations": animations,
        "buffers": [{"byteLength": len(buf.data)}],
        "bufferViews": buf.views,
        "accessors": buf.accessors,
    }
    if mesh_list:  # without meshes nothing would use the skin
        doc["skins"] = skins
        doc["meshes"] = mesh_list
        doc["materials"] = [
            {
                "name": "segment",
                "pbrMetallicRoughness": {"baseColorFactor": [0.8, 0.8, 0.8, 1.0], "metallicFactor": 0.0,
                                         "roughnessFactor": 0.8},
            },
            GROUND_MATERIAL,
        ]
    log.debug("glTF of %s: %d nodes, %d meshes, %d animations, %d bytes", ch.name, len(nodes), len(mesh_list),
              len(animations), len(buf.data))
    return doc, bytes(buf.data)


def _source(rig: Any) -> bool:
    """Whether ``rig`` asks for the input's own rig ("source") rather than the motion's ("character")."""
    if rig not in ("character", "source"):
        raise ExportError(f"rig must be 'character' (the motion's own skeleton) or 'source' (the input's character "
                          f"or skeleton), got {rig!r}")
    return rig == "source"


def to_glb(motion: Motion, *, meshes: bool = True, loop: bool = False, rig: str = "character",
           world: str = DEFAULT_WORLD) -> bytes:
    """Binary glTF (.glb): JSON chunk and BIN chunk. ``meshes``: include the segment ellipsoids.
    ``loop``: the animation is one cycle, frames 0 … P (its last key repeats the first under
    the loop transform: ``extras.loop``), instead of every frame. ``rig="source"``: on the
    input's own character or skeleton, one gait cycle (:func:`solver.export.rig_gltf.rig_glb`:
    the skinned glTF input with its meshes, skin and materials; a BVH or DeepMimic input's
    skeleton with bone shapes when ``meshes``). ``world``: "gravity" (gravity down, the ground as
    the walk found it: a slope's ramp) or "ground" (the solver's level ground, tilted gravity);
    with ``meshes`` the ground is drawn beside the walk (node ``ground``)."""
    _check_flag("loop", loop)
    check_world(world)
    if _source(rig):
        return rig_glb(motion, meshes=meshes, world=world)
    return glb(*_document(motion, meshes, loop, world=world))


def to_gltf_embedded(motion: Motion, *, meshes: bool = True, loop: bool = False, rig: str = "character",
                     world: str = DEFAULT_WORLD) -> str:
    """glTF JSON (.gltf) with the buffer embedded as a base64 data URI (``rig``, ``world`` as :func:`to_glb`)."""
    _check_flag("loop", loop)
    check_world(world)
    if _source(rig):
        return rig_gltf_embedded(motion, meshes=meshes, world=world)
    doc, data = _document(motion, meshes, loop, world=world)
    doc["buffers"][0]["uri"] = "data:application/octet-stream;base64," + base64.b64encode(data).decode("ascii")
    return json.dumps(doc, allow_nan=False, separators=(",", ":"))


def to_gltf(motion: Motion, *, meshes: bool = True, binary: bool = True, loop: bool = False,
            rig: str = "character", world: str = DEFAULT_WORLD) -> bytes | str:
    """glTF 2.0 of ``motion``: the binary ``.glb`` (bytes, the default, as :func:`to_glb`), or
    with ``binary=False`` the ``.gltf`` JSON text with its buffer embedded (:func:`to_gltf_embedded`);
    ``rig="source"``: on the input's own character or skeleton; ``world`` as :func:`to_glb`."""
    if not isinstance(binary, bool):
        raise ExportError(f"binary must be a boolean, got {binary!r}")
    if binary:
        return to_glb(motion, meshes=meshes, loop=loop, rig=rig, world=world)
    return to_gltf_embedded(motion, meshes=meshes, loop=loop, rig=rig, world=world)


def to_library_glb(clips: list[tuple[str, Motion]], *, extras: dict | None = None, meshes: bool = True,
                   loop: bool = True, world: str = DEFAULT_WORLD) -> bytes:
    """One GLB for a motion library: the skeleton (and meshes) once, one named animation per
    (name, motion) — one cycle each with ``loop`` — and ``extras`` (e.g. the grid) in the
    asset's extras under ``library``; with ``meshes`` each clip's ground (node ``ground`` with
    a child ``ground <name>`` per clip). Every motion must be of the same character."""
    if not clips:
        raise ExportError("a library GLB needs at least one clip")
    names = [n for n, _ in clips]
    if len(set(names)) != len(names) or not all(isinstance(n, str) and n for n in names):
        raise ExportError("clip names must be distinct non-empty strings")
    first = _check_motion(clips[0][1])
    for name, m in clips[1:]:
        _check_motion(m)
        if m.character.coordinate_names != first.character.coordinate_names or \
                [s.name for s in m.character.segments] != [s.name for s in first.character.segments]:
            raise ExportError(f"clip {name!r} is of another character than {names[0]!r}")
    doc, data = _document(first, meshes, loop, clips=clips, world=world)
    if extras is not None:
        doc["asset"]["extras"]["library"] = extras
    return glb(doc, data)
