"""The building blocks of a glTF 2.0 document, shared by the character's writer
(:mod:`solver.export.gltf`) and the input rig's (:mod:`solver.export.rig_gltf`): component and
target constants, the binary buffer with its views and accessors (:class:`Buffer`), the GLB
container (:func:`glb`), low-poly meshes (ellipsoid, hexahedron) and the ground's nodes."""

from __future__ import annotations

import json
import struct
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from solver.export import ExportError
from solver.export.world import Ground

FLOAT, UNSIGNED_BYTE, UNSIGNED_SHORT, UNSIGNED_INT = 5126, 5121, 5123, 5125
ARRAY_BUFFER, ELEMENT_ARRAY_BUFFER = 34962, 34963
TRIANGLES = 4
GLB_MAGIC, GLB_JSON, GLB_BIN = 0x46546C67, 0x4E4F534A, 0x004E4942
_NCOMP = {"SCALAR": 1, "VEC3": 3, "VEC4": 4, "MAT4": 16}
_DTYPE = {FLOAT: np.float32, UNSIGNED_BYTE: np.uint8, UNSIGNED_SHORT: np.uint16, UNSIGNED_INT: np.uint32}

#: ellipsoid tessellation: meridian rings (pole to pole) and points around each ring
RINGS, SECTORS = 8, 12


@dataclass
class Buffer:
    """Accumulates buffer views and accessors over one binary buffer."""

    data: bytearray = field(default_factory=bytearray)
    views: list = field(default_factory=list)
    accessors: list = field(default_factory=list)

    def add(self, array: np.ndarray, ctype: int, atype: str, target: int | None = None, minmax: bool = False) -> int:
        arr = np.ascontiguousarray(array, dtype=_DTYPE[ctype])
        count = arr.shape[0]
        if arr.size != count * _NCOMP[atype]:
            raise ExportError(f"internal: {atype} accessor of shape {arr.shape}")
        while len(self.data) % 4:
            self.data.append(0)
        view: dict[str, Any] = {"buffer": 0, "byteOffset": len(self.data), "byteLength": arr.nbytes}
        if target is not None:
            view["target"] = target
        self.data += arr.tobytes()
        self.views.append(view)
        acc: dict[str, Any] = {"bufferView": len(self.views) - 1, "componentType": ctype, "count": count, "type": atype}
        if minmax:
            flat = arr.reshape(count, -1)
            conv = float if ctype == FLOAT else int
            acc["min"] = [conv(x) for x in flat.min(axis=0)]
            acc["max"] = [conv(x) for x in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def ellipsoid_mesh(center: np.ndarray, axis: np.ndarray, a: float,
                   b: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A low-poly prolate ellipsoid: (vertices (V, 3), outward normals (V, 3), triangles (F, 3)).

    Polar semi-axis ``a`` along the unit ``axis``, equatorial semi-axis ``b``, centred at
    ``center``; triangles wound counter-clockwise seen from outside.
    """
    u = np.asarray(axis, dtype=float)
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    v = ref - u * (ref @ u)
    v /= np.linalg.norm(v)
    w = np.cross(u, v)
    verts, norms = [center + a * u], [u]
    for i in range(1, RINGS):
        phi = np.pi * i / RINGS
        for j in range(SECTORS):
            th = 2.0 * np.pi * j / SECTORS
            cu, cv, cw = np.cos(phi), np.sin(phi) * np.cos(th), np.sin(phi) * np.sin(th)
            verts.append(center + a * cu * u + b * cv * v + b * cw * w)
            n = cu / a * u + cv / b * v + cw / b * w
            norms.append(n / np.linalg.norm(n))
    verts.append(center - a * u)
    norms.append(-u)
    last = len(verts) - 1

    def ring(i: int, j: int) -> int:  # vertex j of ring i (1..RINGS-1)
        return 1 + (i - 1) * SECTORS + j % SECTORS

    tris = []
    for j in range(SECTORS):
        tris.append((0, ring(1, j), ring(1, j + 1)))
        tris.append((last, ring(RINGS - 1, j + 1), ring(RINGS - 1, j)))
        for i in range(1, RINGS - 1):
            tris.append((ring(i, j), ring(i + 1, j), ring(i + 1, j + 1)))
            tris.append((ring(i, j), ring(i + 1, j + 1), ring(i, j + 1)))
    verts_a, norms_a, tris_a = np.array(verts), np.array(norms), np.array(tris)
    # orient every triangle outward (counter-clockwise seen from outside)
    p0, p1, p2 = verts_a[tris_a[:, 0]], verts_a[tris_a[:, 1]], verts_a[tris_a[:, 2]]
    outward = np.einsum("ij,ij->i", np.cross(p1 - p0, p2 - p0), (p0 + p1 + p2) / 3.0 - center) < 0
    tris_a[outward] = tris_a[outward][:, [0, 2, 1]]
    return verts_a, norms_a, tris_a


def hexahedron(c: np.ndarray, faces: Sequence[tuple[int, int, int, int]] = (
        (0, 1, 2, 3), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)),
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A convex hexahedron from its 8 corners and its 6 quadrilateral ``faces`` (corner indices;
    by default 0-3 one face and 4-7 the opposite in the same order), flat-shaded: vertices
    (24, 3), normals, triangles (12, 3), counter-clockwise seen from outside."""
    centre = c.mean(axis=0)
    verts: list[np.ndarray] = []
    norms: list[np.ndarray] = []
    tris: list[tuple[int, int, int]] = []
    for f in faces:
        p = c[list(f)]
        n = np.cross(p[1] - p[0], p[2] - p[0]) + np.cross(p[2] - p[0], p[3] - p[0])
        if n @ (p.mean(axis=0) - centre) < 0:
            p, n = p[::-1], -n
        k = len(verts)
        verts += list(p)
        norms += [n / np.linalg.norm(n)] * 4
        tris += [(k, k + 1, k + 2), (k, k + 2, k + 3)]
    return np.array(verts), np.array(norms), np.array(tris)


#: the ground's material: matt grey-blue, seen from both sides
GROUND_MATERIAL = {"name": "ground", "doubleSided": True,
                   "pbrMetallicRoughness": {"baseColorFactor": [0.56, 0.62, 0.68, 1.0], "metallicFactor": 0.0,
                                            "roughnessFactor": 0.95}}


def ground_nodes(buf: Buffer, grounds: Sequence[tuple[str, Ground]], to_scene: np.ndarray, material: int,
                 meshes: list[dict], nodes: list[dict]) -> int:
    """Append the ground's meshes and nodes; returns the node to put at the scene root: ``ground``
    holding the one ground's mesh, or (several, e.g. a library's cells) ``ground`` with one child
    ``ground <name>`` per ground. ``to_scene`` (4x4): our world (metres) -> the scene, a rotation
    and a uniform scale. Each ground node's ``extras`` hold its description in the scene."""
    M = np.asarray(to_scene, dtype=float)
    scale = float(np.cbrt(np.linalg.det(M[:3, :3])))
    Rs = M[:3, :3] / scale
    kids: list[int] = []
    for name, ground in grounds:
        V, N, F = ground.mesh()
        V = V @ M[:3, :3].T + M[:3, 3]
        N = N @ Rs.T
        prim = {"attributes": {"POSITION": buf.add(V, FLOAT, "VEC3", ARRAY_BUFFER, minmax=True),
                               "NORMAL": buf.add(N, FLOAT, "VEC3", ARRAY_BUFFER)},
                "indices": buf.add(F.reshape(-1), UNSIGNED_SHORT if len(V) < 65536 else UNSIGNED_INT, "SCALAR",
                                   ELEMENT_ARRAY_BUFFER, minmax=True),
                "material": material, "mode": TRIANGLES}
        meshes.append({"name": "ground" if len(grounds) == 1 else f"ground {name}", "primitives": [prim]})
        desc = ground.to_json(Rs, scale, origin=M[:3, 3])
        nodes.append({"name": "ground" if len(grounds) == 1 else f"ground {name}", "mesh": len(meshes) - 1,
                      "extras": {"ground": desc, "world": ground.world.name, "animation": name}})
        kids.append(len(nodes) - 1)
    if len(kids) == 1:
        return kids[0]
    nodes.append({"name": "ground", "children": kids})
    return len(nodes) - 1


def glb(doc: dict, data: bytes) -> bytes:
    js = json.dumps(doc, allow_nan=False, separators=(",", ":")).encode("utf-8")
    js += b" " * (-len(js) % 4)
    data += b"\0" * (-len(data) % 4)
    total = 12 + 8 + len(js) + 8 + len(data)
    return b"".join([
        struct.pack("<III", GLB_MAGIC, 2, total),
        struct.pack("<II", len(js), GLB_JSON), js,
        struct.pack("<II", len(data), GLB_BIN), data,
    ])
