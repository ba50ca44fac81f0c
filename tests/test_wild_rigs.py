"""Rigs from the wild: walks on skeletons that are not ours go in, make a HalfBoy tutor and come
back on their own skeleton (``rig="source"``) with the feet planted and the joints HalfBoy does
not model moving as captured.

The clips (``data/``; origin and licence per folder in data/README.md):

- the CMU game clips as retargeted by SNU's ``gengine`` (third-party, 30 fps, ASF names, no
  T-pose): the straight walk and the 90° left turn;
- DeepMimic's humanoid walk (third-party; its own character file), back as a DeepMimic motion
  and a GLB of its skeleton;
- the Mixamo-style rig (T-pose, 60 fps, ×1.08), the Unreal-style rig (A-pose, metres, Z up)
  and the skinned Mixamo-style glTF character (derived here from the CMU walk by their folders'
  scripts);
- made here from the CMU walk, as the issue's files from outside were: the same walk **in
  place** (its root's horizontal channels held still, as game libraries ship walks), and a
  game studio's way of writing it — **six channels on every joint** (position channels that
  repeat the OFFSET), **zero-length End Sites** (so the head, hands and toes have no tip).

Each must import, make a HalfBoy tutor at 15 fps, and come back on its rig with every contact
point of the motion, carried by the rig's foot (heel) or toe joint from where it touched down,
within 2 cm of where the motion holds it through the stance, the ankle joints within 2 cm of the
motion's feet, and the locked joints (spine, arms, head) at the capture's own local rotations at
the same gait phase (RMS reported, held under 1°). A BVH comes back as a file read by our parser
(its forward kinematics: the file as an engine reads it). The figures are written to
``out/wild_rigs.json`` (docs/walkthrough.md quotes them). Every failure a user can meet on such
files says what to pass (the last tests).
"""

from __future__ import annotations

import json
import time
from pathlib import Path

import numpy as np
import pytest
from scipy.spatial.transform import Rotation, Slerp

import solver
from solver.capture import GroundFrame
from solver.errors import InputError
from solver.io.bvh import BvhClip, parse_bvh, read_bvh
from solver.kinematics import contact_points
from solver.rig import SkeletonRig, feet_report, locked_joint_rms, retarget
from solver.trajectory import sample

REPORT = Path(__file__).resolve().parents[1] / "out" / "wild_rigs.json"
PLANTED_M = 0.02  # contact points and ankle joints from the motion's, in stance
LOCKED_RMS_DEG = 1.0
TRUNK_MARGIN_DEG = 8.0  # the written trunk's largest lean from the vertical over the captured one


def write_bvh(clip: BvhClip, channels, motion: np.ndarray, end_sites=None) -> str:
    """A BVH file of ``clip``'s hierarchy with other ``channels`` and ``motion`` (and End Sites)."""
    ends = clip.end_sites if end_sites is None else end_sites
    children = {j: [c for c, p in enumerate(clip.parents) if p == j] for j in range(len(clip.names))}
    out = ["HIERARCHY"]

    def write(j: int, depth: int) -> None:
        pad = "  " * depth
        out.append(f"{pad}{'ROOT' if depth == 0 else 'JOINT'} {clip.names[j]}")
        out.append(f"{pad}{{")
        out.append(f"{pad}  OFFSET {' '.join(f'{x:.6f}' for x in clip.offsets[j])}")
        out.append(f"{pad}  CHANNELS {len(channels[j])} {' '.join(channels[j])}")
        for c in children[j]:
            write(c, depth + 1)
        if j in ends:
            out.extend([f"{pad}  End Site", f"{pad}  {{",
                        f"{pad}    OFFSET {' '.join(f'{x:.6f}' for x in ends[j])}", f"{pad}  }}"])
        out.append(f"{pad}}}")

    write(0, 0)
    out += ["MOTION", f"Frames: {motion.shape[0]}", f"Frame Time: {clip.frame_time:.7f}"]
    out += [" ".join(f"{x:.6f}" for x in row) for row in motion]
    return "\n".join(out) + "\n"


def in_place(src: Path) -> str:
    """The walk with its root's horizontal position channels held at their first value (Y up)."""
    clip = read_bvh(src)
    m = clip.motion.copy()
    for k, c in enumerate(clip.channels[0]):
        if c in ("Xposition", "Zposition"):
            m[:, k] = m[0, k]
    return write_bvh(clip, clip.channels, m)


def six_channels(src: Path) -> str:
    """The walk as a game studio's exporter writes it: six channels on every joint (the position
    ones repeat the joint's OFFSET), every End Site of zero length."""
    clip = read_bvh(src)
    channels, cols, col = [], [], 0
    for j, chans in enumerate(clip.channels):
        rot = [c for c in chans if c.endswith("rotation")]
        pos_cols = {c: col + k for k, c in enumerate(chans) if c.endswith("position")}
        rot_cols = [col + k for k, c in enumerate(chans) if c.endswith("rotation")]
        col += len(chans)
        channels.append(("Xposition", "Yposition", "Zposition", *rot))
        for a, name in enumerate(("Xposition", "Yposition", "Zposition")):
            cols.append(clip.motion[:, pos_cols[name]] if name in pos_cols
                        else np.full(clip.T, clip.offsets[j][a]))
        cols += [clip.motion[:, c] for c in rot_cols]
    return write_bvh(clip, channels, np.stack(cols, axis=1), {j: np.zeros(3) for j in clip.end_sites})


#: name -> (file under data/ or a maker and its source, import options, the formats to write on the rig)
CLIPS = {
    "cmu_gengine_walk": ("cmu16_bvh/16_15_walk.bvh", {"mass": 60}, ("bvh", "gltf")),
    "cmu_gengine_left_turn": ("cmu16_bvh/16_17_walk_90deg_left_turn.bvh", {"mass": 60}, ("bvh",)),
    "deepmimic_humanoid": (("deepmimic_humanoid3d_walk/humanoid3d_walk.txt",
                            "deepmimic_humanoid3d_walk/humanoid3d_character.txt"), {}, ("deepmimic", "gltf")),
    "mixamo_style_60fps": ("mixamo_style_walk/walk.bvh", {"mass": 70}, ("bvh",)),
    "unreal_style_a_pose": ("mixamo_style_walk/walk_unreal_style.bvh", {"mass": 70, "up": "z"}, ("bvh",)),
    "skinned_gltf": ("skinned_walk/walk.glb", {"mass": 70}, ("gltf",)),
    "cmu_in_place": ((in_place, "cmu16_bvh/16_15_walk.bvh"), {"mass": 60}, ("bvh",)),
    "six_channels_zero_end_sites": ((six_channels, "cmu16_bvh/16_15_walk.bvh"), {"mass": 60}, ("bvh",)),
}


@pytest.fixture(scope="module")
def made(shared_data, tmp_path_factory):
    """Every clip imported and its HalfBoy tutor (15 fps), once for the module: name -> (input
    files, capture, tutor motion, seconds)."""
    tmp = tmp_path_factory.mktemp("wild")
    out = {}
    for name, (where, options, _) in CLIPS.items():
        t0 = time.perf_counter()
        if isinstance(where, tuple) and callable(where[0]):
            path = tmp / f"{name}.bvh"
            path.write_text(where[0](shared_data / where[1]))
            files = [path]
        else:
            files = [shared_data / w for w in (where if isinstance(where, tuple) else (where,))]
        capture = solver.load_trial(files, **options)
        tutor = solver.make_tutor(capture, character="halfboy", fps=15.0)
        out[name] = (files, capture, tutor, time.perf_counter() - t0)
    return out


def _carried_contacts(motion, P, R, t, tc, frame: GroundFrame, feet) -> float:
    """The largest distance, over the motion's stance frames, between each contact point of the
    motion and the same point carried by the rig's foot (heel) or toe joint from the frame its
    contact began (``P``, ``R``: the rig's joint positions and rotations in the input's axes;
    ``feet``: the foot and toe joints, right then left; ``t``: the motion's times, ``tc``: the
    capture's clock at them, which a moving ground's frame follows)."""
    Pw = frame.point_from_input(P, tc[:, None])
    Rw = np.einsum("ji,fkjl->fkil", frame.R, R)
    q = sample(motion.q, motion.fps, t, cyclic=motion.cyclic, interpolation=motion.interpolation)
    cp = np.asarray(contact_points(motion.character, q)).reshape(len(motion.character.contacts), 3, -1)
    s = t * motion.fps
    on = motion.contacts[:, np.floor(s + 1e-9).astype(int).clip(0, motion.T - 1)] & \
        motion.contacts[:, np.ceil(s - 1e-9).astype(int).clip(0, motion.T - 1)]
    worst = 0.0
    for i, c in enumerate(motion.character.contacts):
        side = 0 if c.side.startswith("r") else 1
        j = feet[2 + side] if "toe" in c.name else feet[side]
        edges = np.flatnonzero(np.diff(np.concatenate([[0], on[i].astype(int), [0]])))
        for a, b in zip(edges[::2], edges[1::2]):
            local = Rw[a, j].T @ (cp[i, :, a] - Pw[a, j])
            pts = Pw[a:b, j] + np.einsum("fij,j->fi", Rw[a:b, j], local)
            worst = max(worst, float(np.max(np.linalg.norm(pts - cp[i, :, a:b].T, axis=1))))
    return worst


def _locked_rms_from_file(src: BvhClip, out: BvhClip, rig: SkeletonRig, pose) -> tuple[float, int]:
    """RMS (°) between the written file's local rotations and the input file's at the same gait
    phase, over the joints outside the legs that the motion does not drive (spine, arms, head)."""
    legs = set()
    for j in range(len(src.names)):
        a = j
        while a >= 0:
            if a in (rig.roles.get("thigh_r"), rig.roles.get("thigh_l")):
                legs.add(j)
            a = src.parents[a]
    driven = {rig.roles[s] for s in pose.driven if s in rig.roles}  # the joints of the motion's segments
    capture_time = pose.capture_time
    free = [j for j in range(1, len(src.names)) if j not in legs and j not in driven
            and any(c.endswith("rotation") for c in src.channels[j])]
    t_src = np.arange(src.T) * src.frame_time
    errs = []
    for j in free:
        want = Slerp(t_src, Rotation.from_matrix(src.local(j)[0]))(np.clip(capture_time, t_src[0], t_src[-1]))
        got = Rotation.from_matrix(out.local(j)[0])
        errs.append((want.inv() * got).magnitude())
    return (float(np.degrees(np.sqrt(np.mean(np.concatenate(errs) ** 2)))) if errs else 0.0), len(free)


def _trunk_tilt(P: np.ndarray, lumbar: int, top: int, up: np.ndarray) -> np.ndarray:
    """(F,) degrees: the trunk's (lumbar -> head joint) angle from the vertical, joint positions ``P`` (F, J, 3)."""
    d = P[:, top] - P[:, lumbar]
    return np.degrees(np.arccos(np.clip(d @ up / np.linalg.norm(d, axis=1), -1.0, 1.0)))


def _figures(name, made) -> dict:
    files, capture, tutor, seconds = made[name]
    motion = tutor.motion
    rig = motion.context.rig
    pose = retarget(motion, rig)
    frame = motion.frame
    feet = [rig.roles[s] if s in rig.roles else rig.roles[s.replace("toes", "foot")]
            for s in ("foot_r", "foot_l", "toes_r", "toes_l")]
    rep = feet_report(motion, rig, pose)
    fig = {"rig": rig.format, "joints": rig.J, "frames_out": int(pose.times.size),
           "fps_out": round(1.0 / float(pose.times[1] - pose.times[0]), 3),
           "tutor_s": round(seconds, 1), "in_place": capture.source.get("in_place"),
           "ankle_mm": round(1e3 * max(rep[s]["ankle_error_m"] for s in ("right", "left")), 2)}
    if rig.format == "bvh":
        # the file as written, read back: its own forward kinematics
        text = solver.export_motion(motion, "bvh", rig="source", world="ground")
        out = parse_bvh(text)
        R, P = out.forward()  # (J, F, …): to (F, J, …)
        R, P = np.swapaxes(R, 0, 1), np.swapaxes(P, 0, 1)
        fig["contacts_mm"] = round(1e3 * _carried_contacts(motion, P, R, pose.times, pose.capture_time, frame, feet), 2)
        src = read_bvh(files[0])
        fig["locked_rms_deg"], fig["locked_joints"] = _locked_rms_from_file(src, out, rig, pose)
        # the trunk's lean from the vertical, written against captured at the same phase (the issue's 60 fps
        # rig swayed its trunk -10…+14° where the capture held ±1.2°)
        top = rig.roles.get("head")
        if "abdomen" in rig.roles and top is not None:
            up = np.abs(frame.R[:, 2])  # our z in the file's axes
            t_src = np.arange(src.T) * src.frame_time
            P_src = np.swapaxes(src.forward()[1], 0, 1)
            P_cap = np.stack([np.stack([np.interp(pose.capture_time, t_src, P_src[:, j, c]) for c in range(3)], -1)
                              for j in range(P_src.shape[1])], 1)
            out_tilt = _trunk_tilt(P, rig.roles["abdomen"], top, up)
            cap_tilt = _trunk_tilt(P_cap, rig.roles["abdomen"], top, up)
            fig["trunk_lean_deg"] = [round(float(out_tilt.min()), 1), round(float(out_tilt.max()), 1)]
            fig["trunk_lean_capture_deg"] = [round(float(cap_tilt.min()), 1), round(float(cap_tilt.max()), 1)]
        fig["frames_out"], fig["fps_out"] = out.T, round(1.0 / out.frame_time, 3)
    else:
        W, P = rig.forward(pose.local, pose.root, pose.positions)
        fig["contacts_mm"] = round(1e3 * _carried_contacts(motion, P, W, pose.times, pose.capture_time, frame, feet), 2)
        lk = locked_joint_rms(rig, pose)
        fig["locked_rms_deg"], fig["locked_joints"] = lk["rms_deg"], lk["joints"]
    fig["locked_rms_deg"] = round(float(fig["locked_rms_deg"]), 4)
    return fig


def test_every_clip_comes_back_on_its_own_rig_with_the_feet_planted(made):
    figures = {}
    for name, (_, _, formats) in CLIPS.items():
        files, capture, tutor, _ = made[name]
        assert tutor.status == "succeeded", f"{name}: {tutor.message}"
        assert tutor.motion.report["plausible"], name
        fig = figures[name] = _figures(name, made)
        for fmt in formats:  # every format the rig takes writes
            data = solver.export_motion(tutor.motion, fmt, rig="source")
            assert data, (name, fmt)
        assert fig["contacts_mm"] <= 1e3 * PLANTED_M and fig["ankle_mm"] <= 1e3 * PLANTED_M, (name, fig)
        assert fig["locked_joints"] >= 3 and fig["locked_rms_deg"] < LOCKED_RMS_DEG, (name, fig)
        if "trunk_lean_deg" in fig:  # the trunk leans as captured, give or take what HalfBoy's pelvis does
            assert fig["trunk_lean_deg"][1] <= fig["trunk_lean_capture_deg"][1] + TRUNK_MARGIN_DEG, (name, fig)
    REPORT.parent.mkdir(parents=True, exist_ok=True)
    REPORT.write_text(json.dumps(figures, indent=1))
    print(json.dumps(figures, indent=1))


def test_an_in_place_clip_is_walked_overground_and_comes_back_in_place(made):
    _, capture, tutor, _ = made["cmu_in_place"]
    ip = capture.source["in_place"]
    assert ip["detected"] and ip["pelvis_travel_m_s"] < 0.05 and 0.9 < ip["speed_m_s"] < 1.4, ip
    # the tutor walks (overground-equivalent), as the clip's overground original does
    _, _, original, _ = made["cmu_gengine_walk"]
    speed = lambda m: (m.q[0, -2] - m.q[0, 0]) / ((m.T - 2) / m.fps)  # noqa: E731
    assert speed(tutor.motion) == pytest.approx(speed(original.motion), rel=0.15)
    # written on its rig it walks in place again, as it came in
    out = parse_bvh(solver.export_motion(tutor.motion, "bvh", rig="source", world="ground"))
    root = out.forward()[1][0]
    assert np.ptp(root[:, 0]) < 10.0 and np.ptp(root[:, 2]) < 10.0  # cm: the hips sway, they do not travel


def test_six_channels_and_zero_length_end_sites(made):
    """Position channels that repeat the OFFSET are read as the joint's position (not added to it:
    the bones would double, the subject 3 m tall); zero-length End Sites are no tips, the head's,
    hands' and toes' are placed by proportion."""
    files, capture, tutor, _ = made["six_channels_zero_end_sites"]
    _, original, _, _ = made["cmu_gengine_walk"]
    # the same subject (its head placed by proportion, not by the file's own head End Site)
    assert capture.source["fit"]["height_m"] == pytest.approx(original.source["fit"]["height_m"], rel=0.15)
    clip = read_bvh(files[0])
    assert len(clip.absolute) == len(clip.names) - 1  # every joint but the root (its channels move it)
    assert set(capture.source["estimated_tips"]) >= {"head_top", "hand_r", "hand_l", "toe_r", "toe_l"}
    # written back with its six channels, the positions still the OFFSETs
    out = parse_bvh(solver.export_motion(tutor.motion, "bvh", rig="source"))
    assert out.channels == clip.channels and out.absolute == clip.absolute
    col = len(clip.channels[0])  # the second joint's Xposition
    assert out.motion[:, col] == pytest.approx(clip.offsets[1][0], abs=1e-5)


def test_a_60fps_rig_comes_back_at_60fps_and_the_command_line_says_so(made):
    from service.commands.export import _written_frames

    _, _, tutor, _ = made["mixamo_style_60fps"]
    out = parse_bvh(solver.export_motion(tutor.motion, "bvh", rig="source"))
    frames, fps = _written_frames(tutor.motion, {"rig": "source"})
    assert (frames, fps) == (out.T, pytest.approx(1.0 / out.frame_time, rel=1e-6))
    assert fps == pytest.approx(60.0, rel=1e-3) and frames > 60  # not the motion's 15 fps and ~20 frames


# ------------------------------------------------------------------ messages that say what to do


def test_an_in_place_clip_told_not_to_move_says_to_pass_its_speed(shared_data, tmp_path):
    path = tmp_path / "in_place.bvh"
    path.write_text(in_place(shared_data / "cmu16_bvh/16_15_walk.bvh"))
    capture = solver.load_trial([path], mass=60, belt_speed=0)
    assert "in_place" not in capture.source
    with pytest.raises(InputError) as e:
        solver.make_tutor(capture, character="halfboy", fps=15.0)
    assert e.value.parameter == "belt_speed" and "in place" in str(e.value), str(e.value)
    assert str(e.value).count("never on the ground") == 1  # said once, not once per way of cutting a cycle


def test_legs_of_the_wrong_size_name_the_unit_and_the_joints(shared_data):
    with pytest.raises(InputError) as e:
        solver.load_trial([shared_data / "cmu16_bvh/16_15_walk.bvh"], mass=60, units="m")
    msg = str(e.value)
    assert "units" in msg and "joints" in msg, msg


def test_a_head_mapped_far_away_does_not_make_a_giant(shared_data):
    """A joint mapping that puts the head on a hand: the trunk and head disagree with the legs,
    the legs decide the height (was: 'estimated subject height 3.02 m is not plausible')."""
    good = solver.load_trial([shared_data / "cmu16_bvh/16_15_walk.bvh"], mass=60)
    odd = solver.load_trial([shared_data / "cmu16_bvh/16_15_walk.bvh"], mass=60, joints="head=lhand")
    assert odd.source["fit"]["height_m"] == pytest.approx(good.source["fit"]["height_m"], rel=0.15)
