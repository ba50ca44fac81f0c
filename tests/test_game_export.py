"""Game-ready exports (solver.export.game): loop points, root motion separable from the in-place
animation, foot contacts, cycle metadata — in the JSON clip and the glTF extras — and the library
GLB (one named animation per clip). Real motions: the DeepMimic walk's tutor (made by the
pipeline) and one extrapolated cell (slope 5°, curve 20°); three.js's GLTFLoader in Node."""

from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
import shared_tutors

from solver import kinematics as K
from solver.export import Y_UP, ExportError, export_motion, game
from solver.export import clip as CL
from solver.export.gltf import to_library_glb
from solver.motion import FEET, Motion

ROOT = Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "tests" / "js" / "load_glb.mjs"
THREE = ROOT / "service" / "web" / "node_modules" / "three"
NODE = shutil.which("node")
needs_three = pytest.mark.skipif(
    NODE is None or not (THREE / "examples" / "jsm" / "loaders" / "GLTFLoader.js").is_file(),
    reason="node and three.js (cd service/web && npm ci) are needed to load the GLB in three.js")


@pytest.fixture(scope="module")
def tutor(shared_data) -> Motion:
    res = shared_tutors.tutor(shared_data, as_motion=True)
    assert res.status == "succeeded", res.message
    return res.motion


@pytest.fixture(scope="module")
def cell(tutor) -> Motion:
    from solver.continuation import Target, extrapolate

    res = extrapolate(tutor, Target(slope_deg=5.0, curve_deg=20.0))
    assert res.status == "succeeded", res.message
    return res.steps[-1].motion


@pytest.fixture(params=["tutor", "cell"])
def motion(request, tutor, cell) -> Motion:
    return tutor if request.param == "tutor" else cell


def test_solver_motions_loop_exactly_and_the_clip_says_so(motion):
    P = game.loop_frames(motion)
    assert P == motion.T - 2  # the spacetime solver's cyclic motions: frames P, P+1 repeat 0, 1
    clip = CL.to_clip(motion, decimals=None)
    CL.validate_clip(clip)
    loop = clip["game"]["loop"]
    assert loop["seamless"] and loop["start_frame"] == 0 and loop["end_frame"] == P
    assert loop["duration"] == pytest.approx(P / motion.fps)
    assert loop["closure_m"] < 1e-9 and loop["closure_coordinates"] < 1e-12
    # every segment's world frame at P is the loop transform of frame 0's (positions and rotations)
    rot, pos = K.segment_frames(motion.character, motion.q)
    L = game.loop_transform(motion)
    np.testing.assert_allclose(np.einsum("ij,sj->si", L[:3, :3], pos[:, :, 0]) + L[:3, 3], pos[:, :, P], atol=1e-9)
    np.testing.assert_allclose(np.einsum("ij,sjk->sik", L[:3, :3], rot[:, :, :, 0]), rot[:, :, :, P], atol=1e-9)
    assert L[2, 3] == 0.0 and L[2, 2] == 1.0  # planar: a turn about the vertical and a horizontal shift


def test_a_capture_that_does_not_close_is_not_called_seamless(shared_data):
    from test_export import walk_motion

    cap = walk_motion(shared_data, "halfboy")  # raw mocap coordinates, no schedule: last frame = end
    g = game.game_json(cap)
    assert g["loop"]["end_frame"] == cap.T - 1
    assert not g["loop"]["seamless"] and g["loop"]["closure_m"] > 0.01


def test_world_pose_is_the_motion_root_composed_with_the_in_place_pose(motion):
    g = game.game_data(motion)
    rm = g["root_motion"]
    # in-place coordinates: the root at (0, 0, z) with yaw relative to the motion root's heading
    q_in = np.array(motion.q)
    q_in[0:2] = rm["in_place_root_translation"][:, :2].T
    q_in[3] = rm["in_place_root_yaw"]
    _, pos_in = K.segment_frames(motion.character, q_in)
    _, pos = K.segment_frames(motion.character, motion.q)
    for t in range(motion.T):
        M = game.planar(rm["yaw"][t], rm["translation"][t, :2])
        np.testing.assert_allclose(pos_in[:, :, t] @ M[:3, :3].T + M[:3, 3], pos[:, :, t], atol=1e-9)
    # the motion root turns at a constant rate and stays on the ground
    assert np.allclose(np.diff(rm["yaw"], 2), 0.0, atol=1e-12) and np.all(rm["translation"][:, 2] == 0.0)
    # in-place: the loop's last frame is the first one again
    P = g["loop"]["end_frame"]
    np.testing.assert_allclose(pos_in[:, :, P], pos_in[:, :, 0], atol=1e-9)


def test_foot_contacts_are_the_schedule_and_planted_points_stay_put(motion):
    g = game.game_data(motion)
    sched = motion.foot_contact()
    ch = motion.character
    cp = np.asarray(K.contact_points(ch, motion.q))
    for i, foot in enumerate(FEET):
        f = g["foot_contacts"][foot]
        assert np.array_equal(f["planted"], sched[i])
        assert np.all(np.isnan(f["position"][~sched[i]])) and np.all(np.isfinite(f["position"][sched[i]]))
        np.testing.assert_allclose(f["position"][sched[i], 2], 0.0, atol=2e-3)  # on the ground (z = 0)
        # an active contact point that stays active does not slide (the solver's no-slip rows)
        idx = [k for k, c in enumerate(ch.contacts) if c.side == foot]
        for k in idx:
            on = motion.contacts[k]
            both = on[1:] & on[:-1]
            slip = np.linalg.norm(np.diff(cp[k, :2], axis=1)[:, both], axis=0)
            assert slip.size == 0 or slip.max() < 1e-3, (foot, slip.max())
        # the body's weight is carried by the planted feet, never by a foot in the air
        assert np.all(f["load"][~sched[i]] < 1e-6)
        kinds = [e["event"] for e in f["events"]]
        assert kinds.count("plant") == kinds.count("lift") == 1  # one stance per foot and cycle
    total = g["foot_contacts"]["right"]["load"] + g["foot_contacts"]["left"]["load"]
    assert 0.5 < np.mean(total) < 1.5  # on average the feet carry about the body weight


def test_cycle_metadata(tutor, cell):
    a, b = game.game_data(tutor)["cycle"], game.game_data(cell)["cycle"]
    assert a["slope_deg"] == pytest.approx(0.0, abs=1e-9) and b["slope_deg"] == pytest.approx(5.0, abs=1e-9)
    for c in (a, b):
        assert 0.7 < c["speed_m_s"] < 1.4  # a walk
        assert c["speed_m_s"] >= c["stride_length_m"] / c["duration_s"] - 1e-12  # the arc is no shorter than the chord
        assert c["gravity_m_s2"] == pytest.approx(9.81)
    # the curved cell turns left by about its target (20° over the cycle) relative to the tutor
    turned = (b["turn_rate_deg_s"] - a["turn_rate_deg_s"]) * a["duration_s"]
    print(f"cycle: tutor {a}\ncell {b}\nturn relative to the tutor {turned:.2f}°")
    assert 15.0 < turned < 25.0


def test_y_up_clip_expresses_the_same_game_data_in_glTF_axes(cell):
    z, y = CL.to_clip(cell, decimals=None)["game"], CL.to_clip(cell, y_up=True, decimals=None)["game"]
    CL.validate_clip(CL.to_clip(cell, y_up=True))
    np.testing.assert_allclose(np.array(y["root_motion"]["translation"]),
                               np.array(z["root_motion"]["translation"]) @ Y_UP.T)
    assert y["root_motion"]["yaw"] == z["root_motion"]["yaw"] and y["cycle"] == z["cycle"]
    for foot in FEET:
        pz = [p for p in z["foot_contacts"][foot]["position"] if p is not None]
        py = [p for p in y["foot_contacts"][foot]["position"] if p is not None]
        np.testing.assert_allclose(np.array(py), np.array(pz) @ Y_UP.T)


def _three(path: Path, *times: str) -> dict:
    r = subprocess.run([NODE, str(SCRIPT), str(path), *times], capture_output=True, text=True, timeout=60,
                       check=False, env={**os.environ, "THREE_DIR": str(THREE), "ANIMATIONS": "all"})
    assert r.returncode == 0, f"three.js could not load the GLB:\n{r.stderr}"
    return json.loads(r.stdout)


def _turn(axis: np.ndarray, angle: float) -> tuple[np.ndarray, np.ndarray]:
    """The rotation by ``angle`` about the unit ``axis``: its matrix and quaternion (x, y, z, w)."""
    from scipy.spatial.transform import Rotation

    r = Rotation.from_rotvec(np.asarray(axis, dtype=float) / np.linalg.norm(axis) * angle)
    return r.as_matrix(), r.as_quat()


def _qmul(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return np.array([aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
                     aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz])


def assert_loops_in_three(anim_poses: list[dict], extras: list[dict], names: list[str]) -> float:
    """Each animation's last pose (t = duration) is its first pose (t = 0) under the loop transform
    of its extras (a turn about its axis — the ground's normal: +y, or a ramp's normal in the
    gravity world — through the motion root, and a translation), as three.js's AnimationMixer
    evaluates them; returns the worst error (m or rad)."""
    worst = 0.0
    assert [a["name"] for a in anim_poses] == names
    for a, ex in zip(anim_poses, extras):
        first, last = a["poses"][0]["bones"], a["poses"][-1]["bones"]
        rm = ex["root_motion"]
        P = ex["loop"]["end_frame"]
        assert ex["frames_in_animation"] == P + 1 and ex["loop"]["seamless"]
        m0, mP = np.array(rm["translation"][0]), np.array(rm["translation"][P])
        dyaw = rm["yaw"][P] - rm["yaw"][0]
        assert dyaw == pytest.approx(math.radians(ex["loop"]["transform"]["yaw_deg"]), abs=1e-6)
        axis = np.array(ex["loop"]["transform"]["axis"])
        assert np.allclose(axis, rm["up"]) and np.linalg.norm(axis) == pytest.approx(1.0)
        R, qy = _turn(axis, dyaw)
        for bone, b0 in first.items():
            p = R @ (np.array(b0["position"]) - m0) + mP
            d = np.linalg.norm(p - np.array(last[bone]["position"]))
            q = _qmul(qy, np.array(b0["quaternion"]))
            ql = np.array(last[bone]["quaternion"])
            ang = 2 * math.asin(min(1.0, min(np.linalg.norm(q - ql), np.linalg.norm(q + ql)) / 2)) * 2
            worst = max(worst, d, ang)
    return worst


@needs_three
def test_looped_glb_loads_in_three_and_its_last_pose_is_the_first_under_root_motion(cell, tmp_path):
    path = tmp_path / "cell.glb"
    path.write_bytes(export_motion(cell, "glb", loop=True))
    out = _three(path, "0", "end")
    (anim,) = out["animations"]
    P = game.loop_frames(cell)
    assert anim["duration"] == pytest.approx(P / cell.fps, rel=1e-6)
    assert all(t["keys"] == P + 1 for t in anim["tracks"])
    worst = assert_loops_in_three(out["animation_poses"], out["animation_extras"], [anim["name"]])
    print(f"three.js loop closure (float32): {worst:.2e}")
    assert worst < 1e-4
    # without loop= the animation keeps every frame, and still carries the game data
    full = tmp_path / "full.glb"
    full.write_bytes(export_motion(cell, "glb"))
    out = _three(full)
    assert out["animations"][0]["tracks"][0]["keys"] == cell.T
    assert out["animation_extras"][0]["cycle"]["slope_deg"] == pytest.approx(5.0)


@needs_three
def test_library_glb_has_one_named_looping_animation_per_clip(tutor, cell, tmp_path):
    grid = {"axes": {"slope_deg": [0.0, 5.0], "curve_deg": [0.0, 20.0]}}
    path = tmp_path / "library.glb"
    path.write_bytes(to_library_glb([("slope0_curve0", tutor), ("slope5_curve20", cell)], extras=grid))
    out = _three(path, "0", "end")
    names = ["slope0_curve0", "slope5_curve20"]
    assert [a["name"] for a in out["animations"]] == names
    assert out["asset"]["extras"]["library"] == grid
    assert out["skins"] == 1 and out["bones"] == len(tutor.character.segments)  # one skeleton for all
    worst = assert_loops_in_three(out["animation_poses"], out["animation_extras"], names)
    assert worst < 1e-4, worst


def test_library_glb_refuses_bad_input(tutor, shared_data):
    from test_export import walk_motion

    with pytest.raises(ExportError, match="at least one"):
        to_library_glb([])
    with pytest.raises(ExportError, match="distinct"):
        to_library_glb([("a", tutor), ("a", tutor)])
    with pytest.raises(ExportError, match="another character"):
        to_library_glb([("a", tutor), ("b", walk_motion(shared_data, "fullbody"))])
    with pytest.raises(ExportError, match="loop must be a boolean"):
        export_motion(tutor, "glb", loop="yes")
