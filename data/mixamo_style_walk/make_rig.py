"""Retarget the CMU straight walk (``data/cmu16_bvh/16_15_walk.bvh``) onto rigs that are not CMU's.

Run with the project's venv (deterministic; rewrites the files next to this script and prints
the check figures)::

    .venv/bin/python data/mixamo_style_walk/make_rig.py

Two rigs (README.md says what differs from the CMU clip):

- ``walk.bvh``: Mixamo names (``mixamorig:`` namespace), Hips -> Spine -> Spine1 -> Spine2 ->
  Neck -> Head -> HeadTop_End, clavicles, T-pose arms, an index finger, legs spread 3° at rest,
  toes ending in LeftToe_End; centimetres, Y up, the subject scaled by 1.08, 60 fps; the root
  has 6 channels (position, then Z X Y rotation), every other joint 3 (Z X Y).
- ``walk_unreal_style.bvh``: Unreal mannequin names (root, pelvis, spine_01..03, neck_01,
  head, clavicle_l, upperarm_l, lowerarm_l, hand_l, thigh_l, calf_l, foot_l, ball_l), A-pose
  arms; metres, Z up, the subject scaled by 0.95, 30 fps; a static ``root`` at the floor and a
  ``pelvis`` with 6 channels (position relative to the root, then Z X Y rotation; OFFSET 0).

**How the motion is carried over.** Every target joint k is driven by a CMU joint s(k) (or,
for a joint the CMU skeleton does not have, a fraction of the rotation between two CMU
joints: Spine/Spine1/Spine2 share the pelvis -> thorax rotation, Neck takes half of thorax ->
head). Its points are given in the CMU rest pose (where they sit on the CMU bodies) and its
rest orientation by C_k, the rotation from the target bone's rest frame to the CMU bone's rest
frame (T-pose arm: 90° about the facing axis). Then, frame by frame, the target bone's world
rotation is W_k = W_s(k) · C_k, and its rest offsets are C_parentᵀ · (point - parent point) ·
scale: every target joint that sits on a CMU body follows that body exactly, scaled; joints above a
split follow it up to the split's bend: a split shares out the rotation's deviation from its
mean over the clip (the trunk's lateral bending and twist, ±6°), which moves the neck, head and
shoulders by up to 1.5 cm (0.8 cm on average) from the CMU ones. Frames: CMU local
rotations interpolated by a rotation spline and the root position by a cubic spline at the
new rate (the CMU frames are kept exactly at their own times).
"""

from __future__ import annotations

import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation, RotationSpline

HERE = Path(__file__).resolve().parent
SOURCE = HERE.parent / "cmu16_bvh" / "16_15_walk.bvh"
sys.path.insert(0, str(HERE.parents[1]))  # the repository (solver.io.bvh reads the CMU clip)

from solver.io.bvh import BvhClip, read_bvh  # noqa: E402


@dataclass(frozen=True)
class Joint:
    name: str
    parent: str | None
    #: where the joint sits in the CMU rest pose (cm, CMU axes: Y up, facing +Z, left +X)
    at: tuple[float, float, float]
    #: the CMU joint whose rotation drives it; or (from, to, fraction, lean) for a split rotation:
    #: W_from · R̄^lean · D^fraction, where R̄ is the clip's mean from -> to rotation and D the
    #: rest of it (lean 1: the constant part here, for joints whose points ride the "to" body)
    driver: str | tuple[str, str, float, float]
    #: the bone's rest orientation: degrees about Z (facing axis), then about X, of C (target
    #: rest frame -> CMU rest frame)
    rest_z: float = 0.0
    end: tuple[float, float, float] | None = None  # End Site position (CMU rest pose, cm)


def _cmu_rest(clip: BvhClip) -> dict[str, np.ndarray]:
    _, P = clip.forward(np.zeros((1, clip.motion.shape[1])))
    return {n: P[j, 0] for j, n in enumerate(clip.names)}


def mixamo(rest: dict[str, np.ndarray]) -> list[Joint]:
    """The Mixamo-style skeleton, its joints placed on the CMU rest pose."""
    th = rest["thorax"]
    joints = [
        Joint("mixamorig:Hips", None, (0.0, 7.0, -1.0), "pelvis"),
        Joint("mixamorig:Spine", "mixamorig:Hips", tuple(th), ("pelvis", "thorax", 1 / 3, 1.0)),
        Joint("mixamorig:Spine1", "mixamorig:Spine", tuple(th + [0, 11.0, 0]), ("pelvis", "thorax", 2 / 3, 1.0)),
        Joint("mixamorig:Spine2", "mixamorig:Spine1", tuple(th + [0, 23.0, 0]), "thorax"),
        Joint("mixamorig:Neck", "mixamorig:Spine2", tuple(th + [0, 37.8, 1.0]), ("thorax", "head", 0.5, 0.0)),
        Joint("mixamorig:Head", "mixamorig:Neck", tuple(rest["head"]), "head"),
        Joint("mixamorig:HeadTop_End", "mixamorig:Head", tuple(rest["head"] + [0, 5.0, 0]), "head",
              end=tuple(rest["head"] + [0, 6.0, 0])),
    ]
    for side, cs, sx in (("Left", "l", 1.0), ("Right", "r", -1.0)):
        p = f"mixamorig:{side}"
        clav, hum = rest[f"{cs}clavicle"], rest[f"{cs}humerus"]
        rad, hand = rest[f"{cs}radius"], rest[f"{cs}hand"]
        tip = hand + [0, -5.0, 0]  # the CMU hand's End Site
        tz = -90.0 * sx  # T-pose: the arm along ±X at rest, down in the CMU rest pose
        joints += [
            Joint(f"{p}Shoulder", "mixamorig:Spine2", tuple(clav + [3.0 * sx, 0, 0]), f"{cs}clavicle"),
            Joint(f"{p}Arm", f"{p}Shoulder", tuple(hum), f"{cs}humerus", rest_z=tz),
            Joint(f"{p}ForeArm", f"{p}Arm", tuple(rad), f"{cs}radius", rest_z=tz),
            Joint(f"{p}Hand", f"{p}ForeArm", tuple(hand), f"{cs}hand", rest_z=tz),
            Joint(f"{p}HandIndex1", f"{p}Hand", tuple(tip), f"{cs}hand", rest_z=tz),
            Joint(f"{p}HandIndex2", f"{p}HandIndex1", tuple(tip + [0, -3.5, 0]), f"{cs}hand", rest_z=tz),
            Joint(f"{p}HandIndex3", f"{p}HandIndex2", tuple(tip + [0, -6.0, 0]), f"{cs}hand", rest_z=tz,
                  end=tuple(tip + [0, -8.0, 0])),
        ]
        spread = 3.0 * sx  # legs 3° apart at rest
        toes = rest[f"{cs}toes"]
        joints += [
            Joint(f"{p}UpLeg", "mixamorig:Hips", tuple(rest[f"{cs}femur"]), f"{cs}femur", rest_z=-spread),
            Joint(f"{p}Leg", f"{p}UpLeg", tuple(rest[f"{cs}tibia"]), f"{cs}tibia", rest_z=-spread),
            Joint(f"{p}Foot", f"{p}Leg", tuple(rest[f"{cs}foot"]), f"{cs}foot"),
            Joint(f"{p}ToeBase", f"{p}Foot", tuple(toes), f"{cs}toes"),
            Joint(f"{p}Toe_End", f"{p}ToeBase", tuple(toes + [0, 0, 5.0]), f"{cs}toes",
                  end=tuple(toes + [0, 0, 6.0])),
        ]
    return _depth_first(joints)


def unreal(rest: dict[str, np.ndarray]) -> list[Joint]:
    """The Unreal-mannequin-style skeleton (static root at the floor), on the CMU rest pose."""
    th = rest["thorax"]
    floor = np.array([0.0, rest["lfoot"][1], 0.0])  # the rest pose's sole level (CMU feet are level)
    joints = [
        Joint("root", None, tuple(floor), "floor"),
        Joint("pelvis", "root", (0.0, 2.0, -2.0), "pelvis"),
        Joint("spine_01", "pelvis", tuple(th), ("pelvis", "thorax", 0.5, 1.0)),
        Joint("spine_02", "spine_01", tuple(th + [0, 14.0, 0]), "thorax"),
        Joint("spine_03", "spine_02", tuple(th + [0, 27.0, 0]), "thorax"),
        Joint("neck_01", "spine_03", tuple(th + [0, 38.5, 0.5]), "thorax"),
        Joint("head", "neck_01", tuple(rest["head"]), "head", end=tuple(rest["head"] + [0, 5.0, 0])),
    ]
    for cs, sx in (("l", 1.0), ("r", -1.0)):
        clav, tip = rest[f"{cs}clavicle"], rest[f"{cs}hand"] + [0, -5.0, 0]
        tz = -45.0 * sx  # A-pose arms
        joints += [
            Joint(f"clavicle_{cs}", "spine_03", tuple(clav + [2.0 * sx, 0, 1.0]), f"{cs}clavicle"),
            Joint(f"upperarm_{cs}", f"clavicle_{cs}", tuple(rest[f"{cs}humerus"]), f"{cs}humerus", rest_z=tz),
            Joint(f"lowerarm_{cs}", f"upperarm_{cs}", tuple(rest[f"{cs}radius"]), f"{cs}radius", rest_z=tz),
            Joint(f"hand_{cs}", f"lowerarm_{cs}", tuple(rest[f"{cs}hand"]), f"{cs}hand", rest_z=tz, end=tuple(tip)),
            Joint(f"thigh_{cs}", "pelvis", tuple(rest[f"{cs}femur"]), f"{cs}femur"),
            Joint(f"calf_{cs}", f"thigh_{cs}", tuple(rest[f"{cs}tibia"]), f"{cs}tibia"),
            Joint(f"foot_{cs}", f"calf_{cs}", tuple(rest[f"{cs}foot"]), f"{cs}foot"),
            Joint(f"ball_{cs}", f"foot_{cs}", tuple(rest[f"{cs}toes"]), f"{cs}toes",
                  end=tuple(rest[f"{cs}toes"] + [0, 0, 5.0])),
        ]
    return _depth_first(joints)


def _depth_first(joints: list[Joint]) -> list[Joint]:
    by_parent: dict[str | None, list[Joint]] = {}
    for j in joints:
        by_parent.setdefault(j.parent, []).append(j)
    out: list[Joint] = []

    def visit(j: Joint) -> None:
        out.append(j)
        for c in by_parent.get(j.name, []):
            visit(c)

    for r in by_parent[None]:
        visit(r)
    return out


def resampled_cmu(clip: BvhClip, fps: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The CMU clip at ``fps``: times, world rotations (J, T, 3, 3), world positions (J, T, 3),
    from its local rotations (rotation spline) and root position (cubic spline)."""
    T = clip.T
    t_src = np.arange(T) * clip.frame_time
    n = int(np.floor(t_src[-1] * fps + 1e-3)) + 1  # the last CMU frame too (its time is rounded)
    t = np.arange(n) / fps
    J = len(clip.names)
    R = np.zeros((J, n, 3, 3))
    P = np.zeros((J, n, 3))
    for j in range(J):
        loc_R, loc_p = clip.local(j)
        Rj = RotationSpline(t_src, Rotation.from_matrix(loc_R))(t).as_matrix()
        pj = CubicSpline(t_src, loc_p, axis=0)(t) if clip.parents[j] < 0 else np.broadcast_to(loc_p[0], (n, 3))
        par = clip.parents[j]
        if par < 0:
            R[j], P[j] = Rj, pj
        else:
            R[j] = R[par] @ Rj
            P[j] = P[par] + np.einsum("tij,tj->ti", R[par], pj)
    return t, R, P


def _C(j: Joint) -> np.ndarray:
    return Rotation.from_euler("z", j.rest_z, degrees=True).as_matrix()


def retarget(joints: list[Joint], clip: BvhClip, fps: float, scale: float, axes: np.ndarray,
             positioned: set[str]) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray],
                                            dict[str, np.ndarray], dict[str, np.ndarray]]:
    """Times, rest offsets, End Site offsets (target units and axes), local rotations (T, 3, 3)
    and local positions (T, 3; for the root and the ``positioned`` joints) per target joint.

    ``axes``: target axes from CMU axes (rotation); ``scale``: target units per CMU cm."""
    rest = _cmu_rest(clip)
    idx = {n: j for j, n in enumerate(clip.names)}
    t, Rs, Ps = resampled_cmu(clip, fps)
    n = t.size
    floor_at = next((np.array(j.at) for j in joints if j.driver == "floor"), np.zeros(3))

    def body(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """A CMU body's world rotation, position and rest position; "floor": the world, its
        origin (the CMU floor) at the rest point of the joint it drives."""
        if name == "floor":
            return np.broadcast_to(np.eye(3), (n, 3, 3)), np.zeros((n, 3)), floor_at
        return Rs[idx[name]], Ps[idx[name]], rest[name]

    def driven(j: Joint) -> np.ndarray:
        if isinstance(j.driver, str):
            return body(j.driver)[0]
        a, b, f, lean = j.driver
        Ra, Rb = body(a)[0], body(b)[0]
        rel = Rotation.from_matrix(np.einsum("tji,tjk->tik", Ra, Rb))
        mean = rel.mean()
        rest_of_it = (mean.inv() * rel).as_rotvec()
        const = Rotation.from_rotvec(lean * mean.as_rotvec())
        return Ra @ (const * Rotation.from_rotvec(f * rest_of_it)).as_matrix()

    by_name = {j.name: j for j in joints}
    W = {j.name: driven(j) @ _C(j) for j in joints}  # world rotations, CMU axes
    offsets, ends, local_R, local_p = {}, {}, {}, {}
    for j in joints:
        at = np.array(j.at)
        Wt = np.einsum("ij,tjk,lk->til", axes, W[j.name], axes)  # in target axes: A W Aᵀ
        if j.parent is None:  # OFFSET 0, the position channels give the world position
            assert isinstance(j.driver, str)
            Rb, Pb, Xb = body(j.driver)
            local_R[j.name] = Wt
            local_p[j.name] = (Pb + np.einsum("tij,j->ti", Rb, at - Xb)) @ axes.T * scale
            offsets[j.name] = np.zeros(3)
        else:
            par = by_name[j.parent]
            off = _C(par).T @ (at - np.array(par.at))  # the offset in the parent's rest frame (CMU axes)
            offsets[j.name] = axes @ off * scale
            Wp = np.einsum("ij,tjk,lk->til", axes, W[par.name], axes)
            local_R[j.name] = np.einsum("tji,tjk->tik", Wp, Wt)
            if j.name in positioned:  # position channels: where its driver's body puts it, from the rest offset
                assert isinstance(j.driver, str) and isinstance(par.driver, str)
                Rb, Pb, Xb = body(par.driver)
                rb, pb, xb = body(j.driver)
                world = pb + np.einsum("tij,j->ti", rb, at - xb)
                parent_world = Pb + np.einsum("tij,j->ti", Rb, np.array(par.at) - Xb)
                rel = np.einsum("tji,tj->ti", W[par.name], world - parent_world)  # in the parent's frame
                local_p[j.name] = rel @ axes.T * scale
                offsets[j.name] = np.zeros(3)  # readers that add the channels to OFFSET and readers that
                # replace OFFSET by them (bvhio, Blender) then agree
        if j.end is not None:
            ends[j.name] = axes @ (_C(j).T @ (np.array(j.end) - at)) * scale
    return t, offsets, ends, local_R, local_p


def write_bvh(path: Path, joints: list[Joint], t: np.ndarray, offsets: dict[str, np.ndarray],
              ends: dict[str, np.ndarray], local_R: dict[str, np.ndarray], local_p: dict[str, np.ndarray],
              decimals: int) -> None:
    kids: dict[str | None, list[Joint]] = {}
    for j in joints:
        kids.setdefault(j.parent, []).append(j)
    lines = ["HIERARCHY"]
    cols: list[np.ndarray] = []
    fmt = f"{{:.{decimals}f}}"

    def vec(v: np.ndarray) -> str:
        return " ".join(fmt.format(x) for x in v)

    def emit(j: Joint, depth: int) -> None:
        ind = "\t" * depth
        lines.append(f"{ind}{'ROOT' if j.parent is None else 'JOINT'} {j.name}")
        lines.append(f"{ind}{{")
        if j.name in local_p:  # position channels: added to the OFFSET
            lines.append(f"{ind}\tOFFSET {vec(offsets[j.name])}")
            lines.append(f"{ind}\tCHANNELS 6 Xposition Yposition Zposition Zrotation Xrotation Yrotation")
            cols.append(local_p[j.name] - offsets[j.name])
        else:
            lines.append(f"{ind}\tOFFSET {vec(offsets[j.name])}")
            lines.append(f"{ind}\tCHANNELS 3 Zrotation Xrotation Yrotation")
        eul = Rotation.from_matrix(local_R[j.name]).as_euler("ZXY", degrees=True)
        cols.append(np.unwrap(eul, period=360.0, axis=0))
        for c in kids.get(j.name, []):
            emit(c, depth + 1)
        if j.name in ends:
            lines.extend([f"{ind}\tEnd Site", f"{ind}\t{{", f"{ind}\t\tOFFSET {vec(ends[j.name])}", f"{ind}\t}}"])
        lines.append(f"{ind}}}")

    emit(joints[0], 0)
    motion = np.concatenate(cols, axis=1)
    motion[np.abs(motion) < 0.5 * 10.0**-decimals] = 0.0  # no "-0.0000"
    lines += ["MOTION", f"Frames: {t.size}", f"Frame Time: {t[1] - t[0]:.7f}"]
    lines += [" ".join(fmt.format(x) for x in row) for row in motion]
    path.write_text("\n".join(lines) + "\n")


def check(path: Path, clip: BvhClip, scale: float, axes: np.ndarray, pairs: dict[str, str],
          fps: float) -> dict[str, float]:
    """Max distance (cm of the CMU subject scaled: ``scale`` target units per CMU cm) between the
    written file's joints and the CMU joints they sit on, scaled and turned into the target axes:
    at the CMU's own frames (against the CMU file) and at every frame (against the resampled CMU)."""
    out = read_bvh(path)
    _, Pt = out.forward()
    _, Ps = clip.forward()
    _, _, Pr = resampled_cmu(clip, fps)
    step = round(fps * clip.frame_time)
    names = {n: j for j, n in enumerate(out.names)}
    src = {n: j for j, n in enumerate(clip.names)}
    common = all_frames = 0.0
    for tgt, s in pairs.items():
        a = Pt[names[tgt]]
        b_common = Ps[src[s]] @ axes.T * scale
        b_all = Pr[src[s]] @ axes.T * scale
        m = min(a[::step].shape[0], b_common.shape[0])
        common = max(common, float(np.abs(a[::step][:m] - b_common[:m]).max()))
        all_frames = max(all_frames, float(np.abs(a - b_all).max()))
    return {"common_frames_max": common / scale, "all_frames_max": all_frames / scale}


def main() -> None:
    clip = read_bvh(SOURCE)
    rest = _cmu_rest(clip)
    # the Mixamo-style rig: cm, Y up (CMU axes), x1.08, 60 fps
    jm = mixamo(rest)
    scale_m = 1.08
    axes_m = np.eye(3)
    t, off, ends, lr, lp = retarget(jm, clip, 60.0, scale_m, axes_m, set())
    out_m = HERE / "walk.bvh"
    write_bvh(out_m, jm, t, off, ends, lr, lp, decimals=4)
    legs_m = {f"mixamorig:{S}{t_}": f"{s}{c}" for S, s in (("Left", "l"), ("Right", "r"))
              for t_, c in (("UpLeg", "femur"), ("Leg", "tibia"), ("Foot", "foot"), ("ToeBase", "toes"))}
    arms_m = {f"mixamorig:{S}{t_}": f"{s}{c}" for S, s in (("Left", "l"), ("Right", "r"))
              for t_, c in (("Arm", "humerus"), ("ForeArm", "radius"), ("Hand", "hand"))}
    print(f"{out_m.name}: {len(jm)} joints, {t.size} frames at 60 fps")
    print("  legs (hip, knee, ankle, toes) vs CMU x1.08, cm:", check(out_m, clip, scale_m, axes_m, legs_m, 60.0))
    print("  arms (shoulder, elbow, wrist) vs CMU x1.08, cm:", check(out_m, clip, scale_m, axes_m, arms_m, 60.0))
    print("  head (split spine and neck) vs CMU x1.08, cm:",
          check(out_m, clip, scale_m, axes_m, {"mixamorig:Head": "head"}, 60.0))
    # the Unreal-style rig: metres, Z up, x0.95, 30 fps, static root, pelvis with position channels
    ju = unreal(rest)
    scale_u = 0.95 / 100.0
    axes_u = Rotation.from_euler("x", 90, degrees=True).as_matrix()  # CMU Y up -> Z up
    t, off, ends, lr, lp = retarget(ju, clip, 1.0 / clip.frame_time, scale_u, axes_u, {"pelvis"})
    out_u = HERE / "walk_unreal_style.bvh"
    write_bvh(out_u, ju, t, off, ends, lr, lp, decimals=6)
    legs_u = {f"{t_}_{s}": f"{s}{c}" for s in "lr"
              for t_, c in (("thigh", "femur"), ("calf", "tibia"), ("foot", "foot"), ("ball", "toes"))}
    print(f"{out_u.name}: {len(ju)} joints, {t.size} frames at 30 fps")
    print("  legs vs CMU x0.95, cm:", check(out_u, clip, scale_u, axes_u, legs_u, 1.0 / clip.frame_time))


if __name__ == "__main__":
    main()
