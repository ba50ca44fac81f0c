"""DeepMimic importer on the shared humanoid3d walk (45 kg, 30 Hz, looping)."""

import json

import numpy as np
import pytest

from solver.gait import detect_contacts, extract_cycle, gait_events
from solver.io import load_trial
from solver.io.deepmimic import DeepMimicError, deepmimic_track, load_deepmimic
from solver.kinematics import contact_points, points_world

DM = "deepmimic_humanoid3d_walk"


@pytest.fixture(scope="module")
def clip(shared_data):
    d = shared_data / DM
    return load_deepmimic(d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt")


def test_imports_with_the_character_masses(clip):
    ch = clip.character
    assert ch.name == "capture-full" and ch.n == 63
    assert clip.T == 39 and clip.fps == pytest.approx(30.0, rel=1e-3)
    assert ch.total_mass == pytest.approx(45.0)
    assert ch.segment("thigh_r").mass == pytest.approx(4.5) and ch.segment("pelvis").mass == pytest.approx(6.0)
    # same tree as ours: thigh 0.4215 m, shank 0.4099 m (README), exact fit
    assert ch.segment("thigh_l").length == pytest.approx(0.421546, abs=1e-6)
    assert ch.segment("shank_r").length == pytest.approx(0.40987, abs=1e-6)
    assert ch.segment("thigh_r").offset[1] == pytest.approx(-0.084887, abs=1e-6)  # right hip at -y
    assert clip.source["fit"]["landmark_error_mm"]["max"] < 1.0
    assert clip.source["loop"] == "wrap"
    # the foot box is the character's ankle box: 0.177 m long
    assert 2 * ch.foot("right").half[0] == pytest.approx(0.177)


def test_axes(clip):
    ch, q, t = clip.character, clip.q, clip.times
    # README: root advances 1.239 m along +X in 1.267 s
    assert q[ch.index("root_tx"), -1] - q[ch.index("root_tx"), 0] == pytest.approx(1.239, abs=1e-3)
    assert np.polyfit(t, q[ch.index("root_tx")], 1)[0] == pytest.approx(0.98, abs=0.03)
    assert np.median(q[ch.index("root_tz")]) == pytest.approx(0.85, abs=0.05)  # DeepMimic y (up) -> our z
    feet = points_world(ch, q, [("foot_r", [0, 0, 0]), ("foot_l", [0, 0, 0])])
    assert np.all(feet[0, 1] < feet[1, 1])  # DeepMimic +z (right) -> our -y
    cp = contact_points(ch, q)
    assert np.percentile(cp[:, 2], 5, axis=1) == pytest.approx(np.full(4, 0.01), abs=0.01)  # floor y = 0


def test_gait_events_and_cycle(clip):
    ev = gait_events(detect_contacts(clip.character, clip.q, clip.fps), clip.times)
    dt = 1 / 30
    # README: right heel strike ~1.23 s (wraps to 0), left heel strike 0.60-0.63 s, right toe-off 0.63-0.67 s
    assert ev["right_heel_strike"][0] == pytest.approx(1.233, abs=2 * dt)
    assert 0.60 - 2 * dt <= ev["left_heel_strike"][0] <= 0.633 + 2 * dt
    assert 0.63 - 2 * dt <= ev["right_toe_off"][0] <= 0.67 + 2 * dt
    cyc, cc = extract_cycle(clip)
    assert cyc.T == 40 and cc.shape == (4, 40)  # the 39-frame loop + its second frame
    assert cyc.source["cycle"]["period_s"] == pytest.approx(1.2666, abs=1e-3)
    ch = cyc.character
    joints = [i for i, n in enumerate(ch.coordinate_names) if not n.startswith("root")]
    # overlap: q_T = q_2 exactly (same clip frame), q_{T-1} ~ q_1 up to the clip's own closure error
    assert np.allclose(cyc.q[joints, -1], cyc.q[joints, 1])
    x = ch.index("root_tx")
    assert cyc.q[x, -2] - cyc.q[x, 0] == pytest.approx(1.239, abs=1e-3)
    c15, cc15 = extract_cycle(clip, 15)
    assert c15.T == 21 and c15.fps == pytest.approx(15.0)


def test_load_trial_dispatches_deepmimic(shared_data):
    d = shared_data / DM
    cap = load_trial([d / "humanoid3d_character.txt", d / "humanoid3d_walk.txt"], mass=60.0)
    assert cap.character.total_mass == pytest.approx(60.0)


def test_errors(shared_data, tmp_path):
    d = shared_data / DM
    motion = json.loads((d / "humanoid3d_walk.txt").read_text())
    short = dict(motion, Frames=[f[:-1] for f in motion["Frames"]])
    p = tmp_path / "short.txt"
    p.write_text(json.dumps(short))
    with pytest.raises(DeepMimicError, match="model/motion mismatch"):
        deepmimic_track(p, d / "humanoid3d_character.txt")
    nan = dict(motion, Frames=[list(f) for f in motion["Frames"]])
    nan["Frames"][4][9] = float("nan")
    p.write_text(json.dumps(nan).replace("NaN", "NaN"))
    with pytest.raises(DeepMimicError, match="frame 4"):
        deepmimic_track(p, d / "humanoid3d_character.txt")
    with pytest.raises(DeepMimicError, match="no Skeleton"):
        deepmimic_track(d / "humanoid3d_walk.txt", d / "humanoid3d_walk.txt")
    with pytest.raises(DeepMimicError, match="not found"):
        deepmimic_track(tmp_path / "none.txt", d / "humanoid3d_character.txt")
