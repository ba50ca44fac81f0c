"""BVH importer: round trip through a BVH written (here) from the real DeepMimic walk."""

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from solver.io import load_trial
from solver.io.bvh import BvhError, bvh_track, load_bvh, read_bvh
from solver.io.deepmimic import deepmimic_track, read_deepmimic_character
from solver.io.fit import FitError

DM = "deepmimic_humanoid3d_walk"
CMU = {"root": "Hips", "chest": "Spine", "neck": "Head", "right_hip": "RightUpLeg", "right_knee": "RightLeg",
       "right_ankle": "RightFoot", "right_shoulder": "RightArm", "right_elbow": "RightForeArm",
       "right_wrist": "RightHand", "left_hip": "LeftUpLeg", "left_knee": "LeftLeg", "left_ankle": "LeftFoot",
       "left_shoulder": "LeftArm", "left_elbow": "LeftForeArm", "left_wrist": "LeftHand"}


def write_bvh(motion: Path, character: Path, out: Path, scale: float = 100.0, prefix: str = "",
              lower_back: bool = False) -> None:
    """DeepMimic clip -> BVH with CMU joint names (Y up, DeepMimic axes, ZXY Euler channels).

    ``lower_back``: a CMU-style ``LowerBack`` joint on the root (zero offset) above ``Spine``.

    Toes: a fixed ``*ToeBase`` joint at the ankle box's metatarsal point, End Site at the toe
    tip (the same points the DeepMimic reader uses); head and hand End Sites at the head top
    and hand tip.
    """
    sk = read_deepmimic_character(character)
    frames = np.array(json.loads(motion.read_text())["Frames"])
    T = frames.shape[0]
    kids = {j: [c for c, p in enumerate(sk.parents) if p == j] for j in range(len(sk.names))}
    euler, col = {}, 8
    for j, t in enumerate(sk.types):
        if sk.parents[j] < 0:
            q = frames[:, 4:8]
        elif t == "spherical":
            q = frames[:, col:col + 4]
            col += 4
        elif t == "revolute":
            a = frames[:, col]
            col += 1
            q = np.stack([np.cos(a / 2), 0 * a, 0 * a, np.sin(a / 2)], 1)
        else:
            q = np.tile([1.0, 0, 0, 0], (T, 1))
        euler[j] = Rotation.from_quat(q[:, [1, 2, 3, 0]]).as_euler("ZXY", degrees=True)
    foot = sk.bodies["right_ankle"]
    c = np.array([foot["AttachX"], foot["AttachY"], foot["AttachZ"]])
    size = np.array([foot["Param0"], foot["Param1"], foot["Param2"]])
    heel, toe = c + [-size[0] / 2, -size[1] / 2, 0], c + [size[0] / 2, -size[1] / 2, 0]
    mtp = heel + 0.72 * (toe - heel) + [0, 0.02, 0]
    lines, order = ["HIERARCHY"], []

    def vec(v):
        return " ".join(f"{x * scale:.6f}" for x in v)

    def emit(j, depth):
        ind, name = "  " * depth, prefix + CMU[sk.names[j]]
        lines.extend([f"{ind}{'ROOT' if depth == 0 else 'JOINT'} {name}", ind + "{",
                      f"{ind}  OFFSET {vec(sk.attach[j] if depth else np.zeros(3))}",
                      f"{ind}  CHANNELS " + ("6 Xposition Yposition Zposition " if depth == 0 else "3 ")
                      + "Zrotation Xrotation Yrotation"])
        order.append(j)
        for k in kids[j]:
            if lower_back and sk.names[k] == "chest":
                i2 = "  " * (depth + 1)
                lines.extend([f"{i2}JOINT {prefix}LowerBack", i2 + "{", f"{i2}  OFFSET 0 0 0",
                              f"{i2}  CHANNELS 3 Zrotation Xrotation Yrotation"])
                order.append(None)
                emit(k, depth + 2)
                lines.append(i2 + "}")
                continue
            emit(k, depth + 1)
        nm, i2 = sk.names[j], "  " * (depth + 1)
        if nm.endswith("ankle"):
            lines.extend([f"{i2}JOINT {name.replace('Foot', 'ToeBase')}", i2 + "{", f"{i2}  OFFSET {vec(mtp)}",
                          f"{i2}  CHANNELS 3 Zrotation Xrotation Yrotation", f"{i2}  End Site", i2 + "  {",
                          f"{i2}    OFFSET {vec(toe - mtp)}", i2 + "  }", i2 + "}"])
            order.append(None)
        if nm == "neck":
            b = sk.bodies["neck"]
            tip = vec([0, b['AttachY'] + b['Param0'] / 2, 0])
            lines.extend([f"{ind}  End Site", ind + "  {", f"{ind}    OFFSET {tip}", ind + "  }"])
        if nm.endswith("wrist"):
            lines.extend([f"{ind}  End Site", ind + "  {", f"{ind}    OFFSET {vec([0, -sk.bodies[nm]['Param0'], 0])}",
                          ind + "  }"])
        lines.append(ind + "}")

    emit(0, 0)
    lines += ["MOTION", f"Frames: {T}", f"Frame Time: {frames[0, 0]:.6f}"]
    for t in range(T):
        vals = []
        for j in order:
            if j is None:
                vals += [0.0, 0.0, 0.0]
                continue
            if sk.parents[j] < 0:
                vals += list(frames[t, 1:4] * scale)
            vals += list(euler[j][t])
        lines.append(" ".join(f"{v:.6f}" for v in vals))
    out.write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def files(shared_data, tmp_path_factory):
    d = shared_data / DM
    tmp = tmp_path_factory.mktemp("bvh")
    cm, m = tmp / "walk_cm.bvh", tmp / "walk_m.bvh"
    write_bvh(d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt", cm, 100.0)
    write_bvh(d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt", m, 1.0, prefix="mixamorig:")
    ref = deepmimic_track(d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt")
    return cm, m, ref


def test_round_trip_recovers_the_landmarks(files):
    cm, _, ref = files
    tr = bvh_track(cm, mass=45.0)
    assert tr.source["units"] == "cm"
    assert tr.has_upper_body
    # back in the file's axes (metres), every joint landmark is DeepMimic's own
    for k in ("hip_r", "knee_l", "ankle_r", "mtp_l", "toe_r", "lumbar", "neck", "head_top", "shoulder_l",
              "elbow_r", "wrist_l", "hand_r", "pelvis"):
        got = tr.frame.point_to_input(tr.landmarks[k].T) * tr.frame.unit_m
        want = ref.frame.point_to_input(ref.landmarks[k].T)
        assert np.abs(got - want).max() < 1e-5, k
    # the heel is placed from the rest pose (25 % of ankle -> toe behind the ankle): within 2 cm
    got = tr.frame.point_to_input(tr.landmarks["heel_r"].T) * tr.frame.unit_m
    assert np.abs(got - ref.frame.point_to_input(ref.landmarks["heel_r"].T)).max() < 0.02


def test_axes_units_and_fit(files):
    cm, m, _ = files
    a, b = bvh_track(cm, mass=45.0), bvh_track(m, mass=45.0)
    assert b.source["units"] == "m" and b.source["joint_roles"]["hip_r"] == "mixamorig:RightUpLeg"
    for k in a.landmarks:
        assert np.allclose(a.landmarks[k], b.landmarks[k], atol=1e-6)
    assert np.allclose(bvh_track(m, mass=45.0, units="m").landmarks["knee_r"], b.landmarks["knee_r"])
    # Y up -> our z; facing (the hip line's normal) -> our +x: the walk goes forward
    R = a.frame.R  # ours -> file
    assert R[:, 2] == pytest.approx([0, 1, 0], abs=1e-9)
    assert R[0, 0] > 0.99
    assert a.landmarks["pelvis"][0, -1] - a.landmarks["pelvis"][0, 0] == pytest.approx(1.239, abs=0.01)
    assert np.all(a.landmarks["hip_r"][1] < a.landmarks["hip_l"][1])
    cap = load_bvh(cm, mass=45.0)
    assert cap.character.name == "capture-full" and cap.character.total_mass == pytest.approx(45.0)
    assert cap.source["fit"]["landmark_error_mm"]["mean"] < 2.0
    assert cap.character.segment("thigh_r").length == pytest.approx(0.421546, abs=1e-4)
    low = load_trial([cm], mass=45.0, lower_only=True)
    assert low.character.n == 30 and low.character.total_mass == pytest.approx(45.0)


def test_cmu_units_and_lower_back(shared_data, files, tmp_path):
    """CMU database BVH: lengths in 1/0.45 inch, a LowerBack joint sitting on the root."""
    d = shared_data / DM
    p = tmp_path / "cmu.bvh"
    write_bvh(d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt", p, 0.45 / 0.0254, lower_back=True)
    tr = bvh_track(p, mass=45.0)
    assert tr.source["units"] == "cmu"
    assert tr.source["spine_joints"] == ["LowerBack", "Spine"]
    ref = bvh_track(files[0], mass=45.0)
    for k in ("knee_r", "lumbar", "head_top", "toe_l"):
        assert np.allclose(tr.landmarks[k], ref.landmarks[k], atol=1e-5), k


def test_errors(files, tmp_path):
    cm, _, _ = files
    with pytest.raises(FitError, match="mass unknown"):
        load_bvh(cm)
    text = cm.read_text()
    cut = tmp_path / "cut.bvh"
    cut.write_text(text[: len(text) - 200])
    with pytest.raises(BvhError, match="values"):
        read_bvh(cut)
    nolegs = tmp_path / "nolegs.bvh"
    nolegs.write_text(text.replace("RightLeg", "RightCalfX").replace("RightUpLeg", "RightThighX"))
    with pytest.raises(BvhError, match="cannot find the joints for the roles hip_r, knee_r among"):
        bvh_track(nolegs, mass=45.0)
    bad = tmp_path / "bad.bvh"
    bad.write_text("MOTION\nFrames: 1\n")
    with pytest.raises(BvhError, match="HIERARCHY"):
        read_bvh(bad)
    with pytest.raises(BvhError, match="units"):
        bvh_track(cm, mass=45.0, units="furlong")
    with pytest.raises(BvhError, match="cannot tell the length unit"):
        _scaled(cm, tmp_path, 1e-3)


def _scaled(src: Path, tmp: Path, k: float):
    """A copy with every length multiplied by k (leg length 0.85 mm: no plausible unit)."""
    clip = read_bvh(src)
    lines = src.read_text().splitlines()
    out = []
    for ln in lines:
        s = ln.strip()
        if s.startswith("OFFSET"):
            v = [float(x) * k for x in s.split()[1:]]
            ln = ln[: ln.index("OFFSET")] + "OFFSET " + " ".join(f"{x:.9f}" for x in v)
        out.append(ln)
    p = tmp / "scaled.bvh"
    p.write_text("\n".join(out) + "\n")
    assert read_bvh(p).T == clip.T
    return bvh_track(p, mass=45.0)


# --- the CMU clips of a game pipeline (retargeted, 19 joints, Z-X-Y channels, cm, Y up) ------

CMU16 = "cmu16_bvh"
CMU16_CLIPS = {"16_15_walk": 0.0, "16_17_walk_90deg_left_turn": 90.0, "16_19_walk_90deg_right_turn": -100.0}


@pytest.mark.parametrize("clip", sorted(CMU16_CLIPS))
def test_cmu_game_clips_import(shared_data, clip):
    """ASF-style names (pelvis, lfemur, ltibia, lfoot, ltoes, thorax, head, lclavicle, lhumerus,
    lradius, lhand) map to our roles; units cm from the leg; facing and turning as the README says."""
    p = shared_data / CMU16 / f"{clip}.bvh"
    clip_ = read_bvh(p)
    assert len(clip_.names) == 19 and clip_.channels[1] == ("Zrotation", "Xrotation", "Yrotation")
    cap = load_bvh(p, mass=60.0)
    roles = cap.source["joint_roles"]
    assert (roles["hip_l"], roles["knee_l"], roles["ankle_l"], roles["mtp_l"]) == ("lfemur", "ltibia", "lfoot", "ltoes")
    assert (roles["shoulder_r"], roles["elbow_r"], roles["wrist_r"]) == ("rhumerus", "rradius", "rhand")
    assert cap.source["units"] == "cm" and cap.fps == pytest.approx(30.0, rel=1e-4)
    assert cap.character.name == "capture-full" and cap.character.total_mass == pytest.approx(60.0)
    assert cap.source["fit"]["landmark_error_mm"]["max"] < 1.0  # the same rigid tree: an exact fit
    # femur 42.0 cm + tibia 39.9 cm
    assert cap.character.segment("thigh_r").length == pytest.approx(0.420, abs=0.002)
    assert cap.character.segment("shank_r").length == pytest.approx(0.399, abs=0.002)
    # feet on the floor, pelvis at walking height
    from solver.kinematics import contact_points

    z = contact_points(cap.character, cap.q)[:, 2]
    assert -0.01 < np.percentile(z, 2) < 0.03 and 0.7 < np.median(cap.q[2]) < 0.95
    # heading change over the clip (root yaw) as the README states (≈ 0, +90, -100 degrees)
    yaw = np.degrees(np.unwrap(cap.q[3]))
    assert yaw[-1] - yaw[0] == pytest.approx(CMU16_CLIPS[clip], abs=15.0)


def test_bvh_without_mass_names_the_mass_flag(shared_data, tmp_path):
    """No mass in a BVH: the reader says so and the command line names --mass (not 'mass=...')."""
    import shutil
    import subprocess
    import sys

    p = shared_data / CMU16 / "16_15_walk.bvh"
    with pytest.raises(FitError, match=r"mass unknown: the BVH input does not state it; pass mass=\.\.\. \(kg\)") as e:
        load_bvh(p)
    assert e.value.parameter == "mass" and e.value.reason == "subject mass unknown: the BVH input does not state it"
    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    for cmd in (["grf", "--input", p, "--out", tmp_path / "x.csv"], ["tutor", p, "--out", tmp_path / "t.json"]):
        r = subprocess.run([exe, *map(str, cmd)], capture_output=True, text=True, timeout=120)
        assert r.returncode == 2 and "does not state it; pass --mass KG" in r.stderr, r.stderr
        assert "mass=" not in r.stderr, r.stderr


def test_the_unit_names_offered_are_the_readers():
    from solver.formats import BVH_UNITS
    from solver.io.bvh import UNIT_M

    assert ("auto", *UNIT_M) == BVH_UNITS
