"""A skinned glTF character in, the same character out (``solver.io.gltf``, ``to_glb(rig="source")``).

``data/skinned_walk/walk.glb`` (a Mixamo-style character under an ``Armature`` node with scale 0.01
and a 90° rotation, skeleton in centimetres, capsule mesh with 2-3 weights per vertex, a textured
material, the CMU straight walk) is imported; its tutor, 10° slope and 90° curve optima are
written back on it. Checked independently of our writer: the Khronos glTF-Validator (no error,
no warning), pygltflib's reading of the files (the source's meshes, skin, materials, textures,
node names and rest TRS kept), our own forward kinematics of the written nodes (pygltflib + numpy:
the ankle joints where the motion's feet are in stance, contact points not sliding), and three.js's
GLTFLoader and AnimationMixer. The CMU BVH and the DeepMimic character come out as GLBs of their
own skeletons; a library GLB holds one animation per motion; bad files are refused clearly.
"""

from __future__ import annotations

import base64
import json
import os
import re
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation
from test_gltf_threejs import NODE, SCRIPT, THREE, khronos_report

import solver
from solver.errors import InputError
from solver.export import Y_UP, ExportError
from solver.export.rig_gltf import rig_glb, rig_glb_library
from solver.io.bvh import bvh_track
from solver.io.gltf import GltfError, gltf_track, parse_gltf
from solver.io.gltf.animation import _sample_channel
from solver.kinematics import contact_points
from solver.motion import Motion
from solver.rig import SkeletonRig, feet_report, retarget
from solver.trajectory import sample

pygltflib = pytest.importorskip("pygltflib")

TRIAL = "skinned_walk/walk.glb"
MASS = 70.0
SCALE = 0.97  # make_glb.py: the character is the CMU subject x0.97


@pytest.fixture(scope="module")
def runs(shared_data):
    """The glTF character's tutor, its 10° slope optimum (λ = 1) and its curve toward 90° (its last
    natural λ)."""
    t0 = time.perf_counter()
    capture = solver.load_trial([shared_data / TRIAL], mass=MASS)
    tutor = solver.make_tutor(capture, character="halfboy", fps=15.0)
    assert tutor.status == "succeeded", tutor.message
    t1 = time.perf_counter()
    slope = solver.extrapolate(tutor.motion, solver.Target(slope_deg=10))
    curve = solver.extrapolate(tutor.motion, solver.Target(curve_deg=90))
    # HalfBoy's tight curve may end at an impasse at its last natural λ (docs/naturalness.md): the exports
    # carry a curve of λ × 90°
    assert slope.lam_reached == 1.0 and curve.lam_reached > 0.4 and curve.steps[-1].motion.report["natural"]
    print(f"\nglTF character: import + tutor {t1 - t0:.1f} s, slope and curve {time.perf_counter() - t1:.1f} s")
    return capture, {"tutor": tutor.motion, "slope10": slope.steps[-1].motion, "curve90": curve.steps[-1].motion}


# --- an independent reading of a GLB -----------------------------------------------------------------

def _accessor(g, blob: bytes, i: int) -> np.ndarray:
    a = g.accessors[i]
    v = g.bufferViews[a.bufferView]
    n = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}[a.type]
    dt = {5126: "<f4", 5121: "u1", 5123: "<u2", 5125: "<u4"}[a.componentType]
    assert not v.byteStride or v.byteStride == n * np.dtype(dt).itemsize
    off = (v.byteOffset or 0) + (a.byteOffset or 0)
    return np.frombuffer(blob, dtype=dt, count=a.count * n, offset=off).reshape(a.count, n)


def glb_fk(data: bytes, animation: int = 0):
    """pygltflib's document, the animation's key times and every node's world matrix (F, 4, 4) at
    them: each node's TRS, its animated channels' key values in place (LINEAR: exact at the keys)."""
    g = pygltflib.GLTF2.load_from_bytes(data)
    blob = g.binary_blob()
    anim = g.animations[animation]
    times, tracks = None, {}
    for ch in anim.channels:
        s = anim.samplers[ch.sampler]
        assert s.interpolation == "LINEAR"
        t = _accessor(g, blob, s.input)[:, 0].astype(float)
        assert times is None or np.array_equal(t, times)
        times = t
        tracks[(ch.target.node, ch.target.path)] = _accessor(g, blob, s.output).astype(float)
    parent = [-1] * len(g.nodes)
    for i, n in enumerate(g.nodes):
        for c in n.children or []:
            parent[c] = i
    F = times.size
    W: dict[int, np.ndarray] = {}

    def world(i: int) -> np.ndarray:
        if i not in W:
            n = g.nodes[i]
            t = tracks.get((i, "translation"), np.broadcast_to(n.translation or [0, 0, 0], (F, 3)))
            q = tracks.get((i, "rotation"), np.broadcast_to(n.rotation or [0, 0, 0, 1], (F, 4)))
            s = tracks.get((i, "scale"), np.broadcast_to(n.scale or [1, 1, 1], (F, 3)))
            M = np.zeros((F, 4, 4))
            M[:, 3, 3] = 1.0
            M[:, :3, :3] = Rotation.from_quat(q).as_matrix() * s[:, None, :]
            M[:, :3, 3] = t
            W[i] = M if parent[i] < 0 else world(parent[i]) @ M
        return W[i]

    for i in range(len(g.nodes)):
        world(i)
    return g, times, W


def feet_from_fk(motion: Motion, rig: SkeletonRig, pose, W: dict[int, np.ndarray], to_input: np.ndarray,
                 node_of: dict[str, int]) -> dict[str, float]:
    """From the GLB's own node matrices: the ankle joints' largest distance from where the motion's
    feet carry them in stance, and the largest slide of a contact point carried by the rig's foot
    (heel) or toe joint over its contact interval (as ``feet_report``, on the written file)."""
    frame = motion.frame

    def ours(name: str) -> tuple[np.ndarray, np.ndarray]:
        M = np.einsum("ij,fjk->fik", to_input, W[node_of[name]])  # input (rig) space
        R = M[:, :3, :3] / np.linalg.norm(M[:, :3, 0], axis=1)[:, None, None]
        return frame.point_from_input(M[:, :3, 3], pose.capture_time), np.einsum("ji,fjk->fik", frame.R, R)

    s = pose.times * motion.fps
    lo = np.clip(np.floor(s + 1e-9).astype(int), 0, motion.T - 1)
    hi = np.clip(np.ceil(s - 1e-9).astype(int), 0, motion.T - 1)
    feet = motion.foot_contact()
    on = motion.contacts[:, lo] & motion.contacts[:, hi]
    q = sample(motion.q, motion.fps, pose.times, cyclic=True, interpolation=motion.interpolation)
    cp = np.asarray(contact_points(motion.character, q)).reshape(len(motion.character.contacts), 3, -1)
    out = {"ankle_m": 0.0, "slide_m": 0.0}
    for k, side in enumerate("rl"):
        ankle = rig.names[rig.roles[f"foot_{side}"]]
        toe = rig.names[rig.roles.get(f"toes_{side}", rig.roles[f"foot_{side}"])]
        Pa, Ra = ours(ankle)
        Pt, Rt = ours(toe)
        stance = feet[k][lo] & feet[k][hi]
        out["ankle_m"] = max(out["ankle_m"], float(np.linalg.norm(Pa - pose.ankle_target[:, k], axis=1)[stance].max()))
        for i, c in enumerate(motion.character.contacts):
            if c.side[0] != side:
                continue
            P, R = (Pt, Rt) if "toe" in c.name else (Pa, Ra)
            edges = np.flatnonzero(np.diff(np.concatenate([[0], on[i].astype(int), [0]])))
            for a, b in zip(edges[::2], edges[1::2]):
                local = R[a].T @ (cp[i, :, a] - P[a])
                pts = P[a:b] + np.einsum("fij,j->fi", R[a:b], local)
                out["slide_m"] = max(out["slide_m"], float(np.max(np.linalg.norm(pts[:, :2] - pts[0, :2], axis=1))))
    return out


def three_js(path: Path, times: list[str]) -> dict:
    if NODE is None or not (THREE / "examples" / "jsm" / "loaders" / "GLTFLoader.js").is_file():
        pytest.skip("node or three.js missing (cd service/web && npm ci)")
    r = subprocess.run([NODE, str(SCRIPT), str(path), *times], capture_output=True, text=True, timeout=60,
                       check=False, env={**os.environ, "THREE_DIR": str(THREE), "IMAGES": "stub"})
    assert r.returncode == 0, f"three.js could not load the GLB:\n{r.stderr}"
    return json.loads(r.stdout)


# --- import ----------------------------------------------------------------------------------------

def test_import_reads_the_character_as_the_cmu_walk_it_was_made_from(shared_data):
    """The glTF character's landmarks (Armature folded in, centimetres, rest rotations on every
    joint) are the CMU clip's scaled by 0.97: legs to rounding, the arms and head within the split
    spine's 1.5 cm."""
    g = gltf_track(shared_data / TRIAL, mass=MASS)
    b = bvh_track(shared_data / "cmu16_bvh" / "16_15_walk.bvh", mass=MASS)
    assert g.times.shape == b.times.shape and g.frame.unit_m == pytest.approx(0.01)
    legs = [f"{j}_{s}" for j in ("hip", "knee", "ankle", "mtp", "heel", "toe") for s in "rl"] + ["pelvis"]
    assert max(np.abs(g.landmarks[k] - SCALE * b.landmarks[k]).max() for k in legs) < 5e-5
    upper = [k for k in b.landmarks if k not in legs]
    assert set(upper) <= set(g.landmarks) and len(upper) == 12
    assert max(np.abs(g.landmarks[k] - SCALE * b.landmarks[k]).max() for k in upper) < 0.016
    assert g.source["joint_roles"]["hip_l"] == "mixamorig:LeftUpLeg"
    assert g.source["joint_roles"]["mtp_r"] == "mixamorig:RightToeBase"


def test_capture_carries_the_character_without_its_animation(runs, shared_data):
    capture, _ = runs
    rig = capture.rig
    assert isinstance(rig, SkeletonRig) and rig.format == "gltf" and rig.J == 31
    src = pygltflib.GLTF2.load(str(shared_data / TRIAL))
    assert [src.nodes[n].name for n in rig.extra["nodes"]] == list(rig.names)
    asset = base64.b64decode(rig.extra["asset"])
    kept = pygltflib.GLTF2.load_from_bytes(asset)
    assert not kept.animations and len(asset) < 0.8 * (shared_data / TRIAL).stat().st_size
    assert [n.name for n in kept.nodes] == [n.name for n in src.nodes]
    assert capture.character.name == "capture-full"


@pytest.mark.parametrize("interp", ["STEP", "CUBICSPLINE"])
def test_every_interpolation_reads_the_same_keys(shared_data, interp):
    """The walk's samplers rewritten as STEP or CUBICSPLINE (tangents from central differences):
    at the keyframes every interpolation gives the keys, so the landmarks are the LINEAR file's."""
    g = pygltflib.GLTF2.load(str(shared_data / TRIAL))
    blob = bytearray(g.binary_blob())
    for s in g.animations[0].samplers:
        s.interpolation = interp
        if interp == "CUBICSPLINE":
            t = _accessor(g, bytes(blob), s.input)[:, 0].astype(float)
            v = _accessor(g, bytes(blob), s.output).astype(float)
            d = np.gradient(v, t, axis=0)
            out = np.stack([d, v, d], axis=1).reshape(-1, v.shape[1]).astype("<f4")
            blob += b"\0" * (-len(blob) % 4)
            g.bufferViews.append(pygltflib.BufferView(buffer=0, byteOffset=len(blob), byteLength=out.nbytes))
            blob += out.tobytes()
            acc = g.accessors[s.output]
            g.accessors.append(pygltflib.Accessor(bufferView=len(g.bufferViews) - 1, componentType=5126,
                                                  count=out.shape[0], type=acc.type))
            s.output = len(g.accessors) - 1
    g.buffers[0].byteLength = len(blob)
    g.set_binary_blob(bytes(blob))
    asset = parse_gltf(b"".join(g.save_to_bytes()), "variant")
    from solver.io.gltf.trial import _track

    variant, _, _ = _track(asset, "variant", MASS, None, None)
    base = gltf_track(shared_data / TRIAL, mass=MASS)
    assert max(np.abs(variant.landmarks[k] - base.landmarks[k]).max() for k in base.landmarks) < 1e-9


def test_sampler_interpolations_between_keys():
    keys = np.array([0.0, 1.0, 3.0])
    # LINEAR rotation: slerp, the shortest way (the second key is the first's antipode turned 90°)
    q = Rotation.from_euler("z", [[0.0], [90.0], [90.0]], degrees=True).as_quat()
    q[1] *= -1.0
    mid = _sample_channel(keys, keys, q, "LINEAR", "rotation", np.array([0.5]))
    assert Rotation.from_quat(mid).as_euler("zyx", degrees=True)[0, 0] == pytest.approx(45.0)
    # STEP holds the earlier key; times outside the keys are clamped
    v = np.array([[0.0, 0, 0], [1.0, 2, 3], [5.0, 5, 5]])
    got = _sample_channel(keys, keys, v, "STEP", "translation", np.array([-1.0, 0.99, 1.0, 2.5, 9.0]))
    assert np.array_equal(got, v[[0, 0, 1, 1, 2]])
    # CUBICSPLINE with the derivatives as tangents is exact on a cubic
    def f(t):
        return np.stack([t**3 - 2 * t, 0.5 * t**2, 1.0 + 0 * t], axis=-1)

    def df(t):
        return np.stack([3 * t**2 - 2, t, 0 * t], axis=-1)

    vals = np.stack([df(keys), f(keys), df(keys)], axis=1).reshape(-1, 3)
    t = np.linspace(0.0, 3.0, 13)
    assert np.allclose(_sample_channel(keys, keys, vals, "CUBICSPLINE", "translation", t), f(t), atol=1e-12)


def test_nodes_above_the_skeleton_are_folded_into_the_frame(shared_data):
    """The whole character turned 30° about the vertical, moved and scaled x1.1 (its Armature node):
    the same walk, seen by our frame (its landmarks x1.1 since the scene is bigger)."""
    g = pygltflib.GLTF2.load(str(shared_data / TRIAL))
    arm = next(n for n in g.nodes if n.name == "Armature")
    turn = Rotation.from_euler("y", 30, degrees=True) * Rotation.from_quat(arm.rotation)
    arm.rotation = turn.as_quat().tolist()
    arm.translation = [3.0, 0.2, -1.0]
    arm.scale = [0.011] * 3
    asset = parse_gltf(b"".join(g.save_to_bytes()), "turned")
    from solver.io.gltf.trial import _track

    turned, _, _ = _track(asset, "turned", MASS, None, None)
    base = gltf_track(shared_data / TRIAL, mass=MASS)
    assert turned.frame.unit_m == pytest.approx(0.011)
    assert max(np.abs(turned.landmarks[k] - 1.1 * base.landmarks[k]).max() for k in base.landmarks) < 1e-6


def test_embedded_gltf_reads_as_the_glb(shared_data, tmp_path):
    """The .gltf JSON with its buffer and image as data URIs reads as the .glb does."""
    g = pygltflib.GLTF2.load(str(shared_data / TRIAL))
    blob = g.binary_blob()
    img = g.images[0]
    view = g.bufferViews[img.bufferView]
    png = blob[view.byteOffset:view.byteOffset + view.byteLength]
    img.uri = "data:image/png;base64," + base64.b64encode(png).decode()
    img.bufferView = None
    g.buffers[0].uri = "data:application/octet-stream;base64," + base64.b64encode(blob).decode()
    path = tmp_path / "walk.gltf"
    path.write_text(g.gltf_to_json())
    a = gltf_track(path, mass=MASS)
    b = gltf_track(shared_data / TRIAL, mass=MASS)
    assert max(np.abs(a.landmarks[k] - b.landmarks[k]).max() for k in b.landmarks) == 0.0


# --- the character back out ------------------------------------------------------------------------

def _source_kept(src_bytes: bytes, out_bytes: bytes) -> None:
    """The source's meshes, skins, materials, textures, images, samplers, scenes, node names and
    rest TRS in the written file (data compared through pygltflib); after them only the ground
    beside the walk (a node ``ground`` at the scene root, its mesh and its material)."""
    s, o = pygltflib.GLTF2.load_from_bytes(src_bytes), pygltflib.GLTF2.load_from_bytes(out_bytes)
    sb, ob = s.binary_blob(), o.binary_blob()
    assert len(o.nodes) == len(s.nodes) + 1 and o.nodes[-1].name == "ground"
    for a, b in zip(s.nodes, o.nodes):
        assert (a.name, a.children, a.mesh, a.skin) == (b.name, b.children, b.mesh, b.skin)
        assert (a.translation, a.rotation, a.scale, a.matrix) == (b.translation, b.rotation, b.scale, b.matrix)
    assert [sc.nodes for sc in o.scenes] == [sc.nodes + ([len(s.nodes)] if k == (s.scene or 0) else [])
                                             for k, sc in enumerate(s.scenes)] and o.scene == s.scene
    assert len(o.meshes) == len(s.meshes) + 1 == 2 and o.meshes[-1].name == "ground"
    assert [m.name for m in o.materials] == [m.name for m in s.materials] + ["ground"]
    for ma, mb in zip(s.meshes, o.meshes):
        assert ma.name == mb.name and len(ma.primitives) == len(mb.primitives)
        for pa, pb in zip(ma.primitives, mb.primitives):
            assert pa.material == pb.material and pa.mode == pb.mode
            for attr in ("POSITION", "NORMAL", "TEXCOORD_0", "JOINTS_0", "WEIGHTS_0"):
                ia, ib = getattr(pa.attributes, attr), getattr(pb.attributes, attr)
                assert np.array_equal(_accessor(s, sb, ia), _accessor(o, ob, ib)), attr
            assert np.array_equal(_accessor(s, sb, pa.indices), _accessor(o, ob, pb.indices))
    assert len(o.skins) == 1
    for ka, kb in zip(s.skins, o.skins):
        assert (ka.joints, ka.skeleton, ka.name) == (kb.joints, kb.skeleton, kb.name)
        assert np.array_equal(_accessor(s, sb, ka.inverseBindMatrices), _accessor(o, ob, kb.inverseBindMatrices))
    for key in ("materials", "textures", "samplers"):
        assert json.loads(o.to_json())[key][:len(getattr(s, key))] == json.loads(s.to_json())[key], key
    for ia, ib in zip(s.images, o.images):
        va, vb = s.bufferViews[ia.bufferView], o.bufferViews[ib.bufferView]
        assert ia.mimeType == ib.mimeType and ia.name == ib.name
        assert sb[va.byteOffset:va.byteOffset + va.byteLength] == ob[vb.byteOffset:vb.byteOffset + vb.byteLength]


@pytest.mark.parametrize("name", ["tutor", "slope10", "curve90"])
def test_walks_come_out_on_the_input_character(runs, shared_data, name, tmp_path):
    _, motions = runs
    motion = motions[name]
    t0 = time.perf_counter()
    data = solver.export_motion(motion, "gltf", rig="source", world="ground")  # the solver's frame, as retarget's
    # (the default world, gravity down, is checked by tests/test_world_export.py)
    elapsed = time.perf_counter() - t0
    path = tmp_path / f"{name}.glb"
    path.write_bytes(data)
    # (a) the Khronos validator: no error, no warning
    report = khronos_report(path)
    assert report["errors"] == 0 and report["warnings"] == 0, report["messages"]
    assert report["animations"] == 1
    # (b) the character as it came in
    src = (shared_data / TRIAL).read_bytes()
    _source_kept(src, data)
    # (c) our own forward kinematics of the written nodes: one cycle at the input's 30 fps, the feet planted
    g, times, W = glb_fk(data)
    (anim,) = g.animations
    rig = motion.context.rig
    pose = retarget(motion, rig)
    assert np.allclose(times, pose.times, atol=1e-6) and times[0] == 0.0
    assert times[1] == pytest.approx(1 / 30, rel=1e-4)
    if name == "tutor":
        assert anim.name == "tutor"
    else:
        lam = motion.provenance["lambda"]  # 1, or a curve's last natural λ
        assert anim.name.startswith("extrapolate ") and anim.name.endswith(f" lambda={lam:.4f}"), anim.name
    node_of = {n.name: i for i, n in enumerate(g.nodes)}
    arm = node_of["Armature"]
    to_input = np.linalg.inv(W[arm][0])  # the Armature does not move
    assert np.allclose(W[arm], W[arm][0])
    fk = feet_from_fk(motion, rig, pose, W, to_input, node_of)
    rep = feet_report(motion, rig, pose)
    print(f"{name}: GLB FK ankle {fk['ankle_m'] * 1e3:.2f} mm, slide {fk['slide_m'] * 1e3:.2f} mm; feet_report "
          f"{ {s: (round(r['ankle_error_m'] * 1e3, 2), round(r['slide_m'] * 1e3, 2)) for s, r in rep.items()} }; "
          f"export {elapsed:.2f} s")
    assert fk["ankle_m"] <= 0.02 and fk["slide_m"] <= 0.01, fk
    for side in ("right", "left"):
        assert rep[side]["ankle_error_m"] <= 0.02 and rep[side]["slide_m"] <= 0.01, rep
    # the file's joints are the rig's own forward kinematics (float32 rounding only)
    _, P = rig.forward(pose.local, pose.root, pose.positions)
    for j, n in enumerate(rig.names):
        Pin = np.einsum("ij,fj->fi", to_input, W[node_of[n]][:, :, 3])[:, :3]
        assert np.max(np.abs(Pin - P[:, j])) < 2e-3, n  # cm: 20 µm
    # (d) three.js loads it and puts the bones where our FK does
    mid = len(times) // 2
    out = three_js(path, ["0", repr(float(times[mid])), "end"])
    assert out["bones"] == 31 and out["skinned_meshes"] == 1 and out["skins"] == 1
    assert out["materials"][0]["map"] and out["materials"][0]["name"] == "Skin"
    (clip,) = out["animations"]
    assert clip["duration"] == pytest.approx(times[-1], rel=1e-6) and len(clip["tracks"]) == 32
    three_name = {re.sub(r"[\[\].:/]", "", re.sub(r"\s", "_", n)): i for n, i in node_of.items()}  # sanitizeNodeName
    worst = 0.0
    for p, f in zip(out["poses"], [0, mid, len(times) - 1]):
        for bone, w in p["bones"].items():
            worst = max(worst, float(np.linalg.norm(np.array(w["position"]) - W[three_name[bone]][f, :3, 3])))
    assert worst < 1e-4, worst


def test_library_glb_has_one_animation_per_motion(runs, tmp_path):
    _, motions = runs
    items = list(motions.items())
    data = rig_glb_library(items, world="ground")
    path = tmp_path / "library.glb"
    path.write_bytes(data)
    report = khronos_report(path)
    assert report["errors"] == 0 and report["warnings"] == 0, report["messages"]
    g = pygltflib.GLTF2.load_from_bytes(data)
    assert [a.name for a in g.animations] == list(motions)
    assert [m.name for m in g.meshes] == ["Body", *(f"ground {n}" for n in motions)] and len(g.skins) == 1
    for k, (name, motion) in enumerate(items):
        g, times, W = glb_fk(data, animation=k)
        rig = motion.context.rig
        pose = retarget(motion, rig)
        node_of = {n.name: i for i, n in enumerate(g.nodes)}
        fk = feet_from_fk(motion, rig, pose, W, np.linalg.inv(W[node_of["Armature"]][0]), node_of)
        assert fk["ankle_m"] <= 0.02 and fk["slide_m"] <= 0.01, (name, fk)
        assert g.animations[k].extras["motionx"]["step"] == ("tutor" if name == "tutor" else "extrapolate")


def test_bvh_and_deepmimic_rigs_come_out_as_their_own_skeletons(shared_data, tmp_path):
    """The CMU BVH walk and the DeepMimic humanoid: a GLB of the input's skeleton (a node per
    joint with its offset, bone boxes / the character's BodyDefs shapes), valid, its ankles where
    the tutor's feet are in stance."""
    dm = shared_data / "deepmimic_humanoid3d_walk"
    cases = {"bvh": ([shared_data / "cmu16_bvh" / "16_15_walk.bvh"], {"mass": MASS}),
             "deepmimic": ([dm / "humanoid3d_walk.txt", dm / "humanoid3d_character.txt"], {})}
    for fmt, (files, kw) in cases.items():
        t0 = time.perf_counter()
        tutor = solver.make_tutor(solver.load_trial(files, **kw), character="halfboy", fps=15.0)
        assert tutor.status == "succeeded", tutor.message
        motion = tutor.motion
        data = solver.export_motion(motion, "glb", rig="source")
        path = tmp_path / f"{fmt}.glb"
        path.write_bytes(data)
        report = khronos_report(path)
        assert report["errors"] == 0 and report["warnings"] == 0, (fmt, report["messages"])
        rig = motion.context.rig
        g, times, W = glb_fk(data)
        names = [n.name for n in g.nodes]
        assert names[1:1 + rig.J] == list(rig.names) and len(g.skins[0].joints) == rig.J
        for j in range(rig.J):  # rest offsets as the input's
            assert np.allclose(g.nodes[1 + j].translation, rig.offsets[j], atol=1e-9) or j == 0
        if fmt == "deepmimic":  # one shape per body, in the BodyDefs' colours
            bodies = rig.extra["body_defs"]
            colours = {(b["ColorR"], b["ColorG"], b["ColorB"], b["ColorA"]) for b in bodies.values()}
            assert len(g.materials) == len(colours) + 1 and g.materials[-1].name == "ground"
            joints = set()
            blob = g.binary_blob()
            for p in g.meshes[0].primitives:
                joints |= set(_accessor(g, blob, p.attributes.JOINTS_0)[:, 0].tolist())
            assert {rig.names[j] for j in joints} == set(bodies) & set(rig.names)
        # the scene is our world turned Y up (the "rig" node maps the input onto it): the file's joints
        # are the rig's own forward kinematics there, and its ankles are where the tutor's feet are in stance
        pose = retarget(motion, rig)
        frame = motion.frame
        _, P = rig.forward(pose.local, pose.root, pose.positions)
        P_ours = frame.point_from_input(P, pose.capture_time[:, None])
        node_of = {n: i for i, n in enumerate(names)}
        for j, n in enumerate(rig.names):
            assert np.abs(W[node_of[n]][:, :3, 3] - P_ours[:, j] @ Y_UP.T).max() < 1e-5, (fmt, n)
        fk = feet_from_fk(motion, rig, pose, W, np.linalg.inv(W[0][0]), node_of)
        print(f"{fmt}: tutor + GLB {time.perf_counter() - t0:.1f} s, ankle {fk['ankle_m'] * 1e3:.2f} mm, "
              f"slide {fk['slide_m'] * 1e3:.2f} mm, {len(data)} bytes")
        assert fk["ankle_m"] <= 0.02 and fk["slide_m"] <= 0.01, (fmt, fk)
        # and the embedded .gltf of the same
        text = solver.export_motion(motion, "gltf", binary=False, rig="source")
        (tmp_path / f"{fmt}.gltf").write_text(text)
        report = khronos_report(tmp_path / f"{fmt}.gltf")
        assert report["errors"] == 0 and report["warnings"] == 0, (fmt, report["messages"])


# --- refusals --------------------------------------------------------------------------------------

def _variant(shared_data, edit) -> bytes:
    g = pygltflib.GLTF2.load(str(shared_data / TRIAL))
    edit(g)
    return b"".join(g.save_to_bytes())


def _nan_rotation(g) -> None:
    blob = bytearray(g.binary_blob())
    s = g.animations[0].samplers[g.animations[0].channels[10].sampler]
    a = g.accessors[s.output]
    off = g.bufferViews[a.bufferView].byteOffset + (a.byteOffset or 0)
    blob[off:off + 4] = np.array([np.nan], dtype="<f4").tobytes()
    g.set_binary_blob(bytes(blob))


def _rename_legs(g) -> None:
    for i, n in enumerate(g.nodes):
        if n.name and ("UpLeg" in n.name or n.name.endswith("Leg")):
            n.name = f"bone_{i}"


@pytest.mark.parametrize("edit, words", [
    (lambda g: setattr(g, "skins", []) or [setattr(n, "skin", None) for n in g.nodes], "has no skin"),
    (lambda g: setattr(g, "animations", []), "has no animation"),
    (_nan_rotation, "NaN or infinite"),
    (_rename_legs, "cannot find the joints for the roles hip_r, knee_r, hip_l, knee_l"),
    (lambda g: setattr(next(n for n in g.nodes if n.name == "Armature"), "scale", [1.0, 1.0, 1.0]),
     "m long in the scene; a walking person's are 0.45-1.2 m"),
    (lambda g: setattr(next(n for n in g.nodes if n.name == "Armature"), "scale", [0.01, 0.02, 0.01]),
     "only uniform positive scales"),
])
def test_bad_files_are_refused_clearly(shared_data, tmp_path, edit, words):
    path = tmp_path / "bad.glb"
    path.write_bytes(_variant(shared_data, edit))
    with pytest.raises(InputError, match=None) as e:
        solver.load_trial([path], mass=MASS)
    assert words in str(e.value), str(e.value)


def test_bad_options_and_sizes_are_refused(shared_data, tmp_path):
    with pytest.raises(GltfError, match=r"no animation 'run'; the file has 1: 0: mixamo\.com"):
        gltf_track(shared_data / TRIAL, mass=MASS, animation="run")
    assert gltf_track(shared_data / TRIAL, mass=MASS, animation="0").source["animation"] == "mixamo.com"
    with pytest.raises(InputError, match="subject mass unknown"):
        solver.load_trial([shared_data / TRIAL])
    big = tmp_path / "big.glb"
    big.write_bytes((shared_data / TRIAL).read_bytes() + b"\0" * (16 * 2**20))
    with pytest.raises(GltfError, match="at most 16 MB"):
        solver.load_trial([big], mass=MASS)
    ext = tmp_path / "external.gltf"
    ext.write_text(json.dumps({"asset": {"version": "2.0"}, "buffers": [{"uri": "walk.bin", "byteLength": 4}]}))
    with pytest.raises(GltfError, match="buffer 0 is an external file"):
        solver.load_trial([ext], mass=MASS)
    with pytest.raises(GltfError, match=r"x\.glb: GLB version 0; only glTF 2\.0"):
        parse_gltf(b"glTF" + b"\0" * 30, "x.glb")
    with pytest.raises(GltfError, match=r"x\.glb: the glTF JSON is unreadable"):
        parse_gltf(b"PK\x03\x04 not a glTF", "x.glb")


def test_rig_source_refusals(runs, shared_data):
    capture, motions = runs
    tutor = motions["tutor"]
    bare = tutor.evolve(context=tutor.context.with_(rig=None))
    with pytest.raises(ExportError, match="has no source rig"):
        solver.export_motion(bare, "gltf", rig="source")
    with pytest.raises(ExportError, match="rig must be 'character'"):
        solver.export_motion(tutor, "glb", rig="input")
    with pytest.raises(ExportError, match="distinct non-empty"):
        rig_glb_library([("a", tutor), ("a", motions["slope10"])])
    with pytest.raises(ExportError, match="at least one"):
        rig_glb_library([])
    rig = tutor.context.rig
    other = tutor.evolve(context=tutor.context.with_(rig=rig.evolve(names=tuple(reversed(rig.names)))))
    with pytest.raises(ExportError, match="another source rig"):
        rig_glb_library([("a", tutor), ("b", other)])
    assert rig_glb(tutor)[:4] == b"glTF"
