"""Cross-implementation check: three.js's GLTFLoader (the npm package `three` of the web page,
run in Node by tests/js/load_glb.mjs) loads our GLB, and its AnimationMixer puts every bone,
and its skinning every mesh, where our forward kinematics says (converted to Y up); and the
Khronos glTF-Validator (npm `gltf-validator`, tests/js/validate_glb.mjs) finds no error and no
warning in it."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from test_export import walk_motion

from solver import kinematics as K
from solver.export import Y_UP, export_motion

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "tests" / "js" / "load_glb.mjs"
THREE = ROOT / "service" / "web" / "node_modules" / "three"
VALIDATOR = ROOT / "service" / "web" / "node_modules" / "gltf-validator"
NODE = shutil.which("node")

pytestmark = [
    pytest.mark.skipif(NODE is None, reason="node (Node.js) is not on PATH: cannot run three.js's GLTFLoader"),
    pytest.mark.skipif(not (THREE / "examples" / "jsm" / "loaders" / "GLTFLoader.js").is_file(),
                       reason=f"three.js is not installed in {THREE.parent} (cd service/web && npm ci)"),
]


def khronos_report(path: Path) -> dict:
    """The Khronos glTF-Validator's report on the GLB at ``path`` (counts and first messages)."""
    if NODE is None:
        pytest.skip("node (Node.js) is not on PATH: cannot run the Khronos glTF validator")
    if not (VALIDATOR / "index.js").is_file():
        pytest.skip(f"the Khronos glTF validator is not installed in {VALIDATOR} (cd service/web && npm ci)")
    r = subprocess.run([NODE, str(ROOT / "tests" / "js" / "validate_glb.mjs"), str(path)], capture_output=True,
                       text=True, timeout=60, check=False, env={**os.environ, "GLTF_VALIDATOR_DIR": str(VALIDATOR)})
    assert r.returncode == 0, r.stderr
    return json.loads(r.stdout)


def quat_angle(a: np.ndarray, b: np.ndarray) -> float:
    """Angle (rad) between the rotations of unit quaternions a and b (x, y, z, w)."""
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)
    chord = min(np.linalg.norm(a - b), np.linalg.norm(a + b))  # accurate for small angles, unlike arccos
    return float(4.0 * np.arcsin(min(chord / 2.0, 1.0)))


def matrix_quat(m: np.ndarray) -> np.ndarray:
    from scipy.spatial.transform import Rotation

    return Rotation.from_matrix(m).as_quat()  # (x, y, z, w)


@pytest.fixture(scope="module", params=["halfboy", "fullbody"])
def loaded(request, shared_data, tmp_path_factory):
    motion = walk_motion(shared_data, request.param)
    path = tmp_path_factory.mktemp("three") / f"{request.param}.glb"
    path.write_bytes(export_motion(motion, "gltf"))
    frames = [0, motion.T // 3, motion.T - 1]
    times = [f"{f / motion.fps!r}" for f in frames[:-1]] + ["end"]
    r = subprocess.run([NODE, str(SCRIPT), str(path), *times], capture_output=True, text=True, timeout=60, check=False,
                       env={**os.environ, "THREE_DIR": str(THREE)})
    assert r.returncode == 0, f"three.js could not load the GLB:\n{r.stderr}"
    return motion, frames, json.loads(r.stdout)


def test_three_loads_the_skinned_character_and_its_clip(loaded):
    motion, _, out = loaded
    ch = motion.character
    names = [s.name for s in ch.segments]
    assert out["three_revision"] == "187" and out["same_three_instance"]
    assert out["bone_names"] == names and out["bones"] == len(names)
    assert out["skins"] == 1 and out["skeletons"] == 1
    # an ellipsoid per segment with a length and a radius, the feet drawn as their soles, none for a welded toe
    feet = {f.segment for f in ch.feet}
    welded = {s.name for s in ch.segments if s.parent in feet and not s.dofs}
    drawn = [s for s in ch.segments if ((s.length > 0 and s.radius > 0) or s.name in feet) and s.name not in welded]
    with_mesh = len(drawn)
    assert out["skinned_meshes"] == with_mesh and out["meshes"] == with_mesh + 1  # and the ground, not skinned
    assert out["nodes"] == len(names) + with_mesh + 1
    (clip,) = out["animations"]
    assert clip["duration"] == pytest.approx((motion.T - 1) / motion.fps, rel=1e-6)
    tracks = {t["name"]: t for t in clip["tracks"]}
    hinged = [s.name for s in ch.segments if any(d.kind == "hinge" for d in s.dofs)]
    quaternion_tracks = sorted(n for n, t in tracks.items() if t["type"] == "quaternion")
    assert quaternion_tracks == sorted(f"{n}.quaternion" for n in hinged)
    assert [n for n, t in tracks.items() if t["type"] == "vector"] == [f"{names[0]}.position"]  # the root's
    assert len(tracks) == len(hinged) + 1
    for t in tracks.values():
        assert t["keys"] == motion.T and t["interpolation"] == "LINEAR" and t["first"] == 0.0
        assert t["last"] == pytest.approx(clip["duration"], rel=1e-12)


def test_three_evaluates_our_forward_kinematics(loaded):
    motion, frames, out = loaded
    ch = motion.character
    rot, pos = K.segment_frames(ch, motion.q)  # (S, 3, 3, T), (S, 3, T)
    tips = K.points_world(ch, motion.q, [(s.name, s.marker) for s in ch.segments])  # (S, 3, T) bone tips
    assert [p["time"] for p in out["poses"]][:-1] == pytest.approx([f / motion.fps for f in frames[:-1]])
    worst = {"position": 0.0, "rotation": 0.0, "vertex": 0.0}
    for f, p in zip(frames, out["poses"]):
        for i, s in enumerate(ch.segments):
            b = p["bones"][s.name]
            d = np.linalg.norm(np.array(b["position"]) - Y_UP @ pos[i, :, f])
            a = quat_angle(np.array(b["quaternion"]), matrix_quat(Y_UP @ rot[i, :, :, f] @ Y_UP.T))
            worst["position"], worst["rotation"] = max(worst["position"], d), max(worst["rotation"], a)
            # three.js's skinning of the ellipsoid's vertex 0, its pole at the bone tip (feet: their soles)
            v = p["vertex0"].get(f"{s.name}_mesh")
            if v is not None and s.name not in {f.segment for f in ch.feet}:
                worst["vertex"] = max(worst["vertex"], np.linalg.norm(np.array(v) - Y_UP @ tips[i, :, f]))
    print(f"three.js vs our FK, {ch.name}: {worst}")
    assert worst["position"] < 1e-4 and worst["vertex"] < 1e-4 and worst["rotation"] < 1e-4, worst
    # the root really moves: it walks forward (+Z in Y-up) between the first and the last frame
    start, end = (np.array(out["poses"][k]["bones"][ch.segments[0].name]["position"]) for k in (0, -1))
    assert end[2] - start[2] > 0.3


def test_three_draws_the_feet_standing_where_their_contact_points_stand(loaded):
    """The exported foot is a shoe whose sole is the plane through its heel and toe contact points
    (``solver.export.gltf.foot_shape``): three.js's lowest skinned vertex of each foot mesh is our
    lowest sole corner (forward kinematics), which stands on the ground with the contact points
    (tests/test_naturalness.py)."""
    from solver.kinematics import sole_corners

    motion, frames, out = loaded
    ch = motion.character
    corners = sole_corners(ch, motion.q)  # (2, 4, 3, T)
    for f, p in zip(frames, out["poses"]):
        for k, foot in enumerate(ch.feet):
            low = p["lowest"][f"{foot.segment}_mesh"]
            assert low == pytest.approx(float((Y_UP @ corners[k, :, :, f].T)[1].min()), abs=1e-4)


def test_three_rest_pose_is_y_up(loaded):
    _, _, out = loaded
    rest = out["rest"]["bones"]
    for side in "rl":
        hip, knee, ankle = (np.array(rest[f"{s}_{side}"]["position"]) for s in ("thigh", "shank", "foot"))
        for a, b in ((hip, knee), (knee, ankle)):
            np.testing.assert_allclose((b - a) / np.linalg.norm(b - a), [0.0, -1.0, 0.0], atol=1e-6)


@pytest.mark.parametrize("character", ["halfboy", "fullbody"])
def test_khronos_validator_finds_no_error_or_warning(shared_data, tmp_path, character):
    motion = walk_motion(shared_data, character)
    path = tmp_path / f"{character}.glb"
    path.write_bytes(export_motion(motion, "gltf"))
    rep = khronos_report(path)
    assert rep["errors"] == 0 and rep["warnings"] == 0, rep["messages"]
    assert rep["animations"] == 1
    # a broken file is reported, not passed: the JSON chunk's length cut short
    bad = bytearray(path.read_bytes())
    bad[12:16] = (int.from_bytes(bad[12:16], "little") - 8).to_bytes(4, "little")
    (tmp_path / "bad.glb").write_bytes(bad)
    assert khronos_report(tmp_path / "bad.glb")["errors"] > 0
