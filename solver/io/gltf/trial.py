"""The glTF reader functions: a skinned character's animation as landmarks
(:func:`gltf_track`), as a fitted :class:`~solver.capture.Capture` (:func:`load_gltf`) with the
character's own skeleton as its rig (:func:`gltf_rig`), and the trial's files (:func:`trial_files`)."""

from __future__ import annotations

import base64
import logging
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from solver.capture import Capture, GroundFrame
from solver.io.bvh import LEG_RANGE
from solver.io.fit import fit_track
from solver.io.gltf.base import GltfError
from solver.io.gltf.container import GltfAsset, glb_bytes, read_gltf, without_animations
from solver.io.gltf.skeleton import _forward, _read_skeleton, _Skeleton
from solver.io.joint_track import JointPose, ground_landmarks, walk_in_place
from solver.io.readers import TrialError
from solver.io.roles import (
    RoleError,
    describe_names,
    joint_roles,
    missing_roles,
    parse_joint_mapping,
    spine_joints,
)
from solver.io.track import SkeletonTrack
from solver.rig import SkeletonRig, segment_roles

log = logging.getLogger(__name__)


def _roles(sk: _Skeleton, P_rest: np.ndarray, path: str | Path,
           joints: str | Path | Mapping[str, str] | None) -> tuple[dict[str, int], list[int]]:
    try:
        roles = joint_roles(sk.names, sk.parents, parse_joint_mapping(joints), rest=P_rest * sk.unit_m)
    except RoleError as e:
        raise GltfError(f"{path}: {e}", parameter="joints") from None
    missing = missing_roles(roles)
    for s in "rl":
        a = roles.get(f"ankle_{s}")
        if a is not None and f"mtp_{s}" not in roles and a not in sk.parents:
            missing.append(f"mtp_{s}")
    if missing:
        raise GltfError(f"{path}: cannot find the joints for the roles {', '.join(missing)} among the skeleton's "
                        f"joints {describe_names(sk.names)}; name them in a joint mapping ROLE=NAME,... (the roles: "
                        "docs/import.md)", parameter="joints")
    return roles, spine_joints(sk.parents, roles)


def _track(asset: GltfAsset, path: str | Path, mass: float | None, joints: str | Path | Mapping[str, str] | None,
           animation: int | str | None, belt_speed: float | str | None = None
           ) -> tuple[SkeletonTrack, _Skeleton, dict[str, int]]:
    sk = _read_skeleton(asset, animation)
    R_rest, P_rest = _forward(sk.parents, sk.rest_local[None], sk.rest_translation[None])
    R, P = _forward(sk.parents, sk.local, sk.translation)
    roles, spines = _roles(sk, P_rest[:, 0], path, joints)
    leg = float(np.mean([np.linalg.norm(P_rest[roles[f"hip_{s}"], 0] - P_rest[roles[f"knee_{s}"], 0])
                         + np.linalg.norm(P_rest[roles[f"knee_{s}"], 0] - P_rest[roles[f"ankle_{s}"], 0])
                         for s in "rl"])) * sk.unit_m
    if not LEG_RANGE[0] <= leg <= LEG_RANGE[1]:
        raise GltfError(f"{path}: the character's legs (hip -> knee -> ankle) are {leg:.4g} m long in the scene; a "
                        f"walking person's are {LEG_RANGE[0]}-{LEG_RANGE[1]} m (glTF lengths are metres: check the "
                        "scale of the nodes above the skeleton)")
    pose = JointPose(sk.parents, R_rest[:, 0], P_rest[:, 0], R, P, {}, sk.up, GltfError)
    g = ground_landmarks(pose, roles, sk.unit_m, None, path)
    if not g.upper_body:
        log.info("%s: no usable upper body (%s missing): lower-body track", path, g.missing_upper)
    frame = GroundFrame(R=g.R.T, offset=g.offset * sk.unit_m, unit_m=sk.unit_m,
                        axes=f"glTF skeleton space (below node {sk.nodes[0]}'s parents): up "
                             f"{np.round(sk.up, 3).tolist()}, facing {np.round(g.facing, 3).tolist()}, "
                             f"{sk.unit_m:g} m per unit")
    track = SkeletonTrack(
        times=sk.times, landmarks=g.landmarks, frame=frame, mass=mass,
        source={"format": "gltf", "file": str(Path(path).resolve()), "animation": sk.clip.name,
                "animation_index": sk.clip.index, "skin": sk.skin, "metres_per_unit": sk.unit_m,
                "frame_time": float(sk.times[1] - sk.times[0]),
                "mass_from": "given" if mass is not None else None,
                "joint_roles": {r: sk.names[j] for r, j in roles.items()},
                "spine_joints": [sk.names[j] for j in spines], "floor_height_file_units": g.floor_height,
                "estimated_tips": list(g.estimated)},
    )
    return walk_in_place(track, belt_speed, GltfError, path), sk, roles


def gltf_track(path: str | Path, *, mass: float | None = None, joints: str | Path | Mapping[str, str] | None = None,
               animation: int | str | None = None, belt_speed: float | str | None = None) -> SkeletonTrack:
    """The landmarks of a skinned glTF character's animation (conventions in the module doc)."""
    return _track(read_gltf(path), path, mass, joints, animation, belt_speed)[0]


def trial_files(paths: list[Path]) -> dict[str, Path]:
    """A glTF trial is one ``.glb`` or ``.gltf`` file (the reader registry's ``trial_files``)."""
    if len(paths) != 1:
        raise TrialError(f"one .glb or .gltf file expected, got {len(paths)}")
    return {"path": paths[0]}


def load_gltf(path: str | Path, *, mass: float | None = None, lower_only: bool | None = None,
              joints: str | Path | Mapping[str, str] | None = None, animation: int | str | None = None,
              belt_speed: float | str | None = None) -> Capture:
    """Import a skinned glTF character's walk as a :class:`Capture` (conventions in the module
    doc), with the character's own skeleton as its rig (format ``"gltf"``). ``animation``: the
    animation's name or index (default: the first); ``joints``: role -> joint name for joints
    whose names are not recognised; ``belt_speed``: an in-place walk's speed (m/s), ``"auto"``, 0 (not
    in place), None: detected (:func:`solver.io.joint_track.walk_in_place`)."""
    asset = read_gltf(path)
    track, sk, roles = _track(asset, path, mass, joints, animation, belt_speed)
    capture = fit_track(track, lower_only=lower_only)
    return capture.evolve(rig=gltf_rig(asset, sk, roles, track))


def gltf_rig(asset: GltfAsset, sk: _Skeleton, roles: Mapping[str, int], track: SkeletonTrack) -> SkeletonRig:
    """The character's skeleton and animation as a :class:`solver.rig.SkeletonRig` (see the module doc)."""
    J = len(sk.names)
    stripped = without_animations(asset)
    glb = glb_bytes(stripped.doc, stripped.bin)
    offsets = sk.translation[0].copy() if not sk.moved else sk.rest_translation.copy()
    offsets[0] = sk.rest_translation[0]  # the root's translation is the rig's ``root``
    channels = tuple(("Xposition", "Yposition", "Zposition", "quaternion") if j == 0 or sk.moved else ("quaternion",)
                     for j in range(J))
    extra: dict[str, Any] = {
        "frame_time": float(sk.times[1] - sk.times[0]), "nodes": list(sk.nodes), "skin": sk.skin,
        "scales": sk.scales.tolist(), "animation": sk.clip.name, "asset": base64.b64encode(glb).decode("ascii"),
    }
    if sk.moved or roles.get("hips", 0) != 0:  # joints with position channels (a pelvis under a root)
        extra["positions"] = sk.translation.tolist()
    return SkeletonRig("gltf", sk.names, sk.parents, offsets, channels, segment_roles(roles), sk.times, sk.local,
                       sk.translation[:, 0], track.frame, extra=extra)
