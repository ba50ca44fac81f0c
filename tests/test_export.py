"""Exporters: every file is read back by an independent reader (jsonschema + our own
quaternion algebra written here, pygltflib, bvhio and a BVH forward kinematics written
here from the file's text) and must give the world positions of our forward kinematics."""

from __future__ import annotations

import base64
import json
import math
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import jsonschema
import numpy as np
import pygltflib
import pytest

from solver import character as C
from solver import kinematics as K
from solver.export import (
    Y_UP,
    ExportError,
    export_motion,
    ground_reactions,
    local_transforms,
    matrix_to_quaternion,
)
from solver.export import bvh as B
from solver.export import clip as CL
from solver.export import gltf as G
from solver.export import reimport as RI
from solver.motion import Motion

with warnings.catch_warnings():  # bvhio imports PyGLM the way PyGLM plans to deprecate
    warnings.simplefilter("ignore", PendingDeprecationWarning)
    import bvhio



def tilted() -> C.Character:
    """capture-lower with a random rest orientation on every segment and an offset root:
    exercises what the reference characters (world-aligned, root at the origin) do not."""
    from dataclasses import replace

    from scipy.spatial.transform import Rotation

    ch = C.capture_lower()
    rots = Rotation.random(len(ch.segments), random_state=7).as_matrix()
    segs = [replace(s, orientation=r) for s, r in zip(ch.segments, rots)]
    segs[0] = replace(segs[0], offset=np.array([0.1, -0.2, 0.05]))
    return replace(ch, segments=tuple(segs), name="tilted")


CHARACTERS = {"halfboy": C.halfboy, "fullbody": C.fullbody, "capture-full": C.capture_full, "tilted": tilted}

# --- test motions ------------------------------------------------------------------------


def smooth_motion(ch: C.Character, T: int = 48, fps: float = 60.0, seed: int = 0) -> tuple[Motion, dict]:
    """Random smooth joint trajectories within the limits, a walk-like root that turns by
    more than a half turn, a contact schedule, and foot wrenches built from known ground
    reactions (force, CoP on z = 0, free moment), returned as the known answers."""
    rng = np.random.default_rng(seed)
    t = np.arange(T) / fps
    q = np.zeros((ch.n, T))
    for k in range(ch.n):
        lo, hi = ch.lower[k], ch.upper[k]
        lo, hi = max(lo, -math.pi), min(hi, math.pi)
        mid, half = 0.5 * (lo + hi), 0.45 * (hi - lo)
        wave = sum(rng.uniform(-1, 1) * np.sin(2 * np.pi * rng.uniform(0.3, 2.0) * t + rng.uniform(0, 2 * np.pi))
                   for _ in range(3)) / 3.0
        q[k] = mid + half * wave
    names = ch.coordinate_names
    q[names.index("root_tx")] = 1.1 * t + 0.3
    q[names.index("root_ty")] = 0.05 * np.sin(3 * t)
    q[names.index("root_tz")] = 0.62 + 0.02 * np.sin(6 * t)
    q[names.index("root_rz")] = 2.5 + 2.0 * t / t[-1]  # crosses +pi: yaw wraps in Euler/quaternion form
    q[names.index("root_ry")] = 0.2 * np.sin(2 * t)
    q[names.index("root_rx")] = 0.15 * np.cos(3 * t)
    contacts = rng.random((len(ch.contacts), T)) < 0.6
    contacts[:, :5] = True
    # known ground reactions: each foot loaded on ~2/3 of the frames
    loaded = rng.random((2, T)) < 0.65
    force = np.stack([rng.uniform(-40, 40, (2, T)), rng.uniform(-20, 20, (2, T)), rng.uniform(30, 250, (2, T))], -1)
    force[~loaded] = 0.0
    cop = np.stack([rng.uniform(-0.5, 2.0, (2, T)), rng.uniform(-0.3, 0.3, (2, T)), np.zeros((2, T))], -1)
    free = rng.uniform(-2, 2, (2, T))
    free[~loaded] = 0.0
    moment = np.cross(cop, force)
    moment[..., 2] += free
    wrenches = np.concatenate([moment, force], axis=-1).transpose(0, 2, 1)  # (2, 6, T)
    motion = Motion(ch, fps, q, contacts=contacts, wrenches=wrenches, provenance={"step": "test"})
    return motion, {"loaded": loaded, "force": force, "cop": cop, "free": free}


@pytest.fixture(scope="module", params=sorted(CHARACTERS))
def case(request):
    ch = CHARACTERS[request.param]()
    motion, known = smooth_motion(ch, seed=len(request.param))
    rot, pos = K.segment_frames(ch, motion.q)  # (S, 3, 3, T), (S, 3, T)
    return motion, known, rot.transpose(0, 3, 1, 2), pos.transpose(0, 2, 1)


# --- independent rotation algebra (written here, not imported) ------------------------------


def quat_to_matrix(qxyzw: np.ndarray) -> np.ndarray:
    x, y, z, w = np.moveaxis(np.asarray(qxyzw, dtype=float), -1, 0)
    n = np.sqrt(x * x + y * y + z * z + w * w)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def elementary(axis: str, deg: np.ndarray) -> np.ndarray:
    a = np.radians(deg)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    rows = {
        "X": [[o, z, z], [z, c, -s], [z, s, c]],
        "Y": [[c, z, s], [z, o, z], [-s, z, c]],
        "Z": [[c, -s, z], [s, c, z], [z, z, o]],
    }[axis]
    return np.moveaxis(np.array(rows), (0, 1), (-2, -1))


# --- shared pieces ------------------------------------------------------------------------


@pytest.mark.parametrize("name", sorted(CHARACTERS))
def test_local_transforms_compose_to_forward_kinematics(name):
    ch = CHARACTERS[name]()
    motion, _ = smooth_motion(ch, T=10, seed=3)
    lt = local_transforms(ch, motion.q)
    rot, pos = K.segment_frames(ch, motion.q)
    idx = {s.name: i for i, s in enumerate(ch.segments)}
    w_rot, w_pos = np.empty_like(lt.rot), np.empty_like(lt.pos)
    for i, s in enumerate(ch.segments):
        if s.parent is None:
            w_rot[i], w_pos[i] = lt.rot[i], lt.pos[i]
        else:
            j = idx[s.parent]
            w_rot[i] = w_rot[j] @ lt.rot[i]
            w_pos[i] = w_pos[j] + np.einsum("tij,tj->ti", w_rot[j], lt.pos[i])
    np.testing.assert_allclose(w_rot, rot.transpose(0, 3, 1, 2), atol=1e-12)
    np.testing.assert_allclose(w_pos, pos.transpose(0, 2, 1), atol=1e-12)


def test_matrix_to_quaternion_known_answers_and_round_trip():
    half = math.sqrt(0.5)
    rx180 = np.diag([1.0, -1.0, -1.0])
    rz90 = np.array([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 1.0]])
    np.testing.assert_allclose(matrix_to_quaternion(rx180), [1, 0, 0, 0], atol=1e-15)
    np.testing.assert_allclose(matrix_to_quaternion(rz90), [0, 0, half, half], atol=1e-15)
    np.testing.assert_allclose(matrix_to_quaternion(np.eye(3)), [0, 0, 0, 1], atol=0)
    rng = np.random.default_rng(1)
    qs = rng.normal(size=(500, 4))
    qs[:100, 3] = 1e-9  # rotations by almost pi: the pivot must not be w
    qs /= np.linalg.norm(qs, axis=1, keepdims=True)
    mats = quat_to_matrix(qs)
    back = matrix_to_quaternion(mats)
    np.testing.assert_allclose(quat_to_matrix(back), mats, atol=1e-12)
    assert np.all(back[:, 3] >= 0)


def test_y_up_is_a_proper_rotation_sending_up_to_y_and_forward_to_z():
    assert np.linalg.det(Y_UP) == pytest.approx(1.0)
    np.testing.assert_array_equal(Y_UP @ [0, 0, 1], [0, 1, 0])  # up
    np.testing.assert_array_equal(Y_UP @ [1, 0, 0], [0, 0, 1])  # forward
    np.testing.assert_array_equal(Y_UP @ [0, 1, 0], [1, 0, 0])  # left


def test_ground_reactions_recover_cop_force_and_free_moment(case):
    motion, known, _, _ = case
    gr = ground_reactions(motion)
    np.testing.assert_array_equal(gr.loaded, known["loaded"])
    np.testing.assert_allclose(gr.force, known["force"], atol=1e-12)
    L = known["loaded"]
    np.testing.assert_allclose(gr.cop[L], known["cop"][L], atol=1e-12)
    np.testing.assert_allclose(gr.free_moment[L], known["free"][L], atol=1e-11)
    assert np.all(np.isnan(gr.cop[~L])) and np.all(np.isnan(gr.free_moment[~L]))
    # physical check: about the CoP the moment is purely vertical
    moment = motion.wrenches[:, :3].transpose(0, 2, 1)
    about_cop = moment - np.cross(gr.cop, gr.force)
    np.testing.assert_allclose(about_cop[L][:, :2], 0.0, atol=1e-10)
    with pytest.raises(ExportError, match="min_load"):
        ground_reactions(motion, min_load=-1.0)
    with pytest.raises(ExportError, match="no contact wrenches"):
        ground_reactions(motion.evolve(wrenches=None))


# --- JSON clip ------------------------------------------------------------------------------


def clip_world(clip: dict) -> np.ndarray:
    """World origins (S, T, 3) of every segment, recomputed from the clip's data alone."""
    skel = clip["skeleton"]
    idx = {s["name"]: i for i, s in enumerate(skel)}
    rots = quat_to_matrix(np.array(clip["rotations"]).transpose(1, 0, 2))  # (S, T, 3, 3)
    T = clip["frame_count"]
    w_rot, w_pos = np.empty_like(rots), np.empty((len(skel), T, 3))
    for i, s in enumerate(skel):
        if s["parent"] is None:
            w_rot[i], w_pos[i] = rots[i], np.array(clip["root_translation"])
        else:
            j = idx[s["parent"]]
            off = np.array(clip.get("translations", {}).get(s["name"], [s["offset"]] * T))
            w_rot[i] = w_rot[j] @ rots[i]
            w_pos[i] = w_pos[j] + np.einsum("tij,tj->ti", w_rot[j], off)
    return w_pos


@pytest.mark.parametrize("y_up", [False, True])
def test_clip_validates_and_reproduces_world_positions(case, y_up):
    motion, known, _, pos = case
    text = CL.to_clip_json(motion, y_up=y_up, points=True)
    clip = json.loads(text)
    jsonschema.Draft202012Validator(json.loads(CL.SCHEMA_PATH.read_text())).validate(clip)
    CL.validate_clip(clip)
    conv = Y_UP if y_up else np.eye(3)
    assert clip["fps"] == motion.fps and clip["frame_count"] == motion.T
    assert clip["axes"]["up"] == ("+y" if y_up else "+z")
    np.testing.assert_allclose(clip_world(clip), pos @ conv.T, atol=1e-5)
    # rest rotations and offsets are the character's
    for s, d in zip(motion.character.segments, clip["skeleton"]):
        np.testing.assert_allclose(quat_to_matrix(d["rotation"]), conv @ s.orientation @ conv.T, atol=1e-5)
        np.testing.assert_allclose(d["offset"], conv @ s.offset, atol=1e-6)
    # points: markers and contact points in world
    ch = motion.character
    pts = np.concatenate([K.markers(ch, motion.q), K.contact_points(ch, motion.q)]).transpose(2, 0, 1)
    np.testing.assert_allclose(np.array(clip["points"]["positions"]), pts @ conv.T, atol=1e-6)
    # contact flags and ground reactions
    np.testing.assert_array_equal(np.array(clip["contacts"]["flags"]).T, motion.foot_contact())
    for i, foot in enumerate(("right", "left")):
        g = clip["ground_reaction"][foot]
        np.testing.assert_allclose(np.array(g["force"]), known["force"][i] @ conv.T, atol=1e-6)
        for t in range(motion.T):
            if known["loaded"][i, t]:
                np.testing.assert_allclose(g["cop"][t], conv @ known["cop"][i, t], atol=1e-6)
                assert g["free_moment"][t] == pytest.approx(known["free"][i, t], abs=1e-6)
                assert g["cop"][t][1 if y_up else 2] == 0.0  # on the ground plane
            else:
                assert g["cop"][t] is None and g["free_moment"][t] is None


def test_clip_without_schedule_or_wrenches_omits_them_and_rejects_bad_options():
    motion, _ = smooth_motion(C.halfboy(), T=6)
    bare = motion.evolve(contacts=None, wrenches=None)
    clip = CL.to_clip(bare)
    CL.validate_clip(clip)
    assert "contacts" not in clip and "ground_reaction" not in clip and "points" not in clip
    with pytest.raises(ExportError, match="decimals"):
        CL.to_clip(bare, decimals=-1)
    with pytest.raises(ExportError, match="unknown option"):
        export_motion(bare, "json", yup=True)
    with pytest.raises(ExportError, match="unknown export format"):
        export_motion(bare, "fbx")
    with pytest.raises(ExportError, match="Motion"):
        export_motion({"fps": 30}, "json")
    broken = CL.to_clip(bare)
    broken["rotations"][0][0] = [0, 0, 1]
    with pytest.raises(ExportError, match="rotations"):
        CL.validate_clip(broken)


# --- glTF -----------------------------------------------------------------------------------

_NP = {5126: np.float32, 5121: np.uint8, 5123: np.uint16, 5125: np.uint32}
_NC = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}


def load_gltf(data: bytes | str) -> tuple[pygltflib.GLTF2, bytes]:
    if isinstance(data, bytes):
        g = pygltflib.GLTF2.load_from_bytes(data)
        return g, g.binary_blob()
    g = pygltflib.GLTF2.from_json(data)
    uri = g.buffers[0].uri
    assert uri.startswith("data:application/octet-stream;base64,")
    return g, base64.b64decode(uri.split(",", 1)[1])


def read_accessor(g: pygltflib.GLTF2, blob: bytes, i: int) -> np.ndarray:
    acc = g.accessors[i]
    view = g.bufferViews[acc.bufferView]
    dt = np.dtype(_NP[acc.componentType])
    nc = _NC[acc.type]
    assert view.byteStride in (None, 0, nc * dt.itemsize)
    start = (view.byteOffset or 0) + (acc.byteOffset or 0)
    assert start % dt.itemsize == 0
    assert acc.count * nc * dt.itemsize <= view.byteLength
    assert start + acc.count * nc * dt.itemsize <= len(blob)
    return np.frombuffer(blob, dtype=dt, count=acc.count * nc, offset=start).reshape(acc.count, nc)


def node_matrix(t, r, s=None) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = quat_to_matrix(r if r is not None else [0, 0, 0, 1])
    if s is not None:
        m[:3, :3] = m[:3, :3] @ np.diag(s)
    m[:3, 3] = t if t is not None else 0.0
    return m


def animated_world(g: pygltflib.GLTF2, blob: bytes) -> np.ndarray:
    """World matrices (N, T, 4, 4) of every node at every key time, from the file alone."""
    anim = g.animations[0]
    times = None
    tracks: dict[tuple[int, str], np.ndarray] = {}
    for ch in anim.channels:
        smp = anim.samplers[ch.sampler]
        assert smp.interpolation == "LINEAR"
        t = read_accessor(g, blob, smp.input)[:, 0]
        times = t if times is None else times
        np.testing.assert_array_equal(t, times)
        tracks[(ch.target.node, ch.target.path)] = read_accessor(g, blob, smp.output).astype(float)
    T = len(times)
    parent = {c: i for i, n in enumerate(g.nodes) for c in (n.children or [])}
    world = np.empty((len(g.nodes), T, 4, 4))
    done: set[int] = set()

    def visit(i: int) -> None:
        n = g.nodes[i]
        for f in range(T):
            tr = tracks.get((i, "translation"))
            ro = tracks.get((i, "rotation"))
            local = node_matrix(tr[f] if tr is not None else n.translation,
                                ro[f] if ro is not None else n.rotation, n.scale)
            world[i, f] = local if i not in parent else world[parent[i], f] @ local
        done.add(i)
        for c in n.children or []:
            visit(c)

    for root in g.scenes[g.scene].nodes:
        visit(root)
    assert done == set(range(len(g.nodes)))
    return world, times


@pytest.mark.parametrize("kind", ["glb", "gltf"])
def test_gltf_animation_reproduces_forward_kinematics(case, kind):
    motion, _, rot, pos = case
    ch = motion.character
    S = len(ch.segments)
    data = G.to_glb(motion) if kind == "glb" else G.to_gltf(motion, binary=False)
    g, blob = load_gltf(data)
    assert g.asset.version == "2.0"
    world, times = animated_world(g, blob)
    np.testing.assert_allclose(times, np.arange(motion.T) / motion.fps, atol=1e-6)
    assert [n.name for n in g.nodes[:S]] == [s.name for s in ch.segments]
    # Y-up: world positions of segment origins are Y_UP @ ours
    np.testing.assert_allclose(world[:S, :, :3, 3], pos @ Y_UP.T, atol=1e-5)
    np.testing.assert_allclose(world[:S, :, :3, :3], Y_UP @ rot @ Y_UP.T, atol=1e-5)
    # the skin: joints are the segment nodes; inverse bind matrices invert the rest pose
    skin = g.skins[0]
    assert skin.joints == list(range(S))
    ibm = read_accessor(g, blob, skin.inverseBindMatrices).reshape(S, 4, 4).transpose(0, 2, 1)
    rest = np.empty((S, 4, 4))
    for i, n in enumerate(g.nodes[:S]):
        local = node_matrix(n.translation, n.rotation)
        p = ch.segments[i].parent
        rest[i] = local if p is None else rest[[s.name for s in ch.segments].index(p)] @ local
    np.testing.assert_allclose(np.einsum("sij,sjk->sik", rest, ibm), np.broadcast_to(np.eye(4), (S, 4, 4)), atol=1e-6)
    # meshes: every skinned vertex lies, at every frame, on its segment's ellipsoid — a foot's, on a corner
    # of its shoe (its sole through the heel and toe contact points); a welded toes segment has none
    mesh_nodes = [n for n in g.nodes[S:] if n.mesh is not None and n.name != "ground"]
    (ground,) = [n for n in g.nodes if n.name == "ground"]  # the ground beside the walk: not skinned
    assert ground.skin is None and ground.mesh is not None and g.meshes[ground.mesh].name == "ground"
    feet = {f.segment: f.side for f in ch.feet}
    welded = {s.name for s in ch.segments if s.parent in feet and not s.dofs}
    drawn = [s for s in ch.segments if ((s.length > 0 and s.radius > 0) or s.name in feet) and s.name not in welded]
    assert len(mesh_nodes) == len(drawn)
    for n in mesh_nodes:
        assert n.skin == 0
        prim = g.meshes[n.mesh].primitives[0]
        v = read_accessor(g, blob, prim.attributes.POSITION).astype(float)
        j = read_accessor(g, blob, prim.attributes.JOINTS_0)
        w = read_accessor(g, blob, prim.attributes.WEIGHTS_0)
        assert np.all(j[:, 0] == j[0, 0]) and np.all(w[:, 0] == 1.0) and np.all(w[:, 1:] == 0.0)
        k = int(j[0, 0])
        seg = ch.segments[k]
        assert g.nodes[k].name == seg.name
        for f in (0, motion.T // 2, motion.T - 1):
            skinned = (world[k, f] @ ibm[k] @ np.c_[v, np.ones(len(v))].T)[:3].T
            ours = (skinned @ Y_UP) - pos[k, f]  # back to our axes, relative to the segment origin
            local = ours @ rot[k, f]  # segment coordinates
            if seg.name in feet:
                corners = np.vstack(G.foot_shape(ch, feet[seg.name]))  # (8, 3)
                np.testing.assert_allclose(np.abs(local[:, None] - corners[None]).max(axis=2).min(axis=1), 0.0,
                                           atol=1e-5)
                continue
            a, b = seg.length / 2, seg.radius
            along = local @ seg.direction
            across = np.linalg.norm(local - np.outer(along, seg.direction), axis=1)
            np.testing.assert_allclose((along - a) ** 2 / a**2 + across**2 / b**2, 1.0, atol=1e-4)
        idx = read_accessor(g, blob, prim.indices)
        assert idx.max() < len(v)


def test_gltf_accessors_counts_and_bounds_are_consistent(case):
    motion, _, _, _ = case
    g, blob = load_gltf(G.to_glb(motion))
    assert len(blob) == g.buffers[0].byteLength
    for view in g.bufferViews:
        assert view.byteOffset % 4 == 0 and view.byteOffset + view.byteLength <= len(blob)
    for i, acc in enumerate(g.accessors):
        data = read_accessor(g, blob, i)
        view = g.bufferViews[acc.bufferView]
        assert acc.count * _NC[acc.type] * np.dtype(_NP[acc.componentType]).itemsize == view.byteLength
        if acc.min:
            np.testing.assert_array_equal(np.array(acc.min, dtype=data.dtype), data.min(axis=0))
            np.testing.assert_array_equal(np.array(acc.max, dtype=data.dtype), data.max(axis=0))
    for mesh in g.meshes:
        pa = g.accessors[mesh.primitives[0].attributes.POSITION]
        assert pa.min and pa.max  # required by the spec
    for smp in g.animations[0].samplers:
        inp, out = g.accessors[smp.input], g.accessors[smp.output]
        assert inp.count == out.count == motion.T and inp.min
        assert inp.min[0] == 0.0 and inp.max[0] == pytest.approx((motion.T - 1) / motion.fps, rel=1e-6)


def test_gltf_glb_layout_and_bad_options():
    motion, _ = smooth_motion(C.halfboy(), T=5)
    glb = G.to_glb(motion)
    magic, version, length = np.frombuffer(glb[:12], dtype="<u4")
    assert (magic, version, length) == (0x46546C67, 2, len(glb))
    assert len(glb) % 4 == 0
    without = G.to_glb(motion, meshes=False)
    g, _ = load_gltf(without)
    assert not g.meshes and not g.skins and len(g.nodes) == len(motion.character.segments)
    with pytest.raises(ExportError, match="meshes"):
        G.to_glb(motion, meshes="yes")
    with pytest.raises(ExportError, match="unknown option"):
        export_motion(motion, "gltf", units="cm")
    with pytest.raises(ExportError, match="unknown option"):
        export_motion(motion, "glb", y_up=False)


def test_slide_joint_below_the_root_is_animated_in_clip_and_gltf_and_refused_by_bvh():
    from dataclasses import replace

    ch = C.halfboy()
    segs = list(ch.segments)
    k = [s.name for s in segs].index("shank_r")
    slide = C.Dof("shank_slide_r", "slide", np.array([0.0, 0.3, -1.0]), -0.1, 0.1)
    segs[k] = replace(segs[k], dofs=(slide, *segs[k].dofs))
    ch = replace(ch, segments=tuple(segs), name="sliding")
    motion, _ = smooth_motion(ch, T=12, seed=5)
    q = motion.q.copy()
    q[ch.index("shank_slide_r")] = 0.08 * np.sin(np.linspace(0, 3, motion.T))
    motion = motion.evolve(q=q)
    _, pos = K.segment_frames(ch, motion.q)
    pos = pos.transpose(0, 2, 1)
    clip = CL.to_clip(motion)
    CL.validate_clip(clip)
    assert set(clip["translations"]) == {"shank_r"}
    np.testing.assert_allclose(clip_world(clip), pos, atol=1e-5)
    g, blob = load_gltf(G.to_glb(motion))
    world, _ = animated_world(g, blob)
    np.testing.assert_allclose(world[: len(segs), :, :3, 3], pos @ Y_UP.T, atol=1e-5)
    assert any(c.target.node == k and c.target.path == "translation" for c in g.animations[0].channels)
    with pytest.raises(ExportError, match="shank_r"):
        B.to_bvh(motion)


# --- BVH ------------------------------------------------------------------------------------


def bvh_fk(text: str) -> tuple[dict, float, int]:
    """An independent BVH reader: world positions {joint or joint/End: (T, 3)} from the text."""
    tok = text.split()
    i = 0
    joints = []  # (name, parent index, offset, channels)
    ends = []  # (parent index, offset)

    def parse(parent: int) -> None:
        nonlocal i
        name = tok[i + 1]
        assert tok[i + 2] == "{" and tok[i + 3] == "OFFSET"
        off = np.array(tok[i + 4:i + 7], dtype=float)
        assert tok[i + 7] == "CHANNELS"
        nch = int(tok[i + 8])
        chans = tok[i + 9:i + 9 + nch]
        i += 9 + nch
        me = len(joints)
        joints.append((name, parent, off, chans))
        while tok[i] != "}":
            if tok[i] == "JOINT":
                parse(me)
            else:
                assert tok[i:i + 4] == ["End", "Site", "{", "OFFSET"]
                ends.append((me, np.array(tok[i + 4:i + 7], dtype=float)))
                assert tok[i + 7] == "}"
                i += 8
        i += 1

    assert tok[0] == "HIERARCHY" and tok[1] == "ROOT"
    i = 1
    parse(-1)
    assert tok[i] == "MOTION" and tok[i + 1] == "Frames:" and tok[i + 3:i + 5] == ["Frame", "Time:"]
    frames, ftime = int(tok[i + 2]), float(tok[i + 5])
    nch = sum(len(j[3]) for j in joints)
    vals = np.array(tok[i + 6:], dtype=float)
    assert vals.size == frames * nch
    vals = vals.reshape(frames, nch)
    out, w_rot = {}, []
    col = 0
    for name, parent, off, chans in joints:
        p = np.broadcast_to(off, (frames, 3)).copy()
        r = np.broadcast_to(np.eye(3), (frames, 3, 3)).copy()
        for c in chans:
            if c.endswith("position"):
                p[:, "XYZ".index(c[0])] += vals[:, col]  # channel added to OFFSET (OFFSET of the root is 0)
            else:
                r = r @ elementary(c[0], vals[:, col])
            col += 1
        if parent < 0:
            w_rot.append(r)
            out[name] = p
        else:
            pr = w_rot[parent]
            out[name] = out[joints[parent][0]] + np.einsum("tij,tj->ti", pr, p)
            w_rot.append(pr @ r)
    for parent, off in ends:
        out[joints[parent][0] + "/End"] = out[joints[parent][0]] + np.einsum("tij,j->ti", w_rot[parent], off)
    return out, ftime, frames


@pytest.mark.parametrize("units,order", [("cm", "XZY"), ("m", "ZXY"), ("cm", "YZX")])
def test_bvh_text_forward_kinematics_matches_ours(case, units, order):
    motion, _, _, pos = case
    ch = motion.character
    text = B.to_bvh(motion, units=units, rotation_order=order)
    world, ftime, frames = bvh_fk(text)
    scale = 100.0 if units == "cm" else 1.0
    assert frames == motion.T and ftime == pytest.approx(1.0 / motion.fps, rel=1e-12)
    for i, s in enumerate(ch.segments):
        np.testing.assert_allclose(world[s.name] / scale, pos[i] @ Y_UP.T, atol=1e-4, err_msg=s.name)
    # End Sites are the bone tips (markers) of the leaf segments
    leaves = [s for s in ch.segments if not any(c.parent == s.name for c in ch.segments)]
    tips = np.asarray(K.points_world(ch, motion.q, [(s.name, s.marker) for s in leaves])).transpose(0, 2, 1)
    assert {k for k in world if k.endswith("/End")} == {f"{s.name}/End" for s in leaves}
    for s, tip in zip(leaves, tips):
        np.testing.assert_allclose(world[f"{s.name}/End"] / scale, tip @ Y_UP.T, atol=1e-4)


def test_bvh_read_by_bvhio_gives_our_world_positions(case, tmp_path):
    motion, _, _, pos = case
    path = tmp_path / "walk.bvh"
    path.write_text(B.to_bvh(motion))
    raw = bvhio.readAsBvh(str(path))
    assert raw.FrameCount == motion.T and raw.FrameTime == pytest.approx(1.0 / motion.fps)
    root = bvhio.readAsHierarchy(str(path))
    names = [s.name for s in motion.character.segments]
    joints = [j for j, _, _ in root.layout()]
    assert sorted(j.Name for j in joints) == sorted(names)
    for f in range(0, motion.T, 7):
        root.loadPose(f, recursive=True)
        for j in joints:
            got = np.array(j.PositionWorld, dtype=float) / 100.0
            np.testing.assert_allclose(got, Y_UP @ pos[names.index(j.Name), f], atol=1e-4, err_msg=j.Name)


def test_bvh_rotation_channels_are_continuous_and_bad_options_refused():
    motion, _ = smooth_motion(C.halfboy(), T=60)
    text = B.to_bvh(motion)
    rows = np.array([ln.split() for ln in text.split("Frame Time:")[1].splitlines()[1:]], dtype=float)
    # the root yaw crosses 180 degrees, yet no channel jumps between frames
    assert np.abs(np.diff(rows[:, 3:], axis=0)).max() < 30.0
    assert "CHANNELS 6 Xposition Yposition Zposition Xrotation Zrotation Yrotation" in text
    with pytest.raises(ExportError, match="units"):
        B.to_bvh(motion, units="mm")
    with pytest.raises(ExportError, match="rotation_order"):
        B.to_bvh(motion, rotation_order="XYX")
    with pytest.raises(ExportError, match="unknown option"):
        export_motion(motion, "bvh", y_up=True)


# --- command line ---------------------------------------------------------------------------


def motionx(*args: str) -> subprocess.CompletedProcess:
    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    return subprocess.run([exe, *args], capture_output=True, text=True, timeout=120)


def test_cli_export_writes_files_independent_readers_load(tmp_path):
    motion, _ = smooth_motion(tilted(), T=20)  # not a reference: the file carries its definition
    src = tmp_path / "motion.json"
    motion.save(src)
    _, pos = K.segment_frames(motion.character, motion.q)
    pos = pos.transpose(0, 2, 1)

    r = motionx("export", str(src), "--format", "json", "--out", str(tmp_path / "c.json"), "--y-up")
    assert r.returncode == 0, r.stderr
    clip = json.loads((tmp_path / "c.json").read_text())
    CL.validate_clip(clip)
    np.testing.assert_allclose(clip_world(clip), pos @ Y_UP.T, atol=1e-5)

    r = motionx("export", str(src), "--format", "glb", "--out", str(tmp_path / "m.glb"))
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["frames"] == motion.T
    g, blob = load_gltf((tmp_path / "m.glb").read_bytes())
    world, _ = animated_world(g, blob)
    np.testing.assert_allclose(world[: len(pos), :, :3, 3], pos @ Y_UP.T, atol=1e-5)

    r = motionx("export", str(src), "--format", "gltf", "--out", str(tmp_path / "g.glb"))  # gltf = binary
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["media_type"] == "model/gltf-binary"
    assert (tmp_path / "g.glb").read_bytes() == (tmp_path / "m.glb").read_bytes()

    r = motionx("export", str(src), "--format", "gltf", "--embedded", "--out", str(tmp_path / "m.gltf"))
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["media_type"] == "model/gltf+json"
    g, blob = load_gltf((tmp_path / "m.gltf").read_text())
    world, _ = animated_world(g, blob)
    np.testing.assert_allclose(world[: len(pos), :, :3, 3], pos @ Y_UP.T, atol=1e-5)
    for bad, needle in ((["--format", "gltf", "--out", str(tmp_path / "x.gltf")], "--embedded"),
                        (["--format", "gltf", "--embedded", "--out", str(tmp_path / "x.glb")], ".gltf"),
                        (["--format", "bvh", "--embedded", "--out", str(tmp_path / "x.bvh")], "--embedded"),
                        (["--format", "gltf", "--out", "-"], "stdout")):
        r = motionx("export", str(src), *bad)
        assert r.returncode == 2 and needle in r.stderr, (bad, r.stderr)
    assert not (tmp_path / "x.gltf").exists() and not (tmp_path / "x.glb").exists()

    r = motionx("export", str(src), "--format", "bvh", "--units", "m", "--out", str(tmp_path / "m.bvh"))
    assert r.returncode == 0, r.stderr
    world, _, _ = bvh_fk((tmp_path / "m.bvh").read_text())
    np.testing.assert_allclose(world["pelvis"], pos[0] @ Y_UP.T, atol=1e-4)

    r = motionx("export", str(src), "--format", "json", "--units", "cm", "--out", str(tmp_path / "x.json"))
    assert r.returncode == 2 and "--units" in r.stderr
    r = motionx("export", str(tmp_path / "missing.json"), "--format", "bvh", "--out", str(tmp_path / "x.bvh"))
    assert r.returncode == 2 and "not found" in r.stderr
    r = motionx("export", str(src), "--format", "fbx", "--out", str(tmp_path / "x.fbx"))
    assert r.returncode == 2


# --- glTF is the binary GLB; the embedded JSON on request -------------------------------------


def test_gltf_format_is_the_binary_glb_and_binary_false_the_embedded_json():
    from solver.export import media_type

    motion, _ = smooth_motion(C.halfboy(), T=6)
    glb = export_motion(motion, "gltf")
    assert isinstance(glb, bytes) and glb[:4] == b"glTF" and glb == export_motion(motion, "glb")
    assert media_type("gltf") == media_type("glb") == "model/gltf-binary"
    text = export_motion(motion, "gltf", binary=False)
    assert isinstance(text, str) and json.loads(text)["asset"]["version"] == "2.0"
    assert media_type("gltf", binary=False) == "model/gltf+json"
    assert media_type("gltf", binary=True) == "model/gltf-binary"
    with pytest.raises(ExportError, match="binary"):
        export_motion(motion, "gltf", binary="no")
    with pytest.raises(ExportError, match="unknown option"):
        export_motion(motion, "glb", binary=False)  # glb is always binary


# --- re-import: real walks and the synthetic cases ---------------------------------------------


def walk_motion(shared_data: Path, kind: str) -> Motion:
    """A real walk: the shared DeepMimic capture (subject-fitted capture-full skeleton, 30 fps,
    39 frames), or its coordinates on the HalfBoy / full body made from that skeleton."""
    from solver.io import load_trial
    from solver.pipeline import capture_motion, synthesis_character

    d = shared_data / "deepmimic_humanoid3d_walk"
    cap = capture_motion(load_trial([d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt"]))
    if kind == "capture-full":
        return cap
    syn, _ = synthesis_character(cap.character, kind)
    q = np.stack([cap.q[cap.character.index(n)] for n in syn.coordinate_names])
    return Motion(syn, cap.fps, q, provenance={"step": "capture"})


@pytest.fixture(scope="module", params=["halfboy", "fullbody", "capture-full"])
def walk(request, shared_data):
    return walk_motion(shared_data, request.param)


#: format, options, reader options, tolerance on q (rad and m): what each file keeps
ROUND_TRIPS = {
    "glb": ("gltf", {}, {}, 1e-5),  # float32
    "gltf-embedded": ("gltf", {"binary": False}, {}, 1e-5),
    "clip": ("json", {}, {}, 1e-5),  # 6 decimals
    "clip-y-up": ("json", {"y_up": True}, {}, 1e-5),
    "bvh": ("bvh", {}, {}, 1e-6),  # 6 decimals of degrees and cm
    "bvh-m-ZXY": ("bvh", {"units": "m", "rotation_order": "ZXY"}, {"units": "m"}, 1e-5),
}


@pytest.mark.parametrize("how", sorted(ROUND_TRIPS))
def test_round_trip_of_a_real_walk_gives_back_q(walk, how):
    fmt, options, read_options, tol = ROUND_TRIPS[how]
    data = export_motion(walk, fmt, **options)
    back = RI.motion_from_file(data, walk.character, **read_options)
    assert back.source == {"json": "clip"}.get(fmt, fmt)
    assert back.q.shape == walk.q.shape
    err = np.abs(back.q - walk.q).max()
    assert err < tol, (how, err, walk.character.coordinate_names[int(np.abs(back.q - walk.q).max(axis=1).argmax())])
    assert back.fps == pytest.approx(walk.fps, rel=1e-12)
    assert back.rotation_residual < 1e-6 and back.translation_residual < 1e-6
    m = back.motion()
    assert isinstance(m, Motion) and m.T == walk.T


@pytest.mark.parametrize("how", ["glb", "clip", "bvh"])
def test_round_trip_of_the_synthetic_cases(case, how):
    """Random motions over the whole joint range, the root yaw crossing ±180° (angles come back
    continuous, not wrapped). Near gimbal lock (shoulders reach 90° of adduction) the outer
    angles of a 3-hinge chain are ill-conditioned: the file's rounding is amplified by
    1/cos(middle angle), hence the looser bound on q; the pose itself is exact."""
    motion, _, _, pos = case
    fmt, options, read_options, tol = ROUND_TRIPS[how]
    back = RI.motion_from_file(export_motion(motion, fmt, **options), motion.character, **read_options)
    assert np.abs(back.q - motion.q).max() < 500 * tol
    yaw = motion.character.index("root_rz")
    assert np.abs(back.q[yaw] - motion.q[yaw]).max() < tol and motion.q[yaw].max() > math.pi
    _, pos_back = K.segment_frames(motion.character, back.q)
    np.testing.assert_allclose(pos_back.transpose(0, 2, 1), pos, atol=1e-5)


def test_files_for_another_character_are_refused(shared_data):
    hb = C.halfboy()
    subject = walk_motion(shared_data, "halfboy").character
    motion, _ = smooth_motion(hb, T=12)
    for fmt in ("gltf", "json", "bvh"):
        data = export_motion(motion, fmt)
        tag = r"\(exported for 'halfboy'\) " if fmt != "bvh" else ""
        with pytest.raises(RI.ReimportError, match=tag + r"does not match character 'fullbody': missing segments"):
            RI.motion_from_file(data, C.fullbody())
        # same names, another body: the DeepMimic subject's HalfBoy
        with pytest.raises(RI.ReimportError, match=r"segment '\w+' has its joint .* m from the character's"):
            RI.motion_from_file(data, subject)
    # same skeleton, but 3 hinges at the knees: a HalfBoy knee cannot take these rotations
    lower = C.capture_lower()
    motion, _ = smooth_motion(lower, T=12)
    for fmt in ("gltf", "json", "bvh"):
        with pytest.raises(RI.ReimportError, match=r"segment '(shank|foot|toes)_[rl]' .* cannot take the file's "
                                                   r"rotations \(off by .* at frame \d+\); .* another character"):
            RI.motion_from_file(export_motion(motion, fmt), hb)
    # and the other way round a HalfBoy motion is a valid capture-lower motion (extra hinges at 0)
    motion, _ = smooth_motion(hb, T=12)
    back = RI.motion_from_gltf(export_motion(motion, "gltf"), lower)
    sel = [lower.index(n) for n in hb.coordinate_names]
    assert np.abs(back.q[sel] - motion.q).max() < 1e-5
    assert np.abs(np.delete(back.q, sel, axis=0)).max() < 1e-5
    # rest orientations: glTF and the clip carry them (BVH does not: with 3 hinges any rotation fits)
    from dataclasses import replace

    tl = tilted()
    tl = replace(tl, segments=(replace(tl.segments[0], offset=np.zeros(3)),) + tl.segments[1:])
    motion, _ = smooth_motion(tl, T=8)
    for fmt in ("gltf", "json"):
        with pytest.raises(RI.ReimportError, match="segment 'pelvis' has a rest orientation"):
            RI.motion_from_file(export_motion(motion, fmt), lower)


def test_broken_files_are_refused_clearly():
    motion, _ = smooth_motion(C.halfboy(), T=6)
    ch = motion.character
    glb = export_motion(motion, "gltf")
    with pytest.raises(RI.ReimportError, match="truncated GLB"):
        RI.motion_from_gltf(glb[: len(glb) // 2], ch)
    with pytest.raises(RI.ReimportError, match="neither a GLB"):
        RI.motion_from_gltf(b"glTX" + glb[4:], ch)
    doc = json.loads(export_motion(motion, "gltf", binary=False))
    doc["buffers"][0]["uri"] = "walk.bin"
    with pytest.raises(RI.ReimportError, match="external file"):
        RI.motion_from_gltf(doc, ch)
    bvh = export_motion(motion, "bvh")
    with pytest.raises(RI.ReimportError, match="values for 6 frames"):
        RI.motion_from_bvh(bvh.rsplit("\n", 2)[0], ch)
    with pytest.raises(RI.ReimportError, match="expected 'HIERARCHY'"):
        RI.motion_from_bvh("HIERARCHI" + bvh[9:], ch)
    with pytest.raises(RI.ReimportError, match="unrecognised"):
        RI.motion_from_file(b"\x00\x01binary", ch)
    with pytest.raises(ExportError, match="not a motionx clip"):
        RI.motion_from_clip({"format": "other"}, ch)
    with pytest.raises(RI.ReimportError, match="rot_tol"):
        RI.motion_from_gltf(glb, ch, rot_tol=0)


def test_decompose_hinges_any_axes_continuity_and_limits():
    from scipy.spatial.transform import Rotation

    from solver.export import _axis_rotations

    rng = np.random.default_rng(4)
    T = 200
    t = np.linspace(0, 1, T)
    for axes in (
        [np.array([0, 0, 1.0]), np.array([0, 1.0, 0]), np.array([1.0, 0, 0])],  # Tait-Bryan (our root)
        [np.array([0, 0, 1.0]), np.array([1.0, 0, 0]), np.array([0, 0, 1.0])],  # proper Euler
        list(Rotation.random(3, random_state=2).apply(np.eye(3)[[0, 1, 2]] + 0.3 * rng.normal(size=(3, 3)))),
        [np.array([0.3, -1.0, 0.2])],
        [np.array([0, 1.0, 0]), np.array([0.6, 0, 0.8])],
    ):
        axes = [a / np.linalg.norm(a) for a in axes]
        k = len(axes)
        theta = np.stack([0.9 * np.sin(2 * np.pi * (i + 1) * t + i) + (2.5 * t if i == 0 else 0.0)
                          for i in range(k)], axis=1)  # the first angle leaves (-π, π]
        M = np.broadcast_to(np.eye(3), (T, 3, 3)).copy()
        for i, a in enumerate(axes):
            M = M @ _axis_rotations(a, theta[:, i])
        got, res = RI.decompose_hinges(M, axes, -1.4 * np.ones(k), np.r_[10.0, 1.4 * np.ones(k - 1)])
        got = np.stack([RI._continuous(got[:, i], -1.4 if i else -10.0, 10.0 if i == 0 else 1.4)
                        for i in range(k)], axis=1)
        np.testing.assert_allclose(got, theta, atol=1e-9)
        assert res.max() < 1e-12
    with pytest.raises(RI.ReimportError, match="parallel"):
        RI.decompose_hinges(np.eye(3)[None], [np.array([1.0, 0, 0]), np.array([-1.0, 0, 0])])


# --- independent readers: seconds, unit quaternions, root channel, Y up ------------------------


def test_real_walk_glb_and_bvh_conventions_read_independently(walk, tmp_path):
    ch = walk.character
    names = [s.name for s in ch.segments]
    g, blob = load_gltf(export_motion(walk, "gltf"))
    anim = g.animations[0]
    paths = {(c.target.node, c.target.path): anim.samplers[c.sampler] for c in anim.channels}
    # key times in seconds: k / fps, the last one (T - 1) / fps
    times = read_accessor(g, blob, anim.samplers[0].input)[:, 0]
    assert len(times) == walk.T and times[0] == 0.0
    assert times[-1] == pytest.approx((walk.T - 1) / walk.fps, rel=1e-6)
    np.testing.assert_allclose(np.diff(times), 1.0 / walk.fps, rtol=1e-5)
    # one rotation channel of unit quaternions per hinged segment, and the root's translation
    hinged = {i for i, s in enumerate(ch.segments) if any(d.kind == "hinge" for d in s.dofs)}
    assert {n for n, p in paths if p == "rotation"} == hinged
    assert {n for n, p in paths if p == "translation"} == {0} and g.nodes[0].name == names[0]
    for (n, p), smp in paths.items():
        out = read_accessor(g, blob, smp.output)
        if p == "rotation":
            np.testing.assert_allclose(np.linalg.norm(out.astype(float), axis=1), 1.0, atol=1e-6)
    root = read_accessor(g, blob, paths[(0, "translation")].output)
    _, pos = K.segment_frames(ch, walk.q)
    np.testing.assert_allclose(root, pos[0].T @ Y_UP.T, atol=1e-6)  # the walk's root, Y up
    # Y up: in the rest skeleton (node transforms) the legs hang along -Y, the pelvis above the feet
    rest = {}
    for i, n in enumerate(g.nodes[: len(names)]):
        m = node_matrix(n.translation, n.rotation)
        p = ch.segments[i].parent
        rest[n.name] = m if p is None else rest[p] @ m
    for side in "rl":
        hip, knee, ankle = (rest[f"{s}_{side}"][:3, 3] for s in ("thigh", "shank", "foot"))
        for a, b in ((hip, knee), (knee, ankle)):
            d = (b - a) / np.linalg.norm(b - a)
            np.testing.assert_allclose(d, [0.0, -1.0, 0.0], atol=1e-9)
    # BVH (bvhio): frame time 1 / fps, the root's position channels, Y up at rest
    path = tmp_path / "walk.bvh"
    path.write_text(export_motion(walk, "bvh"))
    raw = bvhio.readAsBvh(str(path))
    assert raw.FrameCount == walk.T and raw.FrameTime == pytest.approx(1.0 / walk.fps, rel=1e-12)
    assert [c for c in raw.Root.Channels if c.endswith("position")] == ["Xposition", "Yposition", "Zposition"]
    hier = bvhio.readAsHierarchy(str(path))
    joints = {j.Name: j for j, _, _ in hier.layout()}
    hier.loadRestPose(recursive=True)
    for side in "rl":
        hip, knee, ankle = (np.array(joints[f"{s}_{side}"].PositionWorld, dtype=float)
                            for s in ("thigh", "shank", "foot"))
        for a, b in ((hip, knee), (knee, ankle)):
            np.testing.assert_allclose((b - a) / np.linalg.norm(b - a), [0.0, -1.0, 0.0], atol=1e-6)
        assert np.linalg.norm(ankle - hip) > 40.0  # cm
