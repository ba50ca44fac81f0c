"""Game-ready data of one clip: root motion, foot contacts, loop points, cycle metadata.

Shared by the JSON clip (``clip["game"]``) and the glTF exports (``animation.extras``);
documented in ``docs/export.md`` ("Game-ready data").

**Root motion.** The *motion root* is a ground-level frame M_t per frame: origin at the
root segment's horizontal position (x_t, y_t, h_t), heading ψ_t about the up axis (h_t = 0, or
on stairs the cycle's rise spread evenly over the cycle, h_t = rise · t / P). The
heading turns at the cycle's constant rate, ψ_t = ψ_0 + Δψ · t / P, from the root's yaw at
frame 0 (ψ_0) to its yaw one cycle later (ψ_0 + Δψ, frame P), so a curved walk's motion root
turns smoothly while the pelvis keeps its own yaw oscillation. The *in-place* animation is
the pose relative to M_t: world = M_t ∘ in-place. Only the root segment differs between the
two (every other segment's transform is local to its parent): the in-place root sits at
(0, 0, z_t − h_t) with rotation R_z(yaw_t − ψ_t) · (the rest of its rotation). In an export's
world (:mod:`solver.export.world`: a slope's ground frame turned so that gravity points down)
the motion root is that world's rotation W times M_t: its yaw turns about the ground's normal
(``up``) and ``tilt`` is W.

**Loop.** A cyclic motion of the spacetime solver has T = P + 2 frames: frames P and P + 1
repeat frames 0 and 1 (joints, root height, pitch, roll) and the root's horizontal velocity
and yaw rate are periodic in the walker's heading frame. The loop is frames 0 … P (P frames
of duration, the last key equal to the first under the loop transform L = M_P ∘ M_0⁻¹: a
planar rotation by Δψ and a translation, raised by the cycle's rise on stairs). ``closure``
measures it: the largest distance between a segment origin at frame P and L applied to it at frame 0, and the largest
difference of the in-place coordinates (joints, root height, pitch, roll). A motion whose
closure exceeds :data:`LOOP_TOLERANCE_M` / :data:`LOOP_TOLERANCE_RAD` is reported as not
looping (``loop.seamless`` false) — e.g. a raw capture.

**Foot contacts.** Per foot (right, left) and frame: ``planted`` (the contact schedule: any
of the foot's contact points on the ground), ``position`` (the mean world position of the
foot's active contact points, null in the air: the point an engine's foot lock pins),
``load`` (vertical ground reaction / body weight, when the motion has wrenches), and the
events (``plant`` / ``lift`` frames, the plant's mean position).

**Cycle.** ``speed_m_s`` (arc length of the motion root over the cycle / cycle duration; the
arc through the chord with the heading change Δψ), ``turn_rate_deg_s`` (Δψ / duration),
``slope_deg`` (from the gravity direction: gravity tilted by R_y(slope) along the walking
direction +x), ``stride_length_m`` (the chord over the cycle), gravity and friction.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from solver import kinematics
from solver.environment import STANDARD_GRAVITY_VECTOR, stair_rise
from solver.motion import FEET, Motion

#: a loop closes when the segment origins at frame P match the loop transform of frame 0 within
LOOP_TOLERANCE_M = 1e-4
#: ... and the in-place coordinates (rad or m) within
LOOP_TOLERANCE_RAD = 1e-4

#: root coordinates: x, y, z, yaw, pitch, roll (the reference characters' free joint)
ROOT_X, ROOT_Y, ROOT_Z, ROOT_YAW = 0, 1, 2, 3
ROOT_NAMES = ("root_tx", "root_ty", "root_tz", "root_rz", "root_ry", "root_rx")


def _wrap(a: np.ndarray | float) -> Any:
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def has_free_root(motion: Motion) -> bool:
    return tuple(motion.coordinate_names[:6]) == ROOT_NAMES


def loop_frames(motion: Motion) -> int:
    """P: the frame one cycle after frame 0 (T - 2 for the solver's cyclic motions), or the last
    frame when the motion is not cyclic."""
    T = motion.T
    c = motion.contacts
    cyclic = (c is not None and T >= 5 and np.array_equal(c[:, T - 2], c[:, 0])
              and np.array_equal(c[:, T - 1], c[:, 1]))
    return T - 2 if cyclic else T - 1


def rise(motion: Motion) -> float:
    """Height the walk gains over one cycle in its ground frame: the stairs' (stances × riser), else 0."""
    step = motion.environment.step_height_m
    if not step or motion.contacts is None or loop_frames(motion) != motion.T - 2:
        return 0.0
    return stair_rise(motion.foot_contact(), step)


def motion_root(motion: Motion, P: int | None = None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(xy (T, 2), heading ψ (T,), height h (T,)) of the motion root, in the ground frame (Z up)."""
    if not has_free_root(motion):
        raise ValueError(f"root motion needs the free root {ROOT_NAMES}, got {motion.coordinate_names[:6]}")
    P = loop_frames(motion) if P is None else P
    q = motion.q
    xy = q[[ROOT_X, ROOT_Y]].T.copy()
    yaw0, dpsi = float(q[ROOT_YAW, 0]), float(q[ROOT_YAW, P] - q[ROOT_YAW, 0])
    phase = np.arange(motion.T) / P
    return xy, yaw0 + dpsi * phase, rise(motion) * phase


def planar(psi: float, xy: np.ndarray, height: float = 0.0) -> np.ndarray:
    """The 4x4 homogeneous transform of a planar pose (rotation ψ about z, translation xy),
    raised by ``height``."""
    c, s = math.cos(psi), math.sin(psi)
    m = np.eye(4)
    m[:2, :2] = [[c, -s], [s, c]]
    m[:2, 3] = xy
    m[2, 3] = height
    return m


def loop_transform(motion: Motion, P: int | None = None) -> np.ndarray:
    """L = M_P ∘ M_0⁻¹ (4x4, the ground frame): maps the world pose at frame 0 onto the one at frame P."""
    P = loop_frames(motion) if P is None else P
    xy, psi, h = motion_root(motion, P)
    return planar(psi[P], xy[P], h[P]) @ np.linalg.inv(planar(psi[0], xy[0], h[0]))


def closure(motion: Motion, P: int | None = None) -> dict[str, float]:
    """How well frame P repeats frame 0 under the loop transform (see the module docstring)."""
    P = loop_frames(motion) if P is None else P
    L = loop_transform(motion, P)
    _, pos = kinematics.segment_frames(motion.character, motion.q)  # (S, 3, T)
    p0 = np.c_[pos[:, :, 0], np.ones(len(pos))] @ L.T
    dist = float(np.max(np.linalg.norm(p0[:, :3] - pos[:, :, P], axis=1)))
    q = np.array(motion.q)
    q[ROOT_Z] -= motion_root(motion, P)[2]  # in place
    rows = [i for i in range(motion.n) if i not in (ROOT_X, ROOT_Y, ROOT_YAW)]
    coord = float(np.max(np.abs(q[rows, P] - q[rows, 0]))) if rows else 0.0
    return {"position_m": dist, "coordinates": coord}


def slope_deg(environment: Mapping[str, Any] | None) -> float:
    """Ground slope along +x from a gravity vector tilted by R_y(slope): g ∝ (−sin, 0, −cos)."""
    g = (environment or {}).get("gravity") or STANDARD_GRAVITY_VECTOR
    return math.degrees(math.atan2(-float(g[0]), -float(g[2])))


def _events(planted: np.ndarray, pos: np.ndarray, P: int) -> list[dict]:
    """Plant / lift events within the loop (frames 0 … P−1; a plant that wraps around the loop
    end is one plant)."""
    out: list[dict] = []
    on = planted[:P]
    for t in range(P):
        prev = on[t - 1] if t > 0 else on[P - 1]
        if on[t] and not prev:
            frames = [t]
            k = (t + 1) % P
            while on[k] and k != t:
                frames.append(k)
                k = (k + 1) % P
            out.append({"event": "plant", "frame": t, "frames": len(frames),
                        "position": np.nanmean(pos[frames], axis=0)})
        elif prev and not on[t]:
            out.append({"event": "lift", "frame": t})
    return out


def game_data(motion: Motion, *, axes: np.ndarray | None = None, frames: int | None = None,
              world: Any = None) -> dict[str, Any]:
    """The game-ready data as plain Python values (numpy arrays for per-frame series); vectors
    are expressed with ``axes`` (3x3: e.g. ``solver.export.Y_UP``; default ours) in ``world``
    (a :class:`solver.export.world.World`; default the motion's own ground frame). ``frames``:
    keep the per-frame series of the first ``frames`` frames only (an animation of one cycle)."""
    from solver.export import matrix_to_quaternion

    F = np.eye(3) if axes is None else np.asarray(axes, dtype=float)  # our axes -> the file's
    W = np.eye(3) if world is None else np.asarray(world.rotation, dtype=float)  # ground frame -> world
    A = F @ W  # points and vectors of the ground frame -> the file
    T, fps = motion.T, float(motion.fps)
    P = loop_frames(motion)
    xy, psi, h = motion_root(motion, P)
    dur = P / fps
    cl = closure(motion, P)
    seamless = cl["position_m"] <= LOOP_TOLERANCE_M and cl["coordinates"] <= LOOP_TOLERANCE_RAD
    chord = float(np.linalg.norm(xy[P] - xy[0]))
    dpsi = float(psi[P] - psi[0])
    arc = chord if abs(dpsi) < 1e-9 else chord * (dpsi / 2.0) / math.sin(dpsi / 2.0)
    env = motion.environment.to_dict()
    g = env["gravity"]
    root_pos = np.c_[xy, h] @ A.T
    q = motion.q
    in_place_yaw = q[ROOT_YAW] - psi
    up = A @ np.array([0.0, 0.0, 1.0])
    out: dict[str, Any] = {
        "loop": {
            "start_frame": 0, "end_frame": P, "frames": P, "duration": dur, "seamless": bool(seamless),
            "closure_m": cl["position_m"], "closure_coordinates": cl["coordinates"],
            "transform": {"translation": root_pos[P] - root_pos[0], "yaw_deg": math.degrees(dpsi), "axis": up},
        },
        "root_motion": {
            "definition": "world = motion_root ∘ in_place; the motion root at translation, turned by yaw about up "
                          "(the ground's normal) at the cycle's constant turn rate, after tilt (the ground's "
                          "rotation in this world: none unless a slope is exported with gravity down)",
            "translation": root_pos,
            "yaw": psi,
            "up": up,
            "tilt": matrix_to_quaternion(F @ W @ F.T),
            "in_place_root_translation": np.c_[np.zeros((T, 2)), q[ROOT_Z] - h] @ F.T,
            "in_place_root_yaw": in_place_yaw,
        },
        "cycle": {
            "speed_m_s": arc / dur, "turn_rate_deg_s": math.degrees(dpsi) / dur,
            "slope_deg": slope_deg(env), "stride_length_m": chord, "duration_s": dur,
            "gravity_m_s2": float(np.linalg.norm(g)), "friction": float(env.get("friction", 1.0)),
        },
    }
    if motion.contacts is not None and motion.character.contacts:
        ch = motion.character
        cp = np.asarray(kinematics.contact_points(ch, motion.q))  # (C, 3, T)
        load = None
        if motion.wrenches is not None:
            load = np.clip(motion.wrenches[:, 5, :] / ch.weight, 0.0, None)  # (2, T)
        feet: dict[str, Any] = {}
        for i, foot in enumerate(FEET):
            idx = [k for k, c in enumerate(ch.contacts) if c.side == foot]
            active = motion.contacts[idx]  # (k, T)
            planted = np.asarray(active.any(axis=0))
            pos = np.full((T, 3), np.nan)
            for t in np.flatnonzero(planted):
                pos[t] = cp[[idx[k] for k in np.flatnonzero(active[:, t])], :, t].mean(axis=0)
            pos_a = pos @ A.T
            feet[foot] = {"planted": planted, "position": pos_a, "events": _events(planted, pos_a, P)}
            if load is not None:
                feet[foot]["load"] = load[i]
        out["foot_contacts"] = feet
    if frames is not None:
        rm = out["root_motion"]
        for k in ("translation", "yaw", "in_place_root_translation", "in_place_root_yaw"):
            rm[k] = rm[k][:frames]
        for f in out.get("foot_contacts", {}).values():
            for k in ("planted", "position", "load"):
                if k in f:
                    f[k] = f[k][:frames]
    return out


def _plain(x: Any, decimals: int | None) -> Any:
    if isinstance(x, dict):
        return {k: _plain(v, decimals) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_plain(v, decimals) for v in x]
    if isinstance(x, np.ndarray):
        if x.dtype == bool:
            return x.astype(int).tolist()
        if x.ndim >= 1 and np.isnan(x).any():
            return [None if np.isnan(r).any() else _plain(r, decimals) for r in x]
        x = np.round(x, decimals) + 0.0 if decimals is not None else x
        return x.tolist()
    if isinstance(x, (bool, np.bool_)):
        return bool(x)
    if isinstance(x, (float, np.floating)):
        return round(float(x), decimals) + 0.0 if decimals is not None else float(x)
    if isinstance(x, (np.integer,)):
        return int(x)
    return x


def game_json(motion: Motion, *, axes: np.ndarray | None = None, decimals: int | None = 6,
              frames: int | None = None, world: Any = None) -> dict[str, Any]:
    """:func:`game_data` as JSON-ready values (NaN rows -> null, numbers rounded)."""
    return _plain(game_data(motion, axes=axes, frames=frames, world=world), decimals)
