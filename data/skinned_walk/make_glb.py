"""Make ``walk.glb``: a skinned Mixamo-style character walking the CMU straight walk (glTF 2.0).

Run with the project's venv (deterministic: the same bytes every run)::

    .venv/bin/python data/skinned_walk/make_glb.py

What is in the file (README.md says why):

- **Skeleton**: Mixamo names (``mixamorig:Hips``, ``mixamorig:LeftUpLeg``, ``LeftLeg``, ``LeftFoot``,
  ``LeftToeBase``, ``LeftToe_End``, ``Spine``, ``Spine1``, ``Spine2``, ``Neck``, ``Head``,
  ``HeadTop_End``, ``LeftShoulder``, ``LeftArm``, ``LeftForeArm``, ``LeftHand``, ``LeftHandIndex1-3``
  and the right side), 31 joints, as ``data/mixamo_style_walk/make_rig.py`` places them on the CMU
  subject (scaled by 0.97 here), T-pose. Under an ``Armature`` node with scale 0.01 and a 90°
  rotation about X, like Mixamo characters converted FBX -> glTF by Blender: the skeleton is in
  centimetres, in a space where up is -Z and the character faces +Y; the scene sees it Y up,
  facing +Z, in metres. Every joint node has a rest rotation whose Y axis runs along its bone
  (Blender's bone convention), so the joints' translations are along their parent's Y.
- **Skin**: one mesh ``Body`` (a node at the scene root, as the glTF spec wants for skinned
  meshes) of capsules around the bones, each vertex weighted to its bone and, within 6 cm of
  either end, blended with the bone across that joint (2 influences at a joint, 3 on the short
  bones of the hand, weights summing to 1); normals, texture coordinates, a material with a small checker
  texture (PNG, stored uncompressed); inverse bind matrices of the rest pose.
- **Animation** ``mixamo.com``: the CMU walk retargeted by ``make_rig.py``'s ``retarget`` (each
  bone follows a CMU bone; the split spine shares the trunk's bend), at the CMU's 30 fps,
  translation, rotation and scale channels on every joint (Blender bakes all three), LINEAR.

The script prints how far the file's joints are from the CMU joints they follow (legs: rounding).
"""

from __future__ import annotations

import importlib.util
import json
import struct
import sys
import zlib
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

HERE = Path(__file__).resolve().parent
ROOT = HERE.parents[1]
SOURCE = ROOT / "data" / "cmu16_bvh" / "16_15_walk.bvh"
OUT = HERE / "walk.glb"
SCALE = 0.97  # the character is the CMU subject x0.97 (centimetres)
FPS = 30.0

_spec = importlib.util.spec_from_file_location("make_rig", ROOT / "data" / "mixamo_style_walk" / "make_rig.py")
assert _spec is not None and _spec.loader is not None
make_rig = importlib.util.module_from_spec(_spec)
sys.modules["make_rig"] = make_rig
_spec.loader.exec_module(make_rig)

#: CMU axes (Y up, facing +Z, left +X) -> the skeleton's space under the Armature node (up -Z, facing +Y)
AXES = Rotation.from_euler("x", -90, degrees=True).as_matrix()
ARMATURE_ROTATION = [0.7071067811865476, 0.0, 0.0, 0.7071067811865476]  # +90° about X (x, y, z, w)
ARMATURE_SCALE = 0.01
#: the child a joint's bone (its Y axis) points to, when it has several (names without namespace and side)
MAIN_CHILD = {"Hips": "Spine", "Spine2": "Neck", "Hand": "HandIndex1"}
#: capsule radius (cm) per bone, by the bone's joint (without "mixamorig:" and side)
RADIUS = {"Hips": 11.0, "Spine": 12.0, "Spine1": 13.0, "Spine2": 13.0, "Neck": 5.5, "Head": 9.5, "Shoulder": 5.0,
          "Arm": 5.0, "ForeArm": 4.0, "Hand": 3.5, "HandIndex1": 1.2, "HandIndex2": 1.0, "UpLeg": 7.5, "Leg": 5.5,
          "Foot": 4.5, "ToeBase": 3.5}
BLEND_CM = 6.0  # the length of a bone near each end blended with the bone across the joint
RINGS, SECTORS, CAP_RINGS = 6, 10, 3


def _base(name: str) -> str:
    n = name.split(":")[-1]
    for side in ("Left", "Right"):
        if n.startswith(side):
            return n[len(side):]
    return n


def skeleton() -> tuple[list, dict, dict, dict, np.ndarray]:
    """The joints, their rest offsets (cm, skeleton space), local rotations (T, 3, 3; rest = T-pose
    = identity) and the root's positions (T, 3), from make_rig's retargeting; and the times."""
    clip = make_rig.read_bvh(SOURCE)
    joints = make_rig.mixamo(make_rig._cmu_rest(clip))
    t, offsets, _, local_R, local_p = make_rig.retarget(joints, clip, FPS, SCALE, AXES, set())
    return joints, offsets, local_R, local_p, t


def bone_frames(joints: list, rest_world: dict[str, np.ndarray]) -> dict[str, np.ndarray]:
    """Each joint's rest frame (skeleton space): Y along its bone to its (main) child, X as near the
    skeleton's X (the character's left) as that allows; a leaf joint has its parent's frame."""
    kids: dict[str, list[str]] = {}
    for j in joints:
        if j.parent is not None:
            kids.setdefault(j.parent, []).append(j.name)
    out: dict[str, np.ndarray] = {}
    for j in joints:
        ch = kids.get(j.name, [])
        if not ch:
            out[j.name] = out[j.parent]
            continue
        main = next((c for c in ch if _base(c) == MAIN_CHILD.get(_base(j.name))), ch[0])
        y = rest_world[main] - rest_world[j.name]
        y /= np.linalg.norm(y)
        ref = np.array([1.0, 0.0, 0.0]) if abs(y[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
        x = ref - (ref @ y) * y
        x /= np.linalg.norm(x)
        out[j.name] = np.stack([x, y, np.cross(x, y)], axis=1)
    return out


def capsule(a: np.ndarray, b: np.ndarray, r: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray,
                                                              np.ndarray]:
    """A capsule from a to b of radius r: vertices, normals, uv, the axial parameter of each vertex
    (0 at a, 1 at b, clamped) and triangles (counter-clockwise seen from outside)."""
    axis = b - a
    L = float(np.linalg.norm(axis))
    u = axis / L
    ref = np.array([1.0, 0.0, 0.0]) if abs(u[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    v = ref - (ref @ u) * u
    v /= np.linalg.norm(v)
    w = np.cross(u, v)
    rows = []  # (axial position along u, ring radius, normal's axial component, normal's radial component)
    for i in range(CAP_RINGS, 0, -1):  # the cap at a
        phi = 0.5 * np.pi * i / CAP_RINGS
        rows.append((-r * np.sin(phi), r * np.cos(phi), -np.sin(phi), np.cos(phi)))
    for i in range(RINGS + 1):
        rows.append((L * i / RINGS, r, 0.0, 1.0))
    for i in range(1, CAP_RINGS + 1):  # the cap at b
        phi = 0.5 * np.pi * i / CAP_RINGS
        rows.append((L + r * np.sin(phi), r * np.cos(phi), np.sin(phi), np.cos(phi)))
    verts, norms, uvs, par = [], [], [], []
    total = L + 2 * r
    for s, rad, na, nr in rows:
        for j in range(SECTORS + 1):  # a seam column repeated for the texture
            th = 2 * np.pi * j / SECTORS
            radial = np.cos(th) * v + np.sin(th) * w
            verts.append(a + s * u + rad * radial)
            n = na * u + nr * radial
            norms.append(n / np.linalg.norm(n))
            uvs.append((j / SECTORS, (s + r) / total))
            par.append(min(max(s / L, 0.0), 1.0))
    tris = []
    cols = SECTORS + 1
    for i in range(len(rows) - 1):
        for j in range(SECTORS):
            p0, p1 = i * cols + j, i * cols + j + 1
            q0, q1 = (i + 1) * cols + j, (i + 1) * cols + j + 1
            tris += [(p0, p1, q1), (p0, q1, q0)]
    V, N, T = np.array(verts), np.array(norms), np.array(tris)
    # counter-clockwise seen from outside; drop the degenerate triangles at the poles
    p0, p1, p2 = V[T[:, 0]], V[T[:, 1]], V[T[:, 2]]
    cr = np.cross(p1 - p0, p2 - p0)
    keep = np.linalg.norm(cr, axis=1) > 1e-9 * L * L
    inward = np.einsum("ij,ij->i", cr, N[T[:, 0]] + N[T[:, 1]] + N[T[:, 2]]) < 0
    T[inward] = T[inward][:, [0, 2, 1]]
    return V, N, np.array(uvs), np.array(par), T[keep]


def checker_png(n: int = 8) -> bytes:
    """An n x n RGB checker (two skin tones), PNG with stored (uncompressed) deflate blocks."""
    c0, c1 = (224, 172, 140), (200, 150, 120)
    rows = b"".join(b"\0" + b"".join(bytes(c0 if (x + y) % 2 == 0 else c1) for x in range(n)) for y in range(n))

    def chunk(kind: bytes, data: bytes) -> bytes:
        return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))

    ihdr = struct.pack(">IIBBBBB", n, n, 8, 2, 0, 0, 0)
    return b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", ihdr) + chunk(b"IDAT", zlib.compress(rows, 0)) + chunk(b"IEND", b"")


class Buffer:
    def __init__(self) -> None:
        self.data = bytearray()
        self.views: list[dict] = []
        self.accessors: list[dict] = []

    def view(self, raw: bytes, target: int | None = None) -> int:
        self.data += b"\0" * (-len(self.data) % 4)
        v = {"buffer": 0, "byteOffset": len(self.data), "byteLength": len(raw)}
        if target is not None:
            v["target"] = target
        self.data += raw
        self.views.append(v)
        return len(self.views) - 1

    def add(self, arr: np.ndarray, ctype: int, atype: str, target: int | None = None, minmax: bool = False) -> int:
        dt = {5126: np.float32, 5121: np.uint8, 5123: np.uint16}[ctype]
        a = np.ascontiguousarray(arr, dtype=dt)
        acc = {"bufferView": self.view(a.tobytes(), target), "componentType": ctype, "count": int(a.shape[0]),
               "type": atype}
        if minmax:
            flat = a.reshape(a.shape[0], -1)
            conv = float if ctype == 5126 else int
            acc["min"] = [conv(x) for x in flat.min(axis=0)]
            acc["max"] = [conv(x) for x in flat.max(axis=0)]
        self.accessors.append(acc)
        return len(self.accessors) - 1


def _quat(m: np.ndarray) -> np.ndarray:
    q = Rotation.from_matrix(m).as_quat()  # x, y, z, w
    q = q.reshape(-1, 4)
    for k in range(1, q.shape[0]):
        if q[k] @ q[k - 1] < 0:
            q[k] = -q[k]
    return q


def build() -> tuple[bytes, dict]:
    joints, offsets, local_R, local_p, t = skeleton()
    names = [j.name for j in joints]
    index = {n: k for k, n in enumerate(names)}
    parent = {j.name: j.parent for j in joints}
    root = names[0]
    # rest pose (T-pose, all local rotations identity in make_rig's frames): positions, skeleton space (cm)
    rest_world: dict[str, np.ndarray] = {}
    for j in joints:
        if j.parent is None:
            rest_world[j.name] = AXES @ np.array(j.at) * SCALE
        else:
            rest_world[j.name] = rest_world[j.parent] + offsets[j.name]
    B = bone_frames(joints, rest_world)
    F = t.size
    # glTF local rotation L = B_parentᵀ L_rig B, translation B_parentᵀ offset (root: its position)
    rot = {}
    trans = {}
    rest_rot, rest_trans = {}, {}
    for n in names:
        p = parent[n]
        Bp = np.eye(3) if p is None else B[p]
        rot[n] = np.einsum("ji,tjk,kl->til", Bp, local_R[n], B[n])
        rest_rot[n] = Bp.T @ B[n]
        if p is None:
            trans[n] = local_p[n]
            rest_trans[n] = rest_world[n]
        else:
            rest_trans[n] = Bp.T @ offsets[n]
            trans[n] = np.broadcast_to(rest_trans[n], (F, 3))
    # node order: the mesh node, the joints (depth-first), the Armature
    body, arm = 0, len(names) + 1
    node_of = {n: 1 + k for k, n in enumerate(names)}
    kids: dict[str, list[str]] = {}
    for n in names:
        if parent[n] is not None:
            kids.setdefault(parent[n], []).append(n)
    nodes: list[dict] = [{"name": "Body", "mesh": 0, "skin": 0}]
    for n in names:
        node = {"name": n, "translation": [float(x) for x in rest_trans[n]],
                "rotation": [float(x) for x in _quat(rest_rot[n])[0]]}
        if kids.get(n):
            node["children"] = [node_of[c] for c in kids[n]]
        nodes.append(node)
    nodes.append({"name": "Armature", "rotation": ARMATURE_ROTATION, "scale": [ARMATURE_SCALE] * 3,
                  "children": [node_of[root]]})
    # world rest matrices (scene, metres) and inverse bind matrices
    A = np.eye(4)
    A[:3, :3] = Rotation.from_quat(ARMATURE_ROTATION).as_matrix() * ARMATURE_SCALE
    G = {}
    for n in names:
        m = np.eye(4)
        m[:3, :3] = rest_rot[n]
        m[:3, 3] = rest_trans[n]
        G[n] = (A if parent[n] is None else G[parent[n]]) @ m
    buf = Buffer()
    ibm = np.stack([np.linalg.inv(G[n]) for n in names])
    ibm[:, 3, :] = [0.0, 0.0, 0.0, 1.0]
    ibm_acc = buf.add(np.transpose(ibm, (0, 2, 1)).reshape(len(names), 16), 5126, "MAT4")
    # the mesh: a capsule per bone, in the scene's rest pose (metres)
    Vs, Ns, UVs, Js, Ws, Ts = [], [], [], [], [], []
    count = 0
    for n in names:
        for c in kids.get(n, []):
            base = _base(n)
            if base not in RADIUS or (base in ("Hips", "Spine2") and _base(c) != MAIN_CHILD[base]):
                continue
            a, b = G[n][:3, 3], G[c][:3, 3]
            r = RADIUS[base] * SCALE * ARMATURE_SCALE
            V, N, UV, s, T = capsule(a, b, r)
            blend = min(BLEND_CM * SCALE * ARMATURE_SCALE / float(np.linalg.norm(b - a)), 0.9)
            w_par = np.zeros_like(s)
            w_kid = np.zeros_like(s)
            if parent[n] is not None:  # the joint at a: half its parent's bone at the joint
                k = s < blend
                w_par[k] = 0.5 * (1 - s[k] / blend) ** 2
            if kids.get(c):  # the joint at b: half the child's bone at the joint
                k = s > 1 - blend
                w_kid[k] = 0.5 * (1 - (1 - s[k]) / blend) ** 2
            w_self = 1.0 - w_par - w_kid
            J = np.zeros((V.shape[0], 4), dtype=np.uint8)
            W = np.zeros((V.shape[0], 4))
            J[:, 0], W[:, 0] = index[n], w_self
            slot = 1
            if parent[n] is not None:
                J[:, slot], W[:, slot] = index[parent[n]], w_par
                slot += 1
            if kids.get(c):
                J[:, slot], W[:, slot] = index[c], w_kid
            W[W == 0] = 0.0
            J[W == 0] = 0  # unused influences: joint 0, weight 0
            Vs.append(V)
            Ns.append(N)
            UVs.append(UV)
            Js.append(J)
            Ws.append(W)
            Ts.append(T + count)
            count += V.shape[0]
    V, N, UV = np.concatenate(Vs), np.concatenate(Ns), np.concatenate(UVs)
    Jt, W, T = np.concatenate(Js), np.concatenate(Ws), np.concatenate(Ts)
    W32 = W.astype(np.float32)
    W32[:, 0] = np.float32(1.0) - W32[:, 1:].sum(axis=1, dtype=np.float32)  # sums to 1 in float32
    N = N / np.linalg.norm(N, axis=1, keepdims=True)
    prim = {"attributes": {"POSITION": buf.add(V, 5126, "VEC3", 34962, minmax=True),
                           "NORMAL": buf.add(N, 5126, "VEC3", 34962),
                           "TEXCOORD_0": buf.add(UV, 5126, "VEC2", 34962),
                           "JOINTS_0": buf.add(Jt, 5121, "VEC4", 34962),
                           "WEIGHTS_0": buf.add(W32, 5126, "VEC4", 34962)},
            "indices": buf.add(T.reshape(-1), 5123, "SCALAR", 34963), "material": 0, "mode": 4}
    png = checker_png()
    image_view = buf.view(png)
    # the animation: translation, rotation and scale of every joint, LINEAR, 30 fps
    t_acc = buf.add(t, 5126, "SCALAR", minmax=True)
    samplers, channels = [], []
    for n in names:
        for path, values in (("translation", trans[n]), ("rotation", _quat(rot[n])),
                             ("scale", np.ones((F, 3)))):
            out = buf.add(values, 5126, "VEC4" if path == "rotation" else "VEC3")
            samplers.append({"input": t_acc, "output": out, "interpolation": "LINEAR"})
            channels.append({"sampler": len(samplers) - 1, "target": {"node": node_of[n], "path": path}})
    buf.data += b"\0" * (-len(buf.data) % 4)
    doc = {
        "asset": {"version": "2.0", "generator": "motionx data/skinned_walk/make_glb.py",
                  "copyright": "motion: CMU Graphics Lab Motion Capture Database (mocap.cs.cmu.edu), subject 16 "
                               "trial 15; see README.md"},
        "scene": 0,
        "scenes": [{"name": "Scene", "nodes": [arm, body]}],
        "nodes": nodes,
        "meshes": [{"name": "Body", "primitives": [prim]}],
        "skins": [{"name": "Armature", "inverseBindMatrices": ibm_acc, "joints": [node_of[n] for n in names],
                   "skeleton": node_of[root]}],
        "materials": [{"name": "Skin", "pbrMetallicRoughness": {
            "baseColorTexture": {"index": 0}, "baseColorFactor": [1.0, 1.0, 1.0, 1.0], "metallicFactor": 0.0,
            "roughnessFactor": 0.7}}],
        "textures": [{"sampler": 0, "source": 0}],
        "images": [{"name": "checker", "bufferView": image_view, "mimeType": "image/png"}],
        "samplers": [{"magFilter": 9728, "minFilter": 9728, "wrapS": 10497, "wrapT": 10497}],
        "animations": [{"name": "mixamo.com", "samplers": samplers, "channels": channels}],
        "buffers": [{"byteLength": len(buf.data)}],
        "bufferViews": buf.views,
        "accessors": buf.accessors,
    }
    js = json.dumps(doc, separators=(",", ":")).encode()
    js += b" " * (-len(js) % 4)
    data = bytes(buf.data)
    glb = b"".join([struct.pack("<III", 0x46546C67, 2, 12 + 8 + len(js) + 8 + len(data)),
                    struct.pack("<II", len(js), 0x4E4F534A), js, struct.pack("<II", len(data), 0x004E4942), data])
    info = {"joints": len(names), "frames": F, "vertices": int(V.shape[0]), "triangles": int(T.shape[0]),
            "bytes": len(glb), "max_influences": int((W32 > 0).sum(axis=1).max())}
    return glb, {**info, "_G": G, "_trans": trans, "_rot": rot, "_names": names, "_parent": parent}


def check(info: dict) -> dict[str, float]:
    """The file's leg and arm joints (our FK of the node TRS along the animation, scene metres)
    against the CMU joints they follow (scaled, cm -> m)."""
    clip = make_rig.read_bvh(SOURCE)
    _, P = clip.forward()
    src = {n: j for j, n in enumerate(clip.names)}
    names, parent, rot, trans = info["_names"], info["_parent"], info["_rot"], info["_trans"]
    A = np.eye(4)
    A[:3, :3] = Rotation.from_quat(ARMATURE_ROTATION).as_matrix() * ARMATURE_SCALE
    F = info["frames"]
    W = {}
    for n in names:
        m = np.broadcast_to(np.eye(4), (F, 4, 4)).copy()
        m[:, :3, :3] = rot[n]
        m[:, :3, 3] = trans[n]
        W[n] = (A if parent[n] is None else W[parent[n]]) @ m
    out = {}
    for group, pairs in (("legs", ("UpLeg:femur", "Leg:tibia", "Foot:foot", "ToeBase:toes")),
                         ("arms", ("Arm:humerus", "ForeArm:radius", "Hand:hand"))):
        worst = 0.0
        for pair in pairs:
            ours, cmu = pair.split(":")
            for side, s in (("Left", "l"), ("Right", "r")):
                a = W[f"mixamorig:{side}{ours}"][:, :3, 3]
                b = P[src[f"{s}{cmu}"]][: a.shape[0]] * SCALE * 0.01
                worst = max(worst, float(np.abs(a - b).max()))
        out[f"{group}_max_cm"] = worst * 100
    return out


def main() -> None:
    glb, info = build()
    OUT.write_bytes(glb)
    print(f"{OUT.name}: " + ", ".join(f"{k} {v}" for k, v in info.items() if not k.startswith("_")))
    print("joints vs the CMU joints (x0.97), cm:", check(info))


if __name__ == "__main__":
    main()
