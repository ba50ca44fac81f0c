"""BVH (Biovision hierarchy) importer.

Public API::

    read_bvh(path) -> BvhClip                        # hierarchy + channels, no interpretation
    bvh_track(path, *, mass=None, units="auto", up="y", floor_height=None, joints=None, belt_speed=None)
        -> SkeletonTrack
    load_bvh(path, *, mass=None, units="auto", up="y", floor_height=None, lower_only=None,
             joints=None, belt_speed=None) -> Capture

A small reader of our own (numpy only; the ``bvhio`` package would add PyGLM and
SpatialTransform for what is ~100 lines here). Rotation channels are applied in the order
listed, intrinsically (``Zrotation Xrotation Yrotation`` means R = Rz Rx Ry, the BVH
convention); position channels (root, and any other joint that has them) are added to
the joint's OFFSET — or replace it, for a joint whose channels repeat its OFFSET (game exporters
that give every joint six channels: :func:`absolute_position_joints`).

**In-place clips** (no root motion) are walks on a moving ground: detected, or ``belt_speed``
given, and shifted to the walk overground (:func:`solver.io.joint_track.walk_in_place`).

**Joint roles** (:mod:`solver.io.roles`): from the names (CMU/ASF, Mixamo/MotionBuilder,
Unreal, Unity, Blender, 3ds Max Biped, DAZ styles; sides as ``Left…``/``L…``/``l…`` prefixes or
``_l``/``.L`` suffixes; namespaces and tool prefixes ignored) and the hierarchy (a knee below its
hip, …; lumbar = the first joint of the hips -> neck chain more than 3 cm from the hip joints in
the rest pose). ``joints`` (role -> joint name, ``"hip_l=Thigh_L,knee_l=Shin_L"``) overrides the
detection; a file whose required roles (hips; hip, knee, ankle each side; toes: a joint, or the
ankle's End Site or child) cannot be found is refused with the roles missing and the joint
names seen. The metatarsal heads are the toes joint (its End Site or child = toe tip), the head
top the Head's End Site, the hand tip the wrist's End Site or first child. The lower body is
required; the upper body is used when every upper landmark can be placed.

**Landmarks**: joint positions; pelvis = mid-point of the hips; neck = the Head joint
(base of the head); sternum = mid-point of the clavicle joints (else the Neck joint, else
the mid-point of the shoulders); hand
tip as above. The heel is not a BVH joint: it is placed in the rest pose (all channels 0,
standing) behind and below the ankle — 25 % of the ankle -> toe-tip horizontal length
behind it, at the sole (the rest pose's lowest toe point) — and carried by the foot joint.
The toe landmark is the toe tip moved to the sole the same way.

**Axes and units.** ``up`` names the BVH up axis (``"y"``, the usual, or ``"z"``). Our X is
the subject's facing direction (horizontal, perpendicular to the right -> left hip line,
averaged over the clip), Y left, Z up; ``GroundFrame.R`` maps ours back to the file's axes.
``units``: ``"auto"`` takes the first of cm, m, mm, in, cmu (the CMU database's 1/0.45 inch)
that makes the rest pose's hip -> knee -> ankle length 0.45-1.2 m; else ``"cm"``, ``"m"``,
``"mm"``, ``"in"``, ``"cmu"`` or metres per unit. The floor (our z = 0)
is ``floor_height`` (file units, along ``up``) or the 2nd percentile of the sole points'
heights over the clip. BVH has no subject mass: pass ``mass`` (kg).
"""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from solver import spatial as sp
from solver.capture import Capture, GroundFrame
from solver.errors import InputError
from solver.io.fit import fit_track
from solver.io.joint_track import JointPose, ground_landmarks, walk_in_place
from solver.io.readers import one_file
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

__all__ = ["UNIT_M", "BvhClip", "BvhError", "bvh_track", "load_bvh", "parse_bvh", "read_bvh"]

#: metres per file unit; "cmu": the CMU mocap database's BVH conversions (ASF units, 1/0.45 inch)
UNIT_M = {"cm": 0.01, "m": 1.0, "mm": 0.001, "in": 0.0254, "cmu": 0.0254 / 0.45}
#: plausible hip -> knee -> ankle length (m) for unit detection (children to tall adults)
LEG_RANGE = (0.45, 1.2)


class BvhError(InputError):
    """A BVH file is unreadable or cannot be interpreted; the message names the problem."""


@dataclass(frozen=True, eq=False)
class BvhClip:
    names: tuple[str, ...]  # joints, depth-first (End Sites excluded)
    parents: tuple[int, ...]
    offsets: np.ndarray  # (J, 3)
    channels: tuple[tuple[str, ...], ...]  # per joint, e.g. ("Xposition", ..., "Zrotation", ...)
    end_sites: Mapping[int, np.ndarray]  # joint index -> End Site offset
    frame_time: float
    motion: np.ndarray  # (T, total channels)
    #: joints whose position channels hold their local position (it replaces the OFFSET), not a
    #: displacement from the OFFSET (:func:`absolute_position_joints`)
    absolute: frozenset[int] = frozenset()

    @property
    def T(self) -> int:
        return int(self.motion.shape[0])

    def local(self, j: int, motion: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """Joint ``j``'s rotation (T, 3, 3) and position (T, 3) in its parent's frame: its rotation
        channels applied in the order listed (intrinsic), its position channels added to OFFSET
        (or, for a joint in :attr:`absolute`, in its place)."""
        m = self.motion if motion is None else motion
        T = m.shape[0]
        col = sum(len(c) for c in self.channels[:j])
        loc_p = np.broadcast_to(self.offsets[j], (T, 3)).copy()
        loc_R = np.broadcast_to(np.eye(3), (T, 3, 3)).copy()
        for ch in self.channels[j]:
            v = m[:, col]
            col += 1
            axis = "XYZ".index(ch[0].upper())
            if ch.lower().endswith("position"):
                loc_p[:, axis] = v if j in self.absolute else loc_p[:, axis] + v
            else:
                loc_R = loc_R @ sp.elementary_rotation(axis, np.radians(v))
        return loc_R, loc_p

    def rest_motion(self) -> np.ndarray:
        """(1, channels): the rest pose (every rotation 0, every joint at its OFFSET)."""
        row = np.zeros((1, self.motion.shape[1]))
        col = 0
        for j, chans in enumerate(self.channels):
            for c in chans:
                if j in self.absolute and c.lower().endswith("position"):
                    row[0, col] = self.offsets[j]["XYZ".index(c[0].upper())]
                col += 1
        return row

    def forward(self, motion: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """World rotation (J, T, 3, 3) and position (J, T, 3) of every joint (file axes/units)."""
        m = self.motion if motion is None else motion
        T = m.shape[0]
        J = len(self.names)
        R = np.zeros((J, T, 3, 3))
        P = np.zeros((J, T, 3))
        for j in range(J):
            loc_R, loc_p = self.local(j, m)
            par = self.parents[j]
            if par < 0:
                R[j], P[j] = loc_R, loc_p
            else:
                R[j] = R[par] @ loc_R
                P[j] = P[par] + np.einsum("tij,tj->ti", R[par], loc_p)
        return R, P




_CHANNELS = {f"{a}{k}" for a in "XYZ" for k in ("position", "rotation")}


def read_bvh(path: str | Path) -> BvhClip:
    """The hierarchy and channels of a BVH file (:func:`parse_bvh`)."""
    p = Path(path)
    if not p.is_file():
        raise BvhError(f"BVH file not found: {p}")
    return parse_bvh(p.read_text(errors="replace"), str(p))


def parse_bvh(text: str, where: str = "BVH") -> BvhClip:
    """The one BVH parser (this importer and :func:`solver.export.reimport.motion_from_bvh`):
    hierarchy, channels, frame time and values, no interpretation. Errors name ``where``."""
    p = where
    toks = text.split()
    pos = 0

    def take(what: str) -> str:
        nonlocal pos
        if pos >= len(toks):
            raise BvhError(f"{p}: unexpected end of file (expected {what})")
        pos += 1
        return toks[pos - 1]

    def number(what: str) -> float:
        t = take(what)
        try:
            return float(t)
        except ValueError:
            raise BvhError(f"{p}: expected a number for {what}, got {t!r}") from None

    if take("HIERARCHY").upper() != "HIERARCHY":
        raise BvhError(f"{p}: not a BVH file (expected 'HIERARCHY' first)")
    names: list[str] = []
    parents: list[int] = []
    offsets: list[list[float]] = []
    channels: list[tuple[str, ...]] = []
    ends: dict[int, np.ndarray] = {}
    kw = take("ROOT")
    if kw.upper() != "ROOT":
        raise BvhError(f"{p}: expected ROOT, got {kw!r}")

    def joint(parent: int) -> None:
        name = take("joint name")
        idx = len(names)
        names.append(name)
        parents.append(parent)
        if take("{") != "{":
            raise BvhError(f"{p}: expected '{{' after joint {name!r}")
        off = None
        chans: tuple[str, ...] = ()
        while True:
            t = take("OFFSET/CHANNELS/JOINT/End/}")
            u = t.upper()
            if u == "OFFSET":
                off = [number(f"OFFSET of {name}") for _ in range(3)]
            elif u == "CHANNELS":
                n = int(number(f"CHANNELS count of {name}"))
                chans = tuple(take(f"channel of {name}") for _ in range(n))
                bad = [c for c in chans if c not in _CHANNELS]
                if bad:
                    raise BvhError(f"{p}: joint {name!r} has unknown channels {bad}")
            elif u == "JOINT":
                if off is None:
                    raise BvhError(f"{p}: joint {name!r} has no OFFSET")
                offsets_tmp[idx] = off
                channels_tmp[idx] = chans
                joint(idx)
            elif u == "END":
                take("Site")
                if take("{") != "{" or take("OFFSET").upper() != "OFFSET":
                    raise BvhError(f"{p}: malformed End Site in joint {name!r}")
                ends[idx] = np.array([number("End Site OFFSET") for _ in range(3)])
                if take("}") != "}":
                    raise BvhError(f"{p}: malformed End Site in joint {name!r}")
            elif u == "}":
                break
            else:
                raise BvhError(f"{p}: unexpected token {t!r} in joint {name!r}")
        if off is None:
            raise BvhError(f"{p}: joint {name!r} has no OFFSET")
        offsets_tmp[idx] = off
        channels_tmp[idx] = chans

    offsets_tmp: dict[int, list[float]] = {}
    channels_tmp: dict[int, tuple[str, ...]] = {}
    joint(-1)
    offsets = [offsets_tmp[i] for i in range(len(names))]
    channels = [channels_tmp[i] for i in range(len(names))]
    if take("MOTION").upper() != "MOTION":
        raise BvhError(f"{p}: expected MOTION after the hierarchy")
    if take("Frames:").lower() != "frames:":
        raise BvhError(f"{p}: expected 'Frames:'")
    n_frames = int(number("frame count"))
    if take("Frame").lower() != "frame" or take("Time:").lower() != "time:":
        raise BvhError(f"{p}: expected 'Frame Time:'")
    dt = number("frame time")
    if not (np.isfinite(dt) and dt > 0):
        raise BvhError(f"{p}: Frame Time must be positive, got {dt}")
    nch = sum(len(c) for c in channels)
    vals = toks[pos:]
    if n_frames < 1:
        raise BvhError(f"{p}: the clip has no frames")
    if len(vals) != n_frames * nch:
        raise BvhError(f"{p}: {len(vals)} values for {n_frames} frames x {nch} channels (expected "
                       f"{n_frames * nch})")
    try:
        motion = np.array(vals, dtype=float).reshape(n_frames, nch)
    except ValueError:
        raise BvhError(f"{p}: non-numeric values in the MOTION section") from None
    if not np.all(np.isfinite(motion)):
        r = int(np.argwhere(~np.isfinite(motion))[0, 0])
        raise BvhError(f"{p}: frame {r} contains NaN/inf")
    if len(set(names)) != len(names):
        raise BvhError(f"{p}: duplicate joint names")
    off = np.array(offsets, dtype=float)
    return BvhClip(tuple(names), tuple(parents), off, tuple(channels), ends, dt, motion,
                   absolute_position_joints(off, tuple(channels), motion))


def absolute_position_joints(offsets: np.ndarray, channels: tuple[tuple[str, ...], ...],
                             motion: np.ndarray) -> frozenset[int]:
    """The joints whose position channels are their local position rather than a displacement
    from their OFFSET. BVH writers differ: most put the root's position in its channels over a
    zero OFFSET (the two readings agree), and some game exporters give every joint position
    channels that repeat its OFFSET (the bone's length, frame after frame): adding them to the
    OFFSET would double every bone. A joint with a non-zero OFFSET whose channels' median lies
    nearer its OFFSET than zero is read that way."""
    out = set()
    col = 0
    for j, chans in enumerate(channels):
        axes = [("XYZ".index(c[0].upper()), col + k) for k, c in enumerate(chans) if c.lower().endswith("position")]
        col += len(chans)
        if not axes:
            continue
        off = np.array([offsets[j][a] for a, _ in axes])
        med = np.array([float(np.median(motion[:, c])) for _, c in axes])
        if np.linalg.norm(off) > 1e-9 and np.linalg.norm(med - off) < np.linalg.norm(med):
            out.add(j)
    return frozenset(out)


# --- joint roles ------------------------------------------------------------------------------

def _roles(clip: BvhClip, path: str | Path, joints: str | Path | Mapping[str, str] | None,
           rest_m: np.ndarray | None = None) -> tuple[dict[str, int], list[int]]:
    """Joint index per role (:func:`solver.io.roles.joint_roles`; ``rest_m``: rest-pose joint
    positions in metres, for ``lumbar``) and the spine chain; a :class:`BvhError` naming the
    required roles it cannot find (a foot without a toes joint needs an End Site or a child)."""
    try:
        roles = joint_roles(clip.names, clip.parents, parse_joint_mapping(joints), rest=rest_m)
    except RoleError as e:
        raise BvhError(f"{path}: {e}") from None
    missing = missing_roles(roles)
    for s in "rl":
        a = roles.get(f"ankle_{s}")
        if (a is not None and f"mtp_{s}" not in roles and a not in clip.end_sites
                and a not in clip.parents):
            missing.append(f"mtp_{s}")
    if missing:
        raise BvhError(f"{path}: cannot find the joints for the roles {', '.join(missing)} among the joints "
                       f"{describe_names(clip.names)}; name them in a joint mapping ROLE=NAME,... (the roles: "
                       "docs/import.md)", parameter="joints")
    return roles, spine_joints(clip.parents, roles)


def _unit_scale(units: str | float, leg: float, path: str | Path) -> tuple[str | float, float]:
    """The file's length unit and metres per unit: given, or (``"auto"``) the first unit that
    makes the rest leg length ``leg`` (file units) a human's."""
    if not isinstance(units, str):
        scale = float(units)
        if not (np.isfinite(scale) and scale > 0):
            raise BvhError(f"units must be a positive number of metres per unit, got {units!r}")
        return units, scale
    if units in UNIT_M:
        return units, UNIT_M[units]
    if units != "auto":
        raise BvhError(f"units must be 'auto', one of {sorted(UNIT_M)} or metres per unit, got {units!r}")
    cands = [u for u, k in UNIT_M.items() if LEG_RANGE[0] <= leg * k <= LEG_RANGE[1]]
    if not cands:
        raise BvhError(f"{path}: cannot tell the length unit from the leg length {leg:.4g} (no unit of "
                       f"{sorted(UNIT_M)} makes it {LEG_RANGE[0]}-{LEG_RANGE[1]} m); pass units=")
    if len(cands) > 1:
        log.info("%s: leg length %.4g fits units %s: using %s", path, leg, cands, cands[0])
    return cands[0], UNIT_M[cands[0]]  # first in the order cm, m, mm, in, cmu


def _pose(clip: BvhClip, up_v: np.ndarray) -> JointPose:
    """The clip's joints along the motion and in the rest pose (all channels 0), file axes and units."""
    R_rest, P_rest = clip.forward(clip.rest_motion())
    R, P = clip.forward()
    return JointPose(clip.parents, R_rest[:, 0], P_rest[:, 0], R, P, clip.end_sites, up_v, BvhError)


def bvh_track(
    path: str | Path,
    *,
    mass: float | None = None,
    units: str | float = "auto",
    up: str = "y",
    floor_height: float | None = None,
    joints: str | Path | Mapping[str, str] | None = None,
    belt_speed: float | str | None = None,
) -> SkeletonTrack:
    clip = read_bvh(path)
    roles, spines = _roles(clip, path, joints)
    # axes: file -> our axes (before the facing rotation)
    if up not in ("y", "z"):
        raise BvhError(f"up must be 'y' or 'z', got {up!r}")
    up_v = np.array([0.0, 1.0, 0.0]) if up == "y" else np.array([0.0, 0.0, 1.0])
    pose = _pose(clip, up_v)
    P_rest = pose.P_rest
    # units from the rest leg length
    leg = np.mean([np.linalg.norm(P_rest[roles[f"hip_{s}"]] - P_rest[roles[f"knee_{s}"]])
                   + np.linalg.norm(P_rest[roles[f"knee_{s}"]] - P_rest[roles[f"ankle_{s}"]]) for s in "rl"])
    units, scale = _unit_scale(units, float(leg), path)
    roles, spines = _roles(clip, path, joints, P_rest * scale)  # lumbar: 3 cm clear of the hips
    g = ground_landmarks(pose, roles, scale, floor_height, path)
    if not g.upper_body:
        log.info("%s: no usable upper body (%s missing): lower-body track", path, g.missing_upper)
    lm, A, x_dir, offset_file, floor_height = g.landmarks, g.R, g.facing, g.offset, g.floor_height
    times = np.arange(clip.T) * clip.frame_time
    frame = GroundFrame(R=A.T, offset=offset_file * scale, unit_m=scale,
                        axes=f"BVH: {up.upper()} up, facing {np.round(x_dir, 3).tolist()} (file axes), units {units}")
    track = SkeletonTrack(
        times=times, landmarks=lm, frame=frame, mass=mass,
        source={"format": "bvh", "file": str(Path(path).resolve()), "units": units, "metres_per_unit": scale,
                "mass_from": "given" if mass is not None else None,
                "up": up, "joint_roles": {r: clip.names[j] for r, j in roles.items()},
                "spine_joints": [clip.names[j] for j in spines], "floor_height_file_units": floor_height,
                "estimated_tips": list(g.estimated),
                "absolute_position_joints": [clip.names[j] for j in sorted(clip.absolute)]},
    )
    return walk_in_place(track, belt_speed, BvhError, path)


def trial_files(paths: list[Path]) -> dict[str, Path]:
    """A BVH trial is one ``.bvh`` file (the reader registry's ``trial_files``)."""
    return {"path": one_file(paths, ".bvh")}


def load_bvh(
    path: str | Path,
    *,
    mass: float | None = None,
    units: str | float = "auto",
    up: str = "y",
    floor_height: float | None = None,
    lower_only: bool | None = None,
    joints: str | Path | Mapping[str, str] | None = None,
    belt_speed: float | str | None = None,
) -> Capture:
    """Import a BVH clip as a :class:`Capture` (conventions in the module doc), with the file's
    own skeleton as its rig (:func:`bvh_rig`). ``joints``: role -> joint name, for the joints
    whose names are not recognised (``"hip_l=Thigh_L,knee_l=Shin_L"``, a dict or a mapping file;
    :func:`solver.io.roles.parse_joint_mapping`). ``belt_speed``: an in-place clip's walking speed
    (m/s), ``"auto"`` (the stance foot's), 0 (not in place); None detects an in-place clip
    (:func:`solver.io.joint_track.walk_in_place`)."""
    track = bvh_track(path, mass=mass, units=units, up=up, floor_height=floor_height, joints=joints,
                      belt_speed=belt_speed)
    capture = fit_track(track, lower_only=lower_only)
    return capture.evolve(rig=bvh_rig(read_bvh(path), track))


def bvh_rig(clip: BvhClip, track: SkeletonTrack) -> SkeletonRig:
    """The clip's own skeleton and animation as a :class:`solver.rig.SkeletonRig` (the roles the track
    found: hips -> pelvis, RightUpLeg -> thigh_r, lumbar -> abdomen, …)."""
    by_name = {n: j for j, n in enumerate(clip.names)}
    roles = {r: by_name[n] for r, n in track.source["joint_roles"].items() if n in by_name}
    J, T = len(clip.names), clip.T
    local = np.empty((T, J, 3, 3))
    pos = np.empty((T, J, 3))
    for j in range(J):
        local[:, j], pos[:, j] = clip.local(j)
    moved = any(ch.lower().endswith("position") for j in range(1, J) for ch in clip.channels[j])
    extra: dict[str, Any] = {"frame_time": clip.frame_time, "units": track.source["units"]}
    if clip.absolute:  # position channels that hold the joint's position (the writer writes them so)
        extra["absolute_positions"] = sorted(clip.absolute)
    if moved:
        extra["positions"] = pos.tolist()
    return SkeletonRig("bvh", clip.names, clip.parents, clip.offsets, clip.channels, segment_roles(roles),
                       np.arange(T) * clip.frame_time, local, pos[:, 0], track.frame,
                       end_sites=dict(clip.end_sites), extra=extra)
