"""DeepMimic importer: a motion clip (JSON ``Frames``) + a character file (``Skeleton``/``BodyDefs``).

Public API::

    read_deepmimic_character(path) -> DeepMimicSkeleton
    deepmimic_track(motion, character, *, mass=None) -> SkeletonTrack
    load_deepmimic(motion, character, *, mass=None, lower_only=None) -> Capture

**Frame layout** (DeepMimic humanoid3d): ``[dt, root position (3), root rotation (w, x, y, z),
then per joint in the character's joint order: a quaternion (w, x, y, z) for spherical
joints, one angle (rad, about the joint's local Z) for revolute joints, nothing for fixed
joints]``. Rotations are local (child relative to parent); ``dt`` is each frame's duration
(the last is 0). The layout is derived from the character file, so other DeepMimic
characters with the same joint types load too; a frame of the wrong length is refused.

**Axes.** DeepMimic: Y up, X forward (walking direction), Z to the character's right; ours:
``p = C p_dm`` with the same ``C`` as OpenSim (``[[1,0,0],[0,0,-1],[0,1,0]]``); body
frames at zero rotation are world-aligned (legs and arms hanging), like our segments at
q = 0, so orientations map as ``C R C^T``. The floor is DeepMimic's ground plane y = 0.

**Landmarks**: joint positions from DeepMimic's forward kinematics (``p_child = p_parent
+ R_parent · attach``); pelvis = mid-point of the hips; lumbar = chest joint, neck = neck
joint; head top = neck joint + the neck body's sphere centre + its radius (along the neck
body's up axis); sternum = the chest sphere's front (centre + radius along x); hand tip =
wrist + the wrist sphere's diameter along the forearm. Feet: the ankle body is a box;
heel = back-bottom edge centre, toe = front-bottom edge centre, metatarsal heads = 72 %
of the way heel -> toe, 2 cm above the sole (the box is rigid: ``toes`` gets the foot's
orientation and the fitted mtp angles stay ≈ 0).

**Orientations**: root -> pelvis; chest -> abdomen, thorax (and clavicles); neck -> head;
hip -> thigh; knee -> shank; ankle -> foot and toes; shoulder -> upper arm; elbow ->
forearm and hand (the wrist is fixed).

**Masses** from ``BodyDefs`` (45 kg for humanoid3d): root -> pelvis, chest -> abdomen +
thorax + clavicles (Winter ratios 0.139 : 0.196 : 0.01 : 0.01), neck -> head, hip -> thigh,
knee -> shank, ankle -> foot + toes (0.8 : 0.2), shoulder -> upper arm, elbow -> forearm,
wrist -> hand. Inertias: the capture skeleton's ellipsoids (DeepMimic gives shapes, not
inertias). ``"Loop": "wrap"`` is recorded as ``capture.source["loop"]``, which
:func:`solver.gait.extract_cycle` uses to unroll the clip.
"""

from __future__ import annotations

import json
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
from solver.io.readers import TrialError
from solver.io.track import SkeletonTrack, add_pelvis, rescaled_masses, split_mass
from solver.rig import SkeletonRig

log = logging.getLogger(__name__)

__all__ = ["DeepMimicError", "DeepMimicSkeleton", "deepmimic_track", "load_deepmimic", "read_deepmimic_character"]

C_DM = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
_DOF = {"none": 0, "fixed": 0, "spherical": 4, "revolute": 1}


class DeepMimicError(InputError):
    """A DeepMimic file is unreadable or inconsistent; the message names the problem."""


@dataclass(frozen=True, eq=False)
class DeepMimicSkeleton:
    names: tuple[str, ...]
    types: tuple[str, ...]
    parents: tuple[int, ...]
    attach: np.ndarray  # (J, 3) joint position in the parent frame
    bodies: Mapping[str, Mapping[str, Any]]  # body name -> BodyDefs entry

    @property
    def frame_size(self) -> int:
        return 1 + 7 + sum(_DOF[t] for t, p in zip(self.types, self.parents) if p >= 0)

    def body_mass(self, name: str) -> float:
        return float(self.bodies[name].get("Mass", 0.0))


def _load_json(path: str | Path, what: str) -> Any:
    p = Path(path)
    if not p.is_file():
        raise DeepMimicError(f"{what} file not found: {p}")
    try:
        return json.loads(p.read_text())
    except json.JSONDecodeError as e:
        raise DeepMimicError(f"{p}: not valid JSON ({e})") from None


def read_deepmimic_character(path: str | Path) -> DeepMimicSkeleton:
    d = _load_json(path, "DeepMimic character")
    try:
        joints = d["Skeleton"]["Joints"]
    except (KeyError, TypeError):
        raise DeepMimicError(f"{path}: no Skeleton.Joints (is this a DeepMimic character file?)") from None
    joints = sorted(joints, key=lambda j: int(j["ID"]))
    names, types, parents, attach = [], [], [], []
    for k, j in enumerate(joints):
        if int(j["ID"]) != k:
            raise DeepMimicError(f"{path}: joint IDs must be 0..J-1 in order")
        t = str(j.get("Type", "")).lower()
        if t not in _DOF:
            raise DeepMimicError(f"{path}: joint {j.get('Name')!r} has unsupported type {t!r} (known: {sorted(_DOF)})")
        if any(abs(float(j.get(f"AttachTheta{a}", 0.0))) > 1e-9 for a in "XYZ"):
            raise DeepMimicError(f"{path}: joint {j.get('Name')!r} has a rotated attach frame (not supported)")
        par = int(j["Parent"])
        if par >= k:
            raise DeepMimicError(f"{path}: joint {j.get('Name')!r} is listed before its parent")
        names.append(str(j["Name"]))
        types.append(t)
        parents.append(par)
        attach.append([float(j[f"Attach{a}"]) for a in "XYZ"])
    bodies = {str(b["Name"]): b for b in d.get("BodyDefs", [])}
    return DeepMimicSkeleton(tuple(names), tuple(types), tuple(parents), np.array(attach), bodies)


def _quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """(T, 4) quaternions w, x, y, z -> (T, 3, 3), normalized."""
    n = np.linalg.norm(q, axis=1)
    if np.any(n < 1e-6):
        raise DeepMimicError(f"zero-norm quaternion at frame {int(np.argmax(n < 1e-6))}")
    return sp.quaternion_to_matrix(q[:, [1, 2, 3, 0]])


def _rotz(a: np.ndarray) -> np.ndarray:
    return sp.elementary_rotation(2, a)


def _forward(sk: DeepMimicSkeleton, frames: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World rotation (J, T, 3, 3) and position (J, T, 3) of every joint frame (DeepMimic axes)."""
    T = frames.shape[0]
    J = len(sk.names)
    R = np.zeros((J, T, 3, 3))
    P = np.zeros((J, T, 3))
    col = 8
    for j in range(J):
        t = sk.types[j]
        if sk.parents[j] < 0:
            P[j] = frames[:, 1:4]
            R[j] = _quat_to_matrix(frames[:, 4:8])
            continue
        par = sk.parents[j]
        if t == "spherical":
            loc = _quat_to_matrix(frames[:, col:col + 4])
        elif t == "revolute":
            loc = _rotz(frames[:, col])
        else:
            loc = np.broadcast_to(np.eye(3), (T, 3, 3))
        col += _DOF[t]
        P[j] = P[par] + np.einsum("tij,j->ti", R[par], sk.attach[j])
        R[j] = R[par] @ loc
    return R, P


def _shape(sk: DeepMimicSkeleton, name: str) -> Mapping[str, Any]:
    if name not in sk.bodies:
        raise DeepMimicError(f"character has no body definition for {name!r}")
    return sk.bodies[name]


def deepmimic_track(motion: str | Path, character: str | Path, *, mass: float | None = None) -> SkeletonTrack:
    sk = read_deepmimic_character(character)
    need = ["root", "chest", "neck"] + [f"{s}_{j}" for s in ("right", "left")
                                         for j in ("hip", "knee", "ankle", "shoulder", "elbow", "wrist")]
    missing = [n for n in need if n not in sk.names]
    if missing:
        raise DeepMimicError(f"{character}: the importer needs the humanoid joints {missing}")
    d = _load_json(motion, "DeepMimic motion")
    if not isinstance(d, dict) or "Frames" not in d:
        raise DeepMimicError(f"{motion}: no 'Frames' (is this a DeepMimic motion file?)")
    try:
        frames = np.array(d["Frames"], dtype=float)
    except (TypeError, ValueError):
        raise DeepMimicError(f"{motion}: 'Frames' must be a list of equally long numeric lists") from None
    if frames.ndim != 2 or frames.shape[0] < 2:
        raise DeepMimicError(f"{motion}: a clip needs at least 2 frames, got {frames.shape[0] if frames.ndim else 0}")
    if frames.shape[1] != sk.frame_size:
        raise DeepMimicError(f"{motion}: frames have {frames.shape[1]} values but the character {character} "
                             f"needs {sk.frame_size} (model/motion mismatch)")
    if not np.all(np.isfinite(frames)):
        r = int(np.argwhere(~np.isfinite(frames))[0, 0])
        raise DeepMimicError(f"{motion}: frame {r} contains NaN/inf")
    dt = frames[:, 0]
    if np.any(dt[:-1] <= 0):
        raise DeepMimicError(f"{motion}: frame durations must be positive (frame {int(np.argmax(dt[:-1] <= 0))})")
    times = np.concatenate([[0.0], np.cumsum(dt[:-1])])
    R, P = _forward(sk, frames)
    ji = {n: k for k, n in enumerate(sk.names)}

    def pos(j: str, local=(0.0, 0.0, 0.0)) -> np.ndarray:  # ours, (3, T)
        p = P[ji[j]] + np.einsum("tij,j->ti", R[ji[j]], np.asarray(local, dtype=float))
        return (p @ C_DM.T).T

    def rot(j: str) -> np.ndarray:  # ours, (3, 3, T)
        return np.moveaxis(C_DM @ R[ji[j]] @ C_DM.T, 0, -1)

    def sphere_top(body: str, axis: int) -> np.ndarray:
        b = _shape(sk, body)
        centre = np.array([float(b.get(f"Attach{a}", 0.0)) for a in "XYZ"])
        r = 0.5 * float(b.get("Param0", 0.0))
        centre[axis] += r
        return centre

    lm: dict[str, np.ndarray] = {}
    ori: dict[str, np.ndarray] = {}
    for s, side in (("r", "right"), ("l", "left")):
        lm[f"hip_{s}"] = pos(f"{side}_hip")
        lm[f"knee_{s}"] = pos(f"{side}_knee")
        lm[f"ankle_{s}"] = pos(f"{side}_ankle")
        foot = _shape(sk, f"{side}_ankle")
        if str(foot.get("Shape")) != "box":
            raise DeepMimicError(f"{character}: the {side} ankle body must be a box (got {foot.get('Shape')!r})")
        c = np.array([float(foot.get(f"Attach{a}", 0.0)) for a in "XYZ"])
        size = np.array([float(foot.get(f"Param{i}", 0.0)) for i in range(3)])
        heel = c + np.array([-size[0] / 2, -size[1] / 2, 0.0])
        toe = c + np.array([size[0] / 2, -size[1] / 2, 0.0])
        mtp = heel + 0.72 * (toe - heel) + np.array([0.0, 0.02, 0.0])
        lm[f"heel_{s}"] = pos(f"{side}_ankle", heel)
        lm[f"toe_{s}"] = pos(f"{side}_ankle", toe)
        lm[f"mtp_{s}"] = pos(f"{side}_ankle", mtp)
        lm[f"shoulder_{s}"] = pos(f"{side}_shoulder")
        lm[f"elbow_{s}"] = pos(f"{side}_elbow")
        lm[f"wrist_{s}"] = pos(f"{side}_wrist")
        wr = _shape(sk, f"{side}_wrist")
        lm[f"hand_{s}"] = pos(f"{side}_wrist", (0.0, -float(wr.get("Param0", 0.08)), 0.0))
        ori[f"thigh_{s}"] = rot(f"{side}_hip")
        ori[f"shank_{s}"] = rot(f"{side}_knee")
        ori[f"foot_{s}"] = ori[f"toes_{s}"] = rot(f"{side}_ankle")
        ori[f"upper_arm_{s}"] = rot(f"{side}_shoulder")
        ori[f"forearm_{s}"] = ori[f"hand_{s}"] = rot(f"{side}_elbow")
        ori[f"clavicle_{s}"] = rot("chest")
    add_pelvis(lm)
    lm["lumbar"] = pos("chest")
    lm["neck"] = pos("neck")
    lm["head_top"] = pos("neck", sphere_top("neck", 1))
    lm["sternum"] = pos("chest", sphere_top("chest", 0))
    ori["pelvis"] = rot("root")
    ori["abdomen"] = ori["thorax"] = rot("chest")
    ori["head"] = rot("neck")

    bm = {n: sk.body_mass(n) for n in sk.bodies}
    total = float(sum(bm.values()))
    if total <= 0:
        raise DeepMimicError(f"{character}: BodyDefs give no mass")
    chest_split = {"abdomen": 0.139, "thorax": 0.196, "clavicle_r": 0.01, "clavicle_l": 0.01}
    seg_mass: dict[str, float] = {"pelvis": bm.get("root", 0.0), "head": bm.get("neck", 0.0)}
    split_mass(bm.get("chest", 0.0), chest_split, into=seg_mass)
    for s, side in (("r", "right"), ("l", "left")):
        seg_mass[f"thigh_{s}"] = bm.get(f"{side}_hip", 0.0)
        seg_mass[f"shank_{s}"] = bm.get(f"{side}_knee", 0.0)
        seg_mass[f"foot_{s}"] = 0.8 * bm.get(f"{side}_ankle", 0.0)
        seg_mass[f"toes_{s}"] = 0.2 * bm.get(f"{side}_ankle", 0.0)
        seg_mass[f"upper_arm_{s}"] = bm.get(f"{side}_shoulder", 0.0)
        seg_mass[f"forearm_{s}"] = bm.get(f"{side}_elbow", 0.0)
        seg_mass[f"hand_{s}"] = bm.get(f"{side}_wrist", 0.0)
    if mass is not None:
        if not (np.isfinite(mass) and mass > 0):
            raise DeepMimicError(f"mass must be a positive number of kg, got {mass}")
        seg_mass, total = rescaled_masses(seg_mass, total, mass)
    loop = str(d.get("Loop", "none")).lower()
    return SkeletonTrack(
        times=times, landmarks=lm, orientations=ori,
        frame=GroundFrame(R=C_DM.T, axes="DeepMimic: x forward, y up, z right"),
        mass=total, segment_masses=seg_mass,
        source={"format": "deepmimic", "motion": str(Path(motion).resolve()),
                "character": str(Path(character).resolve()), "loop": loop,
                "mass_from": "given" if mass is not None else "character file"},
    )


def json_kind(path: Path) -> str | None:
    """What a DeepMimic JSON file is, from its content: ``"motion"`` (``Frames``),
    ``"character"`` (``Skeleton``), or None (not JSON, or neither)."""
    try:
        d = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    if isinstance(d, dict) and "Frames" in d:
        return "motion"
    if isinstance(d, dict) and "Skeleton" in d:
        return "character"
    return None


def trial_files(paths: list[Path]) -> dict[str, Path]:
    """A DeepMimic trial is one motion file and one character file, told apart by their
    content (the reader registry's ``trial_files``)."""
    kinds = {p: json_kind(p) for p in paths}
    motions = [p for p, k in kinds.items() if k == "motion"]
    chars = [p for p, k in kinds.items() if k == "character"]
    if len(motions) == 1 and len(chars) == 1 and len(paths) == 2:
        return {"motion": motions[0], "character": chars[0]}
    raise TrialError(
        "a DeepMimic trial is one motion file (JSON with 'Frames') and one character file (JSON with "
        f"'Skeleton'); got {[p.name + ': ' + (k or 'not DeepMimic JSON') for p, k in kinds.items()]}"
    )


def load_deepmimic(
    motion: str | Path, character: str | Path, *, mass: float | None = None, lower_only: bool | None = None
) -> Capture:
    """Import a DeepMimic clip as a :class:`Capture` (conventions in the module doc), with the
    character's own skeleton as its rig (:func:`deepmimic_rig`)."""
    track = deepmimic_track(motion, character, mass=mass)
    capture = fit_track(track, lower_only=lower_only)
    return capture.evolve(rig=deepmimic_rig(read_deepmimic_character(character), motion, track))


#: DeepMimic humanoid joint -> the capture segment it moves (the ankle's box carries the toes,
#: the wrist is fixed: neither drives a segment of its own)
RIG_ROLES = {"root": "pelvis", "chest": "abdomen", "neck": "head",
             **{f"{side}_{j}": f"{seg}_{side[0]}" for side in ("right", "left") for j, seg in (
                 ("hip", "thigh"), ("knee", "shank"), ("ankle", "foot"), ("shoulder", "upper_arm"),
                 ("elbow", "forearm"))}}
#: DeepMimic joint type -> its "channels" in a rig (what a frame holds for it)
RIG_CHANNELS = {"spherical": ("quaternion",), "revolute": ("Zrotation",), "fixed": (), "none": ()}


def deepmimic_rig(sk: DeepMimicSkeleton, motion: str | Path, track: SkeletonTrack) -> SkeletonRig:
    """The character's skeleton and the clip's local rotations as a :class:`solver.rig.SkeletonRig`
    (DeepMimic axes, metres), with its ``BodyDefs`` (shapes for a GLB of the character) and the
    clip's loop mode in ``extra``."""
    frames = np.array(_load_json(motion, "DeepMimic motion")["Frames"], dtype=float)
    T, J = frames.shape[0], len(sk.names)
    local = np.empty((T, J, 3, 3))
    col = 8
    for j in range(J):
        t = sk.types[j]
        if sk.parents[j] < 0:
            local[:, j] = _quat_to_matrix(frames[:, 4:8])
            continue
        if t == "spherical":
            local[:, j] = _quat_to_matrix(frames[:, col:col + 4])
        elif t == "revolute":
            local[:, j] = _rotz(frames[:, col])
        else:
            local[:, j] = np.eye(3)
        col += _DOF[t]
    channels = tuple(("Xposition", "Yposition", "Zposition", "quaternion") if sk.parents[j] < 0
                     else RIG_CHANNELS[sk.types[j]] for j in range(J))
    roles = {seg: sk.names.index(j) for j, seg in RIG_ROLES.items() if j in sk.names}
    body_defs = {n: dict(b) for n, b in sk.bodies.items()}
    return SkeletonRig("deepmimic", sk.names, sk.parents, sk.attach, channels, roles, track.times, local,
                       frames[:, 1:4], track.frame,
                       extra={"frame_time": float(np.median(frames[:-1, 0])), "types": list(sk.types),
                              "body_defs": body_defs, "loop": track.source.get("loop", "none")})
