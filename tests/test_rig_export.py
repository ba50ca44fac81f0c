"""Results on the user's own rig (``solver.rig``, ``to_bvh(rig="source")``, ``to_deepmimic``).

A BVH walk on a rig that is not the capture skeleton goes in; its tutor, its 10° slope and
90° curve optima and a 3 × 3 library come out on the same rig. Checked independently of the
writer: the files are read back by our parser and by ``bvhio`` (its own forward kinematics),
the hierarchy must be the input's, the rig's feet (bvhio's joint positions) must stay where the
motion's feet are on the ground, and the joints the synthesis character locked must carry the
capture's own rotations at the same gait phase.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import shared_tutors
from scipy.spatial.transform import Rotation, Slerp

import solver
from solver.export import ExportError
from solver.io.bvh import parse_bvh, read_bvh
from solver.kinematics import contact_points
from solver.rig import feet_report, retarget
from solver.trajectory import sample

bvhio = pytest.importorskip("bvhio")

#: the rig the walk comes in on (Mixamo-style names, cm, ZXY channels: not the CMU skeleton)
RIG_TRIAL = "mixamo_style_walk/walk.bvh"
MASS = 70.0


@pytest.fixture(scope="module")
def runs(shared_data):
    """tutor, 10° slope (λ = 1), 90° curve (λ = 1) and a 3 × 3 library of the rig's walk."""
    path = shared_data / RIG_TRIAL
    capture = solver.load_trial([path], mass=MASS)
    tutor = solver.make_tutor(capture, character="halfboy", fps=15.0)
    assert tutor.status == "succeeded", tutor.message
    slope = solver.extrapolate(tutor.motion, solver.Target(slope_deg=10))
    curve = solver.extrapolate(tutor.motion, solver.Target(curve_deg=90))
    # HalfBoy's tight curve may end at an impasse at its last natural λ (docs/naturalness.md): the exports
    # carry a curve of λ × 90°
    assert slope.lam_reached == 1.0 and curve.lam_reached > 0.4 and curve.steps[-1].motion.report["natural"]
    lib = solver.solve_library(tutor.motion, solver.grid_cells({"slope_deg": [-5, 0, 5], "curve_deg": [-45, 0, 45]}))
    motions = {"tutor": tutor.motion, "slope10": slope.steps[-1].motion, "curve90": curve.steps[-1].motion}
    for r in lib.cells:
        assert r.motion is not None, r.cell.key
        motions[f"cell_{r.cell.key}"] = r.motion
    runs_library.append(lib)
    return path, motions


runs_library: list = []


def _bvhio_world(text: str, tmp_path, names):
    """World positions (F, J, 3) and rotations (F, J, 3, 3) of the named joints, by bvhio."""
    f = tmp_path / "rig.bvh"
    f.write_text(text)
    root = bvhio.readAsHierarchy(str(f))
    joints = {j.Name: j for j, _, _ in root.layout()}
    frames = len(root.Keyframes) if hasattr(root, "Keyframes") else bvhio.readAsBvh(str(f)).FrameCount
    P = np.empty((frames, len(names), 3))
    R = np.empty((frames, len(names), 3, 3))
    for k in range(frames):
        root.loadPose(k)
        for i, n in enumerate(names):
            j = joints[n]
            p = j.PositionWorld
            P[k, i] = (p.x, p.y, p.z)
            q = j.RotationWorld
            R[k, i] = Rotation.from_quat([q.x, q.y, q.z, q.w]).as_matrix()
    return P, R


def _same_hierarchy(out, src):
    assert out.names == src.names and out.parents == src.parents and out.channels == src.channels
    assert np.allclose(out.offsets, src.offsets, atol=1e-5)
    assert out.end_sites.keys() == src.end_sites.keys()
    for j in src.end_sites:
        assert np.allclose(out.end_sites[j], src.end_sites[j], atol=1e-5)


@pytest.mark.parametrize("name", ["tutor", "slope10", "curve90"])
def test_walks_come_out_on_the_input_rig(runs, name, tmp_path):
    path, motions = runs
    motion = motions[name]
    text = solver.export_motion(motion, "bvh", rig="source", world="ground")  # the solver's frame, as retarget's
    src, out = read_bvh(path), parse_bvh(text)  # (the default world, gravity down: tests/test_world_export.py)
    _same_hierarchy(out, src)
    rig = motion.context.rig
    pose = retarget(motion, rig)
    assert pose.times.size == out.T and abs(out.frame_time - (pose.times[1] - pose.times[0])) < 1e-6
    # bvhio's forward kinematics of the file against the rig's own
    roles = rig.roles
    feet = [roles[s] for s in ("foot_r", "foot_l", "toes_r", "toes_l")]
    P, R = _bvhio_world(text, tmp_path, [src.names[j] for j in feet])
    _, P_ours = rig.forward(pose.local, pose.root, pose.positions)
    assert np.max(np.abs(P - P_ours[:, feet])) < 0.05  # file units (cm): rounding only
    # the feet on the ground, from bvhio's joints: each contact point of the motion, carried by
    # the rig's foot (heel) or toe joint from the start of its contact interval, must not slide
    frame = motion.frame
    Pw = frame.point_from_input(P, pose.capture_time[:, None])
    Rw = np.einsum("ji,fkjl->fkil", frame.R, R)
    q = sample(motion.q, motion.fps, pose.times, cyclic=True, interpolation=motion.interpolation)
    cp = np.asarray(contact_points(motion.character, q)).reshape(len(motion.character.contacts), 3, -1)
    s = pose.times * motion.fps
    on = motion.contacts[:, np.floor(s + 1e-9).astype(int).clip(0, motion.T - 1)] & \
        motion.contacts[:, np.ceil(s - 1e-9).astype(int).clip(0, motion.T - 1)]
    slides = []
    for i, c in enumerate(motion.character.contacts):
        k = (0 if c.side.startswith("r") else 1) + (2 if "toe" in c.name else 0)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], on[i].astype(int), [0]])))
        for a, b in zip(edges[::2], edges[1::2]):
            local = Rw[a, k].T @ (cp[i, :, a] - Pw[a, k])
            pts = Pw[a:b, k] + np.einsum("fij,j->fi", Rw[a:b, k], local)
            slides.append(np.max(np.linalg.norm(pts[:, :2] - pts[0, :2], axis=1)))
    assert slides and max(slides) <= 0.01, f"{name}: rig foot slides {max(slides) * 1e3:.1f} mm"
    # ankle joints where the motion's feet carry them, in stance
    rep = feet_report(motion, rig, pose)
    for side in ("right", "left"):
        assert rep[side]["ankle_error_m"] <= 0.02 and rep[side]["slide_m"] <= 0.01, rep
    ankle_err = np.linalg.norm(Pw[:, :2] - pose.ankle_target, axis=2)
    stance = motion.foot_contact()[:, np.round(s).astype(int).clip(0, motion.T - 1)].T
    assert np.max(ankle_err[stance]) <= 0.02


def _captured_local(src, joints, times):
    """The input's own local rotations (F, J, 3, 3) of ``joints`` at rig times (slerp)."""
    t = np.arange(src.T) * src.frame_time
    out = np.empty((times.size, len(joints), 3, 3))
    for i, j in enumerate(joints):
        R, _ = src.local(j)
        out[:, i] = Slerp(t, Rotation.from_matrix(R))(np.clip(times, t[0], t[-1])).as_matrix()
    return out


@pytest.mark.parametrize("name", ["tutor", "slope10", "curve90"])
def test_locked_joints_carry_the_capture_at_the_same_phase(runs, name):
    """Arms, spine and head (locked by HalfBoy) move as captured: the exported local rotations,
    read back from the file, against the input file's at the gait phase (time-warped)."""
    path, motions = runs
    motion = motions[name]
    src = read_bvh(path)
    out = parse_bvh(solver.export_motion(motion, "bvh", rig="source"))
    rig = motion.context.rig
    pose = retarget(motion, rig)
    legs = set()
    for j in range(len(src.names)):
        a = j
        while a >= 0:
            if a in (rig.roles["thigh_r"], rig.roles["thigh_l"]):
                legs.add(j)
            a = src.parents[a]
    upper = [j for j in range(1, len(src.names)) if j not in legs
             and len([c for c in src.channels[j] if c.endswith("rotation")]) == 3]
    assert len(upper) >= 8
    got = np.stack([out.local(j)[0] for j in upper], axis=1)
    want = _captured_local(src, upper, pose.capture_time)
    rel = np.einsum("fjik,fjil->fjkl", want, got)
    err = np.degrees(Rotation.from_matrix(rel.reshape(-1, 3, 3)).magnitude())
    rms = float(np.sqrt(np.mean(err**2)))
    assert rms < 0.5, f"{name}: locked joints {rms:.2f}° RMS from the capture at the same phase"
    # and they do move: their captured range of motion is kept
    amp_out = np.degrees(Rotation.from_matrix(np.einsum("fjik,jil->fjkl", got, got[0]).reshape(-1, 3, 3)).magnitude())
    assert amp_out.max() > 5.0


def test_library_cells_come_out_on_the_input_rig(runs, tmp_path):
    path, motions = runs
    cells = {k: m for k, m in motions.items() if k.startswith("cell_")}
    assert len(cells) == 9
    src = read_bvh(path)
    for key, m in cells.items():
        out = parse_bvh(solver.export_motion(m, "bvh", rig="source"))
        _same_hierarchy(out, src)
        rig = m.context.rig
        rep = feet_report(m, rig, retarget(m, rig))
        for side in ("right", "left"):
            assert rep[side]["ankle_error_m"] <= 0.02 and rep[side]["slide_m"] <= 0.01, (key, rep)


def test_saved_library_holds_each_cell_on_the_input_rig(runs, tmp_path):
    path, _ = runs
    out = runs_library[-1].save(tmp_path / "lib")
    files = sorted(out.glob("*.rig.bvh"))
    assert len(files) == 9
    src = read_bvh(path)
    for f in files:
        _same_hierarchy(read_bvh(f), src)
    glb = (out / "library.rig.glb").read_bytes()  # the input's skeleton once, one animation per cell
    doc = json.loads(glb[20:20 + int.from_bytes(glb[12:16], "little")])
    assert len(doc["animations"]) == 9
    assert set(src.names) <= {n.get("name") for n in doc["nodes"]}


def test_deepmimic_motion_on_its_own_character(shared_data, tmp_path):
    """A DeepMimic tutor written as a DeepMimic motion for the same character file: it loads
    back through the importer (the frame layout is the character's), loops ("wrap"), and its
    ankles stay where the tutor's feet are."""
    folder = shared_data / "deepmimic_humanoid3d_walk"
    files = [folder / "humanoid3d_walk.txt", folder / "humanoid3d_character.txt"]
    tutor = shared_tutors.tutor(shared_data).motion
    text = solver.export_motion(tutor, "deepmimic")
    d = json.loads(text)
    assert d["Loop"] == "wrap" and len(d["Frames"][0]) == 44 and d["Frames"][-1][0] == 0.0
    f = tmp_path / "walk.txt"
    f.write_text(text)
    back = solver.load_trial([f, files[1]])
    assert len(d["Frames"]) == back.T
    rig = tutor.context.rig
    rep = feet_report(tutor, rig, retarget(tutor, rig))
    for side in ("right", "left"):
        assert rep[side]["ankle_error_m"] <= 0.02 and rep[side]["slide_m"] <= 0.01, rep


def test_source_rig_export_refuses_what_it_cannot_do(runs, shared_data):
    _, motions = runs
    with pytest.raises(ExportError, match="DeepMimic"):
        solver.export_motion(motions["tutor"], "deepmimic")
    with pytest.raises(ExportError, match="rig must be"):
        solver.export_motion(motions["tutor"], "bvh", rig="theirs")
    no_rig = motions["tutor"].evolve(context=motions["tutor"].context.with_(rig=None))
    with pytest.raises(ExportError, match="no source rig"):
        solver.export_motion(no_rig, "bvh", rig="source")


def test_a_z_up_metre_rig_comes_out_on_itself(shared_data):
    """Unreal-style names, metres, Z up, a static root above the pelvis: the tutor on that rig."""
    path = shared_data / "mixamo_style_walk" / "walk_unreal_style.bvh"
    tutor = solver.make_tutor(solver.load_trial([path], mass=MASS, up="z"), character="halfboy", fps=15.0).motion
    text = solver.export_motion(tutor, "bvh", rig="source")
    _same_hierarchy(parse_bvh(text), read_bvh(path))
    rig = tutor.context.rig
    rep = feet_report(tutor, rig, retarget(tutor, rig))
    for side in ("right", "left"):
        assert rep[side]["ankle_error_m"] <= 0.02 and rep[side]["slide_m"] <= 0.01, rep
