"""Joint roles from names and hierarchy (solver.io.roles), the user's joint mapping through the BVH
reader, the command line and the upload form, and the rigs derived from the CMU walk
(data/mixamo_style_walk: Mixamo names in cm, Unreal names in metres, Z up)."""

import json
import shutil
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest

import solver
from solver.io.bvh import BvhError, bvh_track, read_bvh
from solver.io.roles import RoleError, joint_roles, missing_roles, parse_joint_mapping, spine_joints

CMU = "cmu16_bvh/16_15_walk.bvh"
MIXAMO = "mixamo_style_walk/walk.bvh"
UNREAL = "mixamo_style_walk/walk_unreal_style.bvh"


def tree(pairs: str) -> tuple[list[str], list[int]]:
    """``"child<parent; child<parent; root"`` -> names, parent indices (parents listed first)."""
    names: list[str] = []
    parents: list[int] = []
    for item in (p.strip() for p in pairs.split(";") if p.strip()):
        name, _, parent = item.partition("<")
        names.append(name.strip())
        parents.append(names.index(parent.strip()) if parent else -1)
    return names, parents


def named(pairs: str, **kw) -> dict[str, str]:
    names, parents = tree(pairs)
    return {r: names[j] for r, j in joint_roles(names, parents, **kw).items()}


def limbs(side: str, *names: str) -> dict[str, str]:
    roles = ("hip", "knee", "ankle", "mtp", "clavicle", "shoulder", "elbow", "wrist")
    return {f"{r}_{side}": n for r, n in zip(roles, names) if n}


MIXAMO_TREE = ("mixamorig:Hips; mixamorig:Spine<mixamorig:Hips; mixamorig:Spine1<mixamorig:Spine; "
               "mixamorig:Spine2<mixamorig:Spine1; mixamorig:Neck<mixamorig:Spine2; mixamorig:Head<mixamorig:Neck; "
               "mixamorig:HeadTop_End<mixamorig:Head; "
               + "".join(f"mixamorig:{S}Shoulder<mixamorig:Spine2; mixamorig:{S}Arm<mixamorig:{S}Shoulder; "
                         f"mixamorig:{S}ForeArm<mixamorig:{S}Arm; mixamorig:{S}Hand<mixamorig:{S}ForeArm; "
                         f"mixamorig:{S}HandIndex1<mixamorig:{S}Hand; mixamorig:{S}HandThumb1<mixamorig:{S}Hand; "
                         f"mixamorig:{S}UpLeg<mixamorig:Hips; mixamorig:{S}Leg<mixamorig:{S}UpLeg; "
                         f"mixamorig:{S}Foot<mixamorig:{S}Leg; mixamorig:{S}ToeBase<mixamorig:{S}Foot; "
                         f"mixamorig:{S}Toe_End<mixamorig:{S}ToeBase; " for S in ("Left", "Right")))

STYLES = {
    "mixamo": (MIXAMO_TREE, {
        "hips": "mixamorig:Hips", "lumbar": "mixamorig:Spine", "neck": "mixamorig:Neck", "head": "mixamorig:Head",
        **{k: f"mixamorig:{v}" for s, S in (("l", "Left"), ("r", "Right")) for k, v in limbs(
            s, f"{S}UpLeg", f"{S}Leg", f"{S}Foot", f"{S}ToeBase", f"{S}Shoulder", f"{S}Arm", f"{S}ForeArm",
            f"{S}Hand").items()}}),
    # CMU as converted by cgspeed: LHipJoint between Hips and LeftUpLeg, LowerBack, Neck1, fingers
    "cmu_bvh": ("Hips; LHipJoint<Hips; LeftUpLeg<LHipJoint; LeftLeg<LeftUpLeg; LeftFoot<LeftLeg; "
                "LeftToeBase<LeftFoot; RHipJoint<Hips; RightUpLeg<RHipJoint; RightLeg<RightUpLeg; "
                "RightFoot<RightLeg; RightToeBase<RightFoot; LowerBack<Hips; Spine<LowerBack; Spine1<Spine; "
                "Neck<Spine1; Neck1<Neck; Head<Neck1; LeftShoulder<Spine1; LeftArm<LeftShoulder; "
                "LeftForeArm<LeftArm; LeftHand<LeftForeArm; LeftFingerBase<LeftHand; LThumb<LeftHand; "
                "RightShoulder<Spine1; RightArm<RightShoulder; RightForeArm<RightArm; RightHand<RightForeArm",
                {"hips": "Hips", "lumbar": "LowerBack", "neck": "Neck", "head": "Head",
                 **limbs("l", "LeftUpLeg", "LeftLeg", "LeftFoot", "LeftToeBase", "LeftShoulder", "LeftArm",
                         "LeftForeArm", "LeftHand"),
                 **limbs("r", "RightUpLeg", "RightLeg", "RightFoot", "RightToeBase", "RightShoulder", "RightArm",
                         "RightForeArm", "RightHand")}),
    # the CMU ASF bone names (lowercase, glued side letter)
    "cmu_asf": ("root; lhipjoint<root; lfemur<lhipjoint; ltibia<lfemur; lfoot<ltibia; ltoes<lfoot; "
                "rhipjoint<root; rfemur<rhipjoint; rtibia<rfemur; rfoot<rtibia; rtoes<rfoot; lowerback<root; "
                "upperback<lowerback; thorax<upperback; lowerneck<thorax; upperneck<lowerneck; head<upperneck; "
                "lclavicle<thorax; lhumerus<lclavicle; lradius<lhumerus; lwrist<lradius; lhand<lwrist; "
                "rclavicle<thorax; rhumerus<rclavicle; rradius<rhumerus; rwrist<rradius; rhand<rwrist",
                {"hips": "root", "lumbar": "lowerback", "neck": "lowerneck", "head": "head",
                 **limbs("l", "lfemur", "ltibia", "lfoot", "ltoes", "lclavicle", "lhumerus", "lradius", "lwrist"),
                 **limbs("r", "rfemur", "rtibia", "rfoot", "rtoes", "rclavicle", "rhumerus", "rradius", "rwrist")}),
    # Unreal mannequin: a root bone above the pelvis, twist and IK bones
    "unreal": ("root; pelvis<root; spine_01<pelvis; spine_02<spine_01; spine_03<spine_02; neck_01<spine_03; "
               "head<neck_01; clavicle_l<spine_03; upperarm_l<clavicle_l; upperarm_twist_01_l<upperarm_l; "
               "lowerarm_l<upperarm_l; hand_l<lowerarm_l; clavicle_r<spine_03; upperarm_r<clavicle_r; "
               "lowerarm_r<upperarm_r; hand_r<lowerarm_r; thigh_l<pelvis; thigh_twist_01_l<thigh_l; calf_l<thigh_l; "
               "calf_twist_01_l<calf_l; foot_l<calf_l; ball_l<foot_l; thigh_r<pelvis; calf_r<thigh_r; "
               "foot_r<calf_r; ball_r<foot_r; ik_foot_root<root; ik_foot_l<ik_foot_root; ik_foot_r<ik_foot_root",
               {"hips": "pelvis", "lumbar": "spine_01", "neck": "neck_01", "head": "head",
                **limbs("l", "thigh_l", "calf_l", "foot_l", "ball_l", "clavicle_l", "upperarm_l", "lowerarm_l",
                        "hand_l"),
                **limbs("r", "thigh_r", "calf_r", "foot_r", "ball_r", "clavicle_r", "upperarm_r", "lowerarm_r",
                        "hand_r")}),
    "unity": ("Hips; Spine<Hips; Chest<Spine; UpperChest<Chest; Neck<UpperChest; Head<Neck; "
              "LeftShoulder<UpperChest; LeftUpperArm<LeftShoulder; LeftLowerArm<LeftUpperArm; LeftHand<LeftLowerArm; "
              "RightShoulder<UpperChest; RightUpperArm<RightShoulder; RightLowerArm<RightUpperArm; "
              "RightHand<RightLowerArm; LeftUpperLeg<Hips; LeftLowerLeg<LeftUpperLeg; LeftFoot<LeftLowerLeg; "
              "LeftToes<LeftFoot; RightUpperLeg<Hips; RightLowerLeg<RightUpperLeg; RightFoot<RightLowerLeg; "
              "RightToes<RightFoot",
              {"hips": "Hips", "lumbar": "Spine", "neck": "Neck", "head": "Head",
               **limbs("l", "LeftUpperLeg", "LeftLowerLeg", "LeftFoot", "LeftToes", "LeftShoulder", "LeftUpperArm",
                       "LeftLowerArm", "LeftHand"),
               **limbs("r", "RightUpperLeg", "RightLowerLeg", "RightFoot", "RightToes", "RightShoulder",
                       "RightUpperArm", "RightLowerArm", "RightHand")}),
    # DAZ Genesis 2: the hip is the root, the thighs hang from "pelvis", the spine from "hip"
    "daz": ("hip; pelvis<hip; lThigh<pelvis; lShin<lThigh; lFoot<lShin; lToe<lFoot; rThigh<pelvis; rShin<rThigh; "
            "rFoot<rShin; rToe<rFoot; abdomen<hip; abdomen2<abdomen; chest<abdomen2; neck<chest; head<neck; "
            "lCollar<chest; lShldr<lCollar; lForeArm<lShldr; lHand<lForeArm; rCollar<chest; rShldr<rCollar; "
            "rForeArm<rShldr; rHand<rForeArm",
            {"hips": "pelvis", "lumbar": "abdomen", "neck": "neck", "head": "head",
             **limbs("l", "lThigh", "lShin", "lFoot", "lToe", "lCollar", "lShldr", "lForeArm", "lHand"),
             **limbs("r", "rThigh", "rShin", "rFoot", "rToe", "rCollar", "rShldr", "rForeArm", "rHand")}),
    "blender": ("hips; spine<hips; chest<spine; neck<chest; head<neck; shoulder.L<chest; upper_arm.L<shoulder.L; "
                "forearm.L<upper_arm.L; hand.L<forearm.L; shoulder.R<chest; upper_arm.R<shoulder.R; "
                "forearm.R<upper_arm.R; hand.R<forearm.R; thigh.L<hips; shin.L<thigh.L; foot.L<shin.L; toe.L<foot.L; "
                "heel.02.L<foot.L; thigh.R<hips; shin.R<thigh.R; foot.R<shin.R; toe.R<foot.R",
                {"hips": "hips", "lumbar": "spine", "neck": "neck", "head": "head",
                 **limbs("l", "thigh.L", "shin.L", "foot.L", "toe.L", "shoulder.L", "upper_arm.L", "forearm.L",
                         "hand.L"),
                 **limbs("r", "thigh.R", "shin.R", "foot.R", "toe.R", "shoulder.R", "upper_arm.R", "forearm.R",
                         "hand.R")}),
    # 3ds Max Biped: the thighs hang from "Bip01 Spine"; the pelvis joint is "Bip01 Pelvis"
    "biped": ("Bip01; Bip01 Pelvis<Bip01; Bip01 Spine<Bip01 Pelvis; Bip01 L Thigh<Bip01 Spine; "
              "Bip01 L Calf<Bip01 L Thigh; Bip01 L Foot<Bip01 L Calf; Bip01 L Toe0<Bip01 L Foot; "
              "Bip01 L Toe0Nub<Bip01 L Toe0; Bip01 R Thigh<Bip01 Spine; Bip01 R Calf<Bip01 R Thigh; "
              "Bip01 R Foot<Bip01 R Calf; Bip01 R Toe0<Bip01 R Foot; Bip01 Spine1<Bip01 Spine; "
              "Bip01 Neck<Bip01 Spine1; Bip01 Head<Bip01 Neck; Bip01 HeadNub<Bip01 Head; "
              "Bip01 L Clavicle<Bip01 Neck; Bip01 L UpperArm<Bip01 L Clavicle; Bip01 L Forearm<Bip01 L UpperArm; "
              "Bip01 L Hand<Bip01 L Forearm; Bip01 L Finger0<Bip01 L Hand; Bip01 R Clavicle<Bip01 Neck; "
              "Bip01 R UpperArm<Bip01 R Clavicle; Bip01 R Forearm<Bip01 R UpperArm; Bip01 R Hand<Bip01 R Forearm",
              {"hips": "Bip01 Pelvis", "lumbar": "Bip01 Spine", "neck": "Bip01 Neck", "head": "Bip01 Head",
               **{k: f"Bip01 {v}" for s, S in (("l", "L"), ("r", "R")) for k, v in limbs(
                   s, f"{S} Thigh", f"{S} Calf", f"{S} Foot", f"{S} Toe0", f"{S} Clavicle", f"{S} UpperArm",
                   f"{S} Forearm", f"{S} Hand").items()}}),
    # side suffixes and prefixes of other tools: Thigh_L, L_Shin, KneeLeft, Character1_ prefix
    "suffixes": ("Character1_Hips; Character1_Thigh_L<Character1_Hips; Character1_Shin_L<Character1_Thigh_L; "
                 "Character1_Foot_L<Character1_Shin_L; R_Thigh<Character1_Hips; KneeRight<R_Thigh; "
                 "r.ankle<KneeRight; Character1_Spine<Character1_Hips; Character1_Head<Character1_Spine",
                 {"hips": "Character1_Hips", "lumbar": "Character1_Spine", "head": "Character1_Head",
                  **limbs("l", "Character1_Thigh_L", "Character1_Shin_L", "Character1_Foot_L"),
                  **limbs("r", "R_Thigh", "KneeRight", "r.ankle")}),
}


@pytest.mark.parametrize("style", sorted(STYLES))
def test_each_naming_style_gets_its_roles(style):
    pairs, want = STYLES[style]
    got = named(pairs)
    assert got == want
    assert not missing_roles(joint_roles(*tree(pairs)))


def test_the_hierarchy_settles_what_names_leave_open():
    # Kinect style: the "shoulder" joint has the elbow right below it (no clavicle); the foot is below
    # the ankle (the toes); the root is not named hips (the hips' common ancestor); the spine chain
    # joints are not named (SpineMid); the knee is the one unnamed joint between hip and ankle
    got = named("SpineBase; HipLeft<SpineBase; ThighSegL<HipLeft; AnkleLeft<ThighSegL; FootLeft<AnkleLeft; "
                "HipRight<SpineBase; KneeRight<HipRight; AnkleRight<KneeRight; SpineMid<SpineBase; "
                "SpineShoulder<SpineMid; Neck<SpineShoulder; Head<Neck; ShoulderLeft<SpineShoulder; "
                "ElbowLeft<ShoulderLeft; WristLeft<ElbowLeft; HandLeft<WristLeft")
    assert got["hips"] == "SpineBase" and got["lumbar"] == "SpineMid"
    assert (got["hip_l"], got["knee_l"], got["ankle_l"], got["mtp_l"]) == ("HipLeft", "ThighSegL", "AnkleLeft",
                                                                          "FootLeft")
    assert "clavicle_l" not in got and (got["shoulder_l"], got["elbow_l"], got["wrist_l"]) == (
        "ShoulderLeft", "ElbowLeft", "WristLeft")
    # a knee-named joint that is not below the hip is not the knee; the hips-named joint above both
    # hip joints is the pelvis, not the root
    got = named("Root; Hips<Root; LeftUpLeg<Hips; LeftLeg<Root; LeftShin<LeftUpLeg; LeftFoot<LeftShin; "
                "RightUpLeg<Hips; RightLeg<RightUpLeg; RightFoot<RightLeg")
    assert got["knee_l"] == "LeftShin" and got["hips"] == "Hips"


def test_lumbar_is_the_first_spine_joint_clear_of_the_hips():
    """CMU's LowerBack sits on the root: with rest positions the lumbar role goes to the joint above."""
    names, parents = tree("Hips; LeftUpLeg<Hips; LeftLeg<LeftUpLeg; LeftFoot<LeftLeg; RightUpLeg<Hips; "
                          "RightLeg<RightUpLeg; RightFoot<RightLeg; LowerBack<Hips; Spine<LowerBack; Neck<Spine; "
                          "Head<Neck")
    rest = np.zeros((len(names), 3))
    rest[names.index("LeftUpLeg")], rest[names.index("RightUpLeg")] = [0.1, 0, 0], [-0.1, 0, 0]
    rest[names.index("LowerBack")] = [0, 0.02, 0]  # 2 cm: on the pelvis
    rest[names.index("Spine")] = [0, 0.15, 0]
    assert names[joint_roles(names, parents)["lumbar"]] == "LowerBack"
    roles = joint_roles(names, parents, rest=rest)
    assert names[roles["lumbar"]] == "Spine"
    assert [names[j] for j in spine_joints(parents, roles)] == ["LowerBack", "Spine"]


def test_a_user_mapping_overrides_the_detection():
    pairs = ("Root_Ctrl; Thigh_A<Root_Ctrl; Shin_A<Thigh_A; Foot_A<Shin_A; Thigh_B<Root_Ctrl; Shin_B<Thigh_B; "
             "Foot_B<Shin_B; mixamorig:Spine<Root_Ctrl; mixamorig:Spine1<mixamorig:Spine; Head<mixamorig:Spine1; "
             "LeftHand<Head")
    names, parents = tree(pairs)
    assert missing_roles(joint_roles(names, parents)) == [f"{r}_{s}" for s in "rl" for r in ("hip", "knee", "ankle")]
    mapping = "hip_l=Thigh_A, knee_l=shin_a, ankle_l=Foot_A, hip_r=Thigh_B,knee_r=Shin_B,ankle_r=Foot_B," \
              "lumbar=spine1, toe_l=, wrist_l="
    got = named(pairs, mapping=parse_joint_mapping(mapping))
    assert got["hip_l"] == "Thigh_A" and got["knee_l"] == "Shin_A"  # names match case-insensitively
    assert got["lumbar"] == "mixamorig:Spine1"  # ... and without their namespace
    assert got["hips"] == "Root_Ctrl"  # the hip joints' common ancestor
    assert "wrist_l" not in got and "mtp_l" not in got  # an empty name: the role is not used
    assert not missing_roles({r: 0 for r in got})
    # mapping forms: a dict, a text, a file of lines, a JSON file
    assert parse_joint_mapping({"Hip_L": " Thigh_A "}) == {"hip_l": "Thigh_A"}


def test_mapping_files_and_mistakes(tmp_path):
    lines = tmp_path / "map.txt"
    lines.write_text("# my rig\nhip_l = Thigh A   # with a space\nTOE_R=ball.R\n")
    assert parse_joint_mapping(str(lines)) == {"hip_l": "Thigh A", "mtp_r": "ball.R"}
    js = tmp_path / "map.json"
    js.write_text(json.dumps({"knee_r": "Shin.R"}))
    assert parse_joint_mapping(js) == {"knee_r": "Shin.R"}
    with pytest.raises(RoleError, match=r"unknown role 'femur_l'; roles are hips, lumbar, neck, head, hip_r"):
        parse_joint_mapping("femur_l=Thigh")
    with pytest.raises(RoleError, match=r"'hip_l' is not ROLE=NAME"):
        parse_joint_mapping("hip_l")
    with pytest.raises(RoleError, match="joint mapping file not found"):
        parse_joint_mapping(str(tmp_path / "missing.txt"))
    names, parents = tree("Hips; " + "; ".join(f"Joint_Number_{i}<Hips" for i in range(40)))
    with pytest.raises(RoleError, match="no joint named 'Thigh' among: Hips, Joint_Number_0") as e:
        joint_roles(names, parents, {"hip_l": "Thigh"})
    assert len(str(e.value).split("among: ")[1]) <= 200
    names, parents = tree("Hips; a:Thigh<Hips; b:Thigh<Hips")
    with pytest.raises(RoleError, match="matches several joints"):
        joint_roles(names, parents, {"hip_l": "thigh"})


# --- the BVH reader, the command line, the upload form ------------------------------------------

def renamed(src: Path, out: Path) -> Path:
    """The Mixamo-style walk with its leg joints renamed past recognition."""
    text = src.read_text()
    for side, code in (("Left", "A"), ("Right", "B")):
        for part, new in (("UpLeg", "Seg1"), ("Leg", "Seg2"), ("Foot", "Seg3")):
            text = text.replace(f"mixamorig:{side}{part}\n", f"Leg{code}_{new}\n")
    out.write_text(text)
    return out


JOINTS = "hip_l=LegA_Seg1,knee_l=LegA_Seg2,ankle_l=LegA_Seg3,hip_r=LegB_Seg1,knee_r=LegB_Seg2,ankle_r=LegB_Seg3"


def test_bvh_without_recognisable_legs_names_the_roles_and_takes_a_mapping(shared_data, tmp_path):
    p = renamed(shared_data / MIXAMO, tmp_path / "renamed.bvh")
    with pytest.raises(BvhError) as e:
        bvh_track(p, mass=70.0)
    msg = str(e.value)
    assert "cannot find the joints for the roles hip_r, knee_r, ankle_r, hip_l, knee_l, ankle_l among the joints " \
           "mixamorig:Hips, mixamorig:Spine" in msg
    assert len(msg.split("among the joints ")[1].split("; name them")[0]) <= 200
    assert e.value.parameter == "joints" and msg.endswith("pass joints=...")
    got = bvh_track(p, mass=70.0, joints=JOINTS)
    ref = bvh_track(shared_data / MIXAMO, mass=70.0)
    assert got.source["joint_roles"]["knee_l"] == "LegA_Seg2"
    for k, v in ref.landmarks.items():
        np.testing.assert_allclose(got.landmarks[k], v, atol=1e-9, err_msg=k)
    with pytest.raises(BvhError, match="no joint named 'LegA_Seg9'"):
        bvh_track(p, mass=70.0, joints=JOINTS.replace("Seg3", "Seg9"))
    with pytest.raises(BvhError, match="unknown role 'heel_l'"):
        solver.load_trial([p], mass=70.0, joints="heel_l=LegA_Seg3")


def motionx(*args: str) -> subprocess.CompletedProcess:
    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    return subprocess.run([exe, *map(str, args)], capture_output=True, text=True, timeout=120)


def test_the_command_line_names_the_joints_flag(shared_data, tmp_path):
    p = renamed(shared_data / MIXAMO, tmp_path / "renamed.bvh")
    r = motionx("tutor", p, "--mass", "70", "--out", tmp_path / "t.json")
    lines = r.stderr.strip().splitlines()
    assert r.returncode == 2 and len(lines) == 1, r.stderr
    assert "cannot find the joints for the roles hip_r" in lines[0] and lines[0].endswith(
        "; pass --joints ROLE=NAME,...")
    r = motionx("tutor", p, "--mass", "70", "--joints", "femur_l=X", "--out", tmp_path / "t.json")
    assert r.returncode == 2 and r.stderr.strip() == (
        "motionx: error: --joints: joint mapping: unknown role 'femur_l'; roles are hips, lumbar, neck, head, "
        "hip_r, hip_l, knee_r, knee_l, ankle_r, ankle_l, mtp_r, mtp_l, clavicle_r, clavicle_l, shoulder_r, "
        "shoulder_l, elbow_r, elbow_l, wrist_r, wrist_l"), r.stderr


def test_the_upload_form_takes_the_joint_mapping():
    from service.uploads import FORM_FIELDS, UploadError, trial_options

    assert trial_options({"joints": "Hip_L=Thigh_L, knee_l = Bip01 L Calf"}) == {
        "joints": {"hip_l": "Thigh_L", "knee_l": "Bip01 L Calf"}}
    with pytest.raises(UploadError, match=r"joints: 'hip_l' is not ROLE=NAME \(e.g. hip_l=Thigh_L\)"):
        trial_options({"joints": "hip_l"})
    assert "'joints'" in FORM_FIELDS["joints"]


# --- the rigs derived from the CMU walk ---------------------------------------------------------

def test_the_derived_rigs_carry_the_cmu_feet_scaled(shared_data):
    """The generator's own check (make_rig.py), on the committed files: hip, knee, ankle and toe
    paths are the CMU ones scaled by 1.08 (cm, Y up, 60 fps) and 0.95 (metres, Z up, 30 fps)."""
    cmu = read_bvh(shared_data / CMU)
    _, Pc = cmu.forward()
    mix, unr = read_bvh(shared_data / MIXAMO), read_bvh(shared_data / UNREAL)
    assert mix.frame_time == pytest.approx(1 / 60, rel=1e-4) and mix.T == 2 * cmu.T - 1
    assert unr.frame_time == cmu.frame_time and unr.T == cmu.T
    assert mix.channels[0] == ("Xposition", "Yposition", "Zposition", "Zrotation", "Xrotation", "Yrotation")
    assert set(mix.channels[1:]) == {("Zrotation", "Xrotation", "Yrotation")}
    _, Pm = mix.forward()
    _, Pu = unr.forward()
    zup = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]])  # CMU Y up -> Z up
    for s, S in (("l", "Left"), ("r", "Right")):
        for cmu_j, mix_j, unr_j in (("femur", "UpLeg", "thigh"), ("tibia", "Leg", "calf"), ("foot", "Foot", "foot"),
                                    ("toes", "ToeBase", "ball")):
            want = Pc[cmu.names.index(s + cmu_j)]
            got = Pm[mix.names.index(f"mixamorig:{S}{mix_j}")][::2] / 1.08
            assert np.abs(got - want).max() < 0.01, (s, cmu_j)  # cm
            got = Pu[unr.names.index(f"{unr_j}_{s}")] @ zup / 0.0095
            assert np.abs(got - want).max() < 0.01, (s, cmu_j)
    # the rest poses differ: T-pose arms (Mixamo), A-pose (Unreal), CMU's arms down
    for clip, arm, fore, up, elevation in ((cmu, "lhumerus", "lradius", 1, -90.0),
                                           (mix, "mixamorig:LeftArm", "mixamorig:LeftForeArm", 1, 0.0),
                                           (unr, "upperarm_l", "lowerarm_l", 2, -45.0)):
        d = clip.offsets[clip.names.index(fore)]
        assert clip.parents[clip.names.index(fore)] == clip.names.index(arm)
        assert np.degrees(np.arcsin(d[up] / np.linalg.norm(d))) == pytest.approx(elevation, abs=0.1)


@pytest.fixture(scope="module")
def captures(shared_data):
    return (solver.load_trial([shared_data / CMU], mass=70),
            solver.load_trial([shared_data / MIXAMO], mass=70),
            solver.load_trial([shared_data / UNREAL], mass=70, up="z"))


def test_the_derived_rigs_import_as_the_same_walk(captures):
    """Roles found on both rigs (the fingers, HeadTop_End, Toe_End, Unreal's root have none); the
    fitted legs move as the CMU capture's (joint angles within 0.5° RMS at the CMU's frames)."""
    cmu, mix, unr = captures
    assert mix.source["units"] == "cm" and unr.source["units"] == "m" and unr.source["up"] == "z"
    assert mix.fps == pytest.approx(60.0, rel=1e-4)
    roles = mix.source["joint_roles"]
    assert roles["hips"] == "mixamorig:Hips" and roles["lumbar"] == "mixamorig:Spine"
    assert roles["mtp_l"] == "mixamorig:LeftToeBase" and roles["clavicle_r"] == "mixamorig:RightShoulder"
    assert not any("Index" in n or "_End" in n for n in roles.values())
    assert mix.source["spine_joints"] == ["mixamorig:Spine", "mixamorig:Spine1", "mixamorig:Spine2"]
    assert unr.source["joint_roles"]["hips"] == "pelvis" and unr.source["joint_roles"]["mtp_r"] == "ball_r"
    names = cmu.character.coordinate_names
    legs = [i for i, n in enumerate(names) if n.split("_")[0] in ("hip", "knee", "ankle", "mtp")]
    for cap, step in ((mix, 2), (unr, 1)):
        assert cap.character.name == "capture-full" and cap.character.coordinate_names == names
        q = cap.q[:, ::step]
        rms = np.degrees(np.sqrt(np.mean((q[legs] - cmu.q[legs]) ** 2, axis=1)))
        assert rms.max() < 0.5, {names[i]: round(float(r), 2) for i, r in zip(legs, rms)}
        # the subject is scaled: the thigh too
        k = 1.08 if cap is mix else 0.95
        assert cap.character.segment("thigh_r").length == pytest.approx(k * cmu.character.segment("thigh_r").length,
                                                                          rel=1e-3)


def test_bvhio_reads_the_derived_rigs(shared_data):
    with warnings.catch_warnings():  # bvhio imports PyGLM the way PyGLM plans to deprecate
        warnings.simplefilter("ignore", PendingDeprecationWarning)
        import bvhio

    for rel in (MIXAMO, UNREAL):
        path = str(shared_data / rel)
        clip = read_bvh(path)
        _, P = clip.forward()
        raw = bvhio.readAsBvh(path)
        assert raw.FrameCount == clip.T and raw.FrameTime == pytest.approx(clip.frame_time)
        root = bvhio.readAsHierarchy(path)
        joints = [j for j, _, _ in root.layout()]
        assert [j.Name for j in joints] == list(clip.names)
        for f in range(0, clip.T, 29):
            root.loadPose(f, recursive=True)
            for j in joints:
                np.testing.assert_allclose(np.array(j.PositionWorld, dtype=float), P[clip.names.index(j.Name), f],
                                           atol=1e-5 * np.abs(P).max(), err_msg=j.Name)
