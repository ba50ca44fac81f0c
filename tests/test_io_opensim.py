"""OpenSim importer on the two real OpenSim trials (overground 112 kg, treadmill 72.6 kg)."""

import numpy as np
import pytest

from solver.gait import detect_contacts, gait_events
from solver.io import load_trial
from solver.io.opensim import C_OSIM, OpenSimError, load_opensim, read_mot, read_opensim_grf
from solver.kinematics import contact_points, points_world

LW = "opensim_loadedwalking_subject05"
TM = "opensim_gait2354_subject01_treadmill"


@pytest.fixture(scope="module")
def loaded(shared_data):
    d = shared_data / LW
    return load_opensim(d / "Rajagopal2016_subject05_v30516.osim",
                        d / "loadedwalking_subject05_noload_free_trial03_ik_solution.mot",
                        grf=d / "loadedwalking_subject05_noload_free_trial03_grf.mot")


@pytest.fixture(scope="module")
def treadmill(shared_data):
    d = shared_data / TM
    return load_opensim(d / "subject01.osim", d / "subject01_walk1_ik.mot", grf=d / "subject01_walk1_grf.mot",
                        grf_xml=d / "subject01_walk1_grf.xml", belt_speed="auto")


def test_rajagopal_3x_model_imports_whole_body(loaded):
    cap = loaded
    ch = cap.character
    fit = cap.source["fit"]
    assert ch.name == "capture-full" and ch.n == 63 and cap.T == 131
    assert any("repaired" in n for n in cap.source["notes"])  # the 3.x model needed its sockets fixed
    assert ch.total_mass == pytest.approx(112.43, abs=0.01)
    assert fit["masses_from"] == "segment_masses"
    assert ch.segment("thigh_r").mass == pytest.approx(13.881, abs=1e-3)  # femur_r
    # body frames and joint centres from OpenSim: the capture skeleton reproduces them
    assert fit["landmark_error_mm"]["mean"] < 2.0 and fit["landmark_error_mm"]["max"] < 10.0
    assert max(v["max"] for v in fit["orientation_error_deg"].values()) < 3.0
    assert 0.40 < ch.segment("thigh_r").length < 0.50 and 0.40 < ch.segment("shank_r").length < 0.52
    assert 1.6 < fit["height_m"] < 2.1


def test_axes_floor_and_walking_direction(loaded):
    cap = loaded
    q, t, ch = cap.q, cap.times, cap.character
    speed = np.polyfit(t, q[ch.index("root_tx")], 1)[0]
    assert speed == pytest.approx(1.42, abs=0.05)  # README: 1.42 m/s along OpenSim +X = our +x
    assert np.abs(q[ch.index("root_ty")]).max() < 0.5
    assert 0.85 < np.median(q[ch.index("root_tz")]) < 1.15  # hips ~1 m above the floor: z is up
    hips = points_world(ch, q, [("thigh_r", [0, 0, 0]), ("thigh_l", [0, 0, 0])])
    assert np.all(hips[0, 1] < hips[1, 1])  # right hip at negative y (our y is the subject's left)
    cp = contact_points(ch, q)
    # the feet reach the floor (OpenSim ground y = 0 is our z = 0; contact points 1 cm above the sole)
    for k in range(4):
        assert -0.03 < np.percentile(cp[k, 2], 5) < 0.03
    assert np.allclose(cap.frame.R, C_OSIM.T)
    # mapping back: the root in OpenSim ground is the hip mid-point the model computes
    back = cap.frame.point_to_input(q[:3].T, t)
    assert np.all(np.abs(back[:, 2]) < 0.5) and np.all(back[:, 1] > 0.8)  # OpenSim y is up


def test_grf_loaded_walk(loaded):
    m = loaded.measured
    t = loaded.times
    assert m is not None and m.force.shape == (2, 3, loaded.T)
    valid_t = t[m.valid]
    # README: complete GRF from left toe-off (≈0.5-0.6 s, left foot not on a plate before) to 1.30 s
    assert 0.5 <= valid_t[0] <= 0.65 and valid_t[-1] == pytest.approx(1.30)
    assert np.all(np.diff(np.where(m.valid)[0]) == 1)
    w = loaded.character.weight
    total = m.force[:, 2, m.valid].sum(0)
    assert 0.6 * w < total.mean() < 1.4 * w
    # COP meaningless when unloaded: NaN there; on the ground where loaded
    unloaded = m.force[:, 2] < 20
    assert np.all(np.isnan(m.cop[:, 0][unloaded]))
    assert np.nanmax(np.abs(m.cop[:, 2])) < 0.02
    # right COP under the right foot during right single support (0.6-0.95 s)
    k = (t > 0.6) & (t < 0.95)
    heel = points_world(loaded.character, loaded.q[:, k], [("foot_r", [0, 0, 0])])[0]
    assert np.abs(m.cop[0, 1, k] - heel[1]).max() < 0.1


def test_gait_events_loaded_walk(loaded):
    ev = gait_events(detect_contacts(loaded.character, loaded.q, loaded.fps), loaded.times)
    # README (force plates, 20 N): right 0.3895-1.178 s, left from 0.9925 s; 100 Hz kinematics
    assert ev["right_heel_strike"][0] == pytest.approx(0.3895, abs=0.025)
    assert ev["left_heel_strike"][0] == pytest.approx(0.9925, abs=0.025)
    assert ev["right_toe_off"][0] == pytest.approx(1.178, abs=0.035)


def test_treadmill_belt_shift(treadmill, shared_data):
    cap = treadmill
    ch = cap.character
    # gait2354 has no arms: its torso body (head, arms, trunk) rides on the lumbar joint as the abdomen
    assert ch.name == "capture-full" and ch.n == 63
    assert ch.total_mass == pytest.approx(72.6, abs=0.01)
    assert ch.segment("abdomen").mass == pytest.approx(33.068, abs=0.01)  # the model's torso body
    assert cap.source["fit"]["landmark_error_mm"]["mean"] < 2.0
    v = cap.source["belt_speed_m_s"]
    assert 1.0 < v < 1.2  # README: ~1.07 from markers; the IK kinematics' stance feet say ~1.13
    assert np.allclose(cap.frame.velocity, [v, 0, 0])
    t = cap.times
    # overground-equivalent: the root progresses at the belt speed ...
    assert np.polyfit(t, cap.q[ch.index("root_tx")], 1)[0] == pytest.approx(v, abs=0.02)
    # ... and a loaded foot no longer moves
    cp = contact_points(ch, cap.q)
    vx = np.gradient(cp[0, 0], t)
    loaded = cap.measured.force[0, 2] > 300
    assert abs(np.median(vx[loaded])) < 0.05
    # mapped back onto the treadmill, the root (mid-hips, ~7 cm behind OpenSim's pelvis origin)
    # stays where the IK put the pelvis (pelvis_tx 0.58-0.61 m)
    back = cap.frame.point_to_input(cap.q[:3].T, t)
    sto = read_mot(shared_data / TM / "subject01_walk1_ik.mot")
    d = back[:, 0] - sto.column("pelvis_tx")
    assert np.ptp(d) < 0.02 and -0.1 < d.mean() < 0.0
    assert np.ptp(back[:, 0]) < 0.1
    # floor: the plate surface (COP y = -0.0075 m) is our z = 0
    assert cap.frame.offset[1] == pytest.approx(-0.0075)


def _opensim_com(model, motion, frame, times):
    """Whole-body centre of mass (our frame) from the bodies OpenSim itself places (child process)."""
    from solver.io.opensim.worker import run_worker as _run_worker

    sto = read_mot(motion)
    res = _run_worker(str(model), sto.labels, sto.data, sto.in_degrees)
    m = np.asarray(res["body_mass"])
    c = np.einsum("tbij,bj->tbi", res["R"], np.asarray(res["body_com"])) + res["P"]
    return frame.point_from_input(np.einsum("b,tbi->ti", m, c) / m.sum(), times).T  # (3, T)


def _capture_com(cap):
    ch = cap.character
    m = np.array([s.mass for s in ch.segments])
    c = points_world(ch, cap.q, [(s.name, s.com) for s in ch.segments])
    return np.einsum("s,sit->it", m, c) / m.sum()


def test_armless_model_keeps_the_trunk_on_the_lumbar_joint(treadmill, shared_data):
    """gait2354 (no arms): the capture's mass distribution is the model's, moving as OpenSim moves it.

    Independent reference: the whole-body centre of mass of the bodies OpenSim places at every frame
    (the trunk, 46 % of the mass, included). Lumping the torso into the pelvis (rolling and pitching
    with it, the lumbar motion dropped) puts it centimetres off.
    """
    cap, d = treadmill, shared_data / TM
    ref = _opensim_com(d / "subject01.osim", d / "subject01_walk1_ik.mot", cap.frame, cap.times)
    err = np.linalg.norm(_capture_com(cap) - ref, axis=0)
    assert err.max() < 0.002, err.max()  # metres
    # the lumbar joint moves: the trunk is not rigid with the pelvis
    ch, q = cap.character, cap.q
    lumbar = q[[ch.index(f"lumbar_{k}") for k in ("flexion", "bending", "rotation")]]
    assert np.ptp(lumbar, axis=1).max() > np.radians(5)
    assert cap.source["fit"]["orientation_error_deg"]["abdomen"]["max"] < 1.0
    # canonical upper body: placeholders rigid with the torso (negligible mass, no motion of their own)
    for seg in ("thorax", "head", "upper_arm_r", "hand_l"):
        assert 0 < ch.segment(seg).mass < 1e-4
    for name in ("thorax_flexion", "neck_flexion", "shoulder_flexion_r", "elbow_flexion_l"):
        assert np.ptp(q[ch.index(name)]) < np.radians(1.0)


def test_armless_capture_feeds_both_synthesis_characters_and_mujoco(treadmill):
    from mjcf.builder import compile_model
    from solver.pipeline import synthesis_character

    ch = treadmill.character
    half, cap_lower = synthesis_character(ch, "halfboy")
    assert half.n == 16 and "abdomen" not in {s.name for s in cap_lower.segments}
    assert cap_lower.total_mass == pytest.approx(ch.total_mass)  # trunk lumped into the pelvis
    full, _ = synthesis_character(ch, "fullbody")
    assert full.n == 43
    assert compile_model(ch).nbody > 1  # placeholder masses are valid moving bodies for MuJoCo


def test_treadmill_grf_and_gait_events(treadmill):
    cap = treadmill
    m = cap.measured
    assert m.valid.all()  # both feet on their plates throughout (README)
    assert m.force[:, 2].sum(0).mean() / 9.81 == pytest.approx(72.6, rel=0.05)
    ev = gait_events(detect_contacts(cap.character, cap.q, cap.fps), cap.times)
    readme = {"right_heel_strike": [0.618, 1.853, 3.078], "right_toe_off": [1.408, 2.633, 3.840],
              "left_heel_strike": [1.247, 2.460, 3.677], "left_toe_off": [0.787, 2.017, 3.232]}
    for k, ref in readme.items():
        assert len(ev[k]) == len(ref), (k, ev[k])
        assert np.abs(np.array(ev[k]) - ref).max() <= 2.5 / 60, (k, ev[k], ref)  # within two frames at 60 Hz


def test_read_opensim_grf_sides_and_frame(shared_data):
    d = shared_data / LW
    times = np.linspace(0.4, 1.2, 81)
    g = read_opensim_grf(d / "loadedwalking_subject05_noload_free_trial03_grf.mot", times=times)
    sto = read_mot(d / "loadedwalking_subject05_noload_free_trial03_grf.mot")
    # our z is OpenSim's y: the right vertical force is column ground_force_r_vy (low-passed)
    ref = np.interp(times, sto.time, sto.column("ground_force_r_vy"))
    assert np.abs(g.force[0, 2] - ref).max() < 0.05 * ref.max()
    assert g.valid.all()
    with pytest.raises(OpenSimError, match="does not overlap"):
        read_opensim_grf(d / "loadedwalking_subject05_noload_free_trial03_grf.mot", times=np.array([5.0, 6.0]))


def test_mot_errors(tmp_path, shared_data):
    src = (shared_data / TM / "subject01_walk1_ik.mot").read_text().splitlines()
    head = src.index("endheader") + 1
    labels = src[head].split("\t")

    def write(name, lines):
        p = tmp_path / name
        p.write_text("\n".join(lines) + "\n")
        return p

    # NaN row
    rows = src[head + 1:]
    bad = rows[3].split("\t")
    bad[5] = "nan"
    p = write("nan.mot", src[:head + 1] + rows[:3] + ["\t".join(bad)] + rows[4:])
    with pytest.raises(OpenSimError, match="NaN"):
        read_mot(p)
    # not a .mot
    with pytest.raises(OpenSimError, match="endheader"):
        read_mot(write("x.mot", ["hello", "1 2 3"]))
    # model/motion mismatch: a missing coordinate, an unknown column
    keep = [i for i, lab in enumerate(labels) if lab.strip() != "knee_angle_r"]
    cut = ["\t".join(r.split("\t")[i] for i in keep) for r in src[head:]]
    p = write("missing.mot", src[:head] + cut)
    model = shared_data / TM / "subject01.osim"
    with pytest.raises(OpenSimError, match=r"lacks the model's coordinates \['knee_angle_r'\]"):
        load_opensim(model, p)
    ren = [src[head].replace("knee_angle_r", "knee_angle_x")] + src[head + 1:]
    p = write("unknown.mot", src[:head] + ren)
    with pytest.raises(OpenSimError, match=r"columns \['knee_angle_x'\] that are not coordinates"):
        load_opensim(model, p)
    # angle unit not in the header: inferred from the values (walking angles beyond 2π are degrees)
    plain = [ln for ln in src[:head] if "degrees" not in ln.lower()] + src[head:]
    cap = load_opensim(model, write("units.mot", plain))
    assert cap.source["angles_in_degrees"] and any("inferred" in n for n in cap.source["notes"])
    assert cap.source["fit"]["landmark_error_mm"]["mean"] < 2.0
    # belt speed must be a number or 'auto'
    with pytest.raises(OpenSimError, match="belt_speed"):
        load_opensim(model, shared_data / TM / "subject01_walk1_ik.mot", belt_speed="fast")


def test_grf_without_sides_needs_the_xml(tmp_path, shared_data):
    # the treadmill GRF names the right foot's columns without a side: the .xml is required
    with pytest.raises(OpenSimError, match="ExternalLoads"):
        read_opensim_grf(shared_data / TM / "subject01_walk1_grf.mot", times=np.array([1.0, 1.1]))
    bad = tmp_path / "loads.xml"
    bad.write_text("<OpenSimDocument><ExternalLoads><objects><ExternalForce name='F'><applied_to_body>torso"
                   "</applied_to_body></ExternalForce></objects></ExternalLoads></OpenSimDocument>")
    with pytest.raises(OpenSimError, match="cannot tell the side"):
        read_opensim_grf(shared_data / TM / "subject01_walk1_grf.mot", bad, times=np.array([1.0, 1.1]))


def test_load_trial_dispatches_opensim(shared_data, tmp_path):
    d = shared_data / TM
    cap = load_trial([d / "subject01.osim", d / "subject01_walk1_ik.mot", d / "subject01_walk1_grf.mot",
                      d / "subject01_walk1_grf.xml"], belt_speed=1.1)
    assert cap.source["format"] == "opensim" and cap.measured is not None
    assert cap.frame.velocity[0] == pytest.approx(1.1)
    from solver.io import TrialError

    with pytest.raises(TrialError, match="exactly one coordinates"):
        load_trial([d / "subject01.osim", d / "subject01_walk1_grf.mot"])
    other = tmp_path / "walk.xyz"
    other.write_text("1 2 3")
    with pytest.raises(TrialError, match="unknown trial format"):
        load_trial([other])
    with pytest.raises(TrialError, match="file not found"):
        load_trial([tmp_path / "nope.c3d"])


# --- .mot columns for coordinates the model does not have (welded / locked joints) -----------


def _weld(src, dst, joints):
    """A copy of an OpenSim 3.x model with the named CustomJoints replaced by WeldJoints at the
    same frames: the joint's coordinates disappear, its child is fixed in the default pose
    (coordinate 0), as a scaled model with welded subtalar/mtp/wrist joints."""
    import xml.etree.ElementTree as ET

    tree = ET.parse(src)
    n = 0
    for parent in tree.getroot().iter():
        for i, el in enumerate(list(parent)):
            if el.tag == "CustomJoint" and el.get("name") in joints:
                w = ET.Element("WeldJoint", name=el.get("name"))
                for tag in ("parent_body", "location_in_parent", "orientation_in_parent", "location", "orientation"):
                    if el.find(tag) is not None:
                        w.append(el.find(tag))
                parent.remove(el)
                parent.insert(i, w)
                n += 1
    assert n == len(joints)
    tree.write(dst)
    return dst


def _with_columns(src, dst, columns):
    """A copy of a .mot with extra columns (name -> value per row, or a constant)."""
    lines = src.read_text().splitlines()
    h = lines.index("endheader") + 1
    rows = lines[h + 1:]
    out = lines[:h] + ["\t".join([lines[h]] + list(columns))]
    for k, r in enumerate(rows):
        vals = [f"{(v[k] if np.ndim(v) else v):.8f}" for v in columns.values()]
        out.append("\t".join([r] + vals))
    dst.write_text("\n".join(out) + "\n")
    return dst


def test_constant_columns_of_welded_joints_are_ignored_as_opensim_does(shared_data, tmp_path, caplog):
    """mtp welded in the model, the IK still carrying mtp_angle_r/l (all 0): OpenSim reads the
    columns of its coordinates and ignores the others. The import equals that of the original
    model at mtp = 0 (OpenSim places the same bodies), with a warning naming the columns."""
    d = shared_data / TM
    ik = d / "subject01_walk1_ik.mot"
    assert np.ptp(read_mot(ik).column("mtp_angle_r")) == 0.0  # the shared IK has mtp at 0 throughout
    welded = _weld(d / "subject01.osim", tmp_path / "welded.osim", {"mtp_r", "mtp_l"})
    # the Rajagopal case: 8 more constant columns (subtalar, mtp, wrists welded there)
    extra = {f"{c}_{s}": 0.0 for c in ("wrist_flex", "wrist_dev") for s in "rl"}
    extra |= {"pro_sup_r": 0.0, "pro_sup_l": 0.0, "elbow_flex_r": 0.0, "elbow_flex_l": 0.0}
    motion = _with_columns(ik, tmp_path / "ik_extra.mot", extra)
    with caplog.at_level("WARNING"):
        cap = load_opensim(welded, motion)
    ignored = cap.source["ignored_columns"]
    assert ignored == {"mtp_angle_r": 0.0, "mtp_angle_l": 0.0, **extra}
    assert any("ignoring 10 constant column(s)" in r.getMessage() and "mtp_angle_r=0" in r.getMessage()
               for r in caplog.records)
    ref = load_opensim(d / "subject01.osim", ik)
    assert cap.character.coordinate_names == ref.character.coordinate_names
    assert np.abs(cap.q - ref.q).max() < 1e-9
    # OpenSim itself: the welded model has no mtp coordinates and puts every body where the
    # original model does at mtp = 0
    from solver.io.opensim.worker import run_worker

    sto = read_mot(ik)
    a, b = run_worker(str(welded), sto.labels, sto.data, True), run_worker(str(d / "subject01.osim"), sto.labels,
                                                                            sto.data, True)
    assert "mtp_angle_r" not in a["coord_names"] and "mtp_angle_r" in b["coord_names"]
    assert np.abs(a["P"] - b["P"]).max() < 1e-12 and np.abs(a["R"] - b["R"]).max() < 1e-12


def test_varying_columns_the_model_lacks_are_refused_by_name(shared_data, tmp_path):
    """subtalar welded but the IK's subtalar angles vary (-8..14°): motion the model cannot follow."""
    d = shared_data / TM
    welded = _weld(d / "subject01.osim", tmp_path / "welded.osim", {"subtalar_r", "subtalar_l", "mtp_r", "mtp_l"})
    with pytest.raises(OpenSimError, match=r"columns \['subtalar_angle_r', 'subtalar_angle_l'\] that are not "
                                           r"coordinates .* vary over the motion \(subtalar_angle_r -7.851\.\.13.96"):
        load_opensim(welded, d / "subject01_walk1_ik.mot")
    # a column within 1e-6 of constant is constant; 1e-3 of drift is not
    drift = _with_columns(d / "subject01_walk1_ik.mot", tmp_path / "drift.mot",
                          {"wrist_flex_r": np.linspace(0, 1e-3, 211)})
    with pytest.raises(OpenSimError, match=r"\['wrist_flex_r'\]"):
        load_opensim(d / "subject01.osim", drift)


# --- ExternalLoads: several forces per foot --------------------------------------------------


def _split_grf(d, tmp_path, t_split):
    """The treadmill GRF with the right foot's record split in two time-disjoint plates (columns
    ``p1_*`` before ``t_split``, ``p2_*`` after) and an ExternalLoads with 3 forces
    (right, right, left), as an overground trial with plates left, right, left."""
    sto = read_mot(d / "subject01_walk1_grf.mot")
    right = [lab for lab in sto.labels if lab.startswith(("ground_force_", "ground_torque_"))]
    cols = np.stack([sto.column(c) for c in right], axis=1)
    first = np.where((sto.time < t_split)[:, None], cols, 0.0)
    second = np.where((sto.time < t_split)[:, None], 0.0, cols)
    labels = ["time", *sto.labels, *[f"p1_{c}" for c in right], *[f"p2_{c}" for c in right]]
    data = np.column_stack([sto.time, sto.data, first, second])
    out = ["grf3.mot", "endheader", "\t".join(labels)] + ["\t".join(f"{x:.10g}" for x in row) for row in data]
    mot = tmp_path / "grf3.mot"
    mot.write_text("\n".join(out) + "\n")
    xml = (d / "subject01_walk1_grf.xml").read_text()
    import xml.etree.ElementTree as ET

    root = ET.fromstring(xml)
    objs = next(root.iter("objects"))
    forces = list(objs)
    r_force = next(f for f in forces if f.find("applied_to_body").text.strip().endswith("_r"))
    objs.remove(r_force)
    for k in (1, 2):
        f = ET.fromstring(ET.tostring(r_force))
        f.set("name", f"plate{k}_right")
        for tag in ("force_identifier", "point_identifier", "torque_identifier"):
            el = f.find(tag)
            el.text = f"p{k}_" + el.text.strip()
        objs.insert(0, f)
    x = tmp_path / "grf3.xml"
    x.write_text(ET.tostring(root, encoding="unicode"))
    assert sum(1 for _ in root.iter("ExternalForce")) == 3
    return mot, x


def test_several_external_forces_on_one_foot_are_summed(shared_data, tmp_path, treadmill):
    d = shared_data / TM
    mot, xml = _split_grf(d, tmp_path, t_split=2.3)  # mid right stance (1.853-2.633 s)
    times = treadmill.times
    a = read_opensim_grf(mot, xml, times=times, frame=treadmill.frame)
    b = read_opensim_grf(d / "subject01_walk1_grf.mot", d / "subject01_walk1_grf.xml", times=times,
                         frame=treadmill.frame)
    assert np.abs(a.force - b.force).max() < 1e-9
    assert np.abs(a.free_moment - b.free_moment).max() < 1e-9
    assert np.array_equal(np.isnan(a.cop), np.isnan(b.cop)) and np.nanmax(np.abs(a.cop - b.cop)) < 1e-9
    # the same implied mass
    from solver.io.opensim import plates_implied_mass

    assert plates_implied_mass(mot, xml).kg == pytest.approx(plates_implied_mass(d / "subject01_walk1_grf.mot",
                                                                                 d / "subject01_walk1_grf.xml").kg)


def test_combined_plates_keep_the_total_wrench():
    """Two plates loaded at once under one foot: the equivalent wrench (sum of forces at the
    combined CoP with a vertical free moment) has the plates' total force and moment."""
    from solver.io.opensim.external_loads import combine

    rng = np.random.default_rng(3)
    N = 50
    F = np.stack([rng.uniform([-80, 100, -40], [80, 600, 40], (N, 3)) for _ in range(2)])
    P = np.stack([np.column_stack([rng.uniform(-0.3, 0.9, N), np.full(N, -0.0075), rng.uniform(-0.2, 0.2, N)])
                  for _ in range(2)])
    TQ = np.zeros((2, N, 3))
    TQ[:, :, 1] = rng.uniform(-5, 5, (2, N))
    f, p, tq = combine(F, P, TQ)
    assert np.allclose(f, F.sum(0))
    assert np.allclose(p[:, 1], -0.0075) and np.allclose(tq[:, [0, 2]], 0.0)
    M_plates = (np.cross(P, F) + TQ).sum(0)
    assert np.allclose(np.cross(p, f) + tq, M_plates, atol=1e-9)
    # one plate unloaded (its CoP meaningless, e.g. 33609 m): the other plate's own point and moment
    F[1] = 0.0
    P[1] = 33609.0
    f, p, tq = combine(F, P, TQ)
    assert np.allclose(p, P[0]) and np.allclose(tq[:, 1], TQ[0, :, 1])


# --- the body mass the plates imply ----------------------------------------------------------


def test_plates_imply_the_subjects_mass_and_a_wrong_mass_is_flagged(shared_data, loaded, treadmill):
    # treadmill: 11 whole cycles of both plates; overground: one complete stance per foot
    im = treadmill.source["implied_mass"]
    assert im["method"] == "whole cycles" and im["cycles"] >= 10
    assert im["kg"] == pytest.approx(72.6, rel=0.01)  # the model's (and the scaling setup's) mass
    assert "mass_warning" not in treadmill.source
    im = loaded.source["implied_mass"]
    assert im["method"] == "one stance per foot"
    assert im["kg"] == pytest.approx(112.43, rel=0.02)
    # the case: a model mass the plates contradict (62 kg against ~73) is flagged
    d = shared_data / TM
    cap = load_opensim(d / "subject01.osim", d / "subject01_walk1_ik.mot", grf=d / "subject01_walk1_grf.mot",
                       grf_xml=d / "subject01_walk1_grf.xml", belt_speed="auto", mass=62.0)
    assert cap.character.total_mass == pytest.approx(62.0)
    assert "62.0 kg differs from the 72.7 kg the force plates imply (-15 %)" in cap.source["mass_warning"]


# --- markers (.trc) + model: OpenSim's inverse kinematics -------------------------------------


@pytest.fixture(scope="module")
def trc_ik(shared_data):
    from solver.io.opensim.ik import solve_ik

    d = shared_data / TM
    return solve_ik(d / "subject01.osim", d / "marker_trajectories.trc")


def test_trc_inverse_kinematics_agrees_with_the_trials_own_ik(shared_data, trc_ik):
    """OpenSim IK of marker_trajectories.trc (uniform weights) against the trial's IK .mot
    (computed by the lab with its own task weights): docs/import.md has the per-coordinate table."""
    res, src = trc_ik
    ref = read_mot(shared_data / TM / "subject01_walk1_ik.mot")
    t = res["ik_times"]
    assert t.size == 151 and np.allclose(np.diff(t), 1 / 60)  # the file's rounded times rebuilt from its rate
    sel = (t >= ref.time[0] - 1e-6) & (t <= ref.time[-1] + 1e-6)
    rms = {}
    for j, name in enumerate(res["coord_names"]):
        v, r = res["ik_q"][sel, j], np.interp(t[sel], ref.time, ref.column(name))
        v = np.degrees(v) if res["coord_rotational"][j] else 1000 * v
        r = r if res["coord_rotational"][j] else 1000 * r
        rms[name] = float(np.sqrt(np.mean((v - r) ** 2)))
    assert max(rms[f"knee_angle_{s}"] for s in "rl") < 4.0  # deg
    assert max(rms[f"ankle_angle_{s}"] for s in "rl") < 4.0
    assert max(rms[f"pelvis_t{a}"] for a in "xyz") < 6.0  # mm
    rot = [n for n, r in zip(res["coord_names"], res["coord_rotational"]) if r and not n.startswith("mtp")]
    assert np.mean([rms[n] for n in rot]) < 5.5
    ik = src["ik"]
    assert len(ik["markers"]) == 31 and "R.Knee.Lat" in ik["model_markers_without_data"]
    assert "R.Temple" in ik["file_markers_not_in_model"]
    assert 10 < ik["marker_error_mm"]["rms"] < 25 and ik["marker_error_mm"]["max"] < 90


def test_trc_input_makes_a_capture_through_load_trial(shared_data):
    d = shared_data / TM
    cap = load_trial([d / "subject01.osim", d / "marker_trajectories.trc", d / "subject01_walk1_grf.mot",
                      d / "subject01_walk1_grf.xml"], belt_speed="auto")
    assert cap.T == 151 and cap.fps == pytest.approx(60.0) and cap.character.name == "capture-full"
    assert cap.source["motion_from"].startswith("inverse kinematics")
    assert cap.source["ik"]["marker_error_mm"]["rms"] < 25
    assert cap.source["belt_speed_m_s"] == pytest.approx(1.13, abs=0.03)
    assert cap.measured is not None and cap.measured.valid.all()
    with pytest.raises(OpenSimError, match=r"only apply to a \.trc|apply to a \.trc"):
        load_opensim(d / "subject01.osim", d / "subject01_walk1_ik.mot", ik_reweight=1)


def test_trc_errors(shared_data, tmp_path):
    d = shared_data / TM
    bad = tmp_path / "x.trc"
    bad.write_text("hello\n")
    with pytest.raises(OpenSimError, match=r"not a \.trc marker file"):
        load_opensim(d / "subject01.osim", bad)
    # markers none of which the model has
    lines = (d / "marker_trajectories.trc").read_text().splitlines()
    lines[3] = "\t".join(c.replace(".", "_") if c not in ("Frame#", "Time") else c for c in lines[3].split("\t"))
    other = tmp_path / "renamed.trc"
    other.write_text("\n".join(lines) + "\n")
    with pytest.raises(OpenSimError, match=r"only 1 of the model's markers have data in renamed.trc"):
        load_opensim(d / "subject01.osim", other)
    with pytest.raises(OpenSimError, match="weights must be finite"):
        load_opensim(d / "subject01.osim", d / "marker_trajectories.trc", ik_weights={"R.ASIS": -1})
