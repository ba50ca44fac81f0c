"""solver.library and `motionx library`: grids, warm starts along a cell's homotopy (the fact
they rest on: every axis is linear in λ), the library run in one process, the CLI's files."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import shared_tutors

from solver import library as L
from solver.continuation import Target, environment_at, guide_at, nlp_at
from solver.spacetime import Environment


def test_grid_cells_are_the_product_of_the_axes_in_axis_order():
    cells = L.grid_cells({"curve_deg": [-20, 20], "slope_deg": [-5, 0, 5]})
    assert len(cells) == 6 and [k for k, _ in cells[0].params] == ["slope_deg", "curve_deg"]
    assert [c.key for c in cells][:2] == ["slope-5_curve-20", "slope-5_curve20"]
    assert cells[2].values == {"slope_deg": 0.0, "curve_deg": -20.0} and not cells[2].is_neutral()
    assert L.Cell((("slope_deg", 0.0), ("curve_deg", 0.0))).is_neutral()
    # nearest the tutor first
    order = [c.key for c in L.order(cells)]
    assert order[:2] == ["slope0_curve-20", "slope0_curve20"]


@pytest.mark.parametrize("axes, words", [
    ({}, "at least one axis"),
    ({"slope_deg": []}, "no values"),
    ({"slope_deg": [1, 1]}, "repeats"),
    ({"slope_deg": [math.nan]}, "finite"),
    ({"slope_deg": [True]}, "finite"),
    ({"height": [1]}, "unknown axis"),
    ({"slope_deg": list(range(26)), "curve_deg": list(range(5))}, "at most 125"),
])
def test_bad_grids_are_refused_clearly(axes, words):
    with pytest.raises(L.LibraryError, match=words):
        L.grid_cells(axes)


def test_targets_the_solver_refuses_are_refused_per_cell():
    with pytest.raises(L.LibraryError, match="cell slope89"):
        L.check_cells(L.grid_cells({"slope_deg": [89.0]}))
    with pytest.raises(L.LibraryError, match=r"cell speed3: speed_scale must be within \[0.5, 2\]"):
        L.check_cells(L.grid_cells({"speed_scale": [1.0, 3.0]}))
    with pytest.raises(L.LibraryError, match="repeats"):
        L.list_cells([{"slope_deg": 5.0}, {"slope_deg": 5.0, "curve_deg": 0.0}])


def test_the_homotopy_is_linear_in_lambda_so_a_ray_shares_its_problems(shared_data):
    """What warm starts rest on: target B at λ·s is target s·B at λ (environment and guide)."""
    from test_export import walk_motion

    q = walk_motion(shared_data, "halfboy").q
    base = Environment()
    b = Target(slope_deg=10.0, curve_deg=40.0, speed_scale=1.4)
    half = Target(slope_deg=5.0, curve_deg=20.0, speed_scale=1.2)
    for lam in (0.3, 1.0):
        e1, v1 = environment_at(base, b, 0.5 * lam)
        e2, v2 = environment_at(base, half, lam)
        np.testing.assert_allclose(e1.gravity, e2.gravity, atol=1e-12)
        assert v1 == pytest.approx(v2)
        np.testing.assert_allclose(guide_at(q, b, 0.5 * lam), guide_at(q, half, lam), atol=1e-9)
        assert nlp_at(b, 0.5 * lam) == pytest.approx(nlp_at(half, lam))


def test_on_ray_finds_stored_optima_on_a_cells_homotopy():
    outer, inner = L.Cell((("slope_deg", 10.0), ("curve_deg", 40.0))), L.Cell((("slope_deg", 5.0), ("curve_deg", 20.0)))
    other = L.Cell((("slope_deg", 5.0), ("curve_deg", 0.0)))
    assert L.on_ray(outer, inner, 1.0) == pytest.approx(0.5)
    assert L.on_ray(outer, inner, 0.4) == pytest.approx(0.2)
    assert L.on_ray(outer, other, 1.0) is None  # another direction
    assert L.on_ray(inner, outer, 1.0) is None  # beyond the target
    assert L.on_ray(outer, other, 0.0) == 0.0  # the base problem is everyone's
    assert L.on_ray(outer, outer, 0.75) == pytest.approx(0.75)  # its own optimum: resume
    # the speed axis is linear in λ too: 1.2 is half-way to 1.4
    fast, faster = L.Cell((("speed_scale", 1.2),)), L.Cell((("speed_scale", 1.4),))
    assert L.on_ray(faster, fast, 1.0) == pytest.approx(0.5) and L.on_ray(faster, fast, 0.0) == 0.0
    ws = L.best_start(outer, [(other, 1.0), (inner, 0.6), (inner, 1.0), (other, 0.0)])
    assert ws == L.CellStart(0.5, inner.key, 1.0)


@pytest.fixture(scope="module")
def tutor(shared_data):
    res = shared_tutors.tutor(shared_data, as_motion=True)
    assert res.status == "succeeded"
    return res.motion


def test_cli_library_writes_the_glb_clips_and_manifest(tutor, tmp_path):
    from test_cli_conventions import run

    from solver.export import game

    tut = tmp_path / "tutor.json"
    tutor.save(tut)
    out = tmp_path / "lib"
    code, stdout, stderr = run("library", tut, "--slopes=0,2.5,5", "--out", out)
    assert code == 0, stderr
    assert "3 cells" in stdout and "3 succeeded" in stdout
    assert stderr.count("cell ") == 3  # the progress: one line per cell without a terminal
    man = json.loads((out / "manifest.json").read_text())
    assert man["format"] == "motionx.library" and man["grid"]["axes"] == {"slope_deg": [0.0, 2.5, 5.0]}
    cells = {e["key"]: e for e in man["cells"]}
    assert list(cells) == ["slope0", "slope2.5", "slope5"]
    for key, e in cells.items():
        assert e["status"] == "succeeded" and e["lambda_reached"] == 1.0 and e["realism"]["plausible"]
        assert (out / e["files"]["motion"]).is_file() and (out / e["files"]["clip"]).is_file()
        clip = json.loads((out / e["files"]["clip"]).read_text())
        assert clip["game"]["loop"]["seamless"]
        assert e["cycle"]["slope_deg"] == pytest.approx(e["parameters"]["slope_deg"], abs=1e-9)
    # warm starts: the tutor's own ground first (one step from the base problem), then along the ray
    assert cells["slope0"]["warm_start"] is None
    assert cells["slope2.5"]["warm_start"] == {"lam": 0.0, "source_cell": "slope0", "source_lam": 0.0}
    assert cells["slope5"]["warm_start"] == {"lam": 0.5, "source_cell": "slope2.5", "source_lam": 1.0}
    # the neutral cell is the base problem's optimum: the tutor's ground, level
    assert cells["slope0"]["cycle"]["slope_deg"] == pytest.approx(0.0, abs=1e-12)
    print("seconds per cell:", {k: e["wall_time_s"] for k, e in cells.items()}, man["summary"])
    from solver.export.gltf_parts import GLB_MAGIC

    glb = (out / "library.glb").read_bytes()
    assert int.from_bytes(glb[:4], "little") == GLB_MAGIC
    doc = json.loads(glb[20:20 + int.from_bytes(glb[12:16], "little")])
    assert [a["name"] for a in doc["animations"]] == list(cells)
    assert doc["asset"]["extras"]["library"]["axes"] == {"slope_deg": [0.0, 2.5, 5.0]}
    assert all(a["extras"]["frames_in_animation"] == game.loop_frames(tutor) + 1 for a in doc["animations"])
    # engines' importers follow the Khronos validator: no error, no warning, one animation per cell
    from test_gltf_threejs import khronos_report

    rep = khronos_report(out / "library.glb")
    assert rep["errors"] == 0 and rep["warnings"] == 0 and rep["animations"] == len(cells), rep


@pytest.mark.parametrize("args, words", [
    (["--out", "{tmp}/x"], "give the grid"),
    (["--slopes=1,x", "--out", "{tmp}/x"], "comma-separated numbers"),
    (["--speed-scales=0.8,3", "--out", "{tmp}/x"], "speed_scale must be within"),
    (["--slopes=5,5", "--out", "{tmp}/x"], "repeats"),
])
def test_cli_library_mistakes_are_one_line_errors(tutor, tmp_path, args, words):
    from test_cli_conventions import run

    tut = tmp_path / "tutor.json"
    tutor.save(tut)
    code, _, err = run("library", tut, *[a.replace("{tmp}", str(tmp_path)) for a in args])
    assert code == 2 and words in err.strip().splitlines()[-1], err  # argparse adds its usage above


def test_realism_figures_are_the_reports_own():
    rep = {"plausible": False, "root_residual": {"max_force_rel_weight": 2e-9, "max_moment_rel_weight_leg": 1e-9},
           "slip_mm": 0.1, "penetration_mm": 0.0, "friction_cone_excess_N": 0.0, "cop_outside_mm": 0.0,
           "problems": ["realism failure: foot_spin"], "mujoco_replay": {"max_force_rel_weight": 3e-9},
           "realism": {"passed": False, "failed": ["foot_spin"], "warnings": [],
                       "checks": {"foot_spin": {"value": 90.0, "limit": 30.0, "unit": "deg/s", "passed": False,
                                                "severity": "failure", "what": "…"}}}}
    r = L.realism(rep)
    assert r["plausible"] is False and r["root_residual_rel_weight"] == 2e-9
    assert r["mujoco_root_residual_rel_weight"] == 3e-9
    assert r["realism"]["failed"] == ["foot_spin"] and r["realism"]["checks"]["foot_spin"]["value"] == 90.0
    assert L.realism(None) is None
