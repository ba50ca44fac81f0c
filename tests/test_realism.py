"""Realism checks (solver/realism.py): physics that holds between the frames.

The smooth motions are built with exact derivatives (sums of sines; a root on a circular
arc) and the ground wrenches they need from inverse dynamics on those derivatives, so they
obey the equations of motion everywhere, not only at the frames. The jittery motions add a
Nyquist-rate zig-zag (±3° every other frame) to the pelvis yaw and every joint and recompute
the wrenches with the old validator's scheme (RNEA on central differences): the old root
residual is exactly zero, the new checks must see it.
"""

from __future__ import annotations

import json
import math
import zlib

import numpy as np
import pytest

from solver.character import Character, Segment, reference, root_dofs
from solver.dynamics import rnea
from solver.kinematics import finite_differences, standing_leg_length
from solver.motion import Motion, MotionContext
from solver.plausibility import report
from solver.realism import RealismLimits, cycle_of, momentum_from_positions, newton_euler, realism_report, refinement

G = np.array([0.0, 0.0, -9.81])


def smooth_walk(N: int = 30, fps: float = 15.0, curve_deg: float = 45.0, speed: float = 0.5,
                provenance: dict | None = None) -> Motion:
    """A cyclic 'gliding walk' of HalfBoy (both feet loaded, half the wrench each): N distinct
    frames (T = N + 2), the root on a circular arc turning ``curve_deg`` per cycle; ``provenance``
    as a motion file's (its context keys read as the file loader reads them)."""
    ch = reference("halfboy")
    T, P = N + 2, N / fps
    t = np.arange(T) / fps
    w = 2 * math.pi / P
    q, qd, qdd = (np.zeros((ch.n, T)) for _ in range(3))

    def sine(i, a, k, ph, off=0.0):
        q[i] += off + a * np.sin(k * w * t + ph)
        qd[i] += a * k * w * np.cos(k * w * t + ph)
        qdd[i] += -a * (k * w) ** 2 * np.sin(k * w * t + ph)

    psid = math.radians(curve_deg) / P
    q[3], qd[3] = psid * t, psid
    if psid:
        R = speed / psid
        q[0], qd[0], qdd[0] = R * np.sin(psid * t), speed * np.cos(psid * t), -speed * psid * np.sin(psid * t)
        q[1], qd[1], qdd[1] = R * (1 - np.cos(psid * t)), speed * np.sin(psid * t), speed * psid * np.cos(psid * t)
    else:
        q[0], qd[0] = speed * t, speed
    sine(2, 0.01, 2, 0.3, off=standing_leg_length(ch) - 0.02)
    sine(3, 0.03, 1, 0.1)
    sine(4, 0.02, 2, 0.5, off=0.05)
    sine(5, 0.02, 1, 1.0)
    for side, ph in (("r", 0.0), ("l", math.pi)):
        sine(ch.index(f"hip_flexion_{side}"), 0.25, 1, ph, off=0.1)
        sine(ch.index(f"hip_adduction_{side}"), 0.04, 1, ph + 0.5)
        sine(ch.index(f"hip_rotation_{side}"), 0.03, 1, ph + 1.0)
        sine(ch.index(f"knee_angle_{side}"), 0.3, 1, ph - 1.2, off=0.4)
        sine(ch.index(f"ankle_angle_{side}"), 0.15, 1, ph + 0.7)
    h0 = rnea(ch, q, qd, qdd, G).h0
    ctx, prov = MotionContext.split({"environment_values": {"curve_deg": curve_deg}} if provenance is None
                                    else provenance)
    return Motion(ch, fps, q, contacts=np.ones((len(ch.contacts), T), bool), wrenches=np.stack([0.5 * h0] * 2),
                  provenance=prov, context=ctx)


def zigzag(m: Motion, eps_deg: float = 3.0) -> Motion:
    """±eps on the pelvis yaw and every joint, alternating each frame; wrenches from the old
    scheme (RNEA on central differences at the interior frames, overlap frames copied)."""
    q = np.array(m.q)
    q[[3, *range(6, m.n)]] += math.radians(eps_deg) * (-1.0) ** np.arange(m.T)
    qd, qdd = finite_differences(q, m.dt)
    h0 = rnea(m.character, q[:, 1:-1], qd, qdd, G).h0
    W = np.zeros((2, 6, m.T))
    W[:, :, 1:-1] = 0.5 * h0
    W[:, :, 0], W[:, :, -1] = W[:, :, -2], W[:, :, 1]
    return m.evolve(q=q, wrenches=W)


def realism(m: Motion, mu: float = 1.0, g=G) -> dict:
    return realism_report(m, g, mu, m.character.total_mass * 9.81, standing_leg_length(m.character))


# --- smooth passes, the zig-zag the old validator accepts fails ------------------------------------


@pytest.mark.parametrize("fps", [15.0, 30.0])
def test_smooth_motion_passes_and_its_zigzag_that_the_old_validator_accepts_fails(fps):
    smooth = smooth_walk(N=int(2 * fps), fps=fps)
    rs = realism(smooth)
    assert rs["passed"] and not rs["warnings"], rs["failed"]
    c = rs["checks"]
    assert c["newton_force"]["value"] < 0.01 and c["newton_moment"]["value"] < 0.01  # differences of a smooth walk
    assert c["refined_force"]["value"] < 0.01 and c["cycle_impulse"]["value"] < 1e-4

    jit = zigzag(smooth)
    old = report(jit)
    assert old["checks"]["root_force"] and old["checks"]["root_moment"]  # the old EOM hold exactly
    assert old["root_residual"]["max_force_rel_weight"] < 1e-9
    rj = old["realism"]
    assert not rj["passed"] and not old["plausible"]
    # between the frames the zig-zag needs forces the ground does not give
    assert {"newton_force", "newton_moment", "refined_force", "refined_moment", "cycle_impulse", "foot_spin",
            "torsional_friction"} <= set(rj["failed"])
    assert rj["checks"]["refined_force"]["value"] > 0.5 and rj["checks"]["newton_force"]["value"] > 0.2  # BW
    assert old["checks"]["realism_refined_force"] is False
    assert any(p.startswith("realism failure: refined_force") for p in old["problems"])
    if fps == 30.0:
        assert "ground_force_rate" in rj["failed"]


def lowpass_cycle(m: Motion, harmonics: int) -> Motion:
    """The first ``harmonics`` Fourier harmonics of a cyclic motion: repeating coordinates
    directly; root x, y, yaw through their per-frame increments in the heading frame (periodic
    under the cycle's transform), integrated back."""
    cyc, _ = cycle_of(m)
    N, q = cyc.N, m.q

    def lp(x):
        X = np.fft.rfft(x, axis=-1)
        X[..., harmonics + 1:] = 0
        return np.fft.irfft(X, n=N, axis=-1)

    out = np.empty_like(q)
    per = [i for i in range(m.n) if i not in (0, 1, 3)]
    base = lp(q[per, :N])
    out[per] = np.hstack([base, base[:, :2]])
    dyaw = np.r_[lp(np.diff(q[3])[:N]), 0.0]
    dp = np.diff(q[:2], axis=1)[:, :N]
    c, s = np.cos(q[3, :N]), np.sin(q[3, :N])
    v = lp(np.stack([c * dp[0] + s * dp[1], -s * dp[0] + c * dp[1]]))
    dyaw[N], v = dyaw[0], np.hstack([v, v[:, :1]])
    out[3, 0], out[:2, 0] = q[3, 0], q[:2, 0]
    for t in range(m.T - 1):
        c, s = math.cos(out[3, t]), math.sin(out[3, t])
        out[:2, t + 1] = out[:2, t] + [c * v[0, t] - s * v[1, t], s * v[0, t] + c * v[1, t]]
        out[3, t + 1] = out[3, t] + dyaw[t]
    return m.evolve(q=out)


def test_real_walk_smoothed_passes_the_dynamics_checks_and_its_zigzag_fails(shared_data):
    """DeepMimic walk, HalfBoy at 15 fps: the kinematic fit of one cycle (the pipeline's
    simplification) keeping 4 harmonics, its wrenches from inverse dynamics on the periodic
    spline through the frames (split between the feet in contact). Newton–Euler from positions,
    the cycle's impulse and the refinement hold; the same walk with the zig-zag fails them.
    (Its free moment, 0.033 BW·m about the centre of pressure, exceeds the torsional limits: HalfBoy
    has no arms to cancel the legs' vertical angular momentum — the optimizer must shape that.)"""
    from solver.io import load_trial
    from solver.pipeline import simplified_motion
    from solver.realism import refined

    d = shared_data / "deepmimic_humanoid3d_walk"
    sim = simplified_motion(load_trial([d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt"]), fps=15.0)
    m = lowpass_cycle(sim.evolve(wrenches=np.zeros((2, 6, sim.T))), 4)
    cyc, _ = cycle_of(m)
    r = refined(m, cyc, 1)
    frames = r["s"].astype(int)  # 1 .. T-1
    h0 = rnea(m.character, r["q"], r["qd"], r["qdd"], G).h0
    B = m.foot_contact()[:, frames].astype(float)
    B /= np.maximum(B.sum(axis=0), 1.0)
    W = np.zeros((2, 6, m.T))
    W[:, :, frames] = B[:, None, :] * h0[None]
    W[:, :, 0] = cyc.apply_wrench(W[:, :, -2:-1], -1)[:, :, 0]
    smooth = m.evolve(wrenches=W, context=MotionContext())
    dynamics = ("newton_force", "newton_moment", "cycle_impulse", "cycle_angular_impulse", "refined_force",
                "refined_moment", "total_ground_force", "ground_force_rate", "foot_spin")
    rs = realism(smooth)
    assert not set(dynamics) & set(rs["failed"]), rs["failed"]
    assert rs["checks"]["newton_force"]["value"] < 0.03 and rs["checks"]["refined_force"]["value"] < 0.03
    jit = zigzag(smooth)
    old = report(jit)
    assert old["root_residual"]["max_force_rel_weight"] < 1e-9
    assert {"newton_force", "refined_force", "refined_moment"} <= set(old["realism"]["failed"])


# --- known answers -----------------------------------------------------------------------------------


def test_free_fall_has_no_error():
    """Joints held, root ballistic, no ground wrench: every figure is zero (open motion)."""
    ch = reference("halfboy")
    T, fps = 12, 15.0
    t = np.arange(T) / fps
    q = np.zeros((ch.n, T))
    q[6:] = np.linspace(-0.2, 0.3, ch.n - 6)[:, None]
    q[0], q[1], q[2] = 1.2 * t, -0.3 * t, 1.5 + 2.0 * t - 0.5 * 9.81 * t**2
    q[3], q[4], q[5] = 0.4, 0.1, -0.05
    m = Motion(ch, fps, q, wrenches=np.zeros((2, 6, T)))
    cyc, note = cycle_of(m)
    assert cyc is None and "open" in note
    r = realism(m)
    assert r["passed"], r["failed"]
    for name in ("newton_force", "newton_moment", "cycle_impulse", "cycle_angular_impulse", "refined_force",
                 "refined_moment"):
        assert r["checks"][name]["value"] < 1e-9, name


def brick() -> Character:
    """One rigid body (10 kg, principal moments 0.3, 0.2, 0.15 kg·m²) with the six root DOF."""
    body = Segment("body", None, np.zeros(3), root_dofs(), 10.0, np.zeros(3), np.diag([0.3, 0.2, 0.15]))
    return Character("brick", (body,))


def test_body_spinning_at_a_constant_rate_keeps_its_angular_momentum():
    ch = brick()
    T, fps, rate = 20, 15.0, 12.0  # rad/s about the body's x axis: 46° per frame
    t = np.arange(T) / fps
    q = np.zeros((ch.n, T))
    q[0], q[2] = 0.7 * t, 1.0 + 0.2 * t
    q[3], q[4], q[5] = 0.6, -0.3, rate * t
    m = Motion(ch, fps, q, wrenches=np.zeros((2, 6, T)))
    L = momentum_from_positions(m)["L"]
    axis = np.array([[math.cos(0.6) * math.cos(-0.3)], [math.sin(0.6) * math.cos(-0.3)], [-math.sin(-0.3)]])
    np.testing.assert_allclose(L, 0.3 * rate * np.repeat(axis, T - 1, axis=1), atol=1e-12)
    ne = newton_euler(m, np.zeros(3), ch.total_mass * 9.81, 1.0, None)
    assert ne["force_rel_weight"].max() < 1e-12 and ne["moment_rel_weight_leg"].max() < 1e-12
    rf = refinement(m, np.zeros(3), ch.total_mass * 9.81, 1.0, None, 6)
    assert rf["force_rel_weight"].max() < 1e-9 and rf["moment_rel_weight_leg"].max() < 1e-9
    r = realism(m, g=np.zeros(3))  # no feet: the contact checks are skipped, and say so
    assert r["passed"] and "foot_spin" not in r["checks"] and any("no foot boxes" in n for n in r["notes"])


def test_whole_body_turning_rigidly_keeps_its_vertical_angular_momentum():
    """HalfBoy held rigid, turning about the vertical at 90°/s: about its centre of mass its
    angular momentum keeps its vertical component and its length (the horizontal part turns)."""
    ch = reference("halfboy")
    T, fps = 16, 15.0
    q = np.zeros((ch.n, T))
    q[2] = 0.6
    q[6:] = 0.2
    q[3] = math.radians(90.0) * np.arange(T) / fps
    L = momentum_from_positions(Motion(ch, fps, q))["L"]
    assert abs(L[2]).min() > 0.1
    np.testing.assert_allclose(L[2], L[2, 0], rtol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(L, axis=0), np.linalg.norm(L[:, 0]), rtol=1e-12)


def test_a_loaded_foot_turning_10_degrees_per_frame_is_flagged():
    fast = realism(smooth_walk(curve_deg=300.0))  # 150°/s = 10° per frame at 15 fps, feet loaded 0.5 BW
    assert fast["failed"] == ["foot_spin"]
    assert fast["checks"]["foot_spin"]["value"] == pytest.approx(150.0, rel=0.15)
    slow = realism(smooth_walk(curve_deg=120.0))  # 4° per frame
    assert slow["passed"] and slow["checks"]["foot_spin"]["value"] < 75.0


def test_free_moment_beyond_torsional_friction_and_on_an_unloaded_foot_fail():
    m = smooth_walk()
    bw = m.character.total_mass * 9.81
    W = np.array(m.wrenches)
    W[0, 2] += 0.02 * bw  # equal and opposite free moments: the total (Newton–Euler) is unchanged
    W[1, 2] -= 0.02 * bw
    r = realism(m.evolve(wrenches=W))
    assert r["failed"] == ["torsional_friction"]  # 0.02 BW·m > μ ρ f_z ≈ 0.009 BW·m, < 0.03 BW·m
    W[0, 2] += 0.02 * bw
    W[1, 2] -= 0.02 * bw
    assert set(realism(m.evolve(wrenches=W))["failed"]) == {"torsional_friction", "free_moment"}
    # the left foot carries no force but a pure vertical moment of 1 N·m
    W = np.array(m.wrenches)
    W[0] += W[1]
    W[1] = 0.0
    W[1, 2] = 1.0
    W[0, 2] -= 1.0
    r = realism(m.evolve(wrenches=W))
    assert {"unloaded_foot_moment", "torsional_friction"} <= set(r["failed"])
    W[1, 2], W[0, 2] = 0.0, W[0, 2] + 1.0
    W[1, 0] += 2.0  # a tilting moment of 2 N·m with no load: not torsion, still a moment from nothing
    W[0, 0] -= 2.0
    assert realism(m.evolve(wrenches=W))["failed"] == ["unloaded_foot_moment"]


def test_heading_change_is_checked_against_the_request():
    m = smooth_walk(curve_deg=45.0, provenance={"environment_values": {"curve_deg": 90.0}})
    r = realism(m)
    assert r["failed"] == ["heading"] and r["checks"]["heading"]["value"] == pytest.approx(45.0, abs=1e-9)
    m = smooth_walk(curve_deg=45.0, provenance={"target": {"curve_deg": 90.0}, "lambda": 0.5})
    assert realism(m)["passed"]
    r = realism(smooth_walk(curve_deg=45.0, provenance={}))
    assert "heading" not in r["checks"] and any("no requested curve" in n for n in r["notes"])
    # a λ optimum of a tutor that itself turns 5°: λ·curve + the tutor's turn
    both = {"environment_values": {"curve_deg": 40.0}, "tutor_heading_change_deg": 5.0, "heading_change_deg": 45.0}
    assert realism(smooth_walk(curve_deg=45.0, provenance=both))["passed"]
    both["tutor_heading_change_deg"] = 0.0  # the recorded parts disagree with the motion's turn
    r = realism(smooth_walk(curve_deg=45.0, provenance=both))
    assert r["failed"] == ["heading"] and "tutor_heading_change_deg" in r["checks"]["heading"]["what"]
    r = realism(smooth_walk(curve_deg=45.0, provenance={"heading_change_deg": 44.5}))  # what the optimizer was asked
    assert r["passed"] and r["checks"]["heading"]["value"] == pytest.approx(0.5, abs=1e-9)
    # the typed context, as the continuation writes it: an explicit request comes first
    m = smooth_walk(curve_deg=45.0, provenance={})
    asked = m.evolve(context=MotionContext(axis_values={"curve_deg": 40.0}, tutor_heading_change_deg=5.0,
                                           heading_change_requested_deg=30.0))
    r = realism(asked)
    assert r["failed"] == ["heading"] and r["checks"]["heading"]["value"] == pytest.approx(15.0, abs=1e-9)
    assert "heading_change_requested_deg" in r["checks"]["heading"]["what"]


def test_ground_force_limits():
    """Twice the ground force (and gravity) of a smooth walk: 2.08 BW > 2 BW; a 0.5 BW step
    between two frames: 7.5 BW/s at 15 fps passes, at 30 fps (15 BW/s) fails."""
    m = smooth_walk()
    r = realism(m.evolve(wrenches=2 * m.wrenches), g=2 * G)
    assert r["failed"] == ["total_ground_force"]
    assert r["checks"]["total_ground_force"]["value"] == pytest.approx(2.08, abs=0.02)
    for fps, fails in ((15.0, False), (30.0, True)):
        m = smooth_walk(N=int(2 * fps), fps=fps)
        W = np.array(m.wrenches)
        W[:, 5, 8] += 0.25 * m.character.total_mass * 9.81  # a spike of 0.5 BW at frame 8
        r = realism(m.evolve(wrenches=W))
        assert ("ground_force_rate" in r["failed"]) == fails


# --- the cycle -------------------------------------------------------------------------------------------


def test_cycle_transform_of_a_curved_walk():
    m = smooth_walk(curve_deg=45.0)
    cyc, note = cycle_of(m)
    assert cyc is not None and cyc.N == m.T - 2 and "cyclic" in note
    assert math.degrees(cyc.dpsi) == pytest.approx(45.0, abs=1e-9)
    np.testing.assert_allclose(cyc.apply_q(m.q[:, :2], 1), m.q[:, -2:], atol=1e-12)
    np.testing.assert_allclose(cyc.apply_q(cyc.apply_q(m.q[:, :3], 2), -2), m.q[:, :3], atol=1e-12)
    # a force f at p is, one cycle later, R f at R p + d
    p, f = np.array([0.3, -0.2, 0.0]), np.array([5.0, 1.0, 200.0])
    w = cyc.apply_wrench(np.r_[np.cross(p, f), f][:, None], 1)[:, 0]
    p1 = cyc.rot() @ p + cyc.d
    np.testing.assert_allclose(w, np.r_[np.cross(p1, cyc.rot() @ f), cyc.rot() @ f], atol=1e-12)
    # after one cycle the momentum is the first one turned by Δψ (momentum from positions)
    ne = newton_euler(m, G, m.character.total_mass * 9.81, 1.0, cyc)
    np.testing.assert_allclose(ne["momentum_change_Ns"], ne["momentum_change_expected_Ns"], atol=1e-9)
    broken = np.array(m.q)
    broken[6, -2] += 0.01
    cyc2, note2 = cycle_of(m.evolve(q=broken))
    assert cyc2 is None and "do not repeat" in note2


def test_report_section_is_json_and_fast():
    m = smooth_walk()
    rep = report(m)
    text = json.dumps(rep, allow_nan=False)
    assert '"realism"' in text
    assert rep["realism"]["passed"] and rep["realism"]["limits"] == RealismLimits().__dict__
    assert all(k in rep["checks"] for k in ("realism_newton_force", "realism_refined_force", "realism_foot_spin"))
    assert rep["realism"]["time_s"] < 1.0


def test_job_and_motion_api_validation_carries_the_realism_section():
    """The report a job stores for every λ optimum and ``GET /motions/{id}/validation`` returns."""
    from service import work
    from service.jobs import validation_report

    jit = zigzag(smooth_walk())
    rep = validation_report(jit)
    assert rep["plausible"] is False and rep["checks"]["root_force"] and rep["checks"]["mujoco_agrees"]
    assert "refined_force" in rep["realism"]["failed"] and rep["checks"]["realism_refined_force"] is False
    json.dumps(rep, allow_nan=False)
    stored = zlib.compress(jit.to_json().encode())  # how the store keeps a motion
    assert work.validation(stored)["realism"]["failed"] == rep["realism"]["failed"]


# --- motionx validate ----------------------------------------------------------------------------------------


def test_validate_shows_every_realism_check(tmp_path, capsys):
    from service.cli import main

    path = tmp_path / "jittery.json"
    zigzag(smooth_walk()).save(path)
    assert main(["validate", str(path)]) == 1
    text = capsys.readouterr().out
    assert "NOT plausible" in text.splitlines()[0] and text.splitlines()[0].endswith("(halfboy, 32 frames at 15 fps)")
    assert "FAIL refined_force" in text and "ok   total_ground_force" in text and "{" not in text
    assert main(["validate", str(path), "--json"]) == 1
    rep = json.loads(capsys.readouterr().out)
    assert not rep["plausible"] and "refined_force" in rep["realism"]["failed"]
    assert rep["mujoco_replay"]["agreement_force_rel_weight"] < 1e-9


def test_optimizer_bounds_lie_strictly_inside_the_checks_limits():
    """Every bound the optimizer keeps lies strictly inside the limit its check judges, or is a
    safety net behind a cost whose target lies inside it (the swing clearance, the joints' band and
    speed): an optimum is never on the edge of a check; the bounds follow the limits when they change."""
    from dataclasses import replace

    from solver.naturalness import NaturalnessLimits
    from solver.spacetime.types import Naturalness, Realism

    rl, nl = RealismLimits(), NaturalnessLimits()
    r, n = Realism(), Naturalness()
    assert r == Realism.from_limits(rl) and n == Naturalness.from_limits(nl)
    assert r.free_moment_cap < rl.torsion_abs and r.support_max < rl.total_force and r.force_rate < rl.force_rate
    assert r.spin_rate_deg_s < rl.spin_rate and r.torsion_margin < 1.0
    assert r.torsion_radius_fraction == rl.torsion_radius
    # whole-body Newton–Euler from positions sees a sixth of the ground wrench's second differences
    assert r.force_curvature / 6 < rl.newton_force and r.moment_curvature / 6 < rl.newton_moment
    # swing clearance: costed toward a target above the check's limit; the hard bound a safety net below
    assert n.clearance_m < nl.clearance_m < n.clearance_target_m
    assert n.shared_load > nl.shared_load and n.pitch_load < nl.pitch_load
    assert n.pitch_deg == nl.pitch_deg and n.friction_use < nl.friction_use and n.fore_aft < nl.fore_aft
    # joints: costed out of a band wider than the check's, the bounds the model's own; joint speed costed
    # below the check's limit
    assert n.crossover_m < nl.crossover_m and n.limit_band_deg > nl.limit_band_deg and n.limit_margin_deg == 0.0
    assert n.joint_speed_deg_s < nl.joint_speed_deg_s and n.level_deg == nl.level_deg
    assert -n.push_margin > nl.push
    moved = Realism.from_limits(replace(rl, total_force=3.0, spin_rate=100.0))
    assert 2.9 < moved.support_max < 3.0 and 50.0 < moved.spin_rate_deg_s < 100.0
    closer = Naturalness.from_limits(replace(nl, crossover_m=0.05, friction_use=0.8))
    assert 0.03 < closer.crossover_m < 0.05 and 0.7 < closer.friction_use < 0.8


def test_the_report_runs_the_registered_check_sections():
    """The report's sections are the registered ones (solver.checks): the root residual, the
    contacts, realism and naturalness always, the MuJoCo replay when its caller includes it; an
    unknown section is refused. A check without a figure fails unless its producer says why."""
    import mjcf.validate  # noqa: F401  (registers the MuJoCo replay's section)
    from solver.checks import Check, sections

    core = ["residual", "contacts", "realism", "naturalness"]
    assert [s.name for s in sections()] == core
    assert [s.name for s in sections(("mujoco_replay",))] == [*core, "mujoco_replay"]
    with pytest.raises(ValueError, match="unknown check section"):
        sections(("forward_simulation",))
    low = Check.measure("root_height", 0.4, 0.5, "leg", "lowest root height", warning=True, at_least=True)
    assert not low.passed and not low.failed and low.to_dict()["bound"] == "min"
    assert Check.measure("x", 2.0, 1.0, "BW", "x", applies=False).passed
    unmeasured = Check.measure("x", None, 1.0, "BW", "x")  # a misspelt figure reads as None
    assert unmeasured.failed and "not measured" in unmeasured.problem("s")
    nothing = Check.measure("x", None, 1.0, "BW", "x", missing="no swing phase")
    assert nothing.passed and nothing.to_dict()["missing"] == "no swing phase"
