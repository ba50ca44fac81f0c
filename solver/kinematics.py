"""Forward kinematics (docs/method.md (M2.3)), markers, contact points and finite differences (M2.2).

Functions take ``q`` as an n-vector (numpy ``(n,)``), a motion (numpy ``(n, T)``: every
frame at once) or a CasADi column; they return the same kind.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from solver import spatial as sp
from solver.character import Character, Model


@dataclass(frozen=True)
class Pose:
    """World pose of every body: rotation (world <- body) and origin, component-wise."""

    rot: tuple[sp.Mat3, ...]
    pos: tuple[sp.Vec3, ...]


def joint_transform(model: Model, k: int, c: Any, s: Any, qk: Any) -> tuple[sp.Mat3, sp.Vec3]:
    """Body k's frame in its parent's frame: (rotation parent <- body, origin)."""
    r0, p0 = model.rot0[k], model.pos0[k]
    if model.revolute[k]:
        return sp.mat_rotz(r0, c, s), p0
    col_z = (r0[0][2], r0[1][2], r0[2][2])
    return r0, sp.vadd(p0, sp.vscale(qk, col_z))


def forward_kinematics(character: Character, q: Any) -> Pose:
    model = character.model
    qs = sp.components(q, model.n)
    rots: list[sp.Mat3] = []
    poss: list[sp.Vec3] = []
    for k in range(model.n):
        if model.revolute[k]:
            c, s = sp.cos(qs[k]), sp.sin(qs[k])
        else:
            c = s = None
        r, p = joint_transform(model, k, c, s, qs[k])
        par = model.parent[k]
        if par < 0:
            rots.append(r)
            poss.append(p)
        else:
            rp, pp = rots[par], poss[par]
            rots.append(sp.matmul(rp, r))
            poss.append(sp.vadd(pp, sp.matvec(rp, p)))
    return Pose(tuple(rots), tuple(poss))


def point_world(pose: Pose, body: int, p_body: sp.Vec) -> sp.Vec3:
    pb = sp.const_vec(p_body)
    return sp.vadd(pose.pos[body], sp.matvec(pose.rot[body], pb))


def points_world(character: Character, q: Any, points: Sequence[tuple[str, sp.Vec]]) -> Any:
    """World positions of points given as (segment, segment coordinates).

    Returns shape (len(points), 3) numpy for a single frame, (len(points), 3, T) for a
    motion, or a casadi (3*len(points), 1) column.
    """
    model = character.model
    pose = forward_kinematics(character, q)
    out: list[Any] = []
    for seg, p in points:
        b, pb = model.point_on_body(seg, p)
        out.extend(point_world(pose, b, pb))
    return _shape_points(out, len(points), q)


def _shape_points(flat: list, npts: int, like: Any) -> Any:
    arr = sp.stack(flat, like=like)
    if sp.is_symbolic(arr):
        return arr
    return arr.reshape((npts, 3) + arr.shape[1:])


def marker_points(character: Character) -> list[tuple[str, np.ndarray]]:
    """One marker per segment, at its tip (docs/method.md (M5.1), F_dir)."""
    return [(s.name, s.marker) for s in character.segments if s.length > 0]


def markers(character: Character, q: Any) -> Any:
    return points_world(character, q, marker_points(character))


def contact_points(character: Character, q: Any) -> Any:
    """World positions of the character's contact points, in ``character.contacts`` order."""
    return points_world(character, q, [(c.segment, c.position) for c in character.contacts])


def segment_frames(character: Character, q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Numeric world rotation (S, 3, 3[, T]) and origin (S, 3[, T]) of every segment."""
    model = character.model
    pose = forward_kinematics(character, q)
    extra = np.asarray(q).shape[1:]
    rots = np.empty((len(character.segments), 3, 3) + extra)
    poss = np.empty((len(character.segments), 3) + extra)
    for i, s in enumerate(character.segments):
        b = model.seg_body[s.name]
        rs, ps = model.seg_rot[s.name], model.seg_pos[s.name]
        rb = np.array([[np.broadcast_to(pose.rot[b][r][c], extra) for c in range(3)] for r in range(3)])
        pb = np.array([np.broadcast_to(pose.pos[b][r], extra) for r in range(3)])
        rots[i] = np.einsum("ij...,jk->ik...", rb, rs)
        poss[i] = pb + np.einsum("ij...,j->i...", rb, ps)
    return rots, poss


def centre_of_mass(character: Character, q: np.ndarray) -> np.ndarray:
    """(3[, T]) whole-body centre of mass from the segments' poses."""
    R, P = segment_frames(character, q)
    m = np.array([s.mass for s in character.segments])
    X = P + np.einsum("sij...,sj->si...", R, np.array([s.com for s in character.segments]))
    return np.einsum("s,si...->i...", m, X) / m.sum()


def standing_leg_length(character: Character) -> float:
    """Height of the root above the lowest contact point at q = 0 (at least 0.3 m; 1 m if the
    character has no contact points): the length scale of moments and residuals."""
    if not character.contacts:
        return 1.0
    return float(max(0.3, -contact_points(character, np.zeros(character.n))[:, 2].min()))


def finite_differences(Q: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray]:
    """Central differences (docs/method.md (M2.2)) at interior frames 2..T-1: (q̇, q̈), shape (n, T-2)."""
    Q = np.asarray(Q, dtype=float)
    if Q.ndim != 2 or Q.shape[1] < 3:
        raise ValueError(f"a motion needs shape (n, T) with T >= 3, got {Q.shape}")
    if not dt > 0:
        raise ValueError("dt must be positive")
    qd = (Q[:, 2:] - Q[:, :-2]) / (2.0 * dt)
    qdd = (Q[:, 2:] - 2.0 * Q[:, 1:-1] + Q[:, :-2]) / (dt * dt)
    return qd, qdd


def joint_screws(character: Character, q: Any) -> Any:
    """World-frame motion axis (Plücker, (angular; linear) about the origin) of every joint.

    Column k is S_k expressed in the world frame, so that the generalized force of a world
    wrench w on any descendant of joint k is ``S_k · w``. Shape (n, 6[, T]) for numpy.
    """
    model = character.model
    pose = forward_kinematics(character, q)
    rows = []
    for k in range(model.n):
        r, p = pose.rot[k], pose.pos[k]
        z = (r[0][2], r[1][2], r[2][2])
        if model.revolute[k]:
            rows.extend(list(z) + list(sp.cross(p, z)))
        else:
            rows.extend([0.0, 0.0, 0.0] + list(z))
    arr = sp.stack(rows, like=q)
    if sp.is_symbolic(arr):
        return arr
    return arr.reshape((model.n, 6) + arr.shape[1:])


def sole_corners(character: Character, q: np.ndarray) -> np.ndarray:
    """(2, 4, 3, T) the corners of each foot's sole (``Character.sole``): the rectangle through its
    heel and toe contact points (the plane the foot stands on), as wide as its foot box; feet (right,
    left), corners (heel-right, heel-left, toe-right, toe-left) in the foot's axes."""
    pts = []
    for side in ("right", "left"):
        sole = character.sole(side)
        c = sole.corners()  # heel +w, heel −w, toe +w, toe −w
        pts += [(sole.segment, c[k]) for k in (1, 0, 3, 2)]  # right edge first
    out = np.asarray(points_world(character, q, pts))  # (8, 3[, T])
    return out.reshape((2, 4) + out.shape[1:])
