"""Preprocessing: resampling, low-pass, contact detection, gait-cycle extraction (real trials)."""

import numpy as np
import pytest

from solver.gait import (
    GaitError,
    contacts_from_plates,
    detect_contacts,
    extract_cycle,
    lowpass,
    resample,
    unroll_loop,
)
from solver.io.deepmimic import load_deepmimic
from solver.io.opensim import load_opensim

TM = "opensim_gait2354_subject01_treadmill"


@pytest.fixture(scope="module")
def treadmill(shared_data):
    d = shared_data / TM
    return load_opensim(d / "subject01.osim", d / "subject01_walk1_ik.mot", grf=d / "subject01_walk1_grf.mot",
                        grf_xml=d / "subject01_walk1_grf.xml", belt_speed="auto")


@pytest.fixture(scope="module")
def deepmimic(shared_data):
    d = shared_data / "deepmimic_humanoid3d_walk"
    return load_deepmimic(d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt")


def test_resample_keeps_values_at_common_times(treadmill):
    r = resample(treadmill, 30)
    assert r.fps == pytest.approx(30.0)
    assert r.times[0] == treadmill.times[0] and r.T == (treadmill.T - 1) // 2 + 1
    # 60 Hz -> 30 Hz: every other source frame is a common time (to the file's 1e-8 s rounding)
    assert np.allclose(r.q, treadmill.q[:, ::2], atol=1e-6)
    assert r.measured is not None and r.measured.force.shape == (2, 3, r.T)
    assert np.allclose(r.measured.force, treadmill.measured.force[:, :, ::2], atol=1e-3)
    up = resample(treadmill, 120)
    assert np.allclose(up.q[:, ::2], treadmill.q, atol=1e-6)


def test_resample_angles_stay_continuous(deepmimic):
    ch = deepmimic.character
    q = np.array(deepmimic.q)
    yaw = ch.index("root_rz")
    q[yaw] = np.angle(np.exp(1j * (np.pi - 0.2 + 0.4 * np.linspace(0, 1, deepmimic.T))))  # wraps at +-pi
    r = resample(deepmimic.evolve(q=q), 60)
    assert np.abs(np.diff(r.q[yaw])).max() < 0.02  # no 2 pi jump, the yaw keeps turning smoothly
    assert r.q[yaw, -1] == pytest.approx(np.pi + 0.2, abs=1e-3)


def test_lowpass_is_zero_phase():
    fps = 100.0
    t = np.arange(400) / fps
    slow, fast = np.sin(2 * np.pi * 2 * t), np.sin(2 * np.pi * 25 * t)
    y = lowpass(slow + fast, fps, 6.0)
    mid = slice(50, 350)
    assert np.abs(y[mid] - slow[mid]).max() < 0.02  # passband kept, no lag
    assert np.abs(lowpass(fast, fps, 6.0)[mid]).max() < 0.01  # stopband removed
    two = lowpass(np.stack([slow, 2 * slow]), fps, 6.0)
    assert two.shape == (2, 400) and np.allclose(two[1], 2 * two[0])
    with pytest.raises(GaitError, match="fps/2"):
        lowpass(slow, fps, 60.0)
    with pytest.raises(GaitError, match="NaN"):
        lowpass(np.r_[slow[:-1], np.nan], fps, 6.0)


def test_contacts_from_plates_match_the_plates(treadmill):
    c = contacts_from_plates(treadmill.measured, character=treadmill.character, q=treadmill.q, fps=treadmill.fps)
    fz = treadmill.measured.force[:, 2]
    assert np.array_equal(c[0] | c[1], fz[0] > 20) and np.array_equal(c[2] | c[3], fz[1] > 20)
    plain = contacts_from_plates(treadmill.measured)
    assert np.array_equal(plain[0], plain[1]) and np.array_equal(plain[0], fz[0] > 20)


def test_extract_cycle_treadmill(treadmill):
    cyc, cc = extract_cycle(treadmill, 30)
    info = cyc.source["cycle"]
    # README: right heel strikes (plates) at 0.618, 1.853, 3.078 s; cycle ~1.235 s
    assert info["t_start"] == pytest.approx(0.618, abs=2 / 30)
    assert info["period_s"] == pytest.approx(1.235, abs=2 / 30)
    N = round(info["period_s"] * 30)
    assert cyc.T == N + 2 and cc.shape == (4, N + 2)  # two overlap frames (docs/method.md (M5.5))
    assert cc[0, 0] or cc[1, 0]  # the right foot is down at the start
    feet = np.stack([cc[0] | cc[1], cc[2] | cc[3]])
    assert np.any(feet[0, :-2] & feet[1, :-2])
    # overlap frames repeat the first two one period later (a real walk: close, not equal)
    ch = cyc.character
    joints = [i for i, n in enumerate(ch.coordinate_names) if not n.startswith("root")]
    assert np.degrees(np.median(np.abs(cyc.q[joints, -2] - cyc.q[joints, 0]))) < 3.0
    assert np.array_equal(cc[:, -2:], cc[:, :2]) or np.mean(cc[:, -2:] == cc[:, :2]) >= 0.75
    assert cyc.measured is not None and cyc.measured.valid.all()
    left, _ = extract_cycle(treadmill, 30, start="left_heel_strike")
    assert left.source["cycle"]["t_start"] == pytest.approx(1.247, abs=2 / 30)


def test_unroll_loop(deepmimic):
    u = unroll_loop(deepmimic, 3)
    T = deepmimic.T
    assert u.T == 3 * T - 2
    x = deepmimic.character.index("root_tx")
    d = deepmimic.q[x, -1] - deepmimic.q[x, 0]
    assert u.q[x, T - 1 + 5] == pytest.approx(deepmimic.q[x, 5] + d)
    assert np.all(np.diff(u.times) > 0)


def test_cycle_errors(treadmill, deepmimic):
    short = treadmill.evolve(q=treadmill.q[:, :50], times=treadmill.times[:50], measured=None, contacts=None)
    with pytest.raises(GaitError, match="too short for a gait cycle"):
        extract_cycle(short)
    lifted = np.array(treadmill.q)
    lifted[treadmill.character.index("root_tz")] += 0.4
    with pytest.raises(GaitError, match="never touches the ground"):
        detect_contacts(treadmill.character, lifted, treadmill.fps)
    T = treadmill.T
    run = np.zeros((4, T), dtype=bool)  # a run: never both feet down
    period = 40
    for k in range(T):
        ph = k % period
        run[0:2, k] = ph < 14
        run[2:4, k] = 20 <= ph < 34
    with pytest.raises(GaitError, match="no double support"):
        extract_cycle(treadmill, contacts=run)
    stand = np.ones((4, T), dtype=bool)
    with pytest.raises(GaitError, match="no right heel strike"):
        extract_cycle(treadmill, contacts=stand)
    swing = stand.copy()
    swing[2:] = False
    with pytest.raises(GaitError, match="left foot is never on the ground"):
        extract_cycle(treadmill, contacts=swing)
    with pytest.raises(GaitError, match="start must be"):
        extract_cycle(treadmill, start="toe_off")
    with pytest.raises(GaitError, match="fps must be"):
        resample(treadmill, 0)
