"""C3D reader on the shared Plug-in-Gait trial (BTKData PiG_Motion-FlatFoot-Full.c3d).

Facts checked against the trial's README (plates, events, subject), against Vicon's own
Plug-in-Gait outputs stored in the same file (joint centres, ground reaction force) and
against ezc3d's independent force-platform module. Variants of the file (other axes and
units, other plate types, missing plates/markers, gaps) are written to a temp dir.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

ezc3d = pytest.importorskip("ezc3d")

from solver.io.c3d import C3DError, fill_gaps, read_c3d, read_c3d_trial  # noqa: E402
from solver.io.c3d.reader import _runs  # noqa: E402

TRIAL = "btk_pig_flatfoot_full/PiG_Motion-FlatFoot-Full.c3d"
MASS, HEIGHT = 47.5, 1.505


@pytest.fixture(scope="module")
def path(shared_data: Path) -> Path:
    p = shared_data / TRIAL
    if not p.is_file():
        pytest.fail(f"missing shared trial {p}")
    return p


@pytest.fixture(scope="module")
def trial(path):
    return read_c3d_trial(path)


@pytest.fixture(scope="module")
def raw(path):
    c = ezc3d.c3d(str(path), extract_forceplat_data=True)
    labels = [s.strip() for s in c["parameters"]["POINT"]["LABELS"]["value"]]
    return c, labels


def _pig(raw, name: str) -> np.ndarray:
    c, labels = raw
    return c["data"]["points"][:3, labels.index(name)] / 1000.0  # (3, T) m, lab = ours here


def _variant(path: Path, out: Path, edit) -> Path:
    c = ezc3d.c3d(str(path))
    edit(c)
    c.write(str(out))
    return out


# --- force plates ----------------------------------------------------------------------


def test_plate_peaks_and_loading_windows_match_the_readme(trial):
    p1, p2 = trial.plates
    assert (p1.type, p2.type) == (2, 2)
    assert p1.peak_vertical == pytest.approx(482.5, abs=1.0)
    assert p2.peak_vertical == pytest.approx(500.8, abs=1.0)
    # README: FP1 loaded by the right foot 1.081-1.674 s, FP2 by the left 1.583-2.189 s
    assert len(p1.periods) == 1 and len(p2.periods) == 1
    (a1, b1, f1), (a2, b2, f2) = p1.periods[0], p2.periods[0]
    assert (f1, f2) == ("right", "left")
    assert a1 == pytest.approx(1.081, abs=0.02) and b1 == pytest.approx(1.674, abs=0.02)
    assert a2 == pytest.approx(1.583, abs=0.02) and b2 == pytest.approx(2.189, abs=0.02)


def test_plate_signals_agree_with_ezc3d_force_platform_module(trial, raw):
    """ezc3d computes force, CoP and Tz in the lab frame on its own (lab = ours here)."""
    c, _ = raw
    for ours, theirs in zip(trial.plates, c["data"]["platform"]):
        ld = ours.loaded
        assert ld.sum() > 500
        np.testing.assert_allclose(ours.force[:, ld], theirs["force"][:, ld], atol=1e-3)
        np.testing.assert_allclose(ours.cop[:2, ld], theirs["center_of_pressure"][:2, ld] / 1000.0, atol=1e-6)
        # the stored wrench is the reaction on the subject (its force points up once in the lab
        # frame), so ezc3d's lab-frame Tz is our free moment about +z
        assert np.all(theirs["force"][2, ld] > 0)
        np.testing.assert_allclose(ours.free_moment[ld], theirs["Tz"][2, ld] / 1000.0, atol=1e-6)


def test_centre_of_pressure_on_the_plate_and_under_the_loaded_foot(trial):
    for sig in trial.plates:
        lo, hi = sig.corners.min(axis=0), sig.corners.max(axis=0)
        # a plate's CoP is poor at low loads: the heel lands on FP1's rear edge (1.08-1.11 s)
        for fz_min, margin in ((20.0, 0.025), (100.0, 0.015), (200.0, 0.002)):
            ok = sig.force[2] > fz_min
            cop = sig.cop[:2, ok]
            assert np.all(cop >= lo[:2, None] - margin) and np.all(cop <= hi[:2, None] + margin)
    m, lm = trial.track.measured, trial.track.landmarks
    for i, s in enumerate("rl"):
        ok = m.force[i, 2] > 100.0
        heel, toe = lm[f"heel_{s}"][:2, ok], lm[f"toe_{s}"][:2, ok]
        cop = m.cop[i, :2, ok].T if m.cop[i, :2, ok].shape[0] != 2 else m.cop[i, :2, ok]
        axis = toe - heel
        along = np.sum((cop - heel) * axis, axis=0) / np.sum(axis * axis, axis=0)
        across = np.abs(axis[0] * (cop - heel)[1] - axis[1] * (cop - heel)[0]) / np.linalg.norm(axis, axis=0)
        assert np.all((along > -0.05) & (along < 1.05)), f"{s}: CoP off the heel-toe line"
        assert np.all(across < 0.05), f"{s}: CoP more than 5 cm beside the foot"
        # rollover: the CoP starts at the heel and ends under the forefoot
        assert along[:3].mean() < 0.35 and along[-3:].mean() > 0.7
        # and it is not under the other foot
        o = "l" if s == "r" else "r"
        mid_other = 0.5 * (lm[f"heel_{o}"][:2, ok] + lm[f"toe_{o}"][:2, ok])
        mid_own = 0.5 * (heel + toe)
        assert np.median(np.linalg.norm(cop - mid_own, axis=0)) < np.median(np.linalg.norm(cop - mid_other, axis=0))


def test_per_foot_grf_matches_vicon_plug_in_gait_output(trial, raw):
    """The file's own RGroundReactionForce/LGroundReactionForce are in N/kg, same axes."""
    m = trial.track.measured
    for i, side in enumerate("RL"):
        vicon = _pig(raw, f"{side}GroundReactionForce") * 1000.0 * MASS  # undo our mm->m in _pig
        ok = (m.force[i, 2] > 50.0) & np.isfinite(vicon).all(axis=0)
        assert ok.sum() > 40
        for k in range(3):
            assert np.corrcoef(vicon[k, ok], m.force[i, k, ok])[0, 1] > 0.999
        err = np.abs(vicon[:, ok] - m.force[i][:, ok])
        assert err.max() < 0.03 * m.force[i, 2].max()


def test_resampling_keeps_the_impulse(trial):
    m = trial.track.measured
    dt = 1.0 / trial.track.source["point_rate"]
    plates = sum(np.trapezoid(s.force, s.times, axis=1) for s in trial.plates)
    feet = m.force.sum(axis=0).sum(axis=1) * dt
    np.testing.assert_allclose(feet, plates, rtol=0.01, atol=0.5)
    # unloaded feet: no force, no CoP, no free moment
    for i in range(2):
        off = m.force[i, 2] == 0
        assert off.any() and np.isnan(m.cop[i][:, off]).all() and np.all(m.free_moment[i, off] == 0)


# --- axes, units, frame ----------------------------------------------------------------


def test_axes_detected_and_recorded(trial):
    tr = trial.track
    np.testing.assert_allclose(tr.frame.R, np.eye(3), atol=1e-12)
    assert tr.frame.unit_m == 0.001
    np.testing.assert_allclose(tr.frame.offset, 0.0, atol=1e-9)  # plate surfaces at lab z = 0
    lm = tr.landmarks
    assert lm["pelvis"][0, -1] - lm["pelvis"][0, 0] > 2.5  # walks ~3.6 m along +x
    assert np.all(lm["pelvis"][2] > 0.6) and np.all(lm["head_top"][2] > lm["pelvis"][2])
    for j in ("hip", "knee", "ankle", "heel", "toe"):
        assert np.median(lm[f"{j}_l"][1] - lm[f"{j}_r"][1]) > 0.05, j
    # plate forces push up, the trial's mean fore-aft force is small
    fz = tr.measured.force[:, 2].sum(axis=0)
    assert fz.max() > 0 and fz.min() >= 0


def _rotated_lab(c) -> None:
    """The same trial in a Y-up lab, walking along -Z, metres, floor 0.25 m above the origin."""
    A = np.array([[0.0, -1.0, 0.0], [0.0, 0.0, 1.0], [-1.0, 0.0, 0.0]])  # ours -> new lab
    lift = np.array([0.0, 0.25, 0.0])
    pts = c["data"]["points"]
    pts[:3] = np.einsum("ij,jpt->ipt", A, pts[:3]) / 1000.0 + lift[:, None, None]
    c["data"]["points"] = pts
    c["parameters"]["POINT"]["UNITS"]["value"] = ["m"]
    fp = c["parameters"]["FORCE_PLATFORM"]
    corners = np.asarray(fp["CORNERS"]["value"], dtype=float)
    fp["CORNERS"]["value"] = np.einsum("ij,jcn->icn", A, corners) / 1000.0 + lift[:, None, None]
    fp["ORIGIN"]["value"] = np.asarray(fp["ORIGIN"]["value"], dtype=float) / 1000.0
    for k in ("X_SCREEN", "Y_SCREEN"):
        c["parameters"]["POINT"].pop(k, None)


def test_other_axes_units_and_floor_give_the_same_trial(path, trial, tmp_path, raw):
    alt = read_c3d_trial(_variant(path, tmp_path / "ylab.c3d", _rotated_lab))
    a, b = trial.track, alt.track
    assert b.frame.unit_m == 1.0
    assert "-Z forward" in b.frame.axes and "+Y up" in b.frame.axes
    for name in a.landmarks:
        np.testing.assert_allclose(b.landmarks[name], a.landmarks[name], atol=2e-5, err_msg=name)
    np.testing.assert_allclose(b.measured.force, a.measured.force, atol=1e-3)
    np.testing.assert_allclose(b.measured.cop, a.measured.cop, atol=1e-5)
    np.testing.assert_allclose(b.measured.free_moment, a.measured.free_moment, atol=1e-4)
    assert np.array_equal(b.measured.valid, a.measured.valid)
    assert np.array_equal(b.contacts, a.contacts)
    # the ground frame maps our landmarks back onto the file's coordinates
    c = ezc3d.c3d(str(tmp_path / "ylab.c3d"))
    labels = [s.strip() for s in c["parameters"]["POINT"]["LABELS"]["value"]]
    fep = c["data"]["points"][:3, labels.index("RFEP")]  # Vicon's right hip centre, new lab, m
    back = b.frame.point_to_input(b.landmarks["hip_r"].T, b.times).T
    assert np.nanmax(np.linalg.norm(back - fep, axis=0)) < 3e-3


@pytest.mark.parametrize("zero", [None, (1, 10)])
def test_moment_units_and_baseline_offsets_are_handled(path, trial, tmp_path, zero):
    def edit(c):
        if zero is not None:
            c["parameters"]["FORCE_PLATFORM"]["ZERO"]["value"] = np.array(zero)
        a = c["data"]["analogs"]
        for n in range(2):
            a[0, 6 * n + 3: 6 * n + 6] /= 1000.0  # N·mm -> N·m
            a[0, 6 * n + 2] += 35.0  # an unloaded plate reading 35 N
            a[0, 6 * n + 3] += 4.0  # and 4 N·m
        c["data"]["analogs"] = a
        units = list(c["parameters"]["ANALOG"]["UNITS"]["value"])
        for n in range(2):
            units[6 * n + 3: 6 * n + 6] = ["N.m"] * 3
        c["parameters"]["ANALOG"]["UNITS"]["value"] = units

    alt = read_c3d_trial(_variant(path, tmp_path / "nm.c3d", edit))
    for p0, p1 in zip(trial.plates, alt.plates):
        if zero:
            assert p1.baseline == "ZERO frames 1-10"
        else:
            assert p1.baseline.endswith("unloaded samples"), p1.baseline
        assert np.array_equal(p0.loaded, p1.loaded)
        np.testing.assert_allclose(p1.force, p0.force, atol=1e-3)
        np.testing.assert_allclose(p1.cop[:, p0.loaded], p0.cop[:, p0.loaded], atol=1e-5)


def test_type4_plates_with_calibration_matrix(path, trial, tmp_path):
    rng = np.random.default_rng(7)
    cals = np.zeros((6, 6, 2))

    def edit(c):
        a = c["data"]["analogs"]
        for n in range(2):
            C = np.diag([200.0, 210.0, 800.0, 9.0e4, 9.5e4, 4.0e4]) + rng.normal(0.0, 5.0, (6, 6))
            cals[:, :, n] = C
            ch = np.arange(6) + 6 * n
            a[0, ch] = np.linalg.solve(C, a[0, ch])  # the plate's amplifier volts
        c["data"]["analogs"] = a
        c["parameters"]["FORCE_PLATFORM"]["TYPE"]["value"] = np.array([4, 4])
        c["parameters"]["FORCE_PLATFORM"]["CAL_MATRIX"]["value"] = cals
        units = list(c["parameters"]["ANALOG"]["UNITS"]["value"])
        units[:12] = ["V"] * 12
        c["parameters"]["ANALOG"]["UNITS"]["value"] = units

    out = _variant(path, tmp_path / "type4.c3d", edit)
    alt = read_c3d_trial(out)
    theirs = ezc3d.c3d(str(out), extract_forceplat_data=True)["data"]["platform"]
    for p0, p4, ez in zip(trial.plates, alt.plates, theirs):
        assert p4.type == 4
        np.testing.assert_allclose(p4.force, p0.force, atol=1e-3)
        np.testing.assert_allclose(p4.force[:, p4.loaded], ez["force"][:, p4.loaded], atol=1e-3)
        np.testing.assert_allclose(p4.cop[:, p0.loaded], p0.cop[:, p0.loaded], atol=1e-5)
        np.testing.assert_allclose(p4.free_moment, p0.free_moment, atol=1e-3)


def test_type3_kistler_plates_agree_with_ezc3d(path, trial, tmp_path):
    """8 channels (fx12 fx34 fy14 fy23 fz1..fz4) synthesised from the measured wrench."""
    a_x, b_y, az0 = 0.120, 0.200, -0.045  # sensor offsets (m); az0 < 0: Kistler's convention

    def edit(c):
        an = c["data"]["analogs"]
        fp = c["parameters"]["FORCE_PLATFORM"]
        chans = np.zeros((8, 2), dtype=int)
        pins = iter(range(12, 28))
        for n in range(2):
            F = an[0, 6 * n: 6 * n + 3]
            M = an[0, 6 * n + 3: 6 * n + 6] / 1000.0  # about the surface centre (here ORIGIN is 16-20 mm), N·m
            M = M - np.cross(np.array([0, 0, -np.asarray(fp["ORIGIN"]["value"])[2, n] / 1000.0]), F, axis=0)
            # moments about the sensor plane centre, plate z down: surface at z = az0
            Ms = M + np.cross(np.array([0.0, 0.0, az0]), F, axis=0)
            # least-norm split of (F, Ms) onto the 8 Kistler channels
            K = np.zeros((6, 8))
            K[0, [0, 1]] = 1
            K[1, [2, 3]] = 1
            K[2, 4:] = 1
            K[3, 4:] = b_y * np.array([1, 1, -1, -1])
            K[4, 4:] = a_x * np.array([-1, 1, 1, -1])
            K[5, :4] = np.array([-b_y, b_y, a_x, -a_x])
            ch8 = np.linalg.pinv(K) @ np.vstack([F, Ms])
            idx = [6 * n + k for k in range(6)] + [next(pins), next(pins)]
            an[0, idx] = ch8
            chans[:, n] = np.array(idx) + 1
        c["data"]["analogs"] = an
        fp["TYPE"]["value"] = np.array([3, 3])
        fp["CHANNEL"]["value"] = chans
        fp["ORIGIN"]["value"] = np.array([[a_x, a_x], [b_y, b_y], [az0, az0]]) * 1000.0
        units = list(c["parameters"]["ANALOG"]["UNITS"]["value"])
        for n in range(2):
            for k in chans[:, n]:
                units[k - 1] = "N"
        c["parameters"]["ANALOG"]["UNITS"]["value"] = units

    out = _variant(path, tmp_path / "type3.c3d", edit)
    alt = read_c3d_trial(out)
    theirs = ezc3d.c3d(str(out), extract_forceplat_data=True)["data"]["platform"]
    for p0, p3, ez in zip(trial.plates, alt.plates, theirs):
        assert p3.type == 3
        ld = p0.loaded & p3.loaded
        np.testing.assert_allclose(p3.force, p0.force, atol=1e-2)
        np.testing.assert_allclose(p3.cop[:2, ld], p0.cop[:2, ld], atol=1e-4)
        np.testing.assert_allclose(p3.cop[:2, ld], ez["center_of_pressure"][:2, ld] / 1000.0, atol=1e-4)


def test_type1_plates_force_cop_and_free_moment_channels(path, trial, tmp_path):
    """Type 1 stores Fx Fy Fz, the CoP (mm) and Tz in the plate frame: written from the trial."""

    def edit(c):
        an = c["data"]["analogs"]
        corners = np.asarray(c["parameters"]["FORCE_PLATFORM"]["CORNERS"]["value"], dtype=float) / 1000.0
        for n, sig in enumerate(trial.plates):
            cn = corners[:, :, n].T
            ax = (cn[0] - cn[1]) + (cn[3] - cn[2])
            ay = (cn[0] - cn[3]) + (cn[1] - cn[2])
            az = np.cross(ax, ay)
            ay = np.cross(az, ax)
            Rp = np.stack([v / np.linalg.norm(v) for v in (ax, ay, az)], axis=1)
            ld = sig.loaded
            F = Rp.T @ sig.force  # the file's convention here: reaction on the subject
            cop = np.where(ld, Rp.T @ (np.nan_to_num(sig.cop) - cn.mean(axis=0)[:, None]), 0.0)
            tz = sig.free_moment * Rp[2, 2]
            an[0, 6 * n: 6 * n + 6] = np.vstack([F, cop[:2] * 1000.0, tz * 1000.0])
        c["data"]["analogs"] = an
        c["parameters"]["FORCE_PLATFORM"]["TYPE"]["value"] = np.array([1, 1])
        units = list(c["parameters"]["ANALOG"]["UNITS"]["value"])
        for n in range(2):
            units[6 * n: 6 * n + 6] = ["N", "N", "N", "mm", "mm", "Nmm"]
        c["parameters"]["ANALOG"]["UNITS"]["value"] = units

    out = _variant(path, tmp_path / "type1.c3d", edit)
    alt = read_c3d_trial(out)
    theirs = ezc3d.c3d(str(out), extract_forceplat_data=True)["data"]["platform"]
    for p0, p1, ez in zip(trial.plates, alt.plates, theirs):
        assert p1.type == 1
        ld = p0.loaded & p1.loaded
        np.testing.assert_allclose(p1.force, p0.force, atol=1e-3)
        np.testing.assert_allclose(p1.cop[:, ld], p0.cop[:, ld], atol=1e-5)
        np.testing.assert_allclose(p1.free_moment[ld], p0.free_moment[ld], atol=1e-3)
        np.testing.assert_allclose(p1.cop[:2, ld], ez["center_of_pressure"][:2, ld] / 1000.0, atol=1e-5)
        np.testing.assert_allclose(p1.free_moment[ld], ez["Tz"][2, ld] / 1000.0, atol=1e-3)


def test_one_long_plate_under_both_feet_in_turn(path, trial, tmp_path):
    """FP1 + FP2 written as one 1 m plate: the right then the left stance split by the CoP,
    the double support (both feet on the plate, not separable) excluded from ``valid``."""

    def edit(c):
        fp = c["parameters"]["FORCE_PLATFORM"]
        corners = np.asarray(fp["CORNERS"]["value"], dtype=float)
        big = np.stack([corners[:, 0, 0], corners[:, 1, 1], corners[:, 2, 1], corners[:, 3, 0]], axis=1)
        P = big.mean(axis=1) / 1000.0
        F = sum(sig.force for sig in trial.plates)  # lab = ours here, reaction on the subject
        M = sum(np.cross(np.nan_to_num(sig.cop) - P[:, None], sig.force, axis=0)
                + np.outer([0.0, 0.0, 1.0], sig.free_moment) for sig in trial.plates)
        Rp = np.diag([-1.0, 1.0, -1.0])  # plate axes of both plates: x = -X, y = +Y, z = -Z
        d = np.array([0.0, 0.0, -0.0163])  # surface centre seen from the transducer (plate axes)
        F_loc, M_loc = Rp.T @ F, Rp.T @ M
        M_o = M_loc + np.cross(d, F_loc, axis=0)
        an = c["data"]["analogs"]
        an[0, 0:3], an[0, 3:6] = F_loc, M_o * 1000.0
        c["data"]["analogs"] = an
        fp["USED"]["value"] = np.array([1])
        fp["TYPE"]["value"] = np.array([2])
        fp["CORNERS"]["value"] = big[:, :, None]
        fp["ORIGIN"]["value"] = np.array([[0.0], [0.0], [16.3]])
        fp["CHANNEL"]["value"] = np.asarray(fp["CHANNEL"]["value"])[:, :1]

    alt = read_c3d_trial(_variant(path, tmp_path / "long_plate.c3d", edit))
    (sig,) = alt.plates
    feet = [p[2] for p in sig.periods]
    assert feet == ["right", "left"], sig.periods
    (a0, b0, _), (a1, b1, _) = sig.periods
    assert a0 == pytest.approx(1.081, abs=0.02) and b1 == pytest.approx(2.191, abs=0.02)
    assert 1.58 <= b0 <= 1.70 and a1 == pytest.approx(b0, abs=0.011)
    m, t = alt.track.measured, alt.track.times
    runs = [(t[a], t[b - 1]) for a, b in _runs(m.valid)]
    assert len(runs) == 2, runs
    # from the right heel-off (the heel stands behind the plates' rear edge before: test_valid_window...)
    assert runs[0][0] == pytest.approx(1.39, abs=0.03) and runs[1][1] == pytest.approx(2.08, abs=0.03)
    assert not m.valid[(t > 1.60) & (t < 1.66)].any()  # double support on one plate
    single = m.valid & (t > 1.2) & (t < 1.55)  # right single support: same as with two plates
    np.testing.assert_allclose(m.force[0][:, single], trial.track.measured.force[0][:, single], atol=1e-2)
    np.testing.assert_allclose(m.cop[0][:, single], trial.track.measured.cop[0][:, single], atol=1e-4)


# --- landmarks ---------------------------------------------------------------------------


def test_joint_centres_match_vicon_plug_in_gait(trial, raw):
    """Davis hip, chord knee and ankle centres vs Vicon's FEP/FEO/TIO virtual points."""
    lm = trial.track.landmarks
    for s in "RL":
        for ours, theirs in (("hip", "FEP"), ("knee", "FEO"), ("ankle", "TIO")):
            d = np.linalg.norm(lm[f"{ours}_{s.lower()}"] - _pig(raw, s + theirs), axis=0)
            assert np.nanmax(d) < 0.003, (s, ours, np.nanmax(d))


def test_landmarks_are_anatomically_plausible(trial):
    tr = trial.track
    lm = tr.landmarks
    H = tr.height
    assert tr.has_upper_body
    for s in "rl":
        thigh = np.linalg.norm(lm[f"hip_{s}"] - lm[f"knee_{s}"], axis=0)
        shank = np.linalg.norm(lm[f"knee_{s}"] - lm[f"ankle_{s}"], axis=0)
        foot = np.linalg.norm(lm[f"toe_{s}"] - lm[f"heel_{s}"], axis=0)
        # Winter: thigh and shank 0.245/0.246 H, foot 0.152 H; rigid to a few mm over the trial
        assert 0.21 * H < np.median(thigh) < 0.29 * H and np.std(thigh) < 0.008
        assert 0.21 * H < np.median(shank) < 0.29 * H and np.std(shank) < 0.01
        assert 0.13 * H < np.median(foot) < 0.19 * H and np.std(foot) < 0.01
        # stance: heel and toe tip on the floor (sole level), ankle above it
        assert abs(np.percentile(lm[f"heel_{s}"][2], 5)) < 0.01
        assert 0.03 < np.percentile(lm[f"ankle_{s}"][2], 5) < 0.1
    hip_width = np.median(np.linalg.norm(lm["hip_r"] - lm["hip_l"], axis=0))
    assert 0.06 * H < hip_width < 0.11 * H
    assert np.median(lm["head_top"][2]) == pytest.approx(H, rel=0.04)
    assert np.all(lm["neck"][2] > lm["sternum"][2]) and np.all(lm["lumbar"][2] > lm["pelvis"][2])
    arm = np.linalg.norm(lm["shoulder_r"] - lm["elbow_r"], axis=0)
    assert 0.14 * H < np.median(arm) < 0.23 * H


def test_orientations_are_rotations_consistent_with_landmarks(trial):
    tr = trial.track
    for name, R in tr.orientations.items():
        RtR = np.einsum("jit,jkt->ikt", R, R)
        assert np.allclose(RtR, np.eye(3)[:, :, None], atol=1e-9), name
        assert np.allclose(np.linalg.det(np.moveaxis(R, 2, 0)), 1.0), name
    lm = tr.landmarks
    # thigh z along knee -> hip; foot x forward while walking forward; pelvis y to the left
    z = tr.orientations["thigh_r"][:, 2]
    bone = (lm["hip_r"] - lm["knee_r"]) / np.linalg.norm(lm["hip_r"] - lm["knee_r"], axis=0)
    assert np.min(np.sum(z * bone, axis=0)) > 0.9999
    assert np.median(tr.orientations["pelvis"][1, 1]) > 0.9
    for i, s in enumerate("rl"):
        flat = tr.contacts[2 * i] & tr.contacts[2 * i + 1]  # heel and toe down: foot flat
        f = tr.orientations[f"foot_{s}"][:, 0, flat]
        assert flat.sum() > 30
        assert np.all(np.abs(np.degrees(np.arcsin(f[2]))) < 8.0)  # level (heel, toe tip < 1.5 cm)
        assert np.all(f[0] > np.cos(np.radians(30)))  # forward, with a toe-out angle


# --- contacts and the valid window -------------------------------------------------------


def test_valid_window_and_gait_events(trial):
    tr = trial.track
    t = tr.times
    runs = _runs(tr.measured.valid)
    assert len(runs) == 1, [(t[a], t[b - 1]) for a, b in runs]
    a, b = runs[0]
    # README: complete GRF 1.18-2.10 s by the events; but until its heel rises (1.38 s) the right foot's heel
    # (landmark 4.5 cm behind FP1's rear edge at x = -0.500 m, its load-bearing pad from 2 cm in front of it)
    # stands partly off the plate: the plates do not measure all of that foot's load
    heel = tr.landmarks["heel_r"]
    flat = (t > 1.12) & (t < 1.35)
    assert np.all(heel[0, flat] < -0.53) and np.all(heel[2, flat] < 0.03)
    assert t[a] == pytest.approx(1.39, abs=0.03) and t[b - 1] == pytest.approx(2.10, abs=0.03)
    assert not tr.measured.valid[flat].any()
    ev = tr.source["gait_events"]
    # README: right strikes 1.07, 2.10; right offs 0.65, 1.67, 2.70; left strikes 0.55, 1.58, 2.58;
    # left offs 1.18, 2.19 (the first right strike, at 0.06 s, is too close to the start)
    for got, want in (
        (ev["right"]["foot_strike"], [1.07, 2.10]), (ev["right"]["foot_off"], [0.65, 1.67, 2.70]),
        (ev["left"]["foot_strike"], [0.55, 1.58, 2.58]), (ev["left"]["foot_off"], [1.18, 2.19]),
    ):
        for w in want:
            assert np.min(np.abs(np.asarray(got) - w)) < 0.03, (got, w)
    # within the valid window every loaded foot is measured; double support 1.58-1.67 s
    m = tr.measured
    for i in range(2):
        foot_down = tr.contacts[2 * i] | tr.contacts[2 * i + 1]
        assert np.all(~foot_down[a:b] | (m.force[i, 2, a:b] > 0))
    both = (m.force[0, 2] > 0) & (m.force[1, 2] > 0) & m.valid
    assert t[both][0] == pytest.approx(1.59, abs=0.02) and t[both][-1] == pytest.approx(1.68, abs=0.02)


def test_heel_then_toe_contact_on_the_plates(trial):
    tr = trial.track
    t = tr.times
    heel_r, toe_r = tr.contacts[0], tr.contacts[1]
    # the right stance on FP1: heel first (1.08 s), toe last (1.67 s)
    on = (t > 1.0) & (t < 1.8)
    th, tt = t[on & heel_r], t[on & toe_r]
    assert th[0] == pytest.approx(1.09, abs=0.02) and th[0] < tt[0]
    assert tt[-1] == pytest.approx(1.68, abs=0.02) and th[-1] < tt[-1]
    # no contact flag without the foot being low
    lm = tr.landmarks
    for i, s in enumerate("rl"):
        low = np.minimum(lm[f"heel_{s}"][2], lm[f"toe_{s}"][2])
        assert np.all(low[tr.contacts[2 * i] | tr.contacts[2 * i + 1]] < 0.05)


# --- subject, errors ---------------------------------------------------------------------


def test_subject_mass_and_height_from_the_file(path, trial):
    tr = trial.track
    assert tr.mass == pytest.approx(MASS) and tr.source["mass_from"] == "file"
    assert tr.height == pytest.approx(HEIGHT)
    assert read_c3d(path, mass=50.0).mass == 50.0


def test_mass_from_the_plates_when_the_file_has_none(path, trial, tmp_path):
    """Without PROCESSING:Bodymass the mass is the vertical impulse of one whole stance of each foot (one
    stride holds one stance of each) over the stride time; it is reported even when the file has a mass."""
    m = trial.track.measured
    implied = float(np.mean(m.force[:, 2].sum(axis=0)[m.valid])) / 9.81  # the complete-plates window (~ a stride)
    assert trial.track.source["mass_implied_kg"] == pytest.approx(implied, rel=0.03)
    assert trial.track.mass == MASS  # the file's mass is used, the plates' reported

    def no_mass(c):
        c["parameters"]["PROCESSING"]["Bodymass"]["value"] = np.array([0.0])

    tr = read_c3d(_variant(path, tmp_path / "nomass.c3d", no_mass))
    assert tr.mass == pytest.approx(implied, rel=0.03) and "one stance per foot" in tr.source["mass_from"]

    def no_mass_one_plate(c):
        no_mass(c)
        c["parameters"]["FORCE_PLATFORM"]["USED"]["value"] = np.array([1])

    with pytest.raises(C3DError, match=r"mass unknown.*pass mass=") as e:
        read_c3d(_variant(path, tmp_path / "nomass1.c3d", no_mass_one_plate))
    assert e.value.parameter == "mass"  # front ends name their own control (CLI --mass)


def test_file_without_plates(path, tmp_path):
    def edit(c):
        c["parameters"]["FORCE_PLATFORM"]["USED"]["value"] = np.array([0])

    out = _variant(path, tmp_path / "noplates.c3d", edit)
    with pytest.raises(C3DError, match="no force plates"):
        read_c3d(out)
    tr = read_c3d(out, require_plates=False)  # kinematics alone: markers decide the axes
    assert tr.measured is None and tr.contacts is None
    np.testing.assert_allclose(tr.frame.R, np.eye(3), atol=1e-12)
    assert tr.source["axes"]["vertical_from"] == "pelvis above feet"


def test_missing_required_marker_is_named(path, tmp_path):
    def edit(c):
        labels = list(c["parameters"]["POINT"]["LABELS"]["value"])
        labels[labels.index("LHEE")] = "XHEE"
        c["parameters"]["POINT"]["LABELS"]["value"] = labels

    with pytest.raises(C3DError, match="LHEE"):
        read_c3d(_variant(path, tmp_path / "nolhee.c3d", edit))


def test_subject_prefixes_and_a_missing_trunk_marker(path, trial, tmp_path):
    def edit(c):
        labels = [f"BELT_C:{s.strip()}" for s in c["parameters"]["POINT"]["LABELS"]["value"]]
        labels[labels.index("BELT_C:C7")] = "BELT_C:XC7"
        c["parameters"]["POINT"]["LABELS"]["value"] = labels

    tr = read_c3d(_variant(path, tmp_path / "prefixed.c3d", edit))
    # the trunk is modelled upright (never lumped into the pelvis); head and arms still come from markers
    assert tr.has_upper_body and tr.source["upper_body"]["trunk"].startswith("modelled")
    assert tr.source["upper_body"]["head"] == tr.source["upper_body"]["arm_l"] == "markers"
    assert any("trunk" in n for n in tr.source["notes"])
    for name in ("hip_r", "knee_l", "toe_r", "heel_l", "lumbar", "head_top", "wrist_r"):
        np.testing.assert_allclose(tr.landmarks[name], trial.track.landmarks[name], atol=1e-9)
    np.testing.assert_allclose(tr.landmarks["neck"][:2], tr.landmarks["lumbar"][:2], atol=1e-9)  # upright
    np.testing.assert_array_equal(tr.measured.valid, trial.track.measured.valid)


UPPER_PIG = ("C7", "T10", "CLAV", "STRN", "RBAK", "LFHD", "RFHD", "LBHD", "RBHD", "LSHO", "LELB", "LWRA", "LWRB",
             "LFIN", "RSHO", "RELB", "RWRA", "RWRB", "RFIN")


def lower_body_only(path: Path, out: Path) -> Path:
    """The trial as a Plug-in Gait lower-body set (upper-body marker labels removed)."""
    def edit(c):
        labels = [s.strip() for s in c["parameters"]["POINT"]["LABELS"]["value"]]
        c["parameters"]["POINT"]["LABELS"]["value"] = [f"X{s}" if s in UPPER_PIG else s for s in labels]
    return _variant(path, out, edit)


def test_lower_body_marker_set_models_an_upright_trunk_and_hanging_arms(path, trial, tmp_path):
    tr = read_c3d(lower_body_only(path, tmp_path / "lower.c3d"))
    assert tr.has_upper_body and all(v.startswith("modelled") for v in tr.source["upper_body"].values())
    lm = tr.landmarks
    H = tr.height
    up = lm["neck"] - lm["lumbar"]
    np.testing.assert_allclose(up[:2], 0.0, atol=1e-9)  # vertical, whatever the pelvis does
    np.testing.assert_allclose(up[2], 0.24 * H)
    for s in "rl":  # arms hang below the shoulders
        np.testing.assert_allclose((lm[f"hand_{s}"] - lm[f"shoulder_{s}"])[:2], 0.0, atol=1e-9)
    # the modelled trunk faces the walking direction (+x here) and turns with the hips' heading only slowly
    assert np.all(tr.orientations["thorax"][0, 0] > np.cos(np.radians(15)))
    # the pelvis wobbles (obliquity, rotation): the modelled trunk does not follow it
    roll = np.degrees(np.arcsin(tr.orientations["thorax"][2, 1]))
    assert np.ptp(roll) < 1e-6


def test_missing_landmarks_are_listed_with_how_to_map_them(path, trial, tmp_path):
    def edit(c):
        labels = [s.strip() for s in c["parameters"]["POINT"]["LABELS"]["value"]]
        ren = {"LASI": "AntSupL", "RASI": "AntSupR", "LHEE": "HeelL", "RKNE": "EpiLatR"}
        c["parameters"]["POINT"]["LABELS"]["value"] = [ren.get(x, x) for x in labels]

    out = _variant(path, tmp_path / "renamed.c3d", edit)
    with pytest.raises(C3DError) as e:
        read_c3d(out)
    msg = str(e.value)
    for role in ("LASI", "RASI", "LHEE", "RKNE"):
        assert role in msg
    assert "anterior superior iliac spine" in msg and "ANTSUPL" in msg and "--markers" in msg  # labels upper-cased
    mapping = "LASI=AntSupL,RASI=AntSupR,LHEE=HeelL,RKNE=EpiLatR"
    tr = read_c3d(out, markers=mapping)
    for name in ("hip_r", "knee_r", "heel_l", "toe_l"):
        np.testing.assert_allclose(tr.landmarks[name], trial.track.landmarks[name], atol=1e-9)
    with pytest.raises(C3DError, match="no marker 'NOPE'"):
        read_c3d(out, markers="LASI=Nope")
    with pytest.raises(C3DError, match="unknown role 'LFOO'"):
        read_c3d(out, markers="LFOO=AntSupL")


def test_marker_mapping_forms(tmp_path):
    from solver.io.c3d import parse_mapping

    want = {"LASI": "L_IAS", "RASI": "R_IAS", "SACR": ""}
    assert parse_mapping("LASI=L_IAS, RASI=R_IAS,SACR=") == want
    assert parse_mapping({"lasi": "L_IAS", "RASI": "R_IAS", "SACR": ""}) == want
    txt = tmp_path / "map.txt"
    txt.write_text("# my lab\nLASI = L_IAS\nRASI: R_IAS  # right\nSACR=\n")
    assert parse_mapping(txt) == want
    js = tmp_path / "map.json"
    js.write_text('{"LASI": "L_IAS", "RASI": "R_IAS", "SACR": ""}')
    assert parse_mapping(str(js)) == want
    with pytest.raises(C3DError, match="not ROLE=label"):
        parse_mapping("LASI")
    with pytest.raises(C3DError, match="not found"):
        parse_mapping(tmp_path / "missing.txt")


@pytest.mark.parametrize("labels, name", [
    (["LASI", "RASI", "LPSI", "RPSI", "LTHI", "LKNE", "LTIB", "LANK", "LHEE", "LTOE", "RTHI", "RKNE", "RTIB", "RANK",
      "RHEE", "RTOE"], "Plug-in Gait / Helen Hayes"),
    (["LASI", "RASI", "LPSI", "RPSI", "LKNE", "LKNM", "LANK", "LMED", "LHEE", "LTOE", "LTHAP", "LTHAD", "LTIAP",
      "LTIAD", "LFMH", "LVMH", "RKNE", "RKNM", "RANK", "RMED", "RTHAP", "RTHAD", "RTIAP", "RTIAD"], "CGM 2.x"),
    (["L_IAS", "R_IAS", "L_IPS", "R_IPS", "L_FLE", "L_FME", "L_FAL", "L_TAM", "L_FCC", "L_FM1", "L_FM5", "R_FLE"],
     "IOR / ISB anatomical"),
    (["LTH1", "LTH2", "LTH3", "LTH4", "LSK1", "LSK2", "LSK3", "RTH1", "RTH2", "RTH3", "RSK1", "RSK2"], "clusters"),
    (["M1", "M2", "M3", "M4", "M5", "M6", "M7"], "unknown"),
])
def test_marker_sets_are_detected_from_the_labels(labels, name):
    from solver.io.c3d import detect_marker_set

    assert detect_marker_set(labels)["name"] == name


def test_marker_gaps_short_filled_long_refused(path, trial, tmp_path):
    def gap(frames):
        def edit(c):
            labels = [s.strip() for s in c["parameters"]["POINT"]["LABELS"]["value"]]
            p = c["data"]["points"]
            p[:3, labels.index("LKNE"), frames] = np.nan
            c["data"]["points"] = p
        return edit

    short = read_c3d_trial(_variant(path, tmp_path / "short.c3d", gap(slice(150, 156))))
    d = np.linalg.norm(short.track.landmarks["knee_l"] - trial.track.landmarks["knee_l"], axis=0)
    assert 0 < d.max() < 0.003
    with pytest.raises(C3DError, match=r"LKNE.*gap"):
        read_c3d(_variant(path, tmp_path / "long.c3d", gap(slice(100, 140))))


def test_unknown_units_are_refused(path, tmp_path):
    def edit(c):
        c["parameters"]["POINT"]["UNITS"]["value"] = ["furlong"]

    with pytest.raises(C3DError, match="furlong"):
        read_c3d(_variant(path, tmp_path / "units.c3d", edit))


def test_fill_gaps_reproduces_a_smooth_trajectory():
    t = np.linspace(0, 1, 101)
    x = np.vstack([np.sin(3 * t), t**2, np.cos(2 * t)])
    y = x.copy()
    y[:, 40:47] = np.nan
    y[:, :3] = np.nan
    filled, left = fill_gaps(y, max_gap=10)
    assert left == [(0, 3)]
    assert np.max(np.abs(filled[:, 40:47] - x[:, 40:47])) < 1e-4
    _, left = fill_gaps(y, max_gap=5)
    assert (40, 47) in left


# --- fitting (solver.io.fit) -------------------------------------------------------------


def test_load_c3d_fits_the_capture_character(path):
    from solver.io.c3d import load_c3d

    cap = load_c3d(path)
    assert cap.character.name == "capture-full" and cap.T == 315
    fit = cap.source["fit"]
    assert fit["landmark_error_mm"]["rms"] < 5.0
    assert cap.measured is not None and cap.contacts is not None
    np.testing.assert_array_equal(cap.measured.valid, read_c3d(path).measured.valid)
    assert sum(s.mass for s in cap.character.segments) == pytest.approx(MASS)
    assert cap.frame.unit_m == 0.001
    lower = load_c3d(path, lower_only=True)
    assert lower.character.name == "capture-lower" and lower.source["fit"]["landmark_error_mm"]["rms"] < 5.0


# --- a trial from another lab and marker set: Qualisys, ISB/IOR anatomical names -----------------

QUALISYS = "qualisys_ior_walk/Qualisys.c3d"
T0_QUALISYS = 3.520  # file time of the first frame (README)


@pytest.fixture(scope="module")
def qualisys(shared_data: Path):
    return read_c3d_trial(shared_data / QUALISYS)


def test_qualisys_marker_set_and_landmarks(qualisys):
    tr = qualisys.track
    src = tr.source
    assert src["marker_set"]["name"] == "IOR / ISB anatomical"
    assert src["markers"]["LASI"] == "L_IAS" and src["markers"]["RKNM"] == "R_FME" and src["markers"]["CLAV"] == "SNJ"
    assert tr.has_upper_body and set(src["upper_body"].values()) == {"markers"}
    assert tr.frame.axes == "input +X forward, +Y left, +Z up" and tr.frame.unit_m == 0.001
    lm = tr.landmarks
    c, labels = ezc3d.c3d(str(src["path"])), None
    labels = [s.strip() for s in c["parameters"]["POINT"]["LABELS"]["value"]]

    def mk(name):
        return c["data"]["points"][:3, labels.index(name)] / 1000.0

    # knee and ankle centres: mid-points of the epicondyle and malleolus markers (lab axes = ours here)
    np.testing.assert_allclose(lm["knee_r"], 0.5 * (mk("R_FLE") + mk("R_FME")), atol=1e-9)
    np.testing.assert_allclose(lm["ankle_l"], 0.5 * (mk("L_FAL") + mk("L_TAM")), atol=1e-9)
    np.testing.assert_allclose(lm["elbow_r"], 0.5 * (mk("R_HLE") + mk("R_HME")), atol=1e-9)
    # the hip centres sit medial to and below the greater trochanters (FTC), between the ASIS
    for s, S in (("r", "R"), ("l", "L")):
        d = lm[f"hip_{s}"] - mk(f"{S}_FTC")
        assert 0.0 < np.median(np.abs(d[1])) < 0.12 and np.median(np.abs(d[2])) < 0.05
    L = {seg: float(np.median(np.linalg.norm(lm[a] - lm[b], axis=0)))
         for seg, (a, b) in {"thigh": ("hip_r", "knee_r"), "shank": ("knee_r", "ankle_r"),
                             "foot": ("heel_r", "toe_r")}.items()}
    H = src["height_estimate_m"]
    assert 1.4 < H < 1.9
    assert L["thigh"] == pytest.approx(0.245 * H, rel=0.2) and L["shank"] == pytest.approx(0.246 * H, rel=0.2)
    assert L["foot"] == pytest.approx(0.152 * H, rel=0.2)


def test_qualisys_plates_events_mass_and_schedule(qualisys):
    tr = qualisys.track
    # README: FP1 loaded by the left foot 3.595-4.136 s (peak 808 N), FP2 by the right 4.058-4.638 s (840 N)
    (fp1,), (fp2,) = (p.periods for p in qualisys.plates)
    assert fp1[2] == "left" and fp2[2] == "right"
    assert fp1[0] == pytest.approx(3.595 - T0_QUALISYS, abs=0.005) and fp1[1] == pytest.approx(4.136 - T0_QUALISYS,
                                                                                                 abs=0.005)
    assert fp2[0] == pytest.approx(4.058 - T0_QUALISYS, abs=0.005) and fp2[1] == pytest.approx(4.638 - T0_QUALISYS,
                                                                                                 abs=0.02)
    assert [round(p.peak_vertical) for p in qualisys.plates] == [808, 840]
    # the file's EVENT group: LHS 3.590, RTO 3.685, RHS 4.050, LTO 4.160, LHS 4.535, RTO 4.650, RHS 5.030 (the
    # trial ends at 5.215 s); every event is found, those near the trial's ends too (LHS 3.590: 14 frames in)
    ev = tr.source["gait_events"]
    for got, want in ((ev["left"]["foot_strike"], [3.590, 4.535]), (ev["right"]["foot_strike"], [4.050, 5.030]),
                      (ev["right"]["foot_off"], [3.685, 4.650]), (ev["left"]["foot_off"], [4.160])):
        for w in want:
            assert np.min(np.abs(np.asarray(got) - (w - T0_QUALISYS))) < 0.03, (got, w)
    # no mass in the file: one whole stance of each foot over the stride time (README: ~66 kg)
    assert "one stance per foot" in tr.source["mass_from"] and tr.mass == pytest.approx(66.0, rel=0.04)
    # a walk has no flight: every frame has a foot down; double support on both plates 4.05-4.16 s
    feet = np.stack([tr.contacts[0] | tr.contacts[1], tr.contacts[2] | tr.contacts[3]])
    assert feet.any(axis=0).all()
    both = feet.all(axis=0) & tr.measured.valid
    t = tr.times + T0_QUALISYS
    assert t[both][0] == pytest.approx(4.058, abs=0.015) and t[both][-1] == pytest.approx(4.136, abs=0.015)
    # complete plates from the right foot-off (3.685) to the next left strike off the plates (4.535)
    v = np.flatnonzero(tr.measured.valid)
    assert t[v[0]] == pytest.approx(3.69, abs=0.02) and t[v[-1]] == pytest.approx(4.535, abs=0.02)
    assert np.all(np.diff(v) == 1)


def test_gait_events_near_the_trial_ends_are_completed():
    """Zeni's extrema a few frames from the trial's ends fail find_peaks' (one-sided) prominence test;
    the strikes and offs must alternate, so the missing ones are the extrema of their own signal there."""
    from solver.io.c3d.events import _complete_events, _extrema

    fps, T = 100.0, 171  # 1.7 s of a 1.0 s stride: strikes at 0.08 and 1.08 s, offs at 0.64 and 1.64 s
    t = np.arange(T) / fps
    heel = 0.4 * np.cos(2 * np.pi * (t - 0.08))  # heel farthest ahead of the pelvis at the strikes
    fore = -0.4 * np.cos(2 * np.pi * (t - 0.64))  # forefoot farthest behind the pelvis at the offs
    hs, to = _extrema(heel, t, fps, True), _extrema(fore, t, fps, False)
    assert len(hs) + len(to) < 4  # the ones near the ends are missed
    hs, to = _complete_events(hs, to, heel, fore, t)
    np.testing.assert_allclose(hs, [0.08, 1.08], atol=0.002)
    np.testing.assert_allclose(to, [0.64, 1.64], atol=0.002)
    # a trial that ends (or starts) in the middle of a monotone stretch gets no invented event
    hs2, to2 = _complete_events(np.array([0.08]), np.array([0.64]), heel[:100], fore[:100], t[:100])
    assert list(hs2) == [0.08] and list(to2) == [0.64]


def test_a_foot_down_without_events_is_a_stance(trial, tmp_path, path):
    """The independent check of the schedule: frames where a foot is low and still are in stance even
    when no gait event bounds them (here: the events of the last right stance are lost)."""
    from solver.io.c3d import events

    lm = trial.track.landmarks
    down = events._foot_down(lm, "r", 100.0)
    stance = trial.track.contacts[0] | trial.track.contacts[1]
    # on the real trial the events cover every foot-down run (a frame or two at the edges aside)
    assert all(b - a < 5 for a, b in _runs(down & ~stance))
    kin = events._stance_from_events(np.array([1.081]), np.array([0.667, 1.686]), trial.track.times,
                                     np.minimum(lm["heel_r"][2], lm["mtp_r"][2]))
    assert not kin[trial.track.times > 2.1].any()  # without the strike at 2.09 s the last stances vanish ...
    orig = events._zeni_events

    def lose_late_right_events(lm_, s, fwd, times, fps):
        hs, to = orig(lm_, s, fwd, times, fps)
        return (hs[hs < 2.0], to[to < 2.0]) if s == "r" else (hs, to)

    events._zeni_events = lose_late_right_events
    try:
        tr = read_c3d(path)
    finally:
        events._zeni_events = orig
    c = tr.contacts[0] | tr.contacts[1]
    late = tr.times > 2.3  # ... but the foot-down check keeps the right stance of 2.10-2.70 s
    assert c[late & down].all() and (np.stack([c, tr.contacts[2] | tr.contacts[3]]).any(axis=0)).all()


@pytest.mark.parametrize("sacral", ["VSAC", "SACR", "V_SAC"])
def test_a_sacral_marker_stands_for_the_psis_pair(path, trial, tmp_path, sacral):
    """Helen Hayes labs name the sacral marker VSAC (Vicon's V-prefixed virtual markers), Plug-in
    Gait SACR: a file whose PSIS pair is replaced by one sacral marker at their mid-point loads,
    with the same pelvis (hip centres, pelvis frame) as the PSIS pair gives."""
    def edit(c):
        labels = [s.strip() for s in c["parameters"]["POINT"]["LABELS"]["value"]]
        r, l_ = labels.index("RPSI"), labels.index("LPSI")
        pts = c["data"]["points"]
        pts[:3, r] = 0.5 * (pts[:3, r] + pts[:3, l_])
        c["data"]["points"] = pts
        labels[r], labels[l_] = sacral, "XPSI"  # the left spine's label is one no role knows
        c["parameters"]["POINT"]["LABELS"]["value"] = labels

    alt = read_c3d_trial(_variant(path, tmp_path / f"{sacral}.c3d", edit)).track
    assert alt.source["markers"]["SACR"] == sacral and "RPSI" not in alt.source["markers"]
    for name in ("pelvis", "hip_r", "hip_l"):
        assert np.max(np.abs(alt.landmarks[name] - trial.track.landmarks[name])) < 1e-6, name
    assert np.max(np.abs(alt.orientations["pelvis"] - trial.track.orientations["pelvis"])) < 1e-6
