"""The pose the estimator needs (feet and their ancestors), joint screws, foot boxes, CoPs in the feet."""

from __future__ import annotations

import logging
import weakref
from dataclasses import dataclass

import numpy as np

from solver.character import Character, merge_segments
from solver.contact.common import COP_MIN_FZ, cop_and_free_moment
from solver.kinematics import forward_kinematics
from solver.motion import FEET

log = logging.getLogger("solver.contact")


def _side_sets(character: Character, effort: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Joints of A (ancestors of the right foot only) and B (left only) whose force counts in the effort."""
    model = character.model
    anc = [set(model.ancestors(model.seg_body[character.foot(s).segment])) for s in FEET]
    keep = set(range(character.n)) if effort is None else set(np.flatnonzero(effort))
    a = sorted((anc[0] - anc[1]) & keep)
    b = sorted((anc[1] - anc[0]) & keep)
    return np.array(a, dtype=int), np.array(b, dtype=int)


@dataclass(frozen=True, eq=False)
class _Pose:
    """World pose of every body as dense arrays over N frames: rot (N, n, 3, 3) world <- body, pos (N, n, 3)."""

    rot: np.ndarray
    pos: np.ndarray

    def take(self, idx: np.ndarray) -> _Pose:
        return _Pose(self.rot[idx], self.pos[idx])


_LEGS: weakref.WeakKeyDictionary[Character, tuple[Character, np.ndarray]] = weakref.WeakKeyDictionary()


def _legs(character: Character) -> tuple[Character, np.ndarray]:
    """The character reduced to the feet and the segments they hang from (what the estimator
    needs the pose of: joint screws of the feet's ancestors, foot boxes, root), and the indices of
    its coordinates (= bodies) in the full character. Cached per character."""
    hit = _LEGS.get(character)
    if hit is not None:
        return hit
    by_name = {s.name: s for s in character.segments}
    keep: set[str] = set()
    for side in FEET:
        name: str | None = character.foot(side).segment
        while name is not None and name not in keep:
            keep.add(name)
            name = by_name[name].parent
    drop = [s.name for s in character.segments if s.name not in keep and s.parent in keep]
    legs = merge_segments(character, drop, name=f"{character.name}-feet") if drop else character
    kept = np.array([character.index(c) for c in legs.coordinate_names], dtype=int)
    _LEGS[character] = (legs, kept)
    return legs, kept


def _dense_pose(character: Character, q: np.ndarray, full: bool = False) -> _Pose:
    """Pose of the bodies the estimator uses (the feet and their ancestors; NaN for the others):
    forward kinematics of the character reduced to them (the rest of the body does not move them);
    ``full``: every body (the centre of mass needs them)."""
    if full:
        legs, kept = character, np.arange(character.n)
    else:
        legs, kept = _legs(character)
    pose = forward_kinematics(legs, q[kept])
    N, n = q.shape[1], character.n
    rot = np.full((N, n, 3, 3), np.nan)
    pos = np.full((N, n, 3), np.nan)
    for j, k in enumerate(kept):
        for i in range(3):
            pos[:, k, i] = pose.pos[j][i]
            for c in range(3):
                rot[:, k, i, c] = pose.rot[j][i][c]
    return _Pose(rot, pos)


def _screws(character: Character, pose: _Pose) -> np.ndarray:
    """World joint screws (N, n, 6) from a pose: the same as :func:`solver.kinematics.joint_screws`."""
    z = pose.rot[:, :, :, 2]
    rev = np.asarray(character.model.revolute)
    ang = np.where(rev[None, :, None], z, 0.0)
    lin = np.where(rev[None, :, None], np.cross(pose.pos, z), z)
    return np.concatenate([ang, lin], axis=-1)


def _foot_frames(character: Character, pose: _Pose, side: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World rotation (N, 3, 3) world <- box, centre (N, 3) and half extents (3,) of a foot box."""
    box = character.foot(side)
    model = character.model
    b = model.seg_body[box.segment]
    r_sb = model.seg_rot[box.segment]
    c_b = model.seg_pos[box.segment] + r_sb @ box.center
    rot, pos = pose.rot[:, b], pose.pos[:, b]
    return rot @ r_sb, pos + rot @ c_b, np.asarray(box.half, dtype=float)



def _skew(v: np.ndarray) -> np.ndarray:
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2)



def _project_points(p: np.ndarray, G: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Nearest points of the convex polygons {x : G x <= h} (N, m, 2), (N, m) to the points p (N, 2).

    Exact: the nearest point is p itself, its projection onto one edge line, or a vertex (two
    edge lines meeting); every candidate is tried and the nearest feasible one kept."""
    N, m, _ = G.shape
    g2 = np.einsum("nmi,nmi->nm", G, G)
    ok = g2 > 1e-18
    cands = [p[:, None, :]]
    step = np.where(ok, (np.einsum("nmi,ni->nm", G, p) - h) / np.where(ok, g2, 1.0), np.nan)
    cands.append(p[:, None, :] - step[..., None] * G)  # onto each edge line
    i, j = np.triu_indices(m, 1)
    M = np.stack([G[:, i], G[:, j]], axis=-2)  # (N, pairs, 2, 2)
    det = M[..., 0, 0] * M[..., 1, 1] - M[..., 0, 1] * M[..., 1, 0]
    good = np.abs(det) > 1e-12 * np.sqrt(g2[:, i] * g2[:, j] + 1e-300)
    d = np.where(good, det, 1.0)
    hi, hj = h[:, i], h[:, j]
    vx = (hi * M[..., 1, 1] - hj * M[..., 0, 1]) / d
    vy = (M[..., 0, 0] * hj - M[..., 1, 0] * hi) / d
    cands.append(np.where(good[..., None], np.stack([vx, vy], -1), np.nan))  # vertices
    C = np.concatenate(cands, axis=1)  # (N, K, 2)
    slack = np.einsum("nmi,nki->nkm", G, C) - h[:, None, :]
    tol = 1e-9 * (1.0 + np.abs(h)).max(axis=1)
    feasible = np.all(slack <= tol[:, None, None], axis=2) & np.all(np.isfinite(C), axis=2)
    dist = np.where(feasible, np.sum((C - p[:, None, :]) ** 2, axis=2), np.inf)
    best = np.argmin(dist, axis=1)
    out = C[np.arange(N), best]
    return np.where(np.isfinite(dist[np.arange(N), best])[:, None], out, p)


def _project_cop(w: np.ndarray, character: Character, pose: _Pose, side: str,
                 penetration: float) -> tuple[np.ndarray, np.ndarray]:
    """Single-support wrenches (6, N) about the origin whose CoP lies outside the foot's contact
    polygon: the CoP moved to the nearest point of the polygon (same force, same free moment).
    Returns the wrenches and which frames moved."""
    out = np.array(w, dtype=float, copy=True)
    N = out.shape[1]
    moved = np.zeros(N, dtype=bool)
    cop, tz = cop_and_free_moment(out)
    rot, ctr, half = _foot_frames(character, pose, side)
    z_low = ctr[:, 2] - np.abs(rot[:, 2, :]) @ half
    z_plane = np.maximum(0.0, z_low + penetration)
    E = np.swapaxes(rot, 1, 2)  # (N, 3, 3) rows: box axes in world
    A = E[:, :, :2]  # the polygon: |A p + b| <= half, p the CoP on the foot's plane
    b = np.einsum("nkj,nj->nk", E, np.stack([np.zeros(N), np.zeros(N), z_plane], -1) - ctr)
    p = np.nan_to_num(cop[:2].T)
    excess = np.abs(np.einsum("nkj,nj->nk", A, p) + b) - half
    todo = np.flatnonzero(np.isfinite(cop[0]) & np.any(excess > 1e-12, axis=1))
    if len(todo):
        G = np.concatenate([A[todo], -A[todo]], axis=1)
        h = np.concatenate([half - b[todo], half + b[todo]], axis=1)
        pt = _project_points(p[todo], G, h)
        f = out[3:, todo]
        pt3 = np.stack([pt[:, 0], pt[:, 1], np.zeros(len(todo))])
        out[:3, todo] = np.cross(pt3, f, axis=0)
        out[2, todo] += tz[todo]
        moved[todo] = True
    return out, moved


def _cop_violation(wrenches: np.ndarray, character: Character, pose: _Pose, penetration: float) -> np.ndarray:
    """Metres by which each foot's CoP lies outside its contact polygon (0 inside, and 0 for a foot
    carrying less than ``COP_MIN_FZ``: its CoP is undefined), (2, N)."""
    N = pose.rot.shape[0]
    out = np.zeros((2, N))
    cop, _ = cop_and_free_moment(wrenches, COP_MIN_FZ)
    for s, side in enumerate(FEET):
        rot, ctr, half = _foot_frames(character, pose, side)
        z_low = ctr[:, 2] - np.abs(rot[:, 2, :]) @ half
        z_plane = np.maximum(0.0, z_low + penetration)
        p = cop[s].T + np.stack([np.zeros(N), np.zeros(N), z_plane], -1)  # the CoP on the foot's plane
        local = np.einsum("nji,nj->ni", rot, p - ctr)
        excess = np.max(np.abs(local) - half[None, :], axis=1)
        out[s] = np.where(np.isfinite(excess), np.maximum(excess, 0.0), 0.0)
    return out


