"""service.plots (progress, GRF, residual PNGs) and `motionx plot` / `motionx extrapolate`'s plots,
on a real tutor (the pipeline's, from the DeepMimic walk) and a real continuation."""

from __future__ import annotations

import io
import json
import shutil
import subprocess
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np
import pytest
import shared_tutors
from PIL import Image

from service.plots import (
    PlotError,
    describe_target,
    grf_png,
    motion_caption,
    number_text,
    progress_figure,
    progress_png,
    residual_series,
    residuals_png,
)
from solver.motion import Motion
from solver.plausibility import report

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"


def assert_png(data: bytes, min_size=(500, 300)) -> np.ndarray:
    """A valid, decodable, plausibly sized PNG with something drawn on it; returns the pixels."""
    assert data[:8] == PNG_SIGNATURE
    img = Image.open(io.BytesIO(data))
    img.load()
    assert img.format == "PNG"
    w, h = img.size
    assert min_size[0] <= w <= 3000 and min_size[1] <= h <= 3000, img.size
    px = np.asarray(img.convert("RGB"), dtype=float)
    assert px.std() > 10.0  # not blank
    assert (px.min(axis=2) < 200).mean() > 0.01  # more than a frame: at least 1 % of the pixels are ink
    return px


def motionx(*args, timeout: int = 300) -> subprocess.CompletedProcess:
    exe = shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))
    return subprocess.run([exe, *map(str, args)], check=False, capture_output=True, text=True, timeout=timeout)


@pytest.fixture(scope="module")
def tutor(shared_data) -> Motion:
    res = shared_tutors.tutor(shared_data, as_motion=True)
    assert res.status == "succeeded", res.message
    return res.motion


@pytest.fixture(scope="module")
def continuation(tutor):
    """A real, cheap continuation (friction 1 -> 0.7 and 4° uphill, Δ0 = 0.5)."""
    from solver.continuation import StepControl, Target, extrapolate

    target = Target(slope_deg=4.0, friction=0.7)
    res = extrapolate(tutor, target, StepControl(delta0=0.5))
    assert res.status == "succeeded" and res.steps
    return target, res


@pytest.fixture(scope="module")
def tutor_file(tutor, tmp_path_factory) -> Path:
    p = tmp_path_factory.mktemp("plots") / "tutor.json"
    tutor.save(p)
    return p


# --- progress ----------------------------------------------------------------------------


def test_progress_png_from_the_continuations_records(continuation):
    target, res = continuation
    recs = [asdict(r) for r in res.records]
    px = assert_png(progress_png(recs, target.to_dict()))
    # two environment panels (slope and friction change) below λ: taller than a one-parameter figure
    one = assert_png(progress_png(recs, {"friction": 0.7}))
    assert px.shape[0] > one.shape[0]


def test_progress_plot_draws_each_environment_value_on_its_own_axes(continuation):
    """Slope and curve both grow in proportion to λ: on shared or twin axes one line would
    hide the other (and λ). Each gets its own panel, in its own style, with its target."""
    _, res = continuation
    recs = [asdict(r) for r in res.records]
    for r in recs:  # the same solves, as a slope + curve continuation reports them
        r["environment"] = {**r["environment"], "slope_deg": -11.25 * r["lam"], "curve_deg": 90.0 * r["lam"]}
    fig = progress_figure(recs, {"slope_deg": -11.25, "curve_deg": 90.0})
    axes = fig.axes
    assert [a.get_ylabel() for a in axes] == ["λ", "slope (°)", "curve (°)"]
    assert fig._suptitle.get_text().startswith("continuation toward slope -11.25°, curve 90°")
    assert len({id(a) for a in axes}) == 3 and all(a.get_shared_x_axes().joined(axes[0], a) for a in axes)
    styles = [(line.get_linestyle(), line.get_color()) for a in axes for line in a.get_lines()[:1]]
    assert len(set(styles)) == 3, styles  # λ, slope, curve: each line its own style and colour
    slope_lines = {line.get_label(): line for line in axes[1].get_lines()}
    assert "target -11.25" in slope_lines
    assert min(slope_lines["slope reached"].get_ydata()) == pytest.approx(-11.25)
    assert max(axes[2].get_lines()[0].get_ydata()) == pytest.approx(90.0)


def test_numbers_in_titles_keep_the_decimals_they_need(tutor, continuation):
    assert [number_text(v) for v in (-11.25, 90.0, 0.7, 1.62, -0.0, 2.8125, 1 / 3)] == \
        ["-11.25", "90", "0.7", "1.62", "0", "2.8125", "0.3333"]
    assert describe_target({"slope_deg": -11.25, "curve_deg": 0.0}) == "slope -11.25°"
    last = continuation[1].steps[-1].motion
    env = dict(last.context.axis_values, slope_deg=-11.25)
    caption = motion_caption(last.evolve(context=last.context.with_(axis_values=env)))
    assert "slope -11.25°" in caption and "λ = 1" in caption and "-11.2°" not in caption


def test_progress_png_takes_the_api_points(continuation):
    """The job's ``progress`` as the API serves it: a tutor-phase point, rejected attempts,
    the target as the job's spec (JSON: missing keys, nulls)."""
    _, res = continuation
    pts = [{"seq": 0, "phase": "tutor", "wall_time": 1.7, "lam": 0.0, "lam_reached": 0.0, "environment": {},
            "iterations": 41, "accepted": True, "status": "tutor succeeded"}]
    for i, r in enumerate(res.records, 1):
        d = asdict(r)
        pts.append({**d, "seq": i, "phase": "extrapolate"})
    pts.insert(2, {**pts[2], "accepted": False, "lam": 0.9, "status": "Maximum_Iterations_Exceeded"})
    assert_png(progress_png(pts, {"slope_deg": 4.0, "curve_deg": 0.0, "friction": 0.7, "gravity": None}))
    assert_png(progress_png(pts, None))  # no target: the environment values that vary are drawn


def test_progress_png_without_points_says_so():
    assert_png(progress_png([], {"slope_deg": 5.0}))
    assert_png(progress_png([{"phase": "tutor", "wall_time": 2.0, "lam": 0.0, "lam_reached": 0.0,
                              "environment": {}, "iterations": 30, "accepted": True}], {"curve_deg": 90}))


GOOD = {"wall_time": 0.1, "lam": 0.0, "lam_reached": 0.0, "accepted": True, "environment": {"slope_deg": 0.0}}


@pytest.mark.parametrize("progress, target, needle", [
    ("not a list", None, "list of records"),
    ([1.0], None, "progress[0] must be a record"),
    ([{"lam": 0.1}], None, "lacks ['wall_time', 'lam_reached', 'accepted']"),
    ([GOOD, {**GOOD, "wall_time": float("nan")}], None, "progress[1].wall_time must be finite"),
    ([{**GOOD, "lam": "0.5"}], None, "progress[0].lam must be a number"),
    ([{**GOOD, "accepted": 1}], None, "progress[0].accepted must be true or false"),
    ([{**GOOD, "phase": "warmup"}], None, "progress[0].phase"),
    ([{**GOOD, "environment": [1, 2]}], None, "environment must be a mapping"),
    ([{**GOOD, "environment": {"slope_deg": float("inf")}}], None, "environment.slope_deg must be finite"),
    ([GOOD], {"slope": 5}, "unknown target keys ['slope']"),
    ([GOOD], [5.0], "target must be a mapping"),
    ([GOOD], {"gravity": float("nan")}, "target.gravity must be finite"),
])
def test_progress_png_rejects_bad_input(progress, target, needle):
    with pytest.raises(PlotError) as e:
        progress_png(progress, target)
    assert needle in str(e.value)


# --- ground reactions ----------------------------------------------------------------------


def test_grf_png_of_a_tutor_and_of_a_lambda_optimum(tutor, continuation):
    assert_png(grf_png(tutor))
    assert_png(grf_png(continuation[1].steps[-1].motion))


def test_grf_and_residuals_refuse_a_motion_without_wrenches(tutor):
    raw = tutor.evolve(wrenches=None, report=None)
    for f in (grf_png, residuals_png, residual_series):
        with pytest.raises(PlotError, match="motion has no contact wrenches"):
            f(raw)
        with pytest.raises(PlotError, match="expected a motion"):
            f({"frames": []})


# --- residuals -----------------------------------------------------------------------------


def test_residual_series_of_plausible_motions_is_below_tolerance_and_is_the_reports(tutor, continuation):
    for m in (tutor, continuation[1].steps[-1].motion):
        s = residual_series(m)
        # the motion's dynamics samples: every frame of the cycle and the midpoint after it
        S = 2 * (m.T - 2)
        assert s.time.shape == (S,) and s.ours.shape == s.mujoco.shape == (6, S)
        np.testing.assert_allclose(s.time[::2], m.times[1:-1])
        np.testing.assert_allclose(s.time[1::2], m.times[1:-1] + 0.5 * m.dt)
        assert s.ours_force_rel.max() < 1e-6 and s.ours_moment_rel.max() < 1e-6
        assert s.mujoco_force_rel.max() < 1e-6 and s.mujoco_moment_rel.max() < 1e-6
        assert np.abs(s.mujoco - s.ours)[3:].max() < 1e-9 * s.weight_N  # MuJoCo agrees, frame by frame
        rep = report(m)  # the series' maxima are the plausibility report's numbers
        assert s.ours_force_rel.max() == pytest.approx(rep["root_residual"]["max_force_rel_weight"], rel=1e-12)
        assert s.ours_moment_rel.max() == pytest.approx(rep["root_residual"]["max_moment_rel_weight_leg"],
                                                        rel=1e-12)
        assert s.weight_N == pytest.approx(rep["body_weight_N"]) and s.leg_m == pytest.approx(rep["leg_length_m"])


def test_residual_series_sees_missing_ground_reaction(tutor):
    """10 % less ground reaction: the residual force per sample is exactly the 10 % taken away."""
    from solver.trajectory import dynamics_samples

    base, weak = residual_series(tutor), residual_series(tutor.evolve(wrenches=0.9 * tutor.wrenches))
    missing = 0.1 * dynamics_samples(tutor).wrenches[:, 3:].sum(axis=0)
    np.testing.assert_allclose(weak.ours[3:] - base.ours[3:], missing, atol=1e-8)
    np.testing.assert_allclose(weak.mujoco[3:], weak.ours[3:], atol=1e-8)
    assert weak.ours_force_rel.min() > 1e-3


def test_residuals_png(tutor, continuation):
    assert_png(residuals_png(tutor))
    assert_png(residuals_png(continuation[1].steps[-1].motion.evolve(wrenches=0.9 * tutor.wrenches)))
    with pytest.raises(PlotError, match="tolerance must be positive"):
        residuals_png(tutor, tolerance=0.0)


# --- command line --------------------------------------------------------------------------


def test_motionx_plot_writes_the_pngs(tutor_file, tmp_path):
    r = motionx("plot", tutor_file, "--out", tmp_path / "all")
    assert r.returncode == 0, r.stderr
    info = json.loads(r.stdout)
    assert info["files"] == ["grf.png", "residuals.png", "filmstrip.png"]
    assert info["frames"] == Motion.load(tutor_file).T
    for name in info["files"]:
        assert_png((tmp_path / "all" / name).read_bytes())
    r = motionx("plot", tutor_file, "--kind", "grf", "--out", tmp_path / "grf")
    assert r.returncode == 0, r.stderr
    assert sorted(p.name for p in (tmp_path / "grf").iterdir()) == ["grf.png"]


def test_motionx_plot_draws_the_filmstrip_of_any_motion(tutor, tmp_path):
    """The filmstrip needs no ground reactions: a motion without them (a capture) is drawn too."""
    tutor.evolve(wrenches=None, report=None).save(tmp_path / "raw.json")
    r = motionx("plot", tmp_path / "raw.json", "--kind", "filmstrip", "--out", tmp_path / "film")
    assert r.returncode == 0, r.stderr
    assert json.loads(r.stdout)["files"] == ["filmstrip.png"]
    assert_png((tmp_path / "film" / "filmstrip.png").read_bytes())


def test_motionx_plot_refuses_bad_input(tutor, tutor_file, tmp_path):
    tutor.evolve(wrenches=None, report=None).save(tmp_path / "raw.json")
    r = motionx("plot", tmp_path / "raw.json", "--out", tmp_path / "out")
    assert r.returncode == 2 and "motion has no contact wrenches" in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and not (tmp_path / "out").exists()
    r = motionx("plot", tmp_path / "missing.json", "--out", tmp_path / "out")
    assert r.returncode == 2 and "not found" in r.stderr
    r = motionx("plot", tutor_file, "--out", tutor_file)
    assert r.returncode == 2 and "not a directory" in r.stderr
    r = motionx("plot", tutor_file, "--kind", "cop", "--out", tmp_path / "out")
    assert r.returncode == 2 and "invalid choice" in r.stderr


def test_motionx_extrapolate_writes_the_final_motions_plots(tutor_file, tmp_path):
    out = tmp_path / "ex"
    r = motionx("extrapolate", tutor_file, "--friction", "0.7", "--delta0", "0.5", "--out", out, "--quiet")
    assert r.returncode == 0, r.stderr
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "succeeded" and summary["final"]["plots"] == ["grf.png", "residuals.png",
                                                                              "filmstrip.png"]
    for name in ("progress.png", "grf.png", "residuals.png", "filmstrip.png"):
        assert_png((out / name).read_bytes())
    # the residual plot is of the last λ motion, which is plausible
    last = Motion.load(out / summary["final"]["file"])
    assert last.provenance["lambda"] == 1.0 and residual_series(last).ours_force_rel.max() < 1e-6


def test_progress_title_says_whose_tutor_it_is(continuation):
    """The job that made its tutor says how long it took; a job that took it from the store
    (made by another job: service.jobs) says so, not "made first" with 0 iterations."""
    _, res = continuation
    ext = [{**asdict(r), "phase": "extrapolate"} for r in res.records]
    made = {"phase": "tutor", "wall_time": 31.8, "lam": 0.0, "lam_reached": 0.0, "environment": {},
            "iterations": 224, "accepted": True, "status": "tutor succeeded"}
    taken = {**made, "wall_time": 12.4, "iterations": 0, "status": "tutor made by job j_0123"}
    titles = [progress_figure([p, *ext], {"slope_deg": 4.0})._suptitle.get_text() for p in (made, taken)]
    assert titles[0].endswith("(tutor made first: 31.8 s, 224 iterations)")
    assert titles[1].endswith("(tutor made by another job, taken from the store after 12.4 s)")
