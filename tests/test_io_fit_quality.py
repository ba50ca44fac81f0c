"""A fit you can trust: marker RMS, anatomy and the verdict on every shipped C3D trial, the other
labs' trials (fitted or refused), and broken marker mappings refused naming the markers."""

import math
from pathlib import Path

import numpy as np
import pytest

from solver.io import load_trial
from solver.io.c3d import C3DError, load_c3d
from solver.io.fit import PoorFitError
from solver.io.fit_quality import (
    FIT_LIMIT_MM,
    FOOT_HEADING_LIMIT_DEG,
    KNEE_ADDUCTION_RANGE_LIMIT_DEG,
    anatomy,
    marker_figures,
    verdict,
)
from solver.io.track import TrackMarker
from solver.kinematics import points_world

#: folder/file -> (marker set detected, largest marker RMS measured (mm) with a margin)
FITTED = {
    "btk_pig_flatfoot_full/PiG_Motion-FlatFoot-Full.c3d": ("Plug-in Gait / Helen Hayes", 6.0),
    "qualisys_ior_walk/Qualisys.c3d": ("IOR / ISB anatomical", 5.0),
    "c3d_motion_analysis_helen_hayes/Gait.c3d": ("Plug-in Gait / Helen Hayes", 5.0),
    "c3d_opensim_walking5/walking5.c3d": ("Clusters + anatomical (OpenSim / Stanford)", 9.0),
}
_CACHE: dict = {}


def _where(request, name) -> Path:
    """The folder holding ``name``: the repository's data/, else the other labs' (tests/conftest.py:
    skipped when ``$MOTIONX_OTHER_LABS_DATA`` is not set)."""
    shared = request.getfixturevalue("shared_data")
    if (shared / name).is_file():
        return shared
    return request.getfixturevalue("other_labs_data")


def _capture(request, name):
    if name not in _CACHE:
        _CACHE[name] = load_c3d(_where(request, name) / name)
    return _CACHE[name]


@pytest.mark.parametrize("name", sorted(FITTED))
def test_c3d_trials_fit_within_the_marker_noise_with_a_plausible_anatomy(request, name):
    cap = _capture(request, name)
    fit = cap.source["fit"]
    marker_set, bound = FITTED[name]
    assert cap.source["marker_set"]["name"] == marker_set
    v = fit["verdict"]
    assert v["ok"] and v["problems"] == [] and v["limit_mm"] == FIT_LIMIT_MM == 20.0
    assert v["marker_rms_mm"] == fit["marker_rms_mm"] < bound
    # every marker the reader used is registered on its segment and measured
    used = set(cap.source["markers"].values())
    assert set(fit["per_marker_mm"]) == used and fit["markers_not_fitted"] == {}
    for label, m in fit["per_marker_mm"].items():
        assert m["rms"] <= m["max"] < 60.0, label
        assert m["segment"] in fit["per_segment_mm"]
    assert max(fit["per_segment_mm"].values()) < 15.0
    # the overall RMS is the RMS over the markers (each seen at every kept frame)
    per = np.array([m["rms"] for m in fit["per_marker_mm"].values()])
    assert fit["marker_rms_mm"] == pytest.approx(np.sqrt(np.mean(per**2)), abs=0.05)
    anat = fit["anatomy"]
    for side in ("right", "left"):
        a = anat[side]
        assert a["knee_hyperextension"] < 10 and a["knee_adduction_range"] < 25 and a["hip_rotation_max"] < 45
        assert abs(a["foot_heading"]) < 30 and a["knee_rotation_max"] < 60 and a["ankle_rotation_max"] < 60
    assert anat["both"]["pelvis_from_vertical"] < 25 and anat["path_from"] == "pelvis travel"


def test_medial_markers_under_the_lateral_labels_are_told_apart(request):
    """Motion Analysis' four-character labels: the medial knee and ankle markers are a second
    RKNE/RANK. Read as such, the fit is plausible (it was: knees bending sideways, hips rotated
    60-80°, knees hyperextended 20°)."""
    cap = _capture(request, "c3d_motion_analysis_helen_hayes/Gait.c3d")
    mk = cap.source["markers"]
    for s in "RL":
        assert (mk[f"{s}KNE"], mk[f"{s}KNM"], mk[f"{s}ANK"], mk[f"{s}MED"]) == (
            f"{s}KNE", f"{s}KNE#2", f"{s}ANK", f"{s}ANK#2")
    assert sum("two markers labelled" in n for n in cap.source["notes"]) == 4
    # the knee centre is the mid-point of the epicondyles: the knee joint lies between them
    per = cap.source["fit"]["per_marker_mm"]
    lateral, medial = per["RKNE"]["on_segment_m"][1], per["RKNE#2"]["on_segment_m"][1]  # left (+y) of the thigh
    assert lateral < -0.04 and medial > 0.04 and 0.08 < medial - lateral < 0.15  # knee width + two marker radii


def test_a_forward_thigh_wand_is_not_used_for_the_knee_centre(other_labs_data):
    """Without the medial markers, the Helen Hayes thigh and shank wands stand forward of the leg:
    PiG's chord would put the knee centre behind the knee; the reader shifts medially instead."""
    cap = load_c3d(other_labs_data / "c3d_motion_analysis_helen_hayes/Gait.c3d", markers="RKNM=,LKNM=,RMED=,LMED=")
    notes = [n for n in cap.source["notes"] if "not used for the" in n]
    assert {n.split()[0] for n in notes} >= {"RTHI", "LTHI"}
    v = cap.source["fit"]["verdict"]
    assert v["ok"] and v["marker_rms_mm"] < 8.0


def test_a_trial_without_heel_markers_is_refused_naming_them(other_labs_data):
    with pytest.raises(C3DError) as e:
        load_trial([other_labs_data / "c3d_bts_davis" / "type1.C3D"])
    msg = str(e.value)
    assert "marker set 'Davis (BTS SMART / Elite)'" in msg
    for role in ("RHEE", "LHEE", "RTOE", "LTOE"):
        assert f"{role} (" in msg
    assert "RMALL" in msg and "markers=" in msg


@pytest.mark.parametrize("trial, mapping, named, problem", [
    # the knee markers of the two sides swapped: the thighs cross
    ("btk_pig_flatfoot_full/PiG_Motion-FlatFoot-Full.c3d", "LKNE=RKNE,RKNE=LKNE", ("RKNE=LKNE", "LKNE=RKNE"),
     "knee hyperextended"),
    # lateral and medial malleolus swapped: the shank frame turns 180° about its axis
    ("qualisys_ior_walk/Qualisys.c3d", "RANK=R_TAM,RMED=R_FAL", ("RANK=R_TAM", "RMED=R_FAL"),
     "the foot is turned about the shank"),
    # the two ASIS swapped: the pelvis upside down
    ("btk_pig_flatfoot_full/PiG_Motion-FlatFoot-Full.c3d", "LASI=RASI,RASI=LASI", ("LASI=RASI", "RASI=LASI"),
     "the pelvis stands"),
    # heel and ankle swapped on one side: the feet differ
    ("btk_pig_flatfoot_full/PiG_Motion-FlatFoot-Full.c3d", "LANK=LHEE,LHEE=LANK", ("LHEE=LANK",),
     "left and right foot lengths differ"),
])
def test_a_broken_marker_mapping_is_refused_naming_the_markers(shared_data, trial, mapping, named, problem):
    with pytest.raises(PoorFitError) as e:
        load_trial([shared_data / trial], markers=mapping)
    err = e.value
    assert isinstance(err, ValueError) and err.parameter == "markers"
    msg = str(err)
    assert "the fit cannot be trusted" in msg and problem in msg
    for text in named:
        assert text in msg.split("Markers on what does not fit:")[1]
    assert "accept_poor_fit=True" in msg and msg.endswith("pass markers=...")


def test_a_poor_fit_is_imported_only_when_asked(shared_data):
    path = shared_data / "btk_pig_flatfoot_full/PiG_Motion-FlatFoot-Full.c3d"
    cap = load_c3d(path, markers="LKNE=RKNE,RKNE=LKNE", accept_poor_fit=True)
    v = cap.source["fit"]["verdict"]
    assert not v["ok"] and any("knee hyperextended" in p for p in v["problems"])
    # the RMS limit is the fit's: a good trial is refused under a 1 mm limit, naming its worst markers
    with pytest.raises(PoorFitError, match=r"marker RMS \d+\.\d mm exceeds the 1 mm limit; worst markers T10 \(T10\)"):
        load_c3d(path, fit_tolerance_mm=1.0)
    with pytest.raises(ValueError, match="fit_tolerance_mm must be a positive number"):
        load_c3d(path, fit_tolerance_mm=-5)


def test_marker_figures_measure_what_moves_on_its_segment(request):
    """Markers made from the fitted motion itself: rigid on a segment -> 0 mm; sliding ±10 mm
    sinusoidally along the segment -> its RMS about the median, 10/√2 mm."""
    cap = _capture(request, "qualisys_ior_walk/Qualisys.c3d")
    ch, q = cap.character, cap.q
    T = q.shape[1]
    rigid = points_world(ch, q, [("shank_r", np.array([0.01, -0.05, -0.2]))])[0]
    slide = np.stack([points_world(ch, q[:, t:t + 1], [("thigh_l", np.array(
        [0.02, 0.06, -0.2 + 0.01 * math.sin(2 * math.pi * 3 * t / T)]))])[0][:, 0] for t in range(T)], axis=1)
    fig = marker_figures(ch, q, {"A": TrackMarker("shank_r", rigid, "RTIB"), "B": TrackMarker("thigh_l", slide, "LTHI"),
                                 "C": TrackMarker("wing", rigid)})
    per = fig["per_marker_mm"]
    assert per["A"]["rms"] < 1e-6 and per["A"]["on_segment_m"] == pytest.approx([0.01, -0.05, -0.2], abs=1e-6)
    assert per["B"]["rms"] == pytest.approx(10 / math.sqrt(2), rel=0.02)
    assert per["B"]["max"] == pytest.approx(10, rel=0.02)
    assert fig["per_segment_mm"] == {"shank_r": 0.0, "thigh_l": per["B"]["rms"]}
    assert "C" in fig["markers_not_fitted"]


def test_feet_off_the_path_and_knees_sideways_fail_however_small_the_rms(request):
    cap = _capture(request, "qualisys_ior_walk/Qualisys.c3d")
    ch, q = cap.character, cap.q.copy()
    good = anatomy(ch, q, cap.times)
    q[ch.index("ankle_rotation_r")] += math.radians(90)  # right foot turned 90° inwards
    t = np.arange(q.shape[1])
    q[ch.index("knee_adduction_l")] += math.radians(25) * np.sin(2 * np.pi * t / 100)  # ±25° sideways
    bad = anatomy(ch, q, cap.times)
    assert bad["right"]["foot_heading"] == pytest.approx(good["right"]["foot_heading"] - 90, abs=10)
    assert bad["left"]["knee_adduction_range"] > 2 * 25 - 5
    fig = {"marker_rms_mm": 3.0, "per_marker_mm": {}, "per_segment_mm": {}}
    v = verdict(fig, bad)
    assert not v["ok"] and v["marker_rms_mm"] == 3.0
    assert any("right foot heads" in p and f"limit {FOOT_HEADING_LIMIT_DEG:g}°" in p for p in v["problems"])
    assert any("left knee ab/adduction spans" in p and f"limit {KNEE_ADDUCTION_RANGE_LIMIT_DEG:g}°" in p
               for p in v["problems"])
    assert verdict(fig, good)["ok"]
