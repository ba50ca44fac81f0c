"""The OpenSim export on both shared OpenSim trials: the tutor written on the trial's own model,
checked by OpenSim's own InverseDynamicsTool on the files as written (Hicks et al. 2015).

Runtime (2-core x86_64): 150–250 s with the machine's load — three tutors (~15 s), five exports
(~15 s treadmill, ~35 s overground: OpenSim's inverse kinematics refined frame by frame, ~20 s
on the generic model), OpenSim's inverse dynamics re-run on each folder, the command line on
one motion file and a 5° slope λ optimum; it is the thing being verified.
"""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
import xml.etree.ElementTree as ET
import zipfile
from io import BytesIO
from pathlib import Path

import numpy as np
import pytest
import shared_tutors

from solver.export import export_motion, media_type
from solver.export.opensim import GRF_LABELS, OpenSimExportError, opensim_residuals, source_rig
from solver.io import load_trial
from solver.io.opensim import read_mot
from solver.pipeline import capture_motion, make_tutor

TM = "opensim_gait2354_subject01_treadmill"
LW = "opensim_loadedwalking_subject05"
TRIALS = {
    "treadmill": ([f"{TM}/subject01.osim", f"{TM}/subject01_walk1_ik.mot", f"{TM}/subject01_walk1_grf.mot",
                   f"{TM}/subject01_walk1_grf.xml"], {"belt_speed": "auto"}),
    "overground": ([f"{LW}/Rajagopal2016_subject05_v30516.osim",
                    f"{LW}/loadedwalking_subject05_noload_free_trial03_ik_solution.mot",
                    f"{LW}/loadedwalking_subject05_noload_free_trial03_grf.mot"], {}),
}


@pytest.fixture(scope="module")
def trials(shared_data):
    out = {}
    for name, (files, opts) in TRIALS.items():
        cap = load_trial([shared_data / f for f in files], **opts)
        res = make_tutor(cap, character="halfboy", fps=15.0)
        assert res.status == "succeeded", res.message
        out[name] = (cap, res.motion)
    return out


@pytest.fixture(scope="module")
def exports(trials, tmp_path_factory):
    out = {}
    for name, (_, tutor) in trials.items():
        folder = tmp_path_factory.mktemp(f"opensim_{name}")
        data = export_motion(tutor, "opensim", path=folder)
        out[name] = (folder, data, json.loads((folder / "summary.json").read_text()))
    return out


@pytest.mark.parametrize("name", list(TRIALS))
def test_the_tutor_on_the_trials_model_meets_hicks_by_opensims_own_inverse_dynamics(exports, name):
    folder, _, summary = exports[name]
    # OpenSim's InverseDynamicsTool run again on the folder exactly as written
    res = opensim_residuals(folder)
    assert res["meets_hicks_2015"], res
    assert res["peak_residual_force_vector_N"] <= 0.05 * res["peak_net_external_force_N"]
    assert res["peak_residual_moment_Nm"] <= 0.01 * res["com_height_m"] * res["peak_net_external_force_N"]
    assert set(res["forces"]) == {"pelvis_tx", "pelvis_ty", "pelvis_tz"}
    assert set(res["moments"]) == {"pelvis_tilt", "pelvis_list", "pelvis_rotation"}
    # a walk: the net external force peaks above body weight, the centre of mass ~1 m up
    weight = res["model_mass_kg"] * 9.81
    assert 1.0 * weight < res["peak_net_external_force_N"] < 1.6 * weight
    assert 0.8 < res["com_height_m"] < 1.2
    # the summary reports the same run
    written = summary["residuals"]["as_written"]
    assert written["peak_residual_moment_Nm"] == pytest.approx(res["peak_residual_moment_Nm"], abs=1e-3)
    assert written["time_range_s"] == pytest.approx(res["time_range_s"])


@pytest.mark.parametrize("name", list(TRIALS))
def test_the_ground_reactions_moved_little_to_balance_the_model(exports, trials, name):
    """Before the adjustment the exported kinematics and the tutor's own ground reactions already
    agree in force on the model (Hicks' force criterion); what the adjustment moves is small."""
    _, _, summary = exports[name]
    weight = trials[name][1].character.weight
    before = summary["residuals"]["before_reduction"]
    assert before["peak_residual_force_vector_N"] <= before["force_limit_N"]
    for side, foot in summary["residual_reduction"]["per_foot"].items():
        assert foot["force_change_N"]["max"] < 0.05 * weight, (side, foot)
        assert foot["cop_shift_mm"]["max"] < 50.0, (side, foot)
        assert foot["free_moment_change_Nm"]["max"] < 20.0, (side, foot)
    assert summary["residual_reduction"]["large"] is False
    for side, out in summary["residual_reduction"]["cop_outside_footprint_mm"].items():
        assert out["after"] <= out["before"] + 20.0, (side, out)  # no further out of the foot than the tutor had it
    ik = summary["inverse_kinematics"]
    assert ik["marker_rms_mm"]["mean"] < 3.0 and ik["marker_max_mm"] < 30.0


@pytest.mark.parametrize("name", list(TRIALS))
def test_the_trials_own_ik_and_plates_are_reported_beside_the_export(exports, name):
    _, _, summary = exports[name]
    cap = summary["capture_residuals"]
    assert cap["available"], cap
    written = summary["residuals"]["as_written"]
    # the raw capture does not balance on its own model; the export does
    assert cap["peak_residual_force_vector_N"] > written["peak_residual_force_vector_N"] + 10.0
    assert cap["peak_residual_moment_Nm"] > written["peak_residual_moment_Nm"] + 5.0
    assert cap["lowpass_hz"] == 6.0


@pytest.mark.parametrize("name", list(TRIALS))
def test_the_files_are_the_models_coordinates_and_feet(exports, trials, name):
    folder, data, summary = exports[name]
    rig = source_rig(trials[name][1])
    coords = read_mot(folder / "coordinates.mot")
    assert coords.in_degrees is True
    assert list(coords.labels) == list(rig.model_coordinates)
    assert np.allclose(np.diff(coords.time), 0.01, atol=1e-6)  # 100 Hz, three cycles
    cycle = summary["motion"]["cycle_s"]
    assert coords.time[-1] == pytest.approx(3 * cycle, abs=0.011)
    grf = read_mot(folder / "grf.mot")
    assert grf.labels == GRF_LABELS and grf.time.shape == coords.time.shape
    # OpenSim ground: y up; the feet carry the body weight on average, centres of pressure on the floor
    fy = grf.column("ground_force_r_vy") + grf.column("ground_force_l_vy")
    assert np.mean(fy) == pytest.approx(trials[name][1].character.weight, rel=0.05)
    assert summary["ground_frame"]["ground_normal"] == pytest.approx([0.0, 1.0, 0.0], abs=1e-9)  # level ground
    floor = summary["ground_frame"]["ground_point_m"][1]
    assert np.allclose(grf.column("ground_force_r_py"), floor) and np.allclose(grf.column("ground_force_l_py"), floor)
    assert np.allclose(grf.column("ground_torque_r_x")[grf.column("ground_force_r_vy") > 50], 0.0)
    # ExternalLoads names bodies of the model written beside it, and the GRF file's columns
    model = ET.parse(folder / summary["files"]["model"]).getroot()
    bodies = {b.get("name") for b in model.iter("Body")}
    loads = ET.parse(folder / "external_loads.xml").getroot()
    applied = [ef.findtext("applied_to_body") for ef in loads.iter("ExternalForce")]
    assert applied == ["calcn_r", "calcn_l"] and set(applied) <= bodies
    assert loads.findtext(".//datafile") == "grf.mot"
    for ef in loads.iter("ExternalForce"):
        assert ef.findtext("force_identifier") + "x" in grf.labels
        assert ef.findtext("point_identifier") + "x" in grf.labels
        assert ef.findtext("torque_identifier") + "x" in grf.labels
    # the zip holds the folder
    assert media_type("opensim") == "application/zip"
    files = {summary["files"]["model"], "coordinates.mot", "grf.mot", "external_loads.xml", "setup_id.xml",
             "summary.json", "README.md"}
    with zipfile.ZipFile(BytesIO(data)) as z:
        assert set(z.namelist()) == files
    assert files <= {p.name for p in folder.iterdir()}


def test_motionx_export_writes_the_folder(trials, tmp_path):
    tutor = trials["treadmill"][1]
    path = tmp_path / "tutor.json"
    tutor.save(path)
    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    out = tmp_path / "opensim"
    proc = subprocess.run([exe, "export", str(path), "--format", "opensim", "--out", str(out)],
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    line = json.loads(proc.stdout.strip().splitlines()[-1])
    assert line["residuals"]["meets_hicks_2015"] is True
    assert {"coordinates.mot", "grf.mot", "external_loads.xml", "subject01.osim"} <= set(line["files"])
    proc = subprocess.run([exe, "export", str(path), "--format", "opensim", "--out", "-"],
                          capture_output=True, text=True, timeout=60)
    assert proc.returncode == 2 and "--out DIR" in proc.stderr


def test_motions_that_cannot_be_written_on_an_opensim_model_are_refused(trials, tmp_path):
    cap, tutor = trials["treadmill"]
    with pytest.raises(OpenSimExportError, match="no ground reactions"):
        export_motion(capture_motion(cap), "opensim", path=tmp_path / "capture")
    foreign = tutor.evolve(context=tutor.context.with_(rig=None))
    with pytest.raises(OpenSimExportError, match="carries no OpenSim model"):
        export_motion(foreign, "opensim")
    assert not (tmp_path / "capture").exists()
    for bad, msg in (({"cycles": 0}, "cycles"), ({"lowpass": "6 Hz"}, "lowpass"), ({"lowpass": 80.0}, "lowpass"),
                     ({"rate": 5}, "rate"), ({"reduce_residuals": "yes"}, "reduce_residuals")):
        with pytest.raises(OpenSimExportError, match=msg):
            export_motion(tutor, "opensim", **bad)


def test_a_slope_optimum_is_written_on_an_inclined_ground_under_the_models_gravity(trials, tmp_path):
    """The optimizer tilts gravity over a level ground for a slope; OpenSim's gravity is down its
    y axis: the export turns the motion, and the ground plane the reactions are written on
    rises at the slope's angle."""
    import solver

    walk = solver.extrapolate(trials["treadmill"][1], solver.Target(slope_deg=5))
    assert walk.status == "succeeded" and walk.lam_reached == pytest.approx(1.0)
    export_motion(walk.steps[-1].motion, "opensim", path=tmp_path)
    summary = json.loads((tmp_path / "summary.json").read_text())
    normal = np.asarray(summary["ground_frame"]["ground_normal"])
    assert np.degrees(np.arccos(normal[1])) == pytest.approx(5.0, abs=1e-6) and normal[0] < 0  # rising forward
    assert summary["ground_frame"]["gravity_m_s2"] == pytest.approx([0.0, -9.81, 0.0], abs=1e-6)
    res = opensim_residuals(tmp_path)
    assert res["meets_hicks_2015"], res
    grf = read_mot(tmp_path / "grf.mot")
    p = np.stack([grf.column(f"ground_force_r_p{c}") for c in "xyz"], axis=1)
    o = np.asarray(summary["ground_frame"]["ground_point_m"])
    # the points lie on the inclined ground (the treadmill frame's origin moves with the belt)
    belt = np.asarray(summary["ground_frame"]["belt_velocity_m_s"])
    assert np.allclose((p - o - np.outer(grf.time, -belt)) @ normal, 0.0, atol=1e-6)


def test_a_motion_of_another_source_is_written_on_the_generic_model_scaled_to_it(shared_data, tmp_path):
    """A DeepMimic tutor: refused on its (absent) OpenSim model, written on gait2354 scaled to
    its character with the character's masses; OpenSim's inverse dynamics balances it."""
    res = shared_tutors.tutor(shared_data)
    assert res.status == "succeeded", res.message
    tutor = res.motion
    with pytest.raises(OpenSimExportError, match="model='generic'"):
        export_motion(tutor, "opensim")
    export_motion(tutor, "opensim", path=tmp_path, model="generic")
    summary = json.loads((tmp_path / "summary.json").read_text())
    generic = summary["model"]["generic"]
    assert generic["mass_kg"] == pytest.approx(tutor.character.total_mass)
    assert 0.5 < generic["scale_factors"]["femur_r"] < 1.5
    res = opensim_residuals(tmp_path)
    assert res["model_mass_kg"] == pytest.approx(tutor.character.total_mass, rel=1e-3)
    assert res["meets_hicks_2015"], res
    assert summary["residual_reduction"]["large"] is False
    coords = read_mot(tmp_path / "coordinates.mot")
    assert "pelvis_tilt" in coords.labels and "knee_angle_r" in coords.labels
    assert summary["capture_residuals"] == {"available": False, "why": "the trial has no force plates"}


def _glb_keyframes(data: bytes) -> tuple[int, float]:
    """The keyframe count of a GLB's first animation and its frame rate."""
    from test_gltf_rig import glb_fk

    _, times, _ = glb_fk(data)
    return int(times.size), (times.size - 1) / (times[-1] - times[0])


def test_the_command_line_reports_the_frames_the_models_glb_holds(trials):
    """``motionx export --rig source`` on an OpenSim motion reports the frames and rate of the GLB of the
    trial's model (one cycle at 30 frames/s), not the motion's own 15 frames/s; a capture: its own frames."""
    from service.commands.export import _written_frames

    cap, tutor = trials["treadmill"]
    for motion in (tutor, capture_motion(cap)):
        frames, fps = _written_frames(motion, {"rig": "source"})
        glb_frames, glb_fps = _glb_keyframes(export_motion(motion, "glb", rig="source"))
        assert frames == glb_frames and fps == pytest.approx(glb_fps, rel=1e-4)
    assert _written_frames(tutor, {"rig": "source"})[1] == pytest.approx(30.0) and tutor.fps < 16.0
