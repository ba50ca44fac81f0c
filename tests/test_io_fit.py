"""fit_track: capture skeleton from a SkeletonTrack (known answers, real DeepMimic data, errors)."""

import math

import numpy as np
import pytest

from solver import spatial as sp
from solver.character import capture_full
from solver.io.deepmimic import deepmimic_track
from solver.io.fit import FitError, decompose_hinges, fit_track
from solver.io.track import LOWER_LANDMARKS, SkeletonTrack
from solver.kinematics import contact_points, points_world, segment_frames

H, M = 1.75, 70.0


def _synthetic(T: int = 40, seed: int = 0):
    """A known capture_full motion and the landmarks/orientations it produces."""
    ch = capture_full(H, M)
    t = np.arange(T) / 60.0
    rng = np.random.default_rng(seed)
    q = np.zeros((ch.n, T))
    for i, nm in enumerate(ch.coordinate_names):
        if nm == "root_tx":
            q[i] = 1.3 * t
        elif nm == "root_tz":
            q[i] = 0.93
        elif nm.startswith(("thorax", "neck", "lumbar", "clavicle")):
            q[i] = 0.02 * np.sin(2 * np.pi * t + i)  # a stiff trunk (the thorax joint is not observed)
        elif ch.dof_kinds[i] == "hinge":
            q[i] = 0.3 * rng.standard_normal() * np.sin(2 * np.pi * t + rng.uniform(0, 6)) + 0.1 * rng.standard_normal()
    seg = ch.segment
    fl, ah = 0.152 * H, 0.039 * H
    pts = {"pelvis": ("pelvis", [0, 0, 0]), "lumbar": ("abdomen", [0, 0, 0]), "neck": ("head", [0, 0, 0]),
           "head_top": ("head", seg("head").marker), "sternum": ("thorax", [0.08, 0, 0.1])}
    for s in "rl":
        pts.update({
            f"hip_{s}": (f"thigh_{s}", [0, 0, 0]), f"knee_{s}": (f"shank_{s}", [0, 0, 0]),
            f"ankle_{s}": (f"foot_{s}", [0, 0, 0]), f"heel_{s}": (f"foot_{s}", [-0.2 * fl, 0, -ah]),
            f"mtp_{s}": (f"toes_{s}", [0, 0, 0]), f"toe_{s}": (f"toes_{s}", seg(f"toes_{s}").marker),
            f"shoulder_{s}": (f"upper_arm_{s}", [0, 0, 0]), f"elbow_{s}": (f"forearm_{s}", [0, 0, 0]),
            f"wrist_{s}": (f"hand_{s}", [0, 0, 0]), f"hand_{s}": (f"hand_{s}", seg(f"hand_{s}").marker),
        })
    P = points_world(ch, q, [(a, np.asarray(b, float)) for a, b in pts.values()])
    lm = {n: P[i] for i, n in enumerate(pts)}
    R, _ = segment_frames(ch, q)
    ori = {s.name: R[i] for i, s in enumerate(ch.segments)}
    return ch, t, q, lm, ori


@pytest.fixture(scope="module")
def synthetic():
    return _synthetic()


def test_known_skeleton_and_motion_are_recovered(synthetic):
    ch, t, q, lm, ori = synthetic
    cap = fit_track(SkeletonTrack(times=t, landmarks=lm, orientations=ori, mass=M, source={"format": "synthetic"}))
    fit = cap.source["fit"]
    got = cap.character
    assert got.coordinate_names == ch.coordinate_names  # canonical topology and names
    for s in ("thigh_r", "shank_l", "upper_arm_r", "forearm_l", "hand_r"):
        assert got.segment(s).length == pytest.approx(ch.segment(s).length, abs=1e-6)
    assert got.segment("thigh_l").offset == pytest.approx(ch.segment("thigh_l").offset, abs=1e-6)
    assert got.total_mass == pytest.approx(M)
    assert fit["masses_from"] == "Winter table"
    assert got.segment("thigh_r").mass == pytest.approx(0.100 * M)
    assert fit["landmark_error_mm"]["mean"] < 1.0 and fit["landmark_error_mm"]["max"] < 5.0
    legs = [i for i, n in enumerate(ch.coordinate_names) if n.startswith(("hip_", "knee_angle", "ankle_angle"))]
    assert np.degrees(np.abs(cap.q[legs] - q[legs]).max()) < 1.0
    assert np.abs(cap.q[:3] - q[:3]).max() < 2e-3
    assert np.array_equal(cap.times, t)


def test_landmarks_only_fit_stays_close(synthetic):
    ch, t, q, lm, _ = synthetic
    cap = fit_track(SkeletonTrack(times=t, landmarks=lm, mass=M))
    fit = cap.source["fit"]
    assert fit["orientation_error_deg"] == {}
    assert fit["landmark_error_mm"]["mean"] < 3.0
    assert set(fit["frames_from"].values()) == {"landmarks"}
    # without orientations the knee's 3 hinges are not separable, but the observed included
    # angle thigh/shank is what the landmarks say
    pts = points_world(cap.character, cap.q, [("thigh_r", [0, 0, 0]), ("shank_r", [0, 0, 0]),
                                               ("foot_r", [0, 0, 0])])

    def included(h, k, a):
        u, v = h - k, a - k
        return np.degrees(np.arccos(np.sum(u * v, 0) / np.linalg.norm(u, axis=0) / np.linalg.norm(v, axis=0)))

    assert np.abs(included(*pts) - included(lm["hip_r"], lm["knee_r"], lm["ankle_r"])).max() < 1.0


def test_lower_only_lumps_the_upper_body_into_the_pelvis(synthetic):
    _, t, q, lm, ori = synthetic
    full = fit_track(SkeletonTrack(times=t, landmarks=lm, orientations=ori, mass=M))
    low = fit_track(SkeletonTrack(times=t, landmarks=lm, orientations=ori, mass=M), lower_only=True)
    assert low.character.n == 30 and low.character.name == "capture-lower"
    assert low.character.total_mass == pytest.approx(M)
    assert low.character.segment("pelvis").mass == pytest.approx(M - sum(
        s.mass for s in full.character.segments if s.name.startswith(("thigh", "shank", "foot", "toes"))))
    # the lumped pelvis' centre of mass lies above the hips (head, arms, trunk)
    assert low.character.segment("pelvis").com[2] > 0.15
    legs_only = {k: v for k, v in lm.items() if k in LOWER_LANDMARKS}
    auto = fit_track(SkeletonTrack(times=t, landmarks=legs_only, mass=M))
    assert auto.character.name == "capture-lower"
    assert auto.source["fit"]["landmark_error_mm"]["mean"] < 2.0


def test_feet_boxes_and_contact_points_follow_the_landmarks(synthetic):
    _, t, _, lm, ori = synthetic
    cap = fit_track(SkeletonTrack(times=t, landmarks=lm, orientations=ori, mass=M))
    ch = cap.character
    for side in ("right", "left"):
        box = ch.foot(side)
        s = side[0]
        heel = ch.contacts[[c.name for c in ch.contacts].index(f"heel_{s}")]
        toe = ch.contacts[[c.name for c in ch.contacts].index(f"toe_{s}")]
        lo, hi = box.center - box.half, box.center + box.half
        # contact points 1 cm inside the box, on the sole side
        assert heel.position[0] == pytest.approx(lo[0] + 0.01) and toe.position[0] == pytest.approx(hi[0] - 0.01)
        assert heel.position[2] == pytest.approx(lo[2] + 0.01) and toe.position[2] == pytest.approx(lo[2] + 0.01)
        assert 2 * box.half[1] == pytest.approx(0.055 * cap.source["fit"]["height_m"])
        # the box is the foot: heel -> toe tip
        assert 2 * box.half[0] == pytest.approx(cap.source["fit"]["feet"][side]["length_m"])
        assert 0.2 < 2 * box.half[0] < 0.35
    cp = contact_points(ch, cap.q)
    heel_lm = np.stack([lm["heel_r"], lm["heel_l"]])
    assert np.abs(cp[[0, 2], 0] - heel_lm[:, 0] - 0.0).max() < 0.02  # heel point ~ heel landmark (+1 cm inset)


@pytest.mark.parametrize("axes", [
    [(0, -1, 0), (1, 0, 0), (0, 0, 1)],  # right hip: flexion, adduction, rotation
    [(0, -1, 0), (-1, 0, 0), (0, 0, -1)],  # left hip (mirrored)
    [(0, 0, 1), (0, 1, 0), (1, 0, 0)],  # root z-y-x
    [(1, 0, 0), (0, 0, -1), (0, -1, 0)],  # clavicle-like, det = -1
])
def test_decompose_hinges_inverts_the_hinge_sequence(axes):
    rng = np.random.default_rng(1)
    ang = rng.uniform(-1.2, 1.2, (3, 50))
    R = np.stack([
        sp.rotation_about(axes[0], a) @ sp.rotation_about(axes[1], b) @ sp.rotation_about(axes[2], c)
        for a, b, c in ang.T
    ], axis=-1)
    got = decompose_hinges(R, [np.array(a, float) for a in axes])
    assert np.allclose(got, ang, atol=1e-9)
    assert decompose_hinges(np.eye(3), [np.array([1.0, 0, 0]), np.array([1.0, 0, 0]), np.array([0, 0, 1.0])]) is None


def test_gaps_are_tolerated_and_limits_widened(synthetic):
    ch, t, q, lm, ori = synthetic
    lm = dict(lm)
    gap = lm["knee_r"].copy()
    gap[:, 10:15] = np.nan
    lm["knee_r"] = gap
    cap = fit_track(SkeletonTrack(times=t, landmarks=lm, orientations=ori, mass=M))
    assert np.all(np.isfinite(cap.q))
    assert cap.source["fit"]["per_landmark_mm"]["knee_r"]["max"] < 5.0
    # data beyond the canonical limits are kept, and the limits widened to them
    for k, (lo, hi) in cap.source["fit"]["widened_limits"].items():
        i = cap.character.index(k)
        assert math.radians(lo) <= cap.q[i].min() + 1e-9 and cap.q[i].max() - 1e-9 <= math.radians(hi)
    assert np.all(cap.q >= cap.character.lower[:, None] - 1e-9) and np.all(cap.q <= cap.character.upper[:, None] + 1e-9)


def test_real_deepmimic_track_fits_exactly(shared_data):
    d = shared_data / "deepmimic_humanoid3d_walk"
    track = deepmimic_track(d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt")
    cap = fit_track(track)
    fit = cap.source["fit"]
    assert cap.character.total_mass == pytest.approx(45.0)
    assert fit["masses_from"] == "segment_masses"
    assert fit["landmark_error_mm"]["max"] < 1.0  # same topology: the fit is exact
    assert max(v["max"] for v in fit["orientation_error_deg"].values()) < 0.5
    assert fit["ik_ms_per_frame"] < 50.0  # a few ms on this machine; loose bound for a shared CPU


def _bad(track_kwargs, synthetic):
    _, t, _, lm, _ = synthetic
    kw = {"times": t, "landmarks": {k: v for k, v in lm.items() if k in LOWER_LANDMARKS}, "mass": M}
    kw.update(track_kwargs)
    return SkeletonTrack(**kw)


def test_bad_tracks_are_refused_with_clear_messages(synthetic):
    _, t, _, lm, ori = synthetic
    with pytest.raises(FitError, match="mass unknown"):
        fit_track(_bad({"mass": None}, synthetic))
    with pytest.raises(FitError, match="positive number of kg"):
        fit_track(_bad({"mass": -3.0}, synthetic))
    low = {k: v for k, v in lm.items() if k in LOWER_LANDMARKS}
    nan = dict(low)
    nan["knee_l"] = np.full_like(low["knee_l"], np.nan)
    with pytest.raises(FitError, match="'knee_l' is missing"):
        fit_track(_bad({"landmarks": nan}, synthetic))
    with pytest.raises(FitError, match="lower_only=False needs the upper-body landmarks"):
        fit_track(_bad({}, synthetic), lower_only=False)
    with pytest.raises(FitError, match="unknown segments"):
        fit_track(_bad({"segment_masses": {"tail": 1.0}}, synthetic))
    bent = {"thigh_r": 1.5 * ori["thigh_r"]}
    with pytest.raises(FitError, match="not a rotation"):
        fit_track(_bad({"orientations": bent}, synthetic))
    with pytest.raises(FitError, match="unknown segments"):
        fit_track(_bad({"orientations": {"wing": ori["thigh_r"]}}, synthetic))
    with pytest.raises(FitError, match="increase strictly"):
        fit_track(_bad({"times": t[::-1].copy()}, synthetic))
    cm = {k: 100 * v for k, v in low.items()}
    with pytest.raises(FitError, match=r"measure .* m tall: not a"):
        fit_track(_bad({"landmarks": cm}, synthetic))
