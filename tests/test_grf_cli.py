"""``motionx grf`` / ``motionx grf-compare``: the CSV contract, units of the input, errors."""

import csv
import json
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

COLUMNS = ["time", "side", "fx", "fy", "fz", "cop_x", "cop_y", "cop_z", "tz"]


def motionx(*args: str) -> subprocess.CompletedProcess:
    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    return subprocess.run([exe, *map(str, args)], capture_output=True, text=True, timeout=300)


def read_rows(path: Path) -> tuple[list[str], list[dict]]:
    with open(path, newline="") as f:
        r = csv.reader(f)
        header = next(r)
        return header, [dict(zip(header, row)) for row in r]


def per_foot(rows: list[dict], col: str) -> dict[str, np.ndarray]:
    return {s: np.array([float(r[col]) for r in rows if r["side"] == s]) for s in ("right", "left")}


def check_contract(path: Path, vertical: str = "fz") -> list[dict]:
    header, rows = read_rows(path)
    assert header == COLUMNS
    times = [r["time"] for r in rows]
    assert len(rows) == 2 * len(set(times))  # both feet at every frame, right then left
    assert [r["side"] for r in rows[:4]] == ["right", "left", "right", "left"]
    for r in rows:
        assert all(np.isfinite(float(r[c])) for c in ("time", "fx", "fy", "fz"))
        assert r["tz"] == "nan"  # the free moment is not reported (no skill: docs/grf.md)
        if float(r[vertical]) < 10.0:  # no centre of pressure under a few newtons
            assert r["cop_x"] == r["cop_y"] == r["cop_z"] == "nan"
    return rows


@pytest.fixture(scope="module")
def treadmill(shared_data):
    return shared_data / "opensim_gait2354_subject01_treadmill"


@pytest.fixture(scope="module")
def treadmill_estimate(treadmill, tmp_path_factory):
    out = tmp_path_factory.mktemp("treadmill") / "est.csv"
    # the trial's files as `motionx tutor` takes them (the plates' .mot and .xml recognised as such)
    r = motionx("grf", treadmill / "subject01.osim", treadmill / "subject01_walk1_ik.mot",
                treadmill / "subject01_walk1_grf.mot", treadmill / "subject01_walk1_grf.xml",
                "--belt-speed", "auto", "--out", out)
    assert r.returncode == 0, r.stderr
    return out, json.loads(r.stdout)


def test_treadmill_estimate_is_written_in_opensim_axes_and_compares_with_the_plates(tmp_path, treadmill,
                                                                                     treadmill_estimate):
    out, info = treadmill_estimate
    assert info["contacts_from"] == "plates" and info["rows"] == 2 * 209
    # defaults: temporal prior at the kinematics' cut-off, single-support CoPs kept in the feet
    assert info["smoothing_hz"] == info["cutoff_hz"] == 6.0 and info["status_projected"] > 0
    rows = check_contract(out, vertical="fy")  # OpenSim ground: Y up
    t = np.array(sorted({float(r["time"]) for r in rows}))
    assert t[0] == pytest.approx(0.5 + 1 / 60, abs=1e-4) and t[-1] == pytest.approx(4.0 - 1 / 60, abs=1e-4)
    # OpenSim ground: Y is up. Total vertical force ~ body weight on average (72.6 kg).
    fy = per_foot(rows, "fy")
    assert np.mean(fy["right"] + fy["left"]) == pytest.approx(72.6 * 9.81, rel=0.05)
    # CoPs on the treadmill's surface (floor y = -0.0075 m from the plates), in the treadmill's frame:
    # they stay on the belt (x within ~1 m) instead of travelling 4 m with the overground-equivalent body
    for side in ("right", "left"):
        loaded = [r for r in rows if r["side"] == side and float(r["fy"]) > 100]
        assert np.allclose([float(r["cop_y"]) for r in loaded], -0.0075, atol=1e-9)
        x = np.array([float(r["cop_x"]) for r in loaded])
        assert np.ptp(x) < 1.0
    # right foot on the right: OpenSim Z points to the subject's right
    assert np.nanmedian(per_foot(rows, "cop_z")["right"]) > np.nanmedian(per_foot(rows, "cop_z")["left"])

    png, js = tmp_path / "cmp.png", tmp_path / "cmp.json"
    r = motionx("grf-compare", "--estimate", out, "--grf", treadmill / "subject01_walk1_grf.mot",
                "--external-loads", treadmill / "subject01_walk1_grf.xml", "--plot", png, "--json", js)
    assert r.returncode == 0, r.stderr
    assert "rel. RMS" in r.stdout and "double support" in r.stdout
    for comp in ("fx", "fy", "fz", "tz", "cop"):
        assert f"\n{comp} " in r.stdout
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    metrics = json.loads(js.read_text())
    assert metrics["all"]["n_frames"] == 209
    assert metrics["all"]["rows"]["fz"]["rel_rms"] < 0.05  # tests/test_contact.py ACCURACY
    assert metrics["all"]["rows"]["cop"]["rms"] < 4.5


def test_grf_compare_plot_is_drawn_in_the_csvs_frame(tmp_path, treadmill, treadmill_estimate, monkeypatch):
    """The CSV is in OpenSim's ground frame (y up, z right): the plot shows those numbers
    under those names, the measured curves mapped into the same frame."""
    import solver.grf_compare as gc
    from service.cli import main

    out = treadmill_estimate[0]
    drawn = {}
    monkeypatch.setattr(gc, "plot", lambda path, est, meas, **kw: drawn.update(est=est, meas=meas, **kw))
    assert main(["grf-compare", "--estimate", str(out), "--grf", str(treadmill / "subject01_walk1_grf.mot"),
                 "--external-loads", str(treadmill / "subject01_walk1_grf.xml"), "--plot",
                 str(tmp_path / "c.png")]) == 0
    assert drawn["axis_names"] == ("x (forward)", "y (up)", "z (right)") and drawn["vertical"] == 1
    assert drawn["length_unit"] == "m" and "OpenSim ground" in drawn["title"]
    fy = per_foot(read_rows(out)[1], "fy")
    np.testing.assert_allclose(drawn["est"].force[0, 1], fy["right"], rtol=1e-5, atol=1e-3)  # the CSV's fy
    # the plates measure the body weight along y (up) in that frame, not along z
    both = drawn["meas"].force.sum(axis=0)
    assert np.nanmean(both[1]) == pytest.approx(72.6 * 9.81, rel=0.05) and abs(np.nanmean(both[2])) < 50


def test_c3d_estimate_is_in_the_lab_frame_in_millimetres(tmp_path, shared_data):
    c3d = shared_data / "btk_pig_flatfoot_full" / "PiG_Motion-FlatFoot-Full.c3d"
    out = tmp_path / "est.csv"
    r = motionx("grf", "--c3d", c3d, "--out", out)
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["length_unit_m"] == 0.001
    rows = check_contract(out)
    # lab Z up: vertical force in fz; CoP on the floor (z = 0 mm) and in millimetres: the walk crosses
    # the lab over metres, i.e. thousands of units
    fz = per_foot(rows, "fz")
    assert np.mean(fz["right"] + fz["left"]) == pytest.approx(47.5 * 9.81, rel=0.1)
    cz = np.concatenate(list(per_foot(rows, "cop_z").values()))
    assert np.allclose(cz[np.isfinite(cz)], 0.0, atol=1e-6)
    cx = np.concatenate(list(per_foot(rows, "cop_x").values()))
    assert np.nanmax(cx) - np.nanmin(cx) > 2000
    r = motionx("grf-compare", "--estimate", out, "--c3d", c3d, "--json", tmp_path / "cmp.json")
    assert r.returncode == 0, r.stderr
    cop_rms = float(next(line for line in r.stdout.splitlines() if line.startswith("cop ")).split()[2])
    assert cop_rms < 4.8  # cm, tests/test_contact.py ACCURACY
    assert "tz" in r.stdout and "not estimated" in r.stdout
    cmp = json.loads((tmp_path / "cmp.json").read_text())
    assert set(cmp["per_foot"]) == {"right", "left"} and cmp["per_foot"]["left"]["all"]["rows"]["fz"]["samples"] > 0
    # only frames with every loaded foot on a plate are compared: the reader's valid mask already leaves out
    # the right heel behind FP1's rear edge (test_io_c3d), nothing else stands off the plates
    assert cmp["frames_off_plates"] == 0 and cmp["all"]["n_frames"] == 70


def test_c3d_from_another_lab_runs_through_grf_grf_compare_and_tutor(tmp_path, shared_data):
    """The Qualisys trial (ISB/IOR marker names, no mass in the file) through every command."""
    c3d = shared_data / "qualisys_ior_walk" / "Qualisys.c3d"
    out = tmp_path / "est.csv"
    r = motionx("grf", "--c3d", c3d, "--out", out)
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    inp = info["input"]  # the input summary (solver.io.summary.describe)
    assert inp["marker_set"] == "IOR / ISB anatomical" and info["mass_kg"] == pytest.approx(66.0, rel=0.04)
    assert set(inp["upper_body"].values()) == {"markers"}
    assert "one stance per foot" in inp["mass_from"]
    assert inp["mass_implied_kg"] == pytest.approx(info["mass_kg"], abs=0.01) and "mass_warning" not in inp
    assert "support_flight" not in info  # a walk: a foot on the ground at every frame
    assert [len(inp["stances"][f]) for f in ("right", "left")] == [3, 2]
    assert info["free_moment"].startswith("not reported")
    check_contract(out)
    r = motionx("grf-compare", "--estimate", out, "--c3d", c3d, "--json", tmp_path / "cmp.json")
    assert r.returncode == 0, r.stderr
    cmp = json.loads((tmp_path / "cmp.json").read_text())
    assert cmp["all"]["n_frames"] >= 160 and cmp["double_support"]["n_frames"] >= 10
    tut = tmp_path / "tutor.json"
    r = motionx("tutor", c3d, "--character", "halfboy", "--fps", "15", "--out", tut, "--json")
    assert r.returncode == 0, r.stderr + r.stdout
    assert json.loads(r.stdout)["status"] == "succeeded"


def test_unknown_marker_set_error_says_how_to_map(tmp_path, shared_data):
    ezc3d = pytest.importorskip("ezc3d")
    c = ezc3d.c3d(str(shared_data / "qualisys_ior_walk" / "Qualisys.c3d"))
    labels = [s.strip() for s in c["parameters"]["POINT"]["LABELS"]["value"]]
    c["parameters"]["POINT"]["LABELS"]["value"] = [f"M{i:02d}" if s in ("L_IAS", "R_IAS") else s
                                                   for i, s in enumerate(labels)]
    bad = tmp_path / "renamed.c3d"
    c.write(str(bad))
    r = motionx("grf", "--c3d", bad, "--out", tmp_path / "est.csv")
    assert r.returncode == 2 and "LASI" in r.stderr and "RASI" in r.stderr and "--markers" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1
    pair = f"LASI=M{labels.index('L_IAS'):02d},RASI=M{labels.index('R_IAS'):02d}"
    r = motionx("grf", "--c3d", bad, "--markers", pair,
                "--out", tmp_path / "est.csv")
    assert r.returncode == 0, r.stderr
    mapping = tmp_path / "map.txt"
    mapping.write_text(f"LASI = M{labels.index('L_IAS'):02d}\nRASI = M{labels.index('R_IAS'):02d}\n")
    r = motionx("grf", "--c3d", bad, "--markers", mapping, "--out", tmp_path / "est2.csv")
    assert r.returncode == 0, r.stderr
    assert (tmp_path / "est.csv").read_text() == (tmp_path / "est2.csv").read_text()


def test_thesis_form_through_the_cli(tmp_path, shared_data):
    """--smoothing 0 --exact-single-support: one QP per frame and c under the stance foot (the thesis)."""
    c3d = shared_data / "btk_pig_flatfoot_full" / "PiG_Motion-FlatFoot-Full.c3d"
    out = tmp_path / "est.csv"
    r = motionx("grf", c3d, "--smoothing", "0", "--exact-single-support", "--out", out)  # the trial as for tutor
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert "smoothing_hz" not in info and "status_projected" not in info and info["status_single"] > 100
    check_contract(out)


@pytest.mark.parametrize("args, message", [
    (["grf", "--osim", "{T}/subject01.osim", "--out", "x.csv"], "--coordinates"),
    (["grf", "--c3d", "/no/such.c3d", "--out", "x.csv"], "file not found"),
    (["grf", "--osim", "{T}/subject01.osim", "--coordinates", "{T}/subject01_walk1_ik.mot",
      "--c3d", "x.c3d", "--out", "x.csv"], "give the trial once"),
    (["grf", "{T}/subject01.osim", "{T}/subject01_walk1_ik.mot", "--c3d", "x.c3d", "--out", "x.csv"],
     "give the trial once"),
    (["grf", "--osim", "{T}/subject01.osim", "--coordinates", "{T}/subject01_walk1_ik.mot",
      "--belt-speed", "fast", "--out", "x.csv"], "--belt-speed"),
    (["grf", "--osim", "{T}/subject01.osim", "--coordinates", "{T}/subject01_walk1_ik.mot",
      "--smoothing", "-1", "--out", "x.csv"], "--smoothing"),
    # options that conflict are told before the trial is read: here there is no trial to read
    (["grf", "/no/such.c3d", "--method", "nested", "--smoothing", "6", "--out", "x.csv"],
     "--smoothing goes with --method qp"),
    (["grf-compare", "--estimate", "{T}/subject01_walk1_grf.mot"], "--grf GRF.mot"),
    (["grf-compare", "--estimate", "{T}/subject01_walk1_grf.mot", "--grf", "{T}/subject01_walk1_grf.mot"],
     "missing columns"),
])
def test_bad_arguments_give_one_line_and_a_nonzero_status(tmp_path, treadmill, args, message):
    r = motionx(*[a.replace("{T}", str(treadmill)) for a in args])
    assert r.returncode != 0
    lines = r.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0], r.stderr


def test_bad_motion_data_is_refused_clearly(tmp_path, treadmill):
    """A NaN coordinate, a motion of another model, a treadmill walk without the belt speed."""
    src = (treadmill / "subject01_walk1_ik.mot").read_text().split("\n")
    i = src.index("endheader")
    col = src[i + 1].split("\t").index("knee_angle_r")
    row = src[i + 20].split("\t")
    row[col] = "nan"
    src[i + 20] = "\t".join(row)
    bad = tmp_path / "nan.mot"
    bad.write_text("\n".join(src))
    model = treadmill / "subject01.osim"
    r = motionx("grf", "--osim", model, "--coordinates", bad, "--belt-speed", "auto", "--out", tmp_path / "x.csv")
    assert r.returncode != 0 and "knee_angle_r" in r.stderr and len(r.stderr.strip().splitlines()) == 1
    other = treadmill.parent / "opensim_loadedwalking_subject05" / \
        "loadedwalking_subject05_noload_free_trial03_ik_solution.mot"
    r = motionx("grf", "--osim", model, "--coordinates", other, "--out", tmp_path / "x.csv")
    assert r.returncode != 0 and "mismatch" in r.stderr
    # on a treadmill the stance foot slides with the belt: no kinematic contact, no double support
    r = motionx("grf", "--osim", model, "--coordinates", treadmill / "subject01_walk1_ik.mot", "--out",
                tmp_path / "x.csv")
    assert r.returncode != 0 and "double support" in r.stderr and "--belt-speed" in r.stderr
    assert not (tmp_path / "x.csv").exists()


def test_grf_compare_sums_several_plates_per_foot(tmp_path, treadmill):
    """An ExternalLoads with three forces (right, right, left: the right record split into two
    time-disjoint plates) compares exactly as the two-force original."""
    from test_io_opensim import _split_grf

    est = tmp_path / "est.csv"
    r = motionx("grf", "--osim", treadmill / "subject01.osim", "--coordinates", treadmill / "subject01_walk1_ik.mot",
                "--belt-speed", "auto", "--grf", treadmill / "subject01_walk1_grf.mot",
                "--external-loads", treadmill / "subject01_walk1_grf.xml", "--out", est)
    assert r.returncode == 0, r.stderr
    mot, xml = _split_grf(treadmill, tmp_path, t_split=2.3)
    out = {}
    for name, files in (("two", (treadmill / "subject01_walk1_grf.mot", treadmill / "subject01_walk1_grf.xml")),
                        ("three", (mot, xml))):
        js = tmp_path / f"{name}.json"
        c = motionx("grf-compare", "--estimate", est, "--grf", files[0], "--external-loads", files[1], "--json", js)
        assert c.returncode == 0, c.stderr
        out[name] = json.loads(js.read_text())
    for comp in ("fx", "fy", "fz", "tz", "cop"):
        a, b = out["two"]["all"]["rows"][comp], out["three"]["all"]["rows"][comp]
        assert a["samples"] == b["samples"] and a["rms"] == pytest.approx(b["rms"], abs=1e-6, nan_ok=True), comp
