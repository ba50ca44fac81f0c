"""What the tutor tracks (issue: true to the subject): a cycle at the subject's own period, its seam
closed on the captured motion around it, its noise low-passed as a periodic signal, its contact points
where the capture has them, still arms given a swing — each on a known answer or a real trial."""

from __future__ import annotations

import numpy as np
import pytest

from solver.character.reference import REFERENCE
from solver.gait import close_loop, extract_cycle, periodic_lowpass, tighten_contacts
from solver.gait.arms import SHOULDER_AMPLITUDE, arm_swing, arms_still
from solver.kinematics import contact_points, standing_leg_length


@pytest.fixture(scope="module")
def treadmill(shared_data):
    from solver.io import load_trial

    d = shared_data / "opensim_gait2354_subject01_treadmill"
    return load_trial([d / "subject01.osim", d / "subject01_walk1_ik.mot", d / "subject01_walk1_grf.mot",
                       d / "subject01_walk1_grf.xml"], belt_speed="auto")


def _seam(cyc) -> float:
    """RMS (normalized per coordinate) of frames N, N+1 against frames 0, 1: how far a cycle's end is
    from its start one period on (joints only)."""
    q = cyc.q[6:]
    scale = np.maximum(np.std(q, axis=1, keepdims=True), 1e-3)
    return float(np.sqrt(np.mean(((q[:, -2:] - q[:, :2]) / scale) ** 2)))


def test_a_cycles_frames_span_the_subjects_own_period(treadmill):
    """At 15 and 30 frames/s the cycle's period is the same (the capture's, found at its own 60 Hz),
    its N frames span it exactly, and its end meets its start better than a whole number of frames
    at the requested rate did."""
    periods = {}
    for fps in (15.0, 30.0):
        cyc, _ = extract_cycle(treadmill, fps, start="auto")
        info = cyc.source["cycle"]
        N = cyc.T - 2
        assert info["fps_requested"] == fps and abs(info["fps"] - fps) <= 0.5 * fps / N + 1e-9
        assert info["fps"] * info["period_s"] == pytest.approx(N, abs=1e-9)
        assert np.diff(cyc.times) == pytest.approx(1.0 / info["fps"], abs=1e-9)
        periods[fps] = info["period_s"]
        whole = extract_cycle(treadmill.evolve(), fps, start="auto")  # same call: deterministic
        assert whole[0].T == cyc.T
    assert periods[15.0] == pytest.approx(periods[30.0], abs=0.011)


def test_the_seam_is_closed_on_the_motion_that_led_into_it():
    """A cycle whose second stride is a little off its first: with the frames before it, its last
    frames are blended into them and frames N, N+1 become frames 0, 1; without, the ramp spreads it."""
    T, N = 22, 20
    t = np.arange(-4, T) / N
    q = np.zeros((8, t.size))
    q[6] = np.sin(2 * np.pi * t) + 0.2 * (t > 0.9)  # the second stride 0.2 rad off near its end
    q[7] = np.cos(2 * np.pi * t)
    lead_in, cyc = q[:, :4], q[:, 4:]
    closed = close_loop(cyc, lead_in=lead_in)
    assert closed[6:, N:] == pytest.approx(closed[6:, :2])
    assert closed[6:, :N - 4] == pytest.approx(cyc[6:, :N - 4])  # only the last frames are blended
    steps = np.abs(np.diff(closed[6, : N + 2]))
    assert steps.max() < 0.4  # no jump at the seam (a sine's step is 0.31 here)
    ramp = close_loop(cyc)
    assert ramp[6:, N] == pytest.approx(ramp[6:, 0]) and np.abs(ramp[6] - cyc[6]).max() <= 0.2 * (N + 1) / N + 1e-12


def test_a_closed_cycle_loses_its_noise_not_its_walk():
    """Harmonics below 6 Hz pass untouched, above 10 Hz they go; the travel's trend stays."""
    fps, N = 30.0, 36
    k = np.arange(N + 2)
    slow = np.sin(2 * np.pi * 4 * k / N)  # 4 harmonics of a 1.2 s cycle: 3.3 Hz
    fast = 0.1 * np.sin(2 * np.pi * 14 * k / N)  # 11.7 Hz
    q = np.zeros((8, N + 2))
    q[0] = 1.2 * k / N  # travel
    q[6], q[7] = slow + fast, slow
    out = periodic_lowpass(q, fps)
    assert out[7] == pytest.approx(slow, abs=1e-9) and out[6] == pytest.approx(slow, abs=1e-9)
    assert out[0] == pytest.approx(q[0], abs=1e-9)


def test_a_contact_point_above_the_ground_at_a_run_edge_is_lifted():
    """The heel 3 cm up at the end of its run (heel rise) comes off the schedule; the toe, the foot's
    only point at a frame, stays on though it is 2 cm up (the foot is loaded)."""
    ch = REFERENCE["halfboy"]()
    N = 10
    q = np.zeros((ch.n, N + 2))
    q[2] = standing_leg_length(ch)
    A = np.zeros((len(ch.contacts), N + 2), dtype=bool)
    names = [c.name for c in ch.contacts]
    hr, tr_ = names.index("heel_r"), names.index("toe_r")
    A[hr, 0:6] = True
    A[tr_, 0:8] = True
    A[:, N:] = A[:, :2]
    z0 = contact_points(ch, q)[:, 2, 0]
    base = np.array(q)

    def lifted(heights: dict[int, float]) -> np.ndarray:
        """q with the whole body raised at the given frames (both points up by the same amount)."""
        out = base.copy()
        for t, h in heights.items():
            out[2, t] += h
        return out

    q2 = lifted({5: 0.03})  # both points 3 cm up at frame 5: the heel's run ends there, the toe's does not
    out, changes = tighten_contacts(ch, q2, A)
    assert not out[hr, 5] and out[hr, 4] and out[tr_, 5]  # the heel off at its run's end, its mate kept
    assert out[tr_, 6:8].all()  # its run goes on
    assert {c["point"] for c in changes} <= {"heel_r", "toe_r"} and abs(z0[hr]) < 1.0


def test_still_arms_swing_in_antiphase_with_their_legs(treadmill):
    """gait2354 has no arms: the capture's hang still, and the cycle's get the published swing, each
    shoulder flexing as its own hip extends; arms that move (DeepMimic) are left as captured."""
    cyc, _ = extract_cycle(treadmill, 30.0, start="auto")
    names = list(cyc.character.coordinate_names)
    assert arms_still(names, cyc.q)
    q, info = arm_swing(names, cyc.q)
    assert info is not None and info["source"]
    N = cyc.T - 2
    for s in ("r", "l"):
        sh, hip = q[names.index(f"shoulder_flexion_{s}"), :N], q[names.index(f"hip_flexion_{s}"), :N]
        assert np.degrees(np.ptp(sh)) == pytest.approx(2 * SHOULDER_AMPLITUDE, rel=0.05)
        assert np.corrcoef(sh, hip)[0, 1] < -0.99
    moving = q.copy()
    assert arm_swing(names, moving)[1] is None  # once swinging, left alone
