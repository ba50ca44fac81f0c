"""The skeleton read from a skinned glTF character: the skin the animation drives, the tree of
its joints, and their rest pose and sampled animation in the skeleton's parent space, the nodes
above it folded into the ground frame (:func:`_read_skeleton`); forward kinematics
(:func:`_forward`)."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
from scipy.spatial.transform import Rotation

from solver.io.gltf.animation import _Clip, _pick_animation, _sample
from solver.io.gltf.base import GltfError
from solver.io.gltf.container import GltfAsset
from solver.io.gltf.nodes import _ancestors, _matrix, node_parents, node_trs

log = logging.getLogger(__name__)

#: a joint's translation "changes" along the clip beyond this fraction of the skeleton's size
_MOVE_TOL = 1e-5


def _pick_skin(asset: GltfAsset, anim: int) -> int:
    skins = asset.doc.get("skins") or []
    if not skins:
        raise GltfError(f"{asset.where}: the file has no skin (a skinned character is needed: a mesh bound to a "
                        "skeleton)")
    driven = {(ch.get("target") or {}).get("node") for ch in asset.doc["animations"][anim].get("channels") or []}
    nodes = asset.doc.get("nodes", [])
    best, score = 0, -1
    for k, skin in enumerate(skins):
        joints = skin.get("joints") or []
        if not joints or not all(isinstance(j, int) and 0 <= j < len(nodes) for j in joints):
            raise GltfError(f"{asset.where}: skin {k} has no joints, or joints that are not nodes")
        n = len(set(joints) & driven)
        if n > score:
            best, score = k, n
    return best


def _skeleton(asset: GltfAsset, skin: int, parent: list[int]) -> list[int]:
    """The skeleton's nodes, parents first (depth-first): the skin's joints below its top joint
    with the most joints below it, and the nodes between them."""
    joints = set(asset.doc["skins"][skin]["joints"])
    tops = [j for j in joints if not any(a in joints for a in _ancestors(parent, j))]
    below = {t: [j for j in joints if j == t or t in _ancestors(parent, j)] for t in tops}
    top = max(sorted(tops), key=lambda t: len(below[t]))
    members = set()
    for j in below[top]:
        members.add(j)
        for a in _ancestors(parent, j):
            if a == top:
                break
            members.add(a)
    if len(tops) > 1:
        log.info("%s: skin %d has %d top joints; the skeleton is the one under node %d (%d joints)", asset.where,
                 skin, len(tops), top, len(below[top]))
    nodes = asset.doc["nodes"]
    order: list[int] = []

    def visit(i: int) -> None:
        order.append(i)
        for c in nodes[i].get("children", []) or []:
            if c in members:
                visit(c)

    visit(top)
    return order


@dataclass(frozen=True, eq=False)
class _Skeleton:
    nodes: list[int]  # node index per joint
    names: tuple[str, ...]
    parents: tuple[int, ...]
    times: np.ndarray  # (F,)
    local: np.ndarray  # (F, J, 3, 3) local rotations (parent space)
    translation: np.ndarray  # (F, J, 3) local translations in the parent's scaled units (the rig's offsets)
    rest_local: np.ndarray  # (J, 3, 3)
    rest_translation: np.ndarray  # (J, 3)
    scales: np.ndarray  # (J,) accumulated uniform scale of each joint's frame (its own included)
    up: np.ndarray  # the scene's up direction in the skeleton's parent space
    unit_m: float  # metres per unit of the skeleton's parent space
    moved: bool  # some non-root joint's translation changes along the clip
    clip: _Clip
    skin: int


def _uniform(s: np.ndarray, what: str, where: str) -> float:
    if np.any(s <= 0) or np.ptp(s) > 1e-4 * float(np.max(np.abs(s))):
        raise GltfError(f"{where}: {what} has the scale {np.round(s, 6).tolist()}; only uniform positive scales "
                        "are supported")
    return float(np.mean(s))


def _read_skeleton(asset: GltfAsset, animation: int | str | None) -> _Skeleton:
    where = asset.where
    doc = asset.doc
    nodes = doc.get("nodes") or []
    if not nodes:
        raise GltfError(f"{where}: the file has no nodes")
    parent = node_parents(doc, where)
    anim = _pick_animation(asset, animation)
    skin = _pick_skin(asset, anim)
    order = _skeleton(asset, skin, parent)
    index = {n: j for j, n in enumerate(order)}
    top = order[0]
    above = _ancestors(parent, top)  # nearest first
    clip = _sample(asset, anim, set(order) | set(above))
    F, J = clip.times.size, len(order)
    trs = {i: node_trs(nodes[i], where, i) for i in set(order) | set(above)}

    def animated(i: int, path: str, rest: np.ndarray) -> np.ndarray:
        v = clip.tracks.get(i, {}).get(path)
        return np.broadcast_to(rest, (F, rest.size)) if v is None else v

    # the nodes above the skeleton: their rest transform is the ground frame's, their motion the root's
    M_rest = np.eye(4)
    M_anim = np.broadcast_to(np.eye(4), (F, 4, 4)).copy()
    for i in reversed(above):  # root-most first
        t, q, s = trs[i]
        M_rest = M_rest @ _matrix(t, q, s)
        T_, Q_, S_ = animated(i, "translation", t), animated(i, "rotation", q), animated(i, "scale", s)
        for f in range(F):
            M_anim[f] = M_anim[f] @ _matrix(T_[f], Q_[f], S_[f])
    unit = _uniform(np.linalg.norm(M_rest[:3, :3], axis=0), "the nodes above the skeleton", where)
    R_above = M_rest[:3, :3] / unit
    if np.linalg.det(R_above) < 0:
        raise GltfError(f"{where}: the nodes above the skeleton mirror it (negative scale): not supported")
    D = np.einsum("ij,fjk->fik", np.linalg.inv(M_rest), M_anim)  # the motion of the skeleton's parent space
    for f in range(F):
        sv = np.linalg.svd(D[f, :3, :3], compute_uv=False)
        if np.max(np.abs(sv - 1.0)) > 1e-4:
            raise GltfError(f"{where}: the animation scales the nodes above the skeleton: not supported")
    up = R_above.T @ np.array([0.0, 1.0, 0.0])
    names = tuple(str(nodes[i].get("name") or f"node{i}") for i in order)
    parents = tuple(index[parent[i]] if j else -1 for j, i in enumerate(order))
    local = np.empty((F, J, 3, 3))
    trans = np.empty((F, J, 3))
    rest_local = np.empty((J, 3, 3))
    rest_t = np.empty((J, 3))
    scales = np.empty(J)
    for j, i in enumerate(order):
        t, q, s = trs[i]
        if "scale" in clip.tracks.get(i, {}):
            sc = clip.tracks[i]["scale"]
            if np.max(np.abs(sc - s)) > 1e-4 * max(float(np.max(np.abs(s))), 1e-9):
                raise GltfError(f"{where}: the animation scales the joint {names[j]!r}: not supported")
        own = _uniform(s, f"the joint {names[j]!r}", where)
        p = parents[j]
        scales[j] = own * (scales[p] if p >= 0 else 1.0)
        par_scale = scales[p] if p >= 0 else 1.0
        rest_local[j] = Rotation.from_quat(q).as_matrix()
        rest_t[j] = par_scale * t
        local[:, j] = Rotation.from_quat(animated(i, "rotation", q)).as_matrix()
        trans[:, j] = par_scale * animated(i, "translation", t)
    # the root in the (moving) parent space of the skeleton
    Dr = D[:, :3, :3]
    local[:, 0] = np.einsum("fij,fjk->fik", Dr, local[:, 0])
    trans[:, 0] = np.einsum("fij,fj->fi", Dr, trans[:, 0]) + D[:, :3, 3]
    if not (np.all(np.isfinite(local)) and np.all(np.isfinite(trans))):
        raise GltfError(f"{where}: the skeleton's animation has non-finite values")
    size = float(np.max(np.linalg.norm(rest_t, axis=1))) or 1.0
    moved = J > 1 and bool(np.max(np.abs(trans[:, 1:] - trans[:1, 1:])) > _MOVE_TOL * size)
    return _Skeleton(order, names, parents, clip.times, local, trans, rest_local, rest_t, scales, up, unit, moved,
                     clip, skin)


def _forward(parents: tuple[int, ...], local: np.ndarray, trans: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """World rotations (J, F, 3, 3) and positions (J, F, 3) from local rotations (F, J, 3, 3) and
    translations (F, J, 3) (a child's translation in its parent's frame)."""
    F, J = local.shape[:2]
    R = np.empty((J, F, 3, 3))
    P = np.empty((J, F, 3))
    for j, p in enumerate(parents):
        if p < 0:
            R[j], P[j] = local[:, j], trans[:, j]
        else:
            R[j] = R[p] @ local[:, j]
            P[j] = P[p] + np.einsum("fij,fj->fi", R[p], trans[:, j])
    return R, P

