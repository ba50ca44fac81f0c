"""DeepMimic motion export: a motion on the DeepMimic character it came from.

The frames follow the character file's layout (``solver.io.deepmimic``): ``[dt, root position
(3), root rotation (w, x, y, z), then per joint in the character's order a quaternion (w, x,
y, z) for a spherical joint, one angle (rad, about the joint's Z) for a revolute joint,
nothing for a fixed one]``, DeepMimic axes (Y up), metres. One gait cycle at the clip's own
frame rate, written as ``"Loop": "wrap"`` (the last frame is the phase of the first), so it
goes straight into DeepMimic-style imitation learning with the same character file. The
motion's character drives the joints it has; the others carry the capture's values at the
same gait phase (``solver.rig.retarget``). The root is placed in the export's world
(``world="gravity"``, the default: gravity down, a slope walk climbs its ramp — DeepMimic's own
scene has a level floor: give it the ramp, or export ``world="ground"`` and tilt its gravity).
"""

from __future__ import annotations

import json

import numpy as np

from solver.export import DEFAULT_WORLD, ExportError, _check_motion, check_decimals
from solver.export.world import source_pose
from solver.motion import Motion
from solver.rig import matrices_to_quats


def to_deepmimic(motion: Motion, *, rig: str = "source", decimals: int = 6, world: str = DEFAULT_WORLD) -> str:
    """The DeepMimic motion file (JSON text) of ``motion`` on its source DeepMimic character, in
    ``world`` (:mod:`solver.export.world`)."""
    _check_motion(motion)
    if rig != "source":
        raise ExportError(f"a DeepMimic motion is written on the source character only: rig must be 'source', "
                          f"got {rig!r}")
    check_decimals(decimals)
    src_rig, pose = source_pose(motion, ("deepmimic",), "format=deepmimic needs a motion made from a DeepMimic clip",
                                world)
    types = list(src_rig.extra.get("types") or [])
    if len(types) != src_rig.J:
        raise ExportError("the motion's DeepMimic rig has no joint types")
    F = pose.times.size
    dt = float(pose.times[1] - pose.times[0])
    quats = matrices_to_quats(pose.local)  # (F, J, 4) w, x, y, z, continuous in time
    cols: list[np.ndarray] = [np.full((F, 1), dt), pose.root, quats[:, 0]]
    for j in range(1, src_rig.J):
        if types[j] == "spherical":
            cols.append(quats[:, j])
        elif types[j] == "revolute":
            w, z = quats[:, j, 0], quats[:, j, 3]
            cols.append(np.unwrap(2.0 * np.arctan2(z, w))[:, None])
    frames = np.round(np.concatenate(cols, axis=1), decimals) + 0.0
    frames[-1, 0] = 0.0  # DeepMimic: the last frame's duration is 0
    return json.dumps({"Loop": "wrap", "Frames": frames.tolist()}, indent=None)
