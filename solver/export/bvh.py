"""BVH (Biovision hierarchy) export.

One joint per segment, written depth-first from the root. ``OFFSET`` is the segment's
rest offset (its joint location in the parent's frame); the root's OFFSET is 0 and its
position channels carry its full world position, so readers that add the root OFFSET
and readers that ignore it agree. Every joint has 3 rotation channels in one order
(``rotation_order``, intrinsic: "XZY" means R = Rx(a) Rz(b) Ry(c) and the channels are
written Xrotation Zrotation Yrotation); the root also has Xposition Yposition Zposition
first. A joint's rotation is its full local rotation parent <- segment (rest orientation
times our intrinsic hinge sequence), converted exactly from the rotation matrix to Euler
angles in degrees, made continuous in time (each angle is unwrapped, which leaves the
rotation unchanged). Leaf segments get an ``End Site`` at their bone tip (marker).

Axes: Y up, converted like glTF (x_bvh = y, y_bvh = z, z_bvh = x: X left, Y up,
Z forward). Units: centimetres (default) or metres. ``Frame Time`` = 1 / fps. The motion is
written in a world (``world="gravity"``, the default: gravity points down, a slope walk climbs
its ramp; ``"ground"``: the solver's level ground under tilted gravity): the root's channels
carry it (:mod:`solver.export.world`). BVH has no meshes: the ground's description is
:func:`solver.export.world.ground_json` (the command line writes it beside the file).

The default order "XZY" follows our joints: with the Y-up axes a hip, knee, ankle,
spine, shoulder, elbow or wrist sequence (flexion about our y, then ab/adduction about
our x, then axial rotation about our z) *is* X, Z, Y, so the middle (singular) angle is
ab/adduction, which never reaches 90°.
"""

from __future__ import annotations

import io
import logging
import re
import warnings

import numpy as np

from solver.export import LENGTH_UNITS, Y_UP, ExportError, _check_motion, change_axes, check_decimals
from solver.export.world import DEFAULT_WORLD, check_world, source_pose, world_transforms
from solver.motion import Motion

log = logging.getLogger(__name__)

ORDERS = ("XYZ", "XZY", "YXZ", "YZX", "ZXY", "ZYX")
UNITS = LENGTH_UNITS
_BAD_NAME = re.compile(r"[\s{}]")


def euler_angles(rot: np.ndarray, order: str) -> np.ndarray:
    """Intrinsic Euler angles (radians) of rotation matrices (..., 3, 3): R = R_o0(a) R_o1(b) R_o2(c)."""
    from scipy.spatial.transform import Rotation  # lazy: scipy.spatial costs ~0.2 s to import

    shape = rot.shape[:-2]
    with warnings.catch_warnings():
        # at gimbal lock scipy sets the third angle to 0 and still represents the rotation exactly
        warnings.simplefilter("ignore", UserWarning)
        ang = Rotation.from_matrix(rot.reshape(-1, 3, 3)).as_euler(order)
    return ang.reshape(shape + (3,))


def _check(units: object, rotation_order: object, decimals: object) -> None:
    if units not in UNITS:
        raise ExportError(f"units must be one of {sorted(UNITS)}, got {units!r}")
    if rotation_order not in ORDERS:
        raise ExportError(f"rotation_order must be one of {list(ORDERS)}, got {rotation_order!r}")
    check_decimals(decimals)


def to_bvh(motion: Motion, *, units: str = "cm", rotation_order: str = "XZY", decimals: int = 6,
           rig: str = "character", world: str = DEFAULT_WORLD) -> str:
    """BVH text of ``motion`` (Y up; ``units`` "cm" or "m"; ``decimals`` per number) in ``world``
    ("gravity": gravity down, a slope's ramp climbed; "ground": the solver's level ground).
    ``rig="source"``: on the skeleton of the BVH the motion came from (:func:`source_bvh`;
    ``units`` and ``rotation_order`` are then the source's)."""
    _check_motion(motion)
    check_world(world)
    if rig == "source":
        return source_bvh(motion, decimals=decimals, world=world)
    if rig != "character":
        raise ExportError(f"rig must be 'character' (the motion's own skeleton) or 'source' (the input's), got {rig!r}")
    _check(units, rotation_order, decimals)
    ch = motion.character
    segs = ch.segments
    for s in segs:
        if _BAD_NAME.search(s.name) or not s.name:
            raise ExportError(f"segment name {s.name!r} cannot be a BVH joint name (whitespace or braces)")
    slid = [s.name for s in segs[1:] if any(d.kind == "slide" for d in s.dofs)]
    if slid:
        raise ExportError(f"BVH export supports slide joints only at the root; segments with slides: {slid}")
    scale = UNITS[units]
    children: dict[str, list[int]] = {s.name: [] for s in segs}
    for i, s in enumerate(segs):
        if s.parent is not None:
            children[s.parent].append(i)

    lt = world_transforms(motion, world)
    rot, pos = change_axes(lt.rot, lt.pos, True)
    euler = np.degrees(np.unwrap(euler_angles(rot, rotation_order), axis=1))  # (S, T, 3)
    offsets = np.array([s.offset for s in segs]) @ Y_UP.T * scale
    tips = np.array([s.marker for s in segs]) @ Y_UP.T * scale
    rot_channels = " ".join(f"{a}rotation" for a in rotation_order)

    out = io.StringIO()
    fmt = f"{{:.{decimals}f}}"

    def vec(v: np.ndarray) -> str:
        return " ".join(fmt.format(x + 0.0) for x in v)

    columns: list[np.ndarray] = []

    def write(i: int, depth: int) -> None:
        s = segs[i]
        pad = "  " * depth
        if depth == 0:
            out.write(f"ROOT {s.name}\n{pad}{{\n")
            out.write(f"{pad}  OFFSET {vec(np.zeros(3))}\n")
            out.write(f"{pad}  CHANNELS 6 Xposition Yposition Zposition {rot_channels}\n")
            columns.append(pos[i] * scale)
        else:
            out.write(f"{pad}JOINT {s.name}\n{pad}{{\n")
            out.write(f"{pad}  OFFSET {vec(offsets[i])}\n")
            out.write(f"{pad}  CHANNELS 3 {rot_channels}\n")
        columns.append(euler[i])
        for c in children[s.name]:
            write(c, depth + 1)
        if not children[s.name]:
            out.write(f"{pad}  End Site\n{pad}  {{\n{pad}    OFFSET {vec(tips[i])}\n{pad}  }}\n")
        out.write(f"{pad}}}\n")

    out.write("HIERARCHY\n")
    write(0, 0)
    out.write("MOTION\n")
    out.write(f"Frames: {motion.T}\n")
    out.write(f"Frame Time: {1.0 / float(motion.fps)!r}\n")
    table = np.concatenate(columns, axis=1) + 0.0
    np.savetxt(out, table, fmt=f"%.{decimals}f", delimiter=" ")
    log.debug("BVH of %s: %d joints, %d channels, %d frames", ch.name, len(segs), table.shape[1], motion.T)
    return out.getvalue()


def _channel_values(R: np.ndarray, axes: str) -> np.ndarray:
    """Angles (F, len(axes)) in degrees of the rotation channels ``axes`` (e.g. "ZXY", "Z"),
    intrinsic, continuous in time. One or two channels: the rotation's part about those axes
    (swing removed; exact when the joint turns only about them)."""
    from scipy.spatial.transform import Rotation

    if len(axes) == 3:
        ang = euler_angles(R, axes)
    else:
        rest = "".join(a for a in "XYZ" if a not in axes)
        order = axes + rest[: 3 - len(axes)]
        ang = euler_angles(R, order)[..., : len(axes)]
        if len(axes) == 1:  # twist about the one axis (swing-twist decomposition)
            quat = Rotation.from_matrix(R.reshape(-1, 3, 3)).as_quat()
            k = "XYZ".index(axes)
            ang = (2.0 * np.arctan2(quat[:, k], quat[:, 3])).reshape(R.shape[:-2] + (1,))
    return np.degrees(np.unwrap(ang, axis=0))


def source_bvh(motion: Motion, *, decimals: int = 6, world: str = DEFAULT_WORLD) -> str:
    """``motion`` on the skeleton of the BVH it came from: the input's hierarchy, joint names,
    offsets, channels (order and count), End Sites and units, one gait cycle at the input's
    frame rate (``solver.rig.retarget``), its root in ``world``."""
    check_decimals(decimals)
    rig, pose = source_pose(motion, ("bvh",), "rig=source needs a motion made from a BVH trial", world)
    fmt = f"{{:.{decimals}f}}"
    children: dict[int, list[int]] = {j: [] for j in range(rig.J)}
    for j, p in enumerate(rig.parents):
        if p >= 0:
            children[p].append(j)
    out = io.StringIO()
    columns: list[np.ndarray] = []
    absolute = set(rig.extra.get("absolute_positions") or ())  # the input's joints whose channels hold their position

    def vec(v: np.ndarray) -> str:
        return " ".join(fmt.format(float(x) + 0.0) for x in v)

    def write(j: int, depth: int) -> None:
        pad = "\t" * depth
        out.write(f"{pad}{'ROOT' if depth == 0 else 'JOINT'} {rig.names[j]}\n{pad}{{\n")
        out.write(f"{pad}\tOFFSET {vec(rig.offsets[j])}\n")
        chans = rig.channels[j]
        out.write(f"{pad}\tCHANNELS {len(chans)} {' '.join(chans)}\n")
        translation = pose.root if j == 0 else (pose.positions[:, j] if pose.positions is not None
                                                 else np.broadcast_to(rig.offsets[j], pose.root.shape))
        rot_axes = "".join(c[0].upper() for c in chans if c.lower().endswith("rotation"))
        angles = _channel_values(pose.local[:, j], rot_axes) if rot_axes else np.zeros((pose.times.size, 0))
        k = 0
        for c in chans:
            if c.lower().endswith("position"):  # a displacement from the OFFSET, or the position itself
                a = "XYZ".index(c[0].upper())
                columns.append((translation[:, a] - (0.0 if j in absolute else rig.offsets[j][a]))[:, None])
            else:
                columns.append(angles[:, k : k + 1])
                k += 1
        for child in children[j]:
            write(child, depth + 1)
        if j in rig.end_sites:
            out.write(f"{pad}\tEnd Site\n{pad}\t{{\n{pad}\t\tOFFSET {vec(rig.end_sites[j])}\n{pad}\t}}\n")
        out.write(f"{pad}}}\n")

    out.write("HIERARCHY\n")
    write(0, 0)
    frames = pose.times.size
    out.write(f"MOTION\nFrames: {frames}\nFrame Time: {float(pose.times[1] - pose.times[0]):.8f}\n")
    table = (np.concatenate(columns, axis=1) if columns else np.zeros((frames, 0))) + 0.0
    np.savetxt(out, table, fmt=f"%.{decimals}f", delimiter=" ")
    return out.getvalue()
