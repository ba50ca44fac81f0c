"""The glTF node hierarchy: each node's parent, its translation, rotation and scale, and
their 4×4 matrix."""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from scipy.spatial.transform import Rotation

from solver.io.gltf.base import GltfError


def node_trs(node: Mapping[str, Any], where: str, index: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A node's (translation (3,), rotation quaternion (x, y, z, w), scale (3,)); a ``matrix`` is
    decomposed (it must be a rotation, a positive scale per axis and a translation)."""
    try:
        if "matrix" in node:
            m = np.asarray(node["matrix"], dtype=float).reshape(4, 4).T  # column-major
            if not np.all(np.isfinite(m)):
                raise GltfError(f"{where}: node {index} has a non-finite matrix")
            t = m[:3, 3].copy()
            s = np.linalg.norm(m[:3, :3], axis=0)
            if np.any(s < 1e-12) or np.linalg.det(m[:3, :3]) < 0:
                raise GltfError(f"{where}: node {index} ({node.get('name', '')!r}) has a degenerate or mirroring "
                                "matrix")
            r = m[:3, :3] / s
            q = Rotation.from_matrix(r).as_quat()
            return t, q, s
        t = np.asarray(node.get("translation", [0, 0, 0]), dtype=float).reshape(3)
        q = np.asarray(node.get("rotation", [0, 0, 0, 1]), dtype=float).reshape(4)
        s = np.asarray(node.get("scale", [1, 1, 1]), dtype=float).reshape(3)
    except (TypeError, ValueError):
        raise GltfError(f"{where}: node {index} has a malformed transform") from None
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(q)) and np.all(np.isfinite(s))):
        raise GltfError(f"{where}: node {index} ({node.get('name', '')!r}) has a non-finite transform")
    n = np.linalg.norm(q)
    if n < 1e-9:
        raise GltfError(f"{where}: node {index} has a zero rotation quaternion")
    return t, q / n, s


def node_parents(doc: Mapping[str, Any], where: str) -> list[int]:
    """Each node's parent index (-1 for a root); a node with two parents or a cycle is refused."""
    nodes = doc.get("nodes", [])
    parent = [-1] * len(nodes)
    for i, n in enumerate(nodes):
        for c in n.get("children", []) or []:
            if not isinstance(c, int) or not 0 <= c < len(nodes) or c == i:
                raise GltfError(f"{where}: node {i} has an invalid child {c!r}")
            if parent[c] >= 0:
                raise GltfError(f"{where}: node {c} has two parents")
            parent[c] = i
    for i in range(len(nodes)):
        seen, p = {i}, parent[i]
        while p >= 0:
            if p in seen:
                raise GltfError(f"{where}: the node hierarchy has a cycle through node {i}")
            seen.add(p)
            p = parent[p]
    return parent


def _ancestors(parent: list[int], i: int) -> list[int]:
    out, p = [], parent[i]
    while p >= 0:
        out.append(p)
        p = parent[p]
    return out


def _matrix(t: np.ndarray, q: np.ndarray, s: np.ndarray) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = Rotation.from_quat(q).as_matrix() * s
    m[:3, 3] = t
    return m
