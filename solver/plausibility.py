"""Plausibility report of a motion (docs/method.md (M8)): how well it satisfies the constraints of (M5).

Residuals are measured where the motion's own trajectory defines q̇ and q̈
(``solver.trajectory.dynamics_samples``: frames and midpoints of the C² cubic spline for the
optimizer's motions, interior frames by central differences for file v1): the root residual is
h0(q, q̇, q̈, g) minus the sum of the contact wrenches — zero for a physically plausible motion.
Moments are reported about the root (pelvis) position of each frame, so they do not depend on where the world origin is.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import asdict, dataclass, replace
from typing import Any

import numpy as np

import solver.naturalness  # noqa: F401  (registers the naturalness section)
from solver.checks import Check, Context, SectionResult, register_check, sections
from solver.dynamics import rnea
from solver.environment import body_weight, ground_of, stances
from solver.kinematics import contact_points, segment_frames, standing_leg_length
from solver.motion import FEET, Motion
from solver.realism import RealismLimits
from solver.trajectory import dynamics_samples


@dataclass(frozen=True)
class Tolerances:
    residual: float = 1e-6  # root residual force / body weight, moment / (weight × leg length)
    slip_mm: float = 1.0
    penetration_mm: float = 1.0
    contact_height_mm: float = 1.0
    friction: float = 1e-4  # cone excess, negative normal force, wrench in the air / body weight
    cop_mm: float = 1.0


def root_residual(motion: Motion, gravity: Any) -> np.ndarray:
    """(6, S): h0 − Σ wrenches at the motion's dynamics samples, moment about the root position."""
    s = dynamics_samples(motion)
    h0 = rnea(motion.character, s.q, s.qd, s.qdd, np.asarray(gravity, dtype=float)).h0
    if s.wrenches is not None:
        h0 = h0 - s.wrenches.sum(axis=0)
    return about_root(h0, s.q)


def about_root(wrench: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Re-express world wrenches (moment about the origin; force) about the root position."""
    out = wrench.copy()
    out[:3] = wrench[:3] - np.cross(q[:3].T, wrench[3:].T).T
    return out


@register_check(section="residual", verdict="plausible", flags="all", flatten=True, order=0,
                title="root residual")
def _residual_section(ctx: Context) -> SectionResult:
    """The root residual: what the six root coordinates still need once the ground wrenches are
    applied, force / weight and moment / (weight × leg), within the residual tolerance."""
    motion, tol, weight, leg = ctx.motion, ctx.tolerances, ctx.weight, ctx.leg
    res = root_residual(motion, ctx.gravity)
    max_force, max_moment = float(np.abs(res[3:]).max()), float(np.abs(res[:3]).max())
    force, moment = max_force / weight, max_moment / (weight * leg)
    rr: dict[str, Any] = {
        "max_force_N": max_force,
        "max_moment_Nm": max_moment,
        "rms_force_N": float(np.sqrt((res[3:] ** 2).sum(axis=0).mean())),
        "max_force_rel_weight": force,
        "max_moment_rel_weight_leg": moment,
        "about": "root position of each frame",
        "frames": ("frames and midpoints (C2 cubic spline)" if motion.interpolation == "cubic-spline"
                   else "interior (central differences)"),
    }
    checks = [Check.measure("root_force", force, tol.residual, "BW", "root residual force"),
              Check.measure("root_moment", moment, tol.residual, "BW·leg",
                            "root residual moment")]
    if motion.wrenches is None:
        checks.append(Check("wrenches", None, 0.0, "", "the motion stores its contact wrenches", False,
                            missing="no contact wrenches: the ground reaction is unknown"))
    return SectionResult(tuple(checks), {"root_residual": rr})


@register_check(section="contacts", verdict="plausible", flags="all", flatten=True, order=1)
def _contacts_section(ctx: Context) -> SectionResult:
    """The contacts: active points on the ground without slip or penetration; with wrenches, the
    friction cone, unilateral normal force, no wrench on a foot in the air, the centre of pressure
    on the sole."""
    motion, tol, weight = ctx.motion, ctx.tolerances, ctx.weight
    if motion.contacts is None or not motion.character.contacts:
        return SectionResult((Check("contacts", None, 0.0, "", "the motion stores its contact schedule", False,
                                    missing="no contact schedule"),))
    kin = _contact_checks(motion, ctx.friction, weight)
    checks = [Check.measure("slip", kin["slip_mm"], tol.slip_mm, "mm", "slip of a contact point"),
              Check.measure("penetration", kin["penetration_mm"], tol.penetration_mm, "mm", "ground penetration"),
              Check.measure("contact_height", kin["contact_height_error_mm"], tol.contact_height_mm, "mm",
                            "height of an active contact point above the ground")]
    if motion.wrenches is not None:
        f_tol = tol.friction * weight
        checks += [Check.measure("friction", kin["friction_cone_excess_N"], f_tol, "N", "friction cone excess"),
                   Check.measure("normal_force", kin["min_normal_force_N"], -f_tol, "N", "least normal force",
                                 at_least=True),
                   Check.measure("air_wrench", kin["max_wrench_in_air"], f_tol, "N", "wrench of a foot in the air"),
                   Check.measure("cop", kin["cop_outside_mm"], tol.cop_mm, "mm",
                                 "centre of pressure outside the sole (heel to toe, as wide as the foot)")]
    return SectionResult(tuple(checks), kin)


def report(motion: Motion, tol: Tolerances = Tolerances(), realism: RealismLimits = RealismLimits(),
           include: tuple[str, ...] = (), limits: Mapping[str, Any] | None = None) -> dict:
    """The validation report: every registered check section (``solver.checks``) in its order —
    the root residual and the contacts (here), realism, naturalness, and the optional ones named in
    ``include`` (``mjcf.validate``'s MuJoCo replay and simulation). ``limits``: a section's limits
    by its name (``realism``: the ``realism`` argument unless given here). ``plausible``: no
    failed check of the sections deciding it; ``natural``: the naturalness section's verdict
    (None when it could not check the motion). ``sections`` lists what ran, in order."""
    env = motion.environment
    g = np.asarray(env.gravity, dtype=float)
    weight = body_weight(motion)
    leg = standing_leg_length(motion.character)
    out: dict[str, Any] = {
        "character": motion.character.name,
        "frames": motion.T,
        "fps": motion.fps,
        "body_weight_N": weight,
        "leg_length_m": leg,
        "environment": {"gravity": g.tolist(), "friction": env.friction, **_terrain(motion)},
        "has_wrenches": motion.wrenches is not None,
        "has_contacts": motion.contacts is not None,
        "tolerances": asdict(tol),
    }
    flags: dict[str, bool] = {}
    problems: list[str] = []
    verdicts: dict[str, list[bool | None]] = {"plausible": [], "natural": []}
    ctx = Context(motion, g, env.friction, weight, leg, tol, {"realism": realism, **(limits or {})})
    run = sections(include)
    for section in run:
        result = section.produce(ctx)
        if section.flatten:
            out.update(result.extra)
            out[section.name] = replace(result, extra={}).to_dict()
        else:
            out[section.name] = result.to_dict()
        flags.update(section.flag_checks(result))
        problems += section.problems(result)
        if section.flags != "none":
            verdicts[section.verdict] += [not c.failed for c in result.checks]
        else:
            verdicts[section.verdict].append(result.passed)
    out["sections"] = [s.describe() for s in run]
    out["checks"] = flags
    out["problems"] = problems
    out["plausible"] = all(verdicts["plausible"])
    # None: naturalness not checked (no contact schedule or two-point feet)
    out["natural"] = None if None in verdicts["natural"] else all(verdicts["natural"])
    return out


def _terrain(motion: Motion) -> dict:
    """Stairs: the riser height and one tread per stance (foot, frames, centre (x, y, ground
    height) under the foot's contact points) — what a preview draws as steps."""
    step = motion.environment.step_height_m
    if not step or motion.contacts is None:
        return {}
    B, G = motion.foot_contact(), ground_of(motion)
    cp = contact_points(motion.character, motion.q)
    treads = []
    for k, a, b in stances(B):
        side = FEET[k]
        idx = [j for j, c in enumerate(motion.character.contacts) if c.side == side]
        xy = cp[idx, :2, a:b + 1].mean(axis=(0, 2))
        treads.append({"foot": side, "frames": [a, b], "center": [float(xy[0]), float(xy[1]), float(G[k, a])]})
    return {"step_height_m": float(step), "treads": treads}


def _contact_checks(motion: Motion, mu: float, weight: float) -> dict:
    ch = motion.character
    A = motion.contacts
    assert A is not None  # the caller checks that the motion has contacts
    cp = contact_points(ch, motion.q)  # (P, 3, T)
    T = motion.T
    feet_ground = ground_of(motion)  # (2, T): the terrain under each foot
    foot_of = {s: k for k, s in enumerate(FEET)}
    z = cp[:, 2, :] - feet_ground[[foot_of[c.side] for c in ch.contacts]]  # height above the ground
    active_err = float(np.abs(z[A]).max()) if A.any() else 0.0
    penetration = float(max(0.0, -z.min()))
    slip = 0.0
    both = A[:, :-1] & A[:, 1:]
    if both.any():
        d = np.linalg.norm(cp[:, :2, 1:] - cp[:, :2, :-1], axis=1)
        slip = float(d[both].max())
    out = {
        "contact_height_error_mm": 1e3 * active_err,
        "penetration_mm": 1e3 * penetration,
        "slip_mm": 1e3 * slip,
    }
    if motion.wrenches is None:
        return out
    B = motion.foot_contact()
    W = motion.wrenches
    excess, min_fz, air, cop_out = 0.0, np.inf, 0.0, 0.0
    rots, poss = segment_frames(ch, motion.q)
    seg_index = {s.name: i for i, s in enumerate(ch.segments)}
    cops = np.full((2, 3, T), np.nan)
    for k, side in enumerate(FEET):
        foot = ch.foot(side)
        si = seg_index[foot.segment]
        try:
            sole_centre, sole_half = ch.sole_box(side)  # the centre of pressure stays on the sole
        except ValueError:  # a foot without a heel and a toe point: its box
            sole_centre, sole_half = foot.center, foot.half
        for t in range(1, T - 1):
            n0, f = W[k, :3, t], W[k, 3:, t]
            if not B[k, t]:
                air = max(air, float(np.abs(W[k, :, t]).max()))
                continue
            min_fz = min(min_fz, float(f[2]))
            excess = max(excess, float(np.hypot(f[0], f[1]) - mu * f[2]))
            if f[2] > 1e-6 * weight:
                zg = feet_ground[k, t]  # the CoP on the ground plane under the foot
                u = np.array([(zg * f[0] - n0[1]) / f[2], (n0[0] + zg * f[1]) / f[2], zg])
                cops[k, :, t] = u
                local = rots[si, :, :, t].T @ (u - poss[si, :, t]) - sole_centre
                cop_out = max(cop_out, float(np.max(np.abs(local) - sole_half)))
    return {
        **out,
        "friction_cone_excess_N": max(excess, 0.0),
        "min_normal_force_N": float(min_fz) if np.isfinite(min_fz) else 0.0,
        "max_wrench_in_air": air,
        "cop_outside_mm": 1e3 * max(cop_out, 0.0),
    }


def summary(rep: Mapping[str, Any]) -> str:
    r = rep["root_residual"]
    real = rep.get("realism") or {}
    failed = real.get("failed") or []
    nat = rep.get("naturalness") or {}
    unnatural = ", ".join(nat.get("failed") or [])
    return (f"plausible={rep['plausible']} natural={rep.get('natural')} root residual {r['max_force_N']:.2e} N / "
            f"{r['max_moment_Nm']:.2e} N·m (rel {r['max_force_rel_weight']:.1e}), "
            f"slip {rep.get('slip_mm', float('nan')):.3f} mm, "
            f"penetration {rep.get('penetration_mm', float('nan')):.3f} mm, "
            "realism " + ("passed" if real.get("passed") else f"failed ({', '.join(failed) or 'not checked'})")
            + ", naturalness " + ("passed" if nat.get("passed", True) else f"failed ({unnatural})"))
