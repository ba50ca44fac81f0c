"""The homotopy axes registry (solver.axes): one source for names, units, bounds, defaults and
effects — the target, the service's schemas, the CLI flags and the plots read it; and the
speed axis (frame interval as an NLP parameter)."""

from __future__ import annotations

import math

import numpy as np
import pytest
import shared_tutors

from solver import axes as registry
from solver.axes import Target, environment_at, guide_at, nlp_at
from solver.axes.speed import cadence_factor, stride_factor
from solver.environment import STANDARD_GRAVITY, Environment


def test_the_registry_has_every_axis_with_unit_bounds_default_and_doc():
    assert registry.names() == ("slope_deg", "curve_deg", "friction", "gravity", "speed_scale", "step_height_m",
                                "step_going_m")
    for ax in registry.axes():
        assert ax.doc and ax.cli.startswith("--") and ax.lo < ax.hi
        if ax.default is not None:
            assert ax.check(ax.default) == ax.default  # the default lies inside the bounds
        d = ax.describe()
        assert d["name"] == ax.name and d["minimum"] == ax.lo and d["maximum"] == ax.hi
    assert [a.name for a in registry.axes() if a.grid] == ["slope_deg", "curve_deg", "speed_scale"]


@pytest.mark.parametrize("kwargs, words", [
    ({"slope_deg": 95.0}, r"slope_deg must be within \(-89, 89\) °, got 95"),
    ({"slope_deg": 89.0}, r"slope_deg must be within \(-89, 89\)"),  # open bound
    ({"curve_deg": float("nan")}, "curve_deg must be finite"),
    ({"friction": -1.0}, r"friction must be within \(0, 10\]"),
    ({"gravity": 0.0}, r"gravity must be within \(0, 100\] m/s²"),
    ({"speed_scale": 2.5}, r"speed_scale must be within \[0.5, 2\] ×, got 2.5"),
    ({"speed_scale": "fast"}, "speed_scale must be a number"),
    ({"height": 1.0}, "unknown axis 'height'; the axes are slope_deg, curve_deg"),
])
def test_targets_out_of_bounds_are_refused_with_the_axis_its_bounds_and_unit(kwargs, words):
    with pytest.raises(ValueError, match=words):
        Target(**kwargs)


def test_target_is_a_value_over_the_registered_axes():
    t = Target(slope_deg=5.0, speed_scale=1.2)
    assert t.slope_deg == 5.0 and t.curve_deg == 0.0 and t.friction is None and t.speed_scale == 1.2
    assert t == Target(speed_scale=1.2, slope_deg=5.0) and hash(t) == hash(Target(speed_scale=1.2, slope_deg=5.0))
    assert [a.name for a, _ in t.active()] == ["speed_scale", "slope_deg"]  # application order
    assert Target(slope_deg=0.0, speed_scale=1.0).is_identity() and not Target(friction=1.0).is_identity()
    assert t.to_dict() == {"slope_deg": 5.0, "curve_deg": 0.0, "friction": None, "gravity": None, "speed_scale": 1.2,
                           "step_height_m": 0.0, "step_going_m": None}
    with pytest.raises(AttributeError):
        t.slope_deg = 3.0  # type: ignore[misc]


def test_environment_values_report_every_axis_and_gravity_is_standard():
    env, values = environment_at(Environment(), Target(speed_scale=1.44), 0.5)
    assert env == Environment() and env.gravity == (0.0, 0.0, -STANDARD_GRAVITY)
    assert values == pytest.approx({"slope_deg": 0.0, "curve_deg": 0.0, "friction": 1.0,
                                    "gravity": STANDARD_GRAVITY, "speed_scale": 1.22, "step_height_m": 0.0,
                                    "step_going_m": 0.0})


def test_speed_splits_into_stride_and_cadence_and_scales_the_frame_interval():
    s = 1.21
    assert stride_factor(s) * cadence_factor(s) == pytest.approx(s)  # speed = stride × cadence
    assert nlp_at(Target(speed_scale=s), 1.0)["frame_interval"] == pytest.approx(1 / 1.1)
    assert nlp_at(Target(speed_scale=s), 0.0)["frame_interval"] == 1.0
    assert nlp_at(Target(curve_deg=30.0), 0.5)["heading_change_deg"] == pytest.approx(15.0)
    T = 9
    q = np.zeros((16, T))
    q[0] = np.linspace(0.3, 1.3, T)
    q[1] = 0.02 * np.sin(np.linspace(0, 6, T))
    q[2] = 0.9
    g = guide_at(q, Target(speed_scale=s), 1.0)
    np.testing.assert_allclose(g[:2] - g[:2, :1], 1.1 * (q[:2] - q[:2, :1]))  # stride × √s from frame 0
    np.testing.assert_array_equal(g[2:], q[2:])


def test_service_schema_and_cli_flags_are_derived_from_the_registry():
    from service.plots import TARGET_KEYS
    from service.schemas import GridIn, LibraryTargetIn, TargetIn
    from solver.outputs import ENVIRONMENT_KEYS

    props = TargetIn.model_json_schema()["properties"]
    assert tuple(props) == registry.names() == ENVIRONMENT_KEYS == TARGET_KEYS
    sp = props["speed_scale"]
    assert (sp["minimum"], sp["maximum"], sp["default"]) == (0.5, 2.0, 1.0)
    assert props["slope_deg"]["exclusiveMinimum"] == -89.0
    assert set(GridIn.model_fields) == set(LibraryTargetIn.model_fields) == {"slope_deg", "curve_deg", "speed_scale"}
    with pytest.raises(ValueError, match="changes nothing"):
        TargetIn(speed_scale=1.0)
    with pytest.raises(ValueError, match="less than or equal to 2"):
        TargetIn(speed_scale=2.5)

    from test_cli_conventions import run

    code, out, _ = run("extrapolate", "--help")
    assert code == 0 and all(ax.cli in out for ax in registry.axes())
    code, _, err = run("extrapolate", "nowhere.json", "--speed-scale", "3", "--out", "x")
    assert code == 2 and "speed_scale must be within [0.5, 2] ×, got 3" in err
    code, out, _ = run("library", "--help")
    assert code == 0 and "--speed-scales" in out and "--slopes" in out


# --- the speed axis on the DeepMimic walk ---------------------------------------------------


@pytest.fixture(scope="module")
def tutor(shared_data):
    res = shared_tutors.tutor(shared_data)
    assert res.status == "succeeded", res.message
    return res.motion


def test_a_faster_walk_is_realistic_with_a_shorter_cycle_and_a_longer_stride(tutor):
    from solver.continuation import StepControl, extrapolate

    s = 1.15
    res = extrapolate(tutor, Target(speed_scale=s), StepControl())
    assert res.status == "succeeded" and res.lam_reached == 1.0, res.message
    assert all(st.motion.report["plausible"] and st.motion.report["realism"]["passed"] for st in res.steps)
    m = res.steps[-1].motion
    assert m.T == tutor.T and m.fps == pytest.approx(tutor.fps * math.sqrt(s))  # frame count kept
    assert m.context.axis_values["speed_scale"] == pytest.approx(s)
    assert m.provenance["target"]["speed_scale"] == s

    def speed(q, fps):
        return float(np.linalg.norm(q[:2, -2] - q[:2, 0])) * fps / (q.shape[1] - 2)

    # the optimum walks faster by about s (the guide's stride × √s, the cycle ÷ √s)
    assert speed(m.q, m.fps) / speed(tutor.q, tutor.fps) == pytest.approx(s, rel=0.03)


# --- the terrain axis: stairs -----------------------------------------------------------------


def _two_steps() -> np.ndarray:
    """A cyclic foot schedule of 21 frames (19 distinct), two steps: the right foot's stance from
    frame 18 over the cycle's end to frame 10, the left's 8..18."""
    T, P = 21, 19
    B = np.zeros((2, T), dtype=bool)
    B[0, :P] = [t <= 10 or t >= 18 for t in range(P)]
    B[1, :P] = [8 <= t <= 18 for t in range(P)]
    B[:, P:] = B[:, :2]
    return B


def test_stair_heights_put_successive_stances_on_successive_treads():
    from solver.environment import stair_heights, stair_rise

    B = _two_steps()
    P = B.shape[1] - 2
    H = stair_heights(B, 0.1)
    assert stair_rise(B, 0.1) == pytest.approx(0.2)  # two stances per cycle
    np.testing.assert_allclose(H[1, 8:19], 0.0)  # the first stance of the cycle: tread 0
    np.testing.assert_allclose(H[0, 18], 0.1)  # the next: tread 1
    np.testing.assert_allclose(H[0, :11], -0.1)  # the right stance begun in the previous cycle
    np.testing.assert_allclose(H[:, P:], H[:, :2] + 0.2)  # frames T-2, T-1: frames 0, 1 one cycle up
    np.testing.assert_allclose(H[0, 11:18], -0.1)  # swinging: the lower of the treads it left and reaches
    np.testing.assert_array_equal(stair_heights(B, 0.0), 0.0)


def test_a_small_stair_is_climbed_realistically_with_every_contact_on_its_tread(tutor):
    from solver.continuation import StepControl, extrapolate
    from solver.environment import ground_of
    from solver.kinematics import contact_points
    from solver.motion import FEET

    step = 0.05
    res = extrapolate(tutor, Target(step_height_m=step), StepControl())
    assert res.status == "succeeded" and res.lam_reached == 1.0, res.message
    assert all(st.motion.report["plausible"] and st.motion.report["realism"]["passed"] for st in res.steps)
    m = res.steps[-1].motion
    assert m.environment.step_height_m == pytest.approx(step)  # the motion stores its terrain
    G = ground_of(m)
    assert np.ptp(G) >= step - 1e-12  # the ground is not flat
    cp = contact_points(m.character, m.q)
    side = {s: k for k, s in enumerate(FEET)}
    gz = G[[side[c.side] for c in m.character.contacts]]
    z = cp[:, 2, :] - gz
    assert np.abs(z[m.contacts]).max() < 1e-3  # active contacts on their treads (1 mm)
    assert z.min() > -1e-3  # nothing below its ground
    assert m.q[2, -2] - m.q[2, 0] == pytest.approx(2 * step, abs=1e-6)  # the root climbs two risers per cycle
    # the report carries one tread per stance for a preview to draw, at successive heights
    treads = m.report["environment"]["treads"]
    assert m.report["environment"]["step_height_m"] == pytest.approx(step) and len(treads) >= 3
    heights = sorted({round(t["center"][2], 9) for t in treads})
    assert np.allclose(np.diff(heights), step)


def test_stair_flight_puts_each_step_on_its_own_tread_and_the_nosings_on_the_higher_edge():
    from solver.environment import DEFAULT_GOING_M, Environment, stair_flight, stair_indices, walker_going

    B = _two_steps()
    T, P = B.shape[1], B.shape[1] - 2
    left, reached, n = stair_indices(B)
    assert n == 2 and left[1, 8] == reached[1, 8] == 0 and left[0, 18] == 1 and left[0, 0] == -1
    assert left[0, 12] == -1 and reached[0, 12] == 1  # a swing passes over one tread onto the next
    np.testing.assert_array_equal(left[:, P:], left[:, :2] + 2)
    # a walk along +x turned by 30°, its stance feet 0.3 m apart per step
    q = np.zeros((16, T))
    heading = math.radians(30.0)
    u = np.array([math.cos(heading), math.sin(heading)])
    q[:2] = np.outer(u, np.arange(T) * 0.6 / P)
    assert walker_going(q, B) == pytest.approx(0.3)
    feet = np.zeros((2, 2, T))
    for k in range(2):
        feet[k] = np.outer(u, 0.3 * left[k] + 0.12)  # each stance foot 0.12 m past its tread's start
    f = stair_flight(feet, B, 0.17, 0.28, q=q)
    assert f.heading == pytest.approx(heading) and f.going == 0.28 and f.n == 2
    s = f.along(np.moveaxis(feet, 1, 0))
    mid = (left + 0.5) * 0.28
    assert np.mean((s - mid)[:, :P][B[:, :P]]) == pytest.approx(0.0, abs=1e-12)  # centred on average
    assert f.nosing(1) == (pytest.approx(0.28), pytest.approx(0.17))  # going up: the front edge of tread 1
    down = stair_flight(None, B, -0.17, 0.28, at=f.at)
    assert down.nosing(1) == (pytest.approx(0.28), pytest.approx(0.0))  # going down: the edge of tread 0
    assert down.ground(np.array([0.27, 0.29])).tolist() == pytest.approx([0.0, -0.17])
    assert DEFAULT_GOING_M == 0.28 and Environment.from_dict(Environment(step_height_m=0.17, step_going_m=0.28,
                                                                         stairs_at=f.at).to_dict()).stairs_at == f.at
    with pytest.raises(ValueError, match="going"):
        stair_flight(feet, B, 0.17, 0.0, q=q)
    with pytest.raises(ValueError, match="step_going_m"):
        Environment(step_going_m=-0.1)
