"""Realism checks: physics that must hold *between* the frames.

The plausibility report's root residual is the optimizer's own discretization (RNEA on
central differences at the frames): a coordinate that zig-zags from one frame to the next,
with wrenches that zig-zag with it, satisfies it exactly. The checks here share nothing with
that scheme — neither its q̇/q̈ nor its derivatives:

1. ``newton_euler``: whole-body Newton–Euler from *positions and orientations*: linear
   momentum from the segments' centres of mass (second difference of the mass-weighted
   centre), angular momentum about the centre of mass from each segment's orientation
   change (inertia × angular velocity + m r × v), compared with gravity and the stored
   ground wrenches at every frame, and their sum over the cycle (impulse = momentum change).
2. ``refinement``: the motion interpolated by an independent smooth cubic spline through the
   frames (periodic, under the cycle's rigid transform for root x, y, yaw) and the wrenches
   linearly, inverse dynamics on a grid ``REFINE`` times finer than the frames.
3. ``torsional_friction``: the free moment at the centre of pressure within μ·ρ·f_z
   (ρ = foot length / 10) and an absolute bound; an unloaded foot carries no moment.
4. ``foot_spin``: a loaded foot does not turn about the ground normal.
5. ranges for walking: total ground force, its rate of change, the heading change over the
   cycle against the request; joint speeds and root height as warnings.

Limits and their sources: docs/spacetime.md, "Realism checks". Cyclic motions (the
tutor's and the continuation's) have two overlap frames: frames T-2, T-1 are frames 0, 1
moved by the cycle's rigid transform (a yaw Δψ about the vertical and a translation).
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
from scipy.interpolate import CubicSpline
from scipy.spatial.transform import Rotation

from solver.checks import Check, Context, SectionResult, register_check
from solver.dynamics import rnea
from solver.environment import ground_of
from solver.kinematics import segment_frames
from solver.motion import FEET, Motion

#: coordinates moved by the cycle's rigid transform (root x, y, yaw); the others repeat
ROOT_X, ROOT_Y, ROOT_Z, ROOT_YAW = 0, 1, 2, 3
TRANSFORMED = (ROOT_X, ROOT_Y, ROOT_YAW)
#: frames 0, 1 and T-2, T-1 of a cyclic motion agree (after the transform) within this (m, rad)
CYCLE_TOL = 1e-5


@dataclass(frozen=True)
class RealismLimits:
    """Limits of the realism checks (BW = body weight, leg = standing leg length)."""

    newton_force: float = 0.08  # BW, per frame
    newton_moment: float = 0.04  # BW·leg, per frame
    cycle_force: float = 0.02  # BW: |impulse − momentum change| / (BW × cycle duration)
    cycle_moment: float = 0.02  # BW·leg, the same for the angular impulse about the COM
    refine: int = 6  # refinement factor of the time grid
    refine_force: float = 0.08  # BW
    refine_moment: float = 0.04  # BW·leg
    torsion_radius: float = 0.1  # ρ / foot length: |τ_free| ≤ μ ρ f_z
    torsion_abs: float = 0.03  # BW·m
    torsion_tol: float = 1e-4  # BW·m: numerical tolerance of the excess (the friction cone's is 1e-4 BW)
    unloaded: float = 0.02  # BW: a foot below this carries (almost) no moment
    spin_load: float = 0.10  # BW: a foot above this at both frames is "loaded"
    spin_rate: float = 75.0  # deg/s about the ground normal (5° per frame at 15 fps)
    total_force: float = 2.0  # BW
    force_rate: float = 12.0  # BW/s of the total ground force (0.8 BW per frame at 15 fps)
    heading_deg: float = 1.0  # deg, heading change over the cycle against the request
    joint_speed: float = 1000.0  # deg/s (warning)
    root_height: float = 0.5  # × leg, lowest root height (warning)


# --- the cycle ------------------------------------------------------------------------------


@dataclass(frozen=True)
class Cycle:
    """Rigid transform of one cycle: p ↦ R(Δψ) p + d, yaw ↦ yaw + Δψ (d[2]: the cycle's rise
    on stairs, 0 on flat ground)."""

    N: int  # distinct frames (T - 2)
    dpsi: float
    d: np.ndarray  # (3,)

    def rot(self, k: int = 1) -> np.ndarray:
        c, s = math.cos(k * self.dpsi), math.sin(k * self.dpsi)
        return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])

    def shift(self, k: int) -> np.ndarray:
        """Translation of the transform applied k times (k may be negative)."""
        out = np.zeros(3)
        if k >= 0:
            for _ in range(k):
                out = self.rot() @ out + self.d
        else:
            for _ in range(-k):
                out = self.rot(-1) @ (out - self.d)
        return out

    def apply_q(self, q: np.ndarray, k: int) -> np.ndarray:
        """Frames (n, m) moved by k cycles."""
        out = np.array(q, dtype=float, copy=True)
        p = np.vstack([q[ROOT_X], q[ROOT_Y], q[ROOT_Z]])
        p = self.rot(k) @ p + self.shift(k)[:, None]
        out[ROOT_X], out[ROOT_Y], out[ROOT_Z] = p[0], p[1], p[2]
        out[ROOT_YAW] = q[ROOT_YAW] + k * self.dpsi
        return out

    def apply_wrench(self, w: np.ndarray, k: int) -> np.ndarray:
        """World wrenches (..., 6[, m]) (moment about the origin; force) moved by k cycles."""
        r, dk = self.rot(k), self.shift(k)
        f = np.einsum("ij,...j->...i", r, np.moveaxis(w[..., 3:6, :], -2, -1))
        n = np.einsum("ij,...j->...i", r, np.moveaxis(w[..., 0:3, :], -2, -1)) + np.cross(dk, f)
        return np.concatenate([np.moveaxis(n, -1, -2), np.moveaxis(f, -1, -2)], axis=-2)


def cycle_of(motion: Motion) -> tuple[Cycle | None, str]:
    """The motion's cycle when frames T-2, T-1 repeat frames 0, 1 under one rigid transform."""
    q, T = motion.q, motion.T
    if T < 5 or motion.character.n < 6:
        return None, "fewer than 5 frames: treated as an open motion"
    if motion.contacts is not None and not np.array_equal(motion.contacts[:, -2:], motion.contacts[:, :2]):
        return None, "the contact schedule does not repeat: treated as an open motion"
    dpsi = float(q[ROOT_YAW, T - 2] - q[ROOT_YAW, 0])
    c, s = math.cos(dpsi), math.sin(dpsi)
    p0 = q[[ROOT_X, ROOT_Y], 0]
    d2 = q[[ROOT_X, ROOT_Y], T - 2] - np.array([c * p0[0] - s * p0[1], s * p0[0] + c * p0[1]])
    rise = float(q[ROOT_Z, T - 2] - q[ROOT_Z, 0]) if motion.environment.step_height_m else 0.0
    cyc = Cycle(T - 2, dpsi, np.array([d2[0], d2[1], rise]))
    err = float(np.max(np.abs(cyc.apply_q(q[:, :2], 1) - q[:, T - 2:])))
    if err > CYCLE_TOL:
        return None, f"frames T-2, T-1 do not repeat frames 0, 1 (by {err:.2g}): treated as an open motion"
    return cyc, "cyclic: frames T-2, T-1 are frames 0, 1 moved by the cycle's rigid transform"


# --- helpers -------------------------------------------------------------------------------


def _about(wrench: np.ndarray, point: np.ndarray) -> np.ndarray:
    """World wrenches (6, m) (moment about the origin; force) re-expressed about points (3, m)."""
    out = np.array(wrench, dtype=float, copy=True)
    out[:3] = wrench[:3] - np.cross(point.T, wrench[3:].T).T
    return out


def frame_wrenches(motion: Motion, cyc: Cycle | None) -> tuple[np.ndarray, np.ndarray]:
    """Per-foot wrenches (2, 6, m) on frames ``idx`` (returned): frames 1..T-2, and for a cycle
    frame T-1 as frame 1 moved by the transform (the stored overlap frames are copies)."""
    W = motion.wrenches
    assert W is not None  # callers check that the motion has wrenches
    idx = np.arange(1, motion.T - 1)
    if cyc is None:
        return W[:, :, 1:-1], idx
    return np.concatenate([W[:, :, 1:-1], cyc.apply_wrench(W[:, :, 1:2], 1)], axis=2), np.arange(1, motion.T)


# --- 1. Newton–Euler from positions ----------------------------------------------------------


def momentum_from_positions(motion: Motion) -> dict[str, np.ndarray]:
    """Centre of mass at the frames (3, T); linear momentum (3, T-1) and angular momentum about
    the centre of mass (3, T-1) between frames t and t+1, from positions and orientations."""
    ch = motion.character
    rots, poss = segment_frames(ch, motion.q)  # (S, 3, 3, T), (S, 3, T)
    segs = [i for i, s in enumerate(ch.segments) if s.mass > 0]
    m = np.array([ch.segments[i].mass for i in segs])
    M = float(m.sum())
    R = np.moveaxis(rots[segs], -1, 1)  # (S, T, 3, 3)
    com_local = np.array([ch.segments[i].com for i in segs])
    x = poss[segs] + np.einsum("sijt,sj->sit", rots[segs], com_local)  # (S, 3, T)
    c = np.einsum("s,sit->it", m, x) / M
    dt = motion.dt
    S, T = len(segs), motion.T
    rel = np.einsum("stij,stkj->stik", R[:, 1:], R[:, :-1])  # R_{t+1} R_tᵀ
    rv = Rotation.from_matrix(rel.reshape(-1, 3, 3)).as_rotvec().reshape(S, T - 1, 3)
    half = Rotation.from_rotvec(0.5 * rv.reshape(-1, 3)).as_matrix().reshape(S, T - 1, 3, 3)
    Rm = np.einsum("stij,stjk->stik", half, R[:, :-1])
    inertia = np.array([ch.segments[i].inertia for i in segs])
    Iw = np.einsum("stij,sjk,stlk->stil", Rm, inertia, Rm)
    omega = rv / dt  # (S, T-1, 3), world frame
    v = np.moveaxis((x[:, :, 1:] - x[:, :, :-1]) / dt, 1, 2)  # (S, T-1, 3)
    xm = np.moveaxis(0.5 * (x[:, :, 1:] + x[:, :, :-1]), 1, 2)
    cm = 0.5 * (c[:, 1:] + c[:, :-1]).T  # (T-1, 3)
    vc = ((c[:, 1:] - c[:, :-1]) / dt).T
    L = np.einsum("stij,stj->ti", Iw, omega) + np.einsum("s,sti->ti", m, np.cross(xm - cm, v - vc))
    return {"com": c, "P": (M * vc).T, "L": L.T, "mass": np.array(M)}


def newton_euler(motion: Motion, gravity: np.ndarray, weight: float, leg: float,
                 cyc: Cycle | None) -> dict[str, Any]:
    """Per-frame and whole-cycle errors of Newton–Euler from positions (frames 1..T-2).

    The momenta are means over each frame interval (differences of positions), so their
    difference across frame t is exactly the impulse of the external forces weighted by the hat
    function of frames t-1..t+1; with the wrenches linear between the frames (as the refinement
    assumes) that is (G_{t-1} + 4 G_t + G_{t+1}) / 6 — no discretization error in the
    comparison. (Open motions: the end frames 1 and T-2 use G_t alone.) The point comparison
    (G_t alone everywhere) is reported too."""
    mom = momentum_from_positions(motion)
    dt, M, c = motion.dt, float(mom["mass"]), mom["com"]
    assert motion.wrenches is not None  # callers check that the motion has wrenches
    W = motion.wrenches.sum(axis=0)  # (6, T)
    if cyc is not None:  # the overlap frames as the cycle's transform of frames T-2 and 1
        W = np.concatenate([cyc.apply_wrench(W[:, -2:-1], -1), W[:, 1:-1], cyc.apply_wrench(W[:, 1:2], 1)], axis=1)
    G = _about(W, c)
    G[3:] += M * gravity[:, None]  # (moment about the COM; force incl. gravity), (6, T)
    hat = (G[:, :-2] + 4.0 * G[:, 1:-1] + G[:, 2:]) / 6.0
    if cyc is None:
        hat[:, [0, -1]] = G[:, [1, -2]]
    dP = (mom["P"][:, 1:] - mom["P"][:, :-1]) / dt
    dL = (mom["L"][:, 1:] - mom["L"][:, :-1]) / dt
    err = np.vstack([dL, dP]) - hat
    fr = np.linalg.norm(err[3:], axis=0) / weight
    mr = np.linalg.norm(err[:3], axis=0) / (weight * leg)
    point = np.linalg.norm(dP - G[3:, 1:-1], axis=0) / weight
    ground = hat
    dur = (motion.T - 2) * dt
    impulse = ground[3:].sum(axis=1) * dt
    dmom = mom["P"][:, -1] - mom["P"][:, 0]
    ang_impulse = ground[:3].sum(axis=1) * dt
    dang = mom["L"][:, -1] - mom["L"][:, 0]
    out = {
        "force_rel_weight": fr, "moment_rel_weight_leg": mr, "point_force_rel_weight": point,
        "worst_force_frame": int(np.argmax(fr)) + 1, "worst_moment_frame": int(np.argmax(mr)) + 1,
        "cycle_force_rel_weight": float(np.linalg.norm(impulse - dmom) / (weight * dur)),
        "cycle_moment_rel_weight_leg": float(np.linalg.norm(ang_impulse - dang) / (weight * leg * dur)),
        "impulse_Ns": impulse.tolist(), "momentum_change_Ns": dmom.tolist(),
        "angular_impulse_Nms": ang_impulse.tolist(), "angular_momentum_change_Nms": dang.tolist(),
    }
    if cyc is not None:  # the momentum after one cycle is the first one turned by Δψ
        out["momentum_change_expected_Ns"] = ((cyc.rot() - np.eye(3)) @ mom["P"][:, 0]).tolist()
    return out


# --- 2. refinement -----------------------------------------------------------------------------


def refined(motion: Motion, cyc: Cycle | None, factor: int) -> dict[str, np.ndarray]:
    """q, q̇, q̈ (n, m) of a cubic spline through the frames and the linearly interpolated
    per-foot wrenches (2, 6, m) on a grid ``factor`` times finer; times (m,) in frame units.

    Cyclic: periodic splines for the repeating coordinates; root x, y, yaw padded by one
    cycle on each side with the cycle's transform and fitted by a not-a-knot spline, read in
    the middle cycle. The grid spans frames 1 .. T-1 (one cycle). Open: not-a-knot spline over
    all frames, grid over frames 1 .. T-2 (where the wrenches hold)."""
    q, dt, T = motion.q, motion.dt, motion.T
    W, idx = frame_wrenches(motion, cyc)
    s = np.arange(idx[0] * factor, idx[-1] * factor + (0 if cyc is not None else 1)) / factor  # frame units
    ts = s * dt
    out = np.empty((3, motion.n, s.size))
    if cyc is None:
        sp = CubicSpline(np.arange(T) * dt, q, axis=1, bc_type="not-a-knot")
        out[:] = [sp(ts), sp(ts, 1), sp(ts, 2)]
    else:
        N = cyc.N
        base = q[:, :N]
        per = CubicSpline(np.arange(N + 1) * dt, np.hstack([base, base[:, :1]]), axis=1, bc_type="periodic")
        out[:] = [per(ts), per(ts, 1), per(ts, 2)]
        ext = np.hstack([cyc.apply_q(base, -1), base, cyc.apply_q(base, 1), cyc.apply_q(base[:, :2], 2)])
        tr = list(TRANSFORMED) + ([ROOT_Z] if cyc.d[2] != 0.0 else [])  # stairs: root z rises per cycle
        pad = CubicSpline((np.arange(ext.shape[1]) - N) * dt, ext[tr], axis=1, bc_type="not-a-knot")
        out[0][tr], out[1][tr], out[2][tr] = pad(ts), pad(ts, 1), pad(ts, 2)
    w = np.empty((2, 6, s.size))
    for k in range(2):
        for r in range(6):
            w[k, r] = np.interp(s, idx, W[k, r])
    return {"s": s, "q": out[0], "qd": out[1], "qdd": out[2], "wrenches": w}


def refinement(motion: Motion, gravity: np.ndarray, weight: float, leg: float, cyc: Cycle | None,
               factor: int) -> dict[str, Any]:
    r = refined(motion, cyc, factor)
    h0 = rnea(motion.character, r["q"], r["qd"], r["qdd"], gravity).h0 - r["wrenches"].sum(axis=0)
    res = _about(h0, r["q"][:3])
    fr = np.abs(res[3:]).max(axis=0) / weight
    mr = np.abs(res[:3]).max(axis=0) / (weight * leg)
    on_frames = np.abs(r["s"] - np.round(r["s"])) < 1e-9
    return {"refined": r, "force_rel_weight": fr, "moment_rel_weight_leg": mr,
            "worst_force_time_frames": float(r["s"][np.argmax(fr)]),
            "worst_moment_time_frames": float(r["s"][np.argmax(mr)]),
            "max_force_between_frames": float(fr[~on_frames].max()) if (~on_frames).any() else 0.0}


# --- 3.-4. contact: torsional friction, loaded-foot spin --------------------------------------------


def foot_length(motion: Motion, side: str) -> float:
    half = motion.character.foot(side).half
    return 2.0 * float(max(half[0], half[1]))


def free_moments(motion: Motion) -> np.ndarray:
    """(2, T) vertical free moment at each foot's centre of pressure (N·m; nan where f_z ≤ 0),
    the CoP on the ground under the foot (``solver.environment.ground_of``)."""
    W = motion.wrenches
    assert W is not None  # callers check that the motion has wrenches
    n, f = W[:, :3], W[:, 3:]
    zg = ground_of(motion)
    with np.errstate(divide="ignore", invalid="ignore"):
        ux, uy = (zg * f[:, 0] - n[:, 1]) / f[:, 2], (n[:, 0] + zg * f[:, 1]) / f[:, 2]
        tau = n[:, 2] - (ux * f[:, 1] - uy * f[:, 0])
    return np.where(f[:, 2] > 0, tau, np.nan)


def torsion(motion: Motion, mu: float, weight: float, lim: RealismLimits) -> dict[str, Any]:
    """Free moments against torsional friction (frames 1..T-2), and the whole moment of an
    unloaded foot about its centre on the ground (``moment_room_m``: the lever a foot of that
    size can give its load — half its length plus the torsion radius)."""
    ch = motion.character
    frames = slice(1, motion.T - 1)
    assert motion.wrenches is not None  # callers check that the motion has wrenches
    W = motion.wrenches[:, :, frames]
    tau = free_moments(motion)[:, frames]
    fz, nz = W[:, 5], W[:, 2]
    length = np.array([foot_length(motion, side) for side in FEET])[:, None]
    rho = lim.torsion_radius * length
    bound = mu * rho * np.maximum(fz, 0.0)
    tau_abs = np.where(np.isnan(tau), np.abs(nz), np.abs(tau))  # no normal force: any moment is free
    excess = np.where(tau_abs > 0, (tau_abs - bound) / weight, 0.0)
    unloaded = fz < lim.unloaded * weight
    names = [sg.name for sg in ch.segments]
    rots, poss = segment_frames(ch, motion.q[:, frames])
    ground = ground_of(motion)[:, frames]
    n_centre = np.empty(fz.shape)
    for k, side in enumerate(FEET):
        foot = ch.foot(side)
        i = names.index(foot.segment)
        p = poss[i] + np.einsum("ijt,j->it", rots[i], foot.center)
        p[2] = ground[k]
        n_centre[k] = np.linalg.norm(_about(W[k], p)[:3], axis=0)
    return {
        "max_free_moment_Nm": float(tau_abs.max()),
        "max_free_moment_rel_weight_m": float(tau_abs.max() / weight),
        "max_excess_rel_weight_m": float(max(0.0, excess.max())),
        "max_unloaded_moment_Nm": float(n_centre[unloaded].max()) if unloaded.any() else 0.0,
        "radius_m": [float(r) for r in rho[:, 0]],
        "moment_room_m": float((0.5 * length + mu * rho).max()),
    }


def foot_spin(motion: Motion, weight: float, lim: RealismLimits) -> dict[str, Any]:
    """Largest rotation about the vertical (deg per frame) of a foot loaded at two adjacent frames."""
    ch = motion.character
    names = [s.name for s in ch.segments]
    rots, _ = segment_frames(ch, motion.q)
    out, worst = 0.0, None
    assert motion.wrenches is not None  # callers check that the motion has wrenches
    for k, side in enumerate(FEET):
        R = np.moveaxis(rots[names.index(ch.foot(side).segment)], -1, 0)  # (T, 3, 3)
        rv = Rotation.from_matrix(np.einsum("tij,tkj->tik", R[1:], R[:-1])).as_rotvec()
        fz = motion.wrenches[k, 5]
        loaded = (fz[:-1] > lim.spin_load * weight) & (fz[1:] > lim.spin_load * weight)
        turn = np.degrees(np.abs(rv[:, 2]))
        if loaded.any() and turn[loaded].max() > out:
            out = float(turn[loaded].max())
            worst = {"foot": side, "frame": int(np.flatnonzero(loaded)[np.argmax(turn[loaded])])}
    return {"max_turn_deg_per_frame": out, "max_turn_deg_per_s": out * motion.fps, "worst": worst}


# --- 5. ranges ---------------------------------------------------------------------------------------


def requested_heading(motion: Motion) -> tuple[float | None, str]:
    """Heading change over the cycle the motion was asked for (deg, left positive) and where the
    request was read (the motion's context, ``solver.motion.MotionContext``; named by the motion
    file's keys), first found of: ``heading_change_requested_deg``; the continuation's λ·curve
    (``environment_values.curve_deg``; in files that predate it ``target.curve_deg`` × ``lambda``)
    plus the tutor's own heading change ``tutor_heading_change_deg`` when both are recorded;
    ``heading_change_deg`` (the heading the optimizer was asked for: a tutor's, or the tutor's +
    λ·curve of a λ optimum); the continuation's λ·curve alone, which assumes a straight tutor."""
    ctx = motion.context
    curve = ctx.axis_values.get("curve_deg")
    where = "environment_values.curve_deg"
    if ctx.heading_change_requested_deg is not None:
        return ctx.heading_change_requested_deg, "heading_change_requested_deg"
    if curve is not None and ctx.tutor_heading_change_deg is not None:
        return curve + ctx.tutor_heading_change_deg, where + " + tutor_heading_change_deg"
    if ctx.heading_change_deg is not None:
        return ctx.heading_change_deg, "heading_change_deg"
    if curve is not None:
        return curve, where + " (a straight tutor assumed)"
    return None, ""


# --- the report ---------------------------------------------------------------------------------------


def realism_report(motion: Motion, gravity: Any, mu: float, weight: float, leg: float,
                   lim: RealismLimits = RealismLimits()) -> dict[str, Any]:
    """The realism section of the plausibility report: every check as a figure with its limit."""
    return realism_checks(motion, gravity, mu, weight, leg, lim).to_dict()


@register_check(section="realism", verdict="plausible", flags="failures", prefix="realism_", order=10)
def _realism_section(ctx: Context) -> SectionResult:
    return realism_checks(ctx.motion, ctx.gravity, ctx.friction, ctx.weight, ctx.leg,
                          ctx.limits_for("realism", RealismLimits()))


def realism_checks(motion: Motion, gravity: Any, mu: float, weight: float, leg: float,
                   lim: RealismLimits = RealismLimits()) -> SectionResult:
    """The realism checks of a motion (and the section's limits, notes and figures)."""
    t0 = time.perf_counter()
    g = np.asarray(gravity, dtype=float)
    out: dict[str, Any] = {"limits": asdict(lim), "notes": []}
    if motion.wrenches is None:
        out["notes"].append("no contact wrenches: nothing to check the motion's physics against")
        out["time_s"] = time.perf_counter() - t0
        return SectionResult((), out, checked=False, unchecked=False)
    cyc, note = cycle_of(motion)
    out["notes"].append(note)
    out["cycle"] = None if cyc is None else {"frames": cyc.N, "heading_change_deg": math.degrees(cyc.dpsi),
                                             "translation_m": cyc.d[:2].tolist()}
    checks: list[Check] = []
    ne = newton_euler(motion, g, weight, leg, cyc)
    checks.append(Check.measure("newton_force", ne["force_rel_weight"].max(), lim.newton_force, "BW",
                                "whole-body Newton from COM positions vs gravity + ground, worst frame"))
    checks.append(Check.measure("newton_moment", ne["moment_rel_weight_leg"].max(), lim.newton_moment, "BW·leg",
                                "angular momentum change about the COM vs ground moment, worst frame"))
    checks.append(Check.measure("cycle_impulse", ne["cycle_force_rel_weight"], lim.cycle_force, "BW",
                                "|impulse of ground + gravity − momentum change| / (BW × duration)"))
    checks.append(Check.measure("cycle_angular_impulse", ne["cycle_moment_rel_weight_leg"], lim.cycle_moment, "BW·leg",
                                "|angular impulse about the COM − its change| / (BW·leg × duration)"))
    rf = refinement(motion, g, weight, leg, cyc, lim.refine)
    checks.append(Check.measure("refined_force", rf["force_rel_weight"].max(), lim.refine_force, "BW",
                                f"root residual force on a spline at {lim.refine}× the frame rate"))
    checks.append(Check.measure("refined_moment", rf["moment_rel_weight_leg"].max(), lim.refine_moment, "BW·leg",
                                f"root residual moment on a spline at {lim.refine}× the frame rate"))
    feet = len(motion.character.feet) == 2
    to = torsion(motion, mu, weight, lim) if feet else None
    if to is None:
        out["notes"].append("the character has no foot boxes: torsional friction and foot spin not checked")
    else:
        checks.append(Check.measure("torsional_friction", to["max_excess_rel_weight_m"], lim.torsion_tol, "BW·m",
                                    f"free moment beyond μ·ρ·f_z (ρ = foot length × {lim.torsion_radius:g})"))
        checks.append(Check.measure("free_moment", to["max_free_moment_rel_weight_m"], lim.torsion_abs, "BW·m",
                                    "largest free moment at a centre of pressure"))
        checks.append(Check.measure("unloaded_foot_moment", to["max_unloaded_moment_Nm"] / weight,
                                    to["moment_room_m"] * lim.unloaded, "BW·m",
                                    f"moment about its centre of a foot carrying < {lim.unloaded:g} BW"))
        sp = foot_spin(motion, weight, lim)
        checks.append(Check.measure("foot_spin", sp["max_turn_deg_per_s"], lim.spin_rate, "deg/s",
                                    f"turn about the normal of a foot loaded > {lim.spin_load:g} BW at both frames"))
    W, idx = frame_wrenches(motion, cyc)
    F = W[:, 3:].sum(axis=0)
    checks.append(Check.measure("total_ground_force", np.linalg.norm(F, axis=0).max() / weight, lim.total_force, "BW",
                                "largest total ground force"))
    rate = np.linalg.norm(np.diff(F, axis=1), axis=0).max() / weight * motion.fps if F.shape[1] > 1 else 0.0
    checks.append(Check.measure("ground_force_rate", rate, lim.force_rate, "BW/s",
                                "largest change of the total ground force between adjacent frames"))
    want, source = requested_heading(motion)
    if cyc is not None and want is not None:
        got = math.degrees(cyc.dpsi)
        checks.append(Check.measure("heading", abs(got - want), lim.heading_deg, "deg",
                                    f"heading change over the cycle {got:.2f}° vs {want:.2f}° requested ({source})"))
    elif want is not None:
        out["notes"].append("heading change not checked: the motion is not cyclic")
    else:
        out["notes"].append("heading change not checked: the motion records no requested curve")
    hinge = [i for i, kd in enumerate(motion.character.dof_kinds) if kd == "hinge"]
    speeds = np.degrees(np.abs(rf["refined"]["qd"][hinge])).max(axis=1)
    fast = int(np.argmax(speeds))
    checks.append(Check.measure("joint_speed", speeds[fast], lim.joint_speed, "deg/s",
                                f"fastest coordinate ({motion.coordinate_names[hinge[fast]]}) on the spline",
                                warning=True))
    checks.append(Check.measure("root_height", motion.q[2].min() / leg, lim.root_height, "leg", "lowest root height",
                                warning=True, at_least=True))
    out["figures"] = {
        "newton": {k: (v.tolist() if isinstance(v, np.ndarray) else v) for k, v in ne.items()},
        "refinement": {"factor": lim.refine, "worst_force_time_frames": rf["worst_force_time_frames"],
                       "worst_moment_time_frames": rf["worst_moment_time_frames"],
                       "max_force_between_frames_rel_weight": rf["max_force_between_frames"]},
        "torsion": to, "foot_spin": sp if feet else None,
        "ground_force_rel_weight": (np.linalg.norm(F, axis=0) / weight).tolist(),
        "joint_speed_deg_s": dict(zip([motion.coordinate_names[i] for i in hinge], speeds.tolist())),
    }
    out["time_s"] = time.perf_counter() - t0
    return SectionResult(tuple(checks), out)
