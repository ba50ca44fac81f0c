"""Naturalness checks: the features of a human walk that physics alone does not impose.

A motion can satisfy every equation of motion and still not look like a walk: a swing foot
skimming the floor, a foot standing on its toe tip under the body's weight, a turn taken in
the hips at their limits, the load jumping from one foot to the other. Each check here is a
figure with its limit and the published source of the limit (``SOURCES``); every check runs
on the captured walk too (``gait_figures`` of the capture, with its force plates where it has
them), so a result is judged against its own capture and against the published ranges for
its environment.

Nothing here shares the optimizer's transcription: heights, speeds and angles are read from
the frames' forward kinematics (speeds by central differences between the frames), loads
from the stored ground reactions (or the plates).

Failures (a λ optimum breaking one is rejected by the continuation, like an unrealistic one)
are what an observer sees at once and what people do not do: a foot dragging (trip), a toe
tip carrying the weight, a joint jammed at its limit, a loaded foot across the body's
midline, the load jumping between the feet, a level walk braking and pushing twice as hard
as people do, the trunk leaning back going uphill, a walk using all the friction there is.
Warnings are figures where gait varies between people and environments (force shape, lateral
force, push toward the centre of mass, pelvis ranges, foot heading). Step widths are reported
as figures (``step_width_m``), not judged: crossover is the failure they lead to.

The limits and their sources are in ``solver.naturalness_limits``, the figures in
``solver.naturalness_figures``; this module turns the figures into checks, for a motion and for
its captured walk.
"""

from __future__ import annotations

import time
from collections.abc import Mapping
from dataclasses import asdict
from typing import Any

import numpy as np

from solver.checks import Check, Context, SectionResult, register_check
from solver.environment import body_weight, ground_of
from solver.jsonable import jsonable
from solver.motion import FEET, Motion
from solver.naturalness_figures import (
    CORNERS,
    MIN_LIMITED_RANGE_DEG,
    gait_figures,
    limited_coordinates,
    path_heading,
    trunk_axis,
)
from solver.naturalness_limits import SOURCES, STAIRS_SWING, NaturalnessLimits
from solver.stairs import flight_of

__all__ = [
    "CORNERS",
    "MIN_LIMITED_RANGE_DEG",
    "SOURCES",
    "STAIRS_SWING",
    "NaturalnessLimits",
    "against_plates",
    "capture_figures",
    "checks_of",
    "gait_figures",
    "joint_rms_deg",
    "limited_coordinates",
    "motion_figures",
    "naturalness_checks",
    "naturalness_report",
    "path_heading",
    "plate_forces",
    "trunk_axis",
]


# --- the checks -------------------------------------------------------------------------------------


def _get(d: Mapping | None, *keys: str) -> Any:
    for k in keys:
        if not isinstance(d, Mapping):
            return None
        d = d.get(k)
    return d


def _fig(d: Mapping[str, Any], *keys: str) -> Any:
    """A figure of the motion's own: a path it does not have raises (a misspelt figure is an
    error, not a check that passes); a figure with nothing to measure is None."""
    for k in keys:
        d = d[k]
    return d


def checks_of(fig: Mapping[str, Any], *, reference: Mapping[str, Any] | None = None,
              lim: NaturalnessLimits = NaturalnessLimits()) -> dict[str, Check]:
    """The checks (figure, limit, source, the capture's figure) from ``gait_figures``, by name;
    ``reference``: {"capture": figures of the captured walk, "tutor": figures of the tutor}."""
    cap = (reference or {}).get("capture")
    tut = (reference or {}).get("tutor")
    level = fig["tilt_deg"] <= lim.level_deg and not fig.get("stairs")
    checks: list[Check] = []
    fit = (reference or {}).get("fit")
    if isinstance(fit, Mapping) and fit.get("marker_rms_mm") is not None:
        checks.append(Check.measure(
            "fit_quality", fit["marker_rms_mm"], lim.fit_marker_rms_mm, "mm",
            "RMS distance between the capture's markers and the fitted skeleton's (the capture this walk keeps)",
            source=SOURCES["fit_quality"]))
    checks.append(Check.measure(
        "swing_clearance", _fig(fig, "swing_clearance", "min_m"), lim.clearance_m, "m",
        f"lowest heel, toe or sole corner of a swing foot moving faster than {lim.moving_speed:g} m/s in mid-swing "
        f"(more than {lim.swing_edge_frames} frame from lift-off and touchdown)",
        source=SOURCES["swing_clearance"], at_least=True, capture=_get(cap, "swing_clearance", "min_m"),
        missing="no swing foot moving in mid-swing"))
    if "foot_pitch_under_load" in fig:
        checks.append(Check.measure(
            "foot_pitch_under_load", _fig(fig, "foot_pitch_under_load", "max_deg"), lim.pitch_deg, "deg",
            f"largest pitch, heel up or toe up, of a foot carrying more than {lim.pitch_load:g} BW",
            source=SOURCES["foot_pitch_under_load"], capture=_get(cap, "foot_pitch_under_load", "max_deg"),
            missing="no foot carries the load"))
    checks.append(Check.measure(
        "joint_limits", fig["joints_at_limits"]["max_frames"], lim.limit_frames, "frames",
        f"frames a coordinate spends within {lim.limit_band_deg:g}° of its model limit"
        + (f" (worst: {fig['joints_at_limits']['worst']})" if fig["joints_at_limits"]["worst"] else ""),
        source=SOURCES["joint_limits"], capture=_get(cap, "joints_at_limits", "max_frames")))
    js = _fig(fig, "joint_speed")
    checks.append(Check.measure(
        "joint_speed", js.get("max_deg_s"), lim.joint_speed_deg_s, "deg/s",
        "fastest change of a joint coordinate between two frames"
        + (f" (worst: {js['worst']['coordinate']})" if js.get("worst") else ""),
        source=SOURCES["joint_speed"], capture=_get(cap, "joint_speed", "max_deg_s"), missing="no hinge joint"))
    checks.append(Check.measure(
        "crossover", _fig(fig, "crossover", "max_far_side_m"), lim.crossover_m, "m",
        "furthest a loaded foot stands on the far side of the pelvis, across the direction of travel and "
        "across the pelvis's heading", source=SOURCES["crossover"], capture=_get(cap, "crossover", "max_far_side_m"),
        missing="no loaded foot"))
    if "shared_load" in fig:
        checks.append(Check.measure(
            "shared_load", _fig(fig, "shared_load", "min_bw"), lim.shared_load, "BW",
            "least, over the changes of support, of the load both feet carry at once", source=SOURCES["shared_load"],
            at_least=True, capture=_get(cap, "shared_load", "min_bw"), missing="no change of support"))
    if "forces_bw" in fig:
        checks.append(Check.measure(
            "fore_aft_force", fig["forces_bw"]["fore_aft_max_abs"], lim.fore_aft, "BW",
            "largest fore-aft force of a foot, level ground", source=SOURCES["fore_aft_force"],
            capture=_get(cap, "forces_bw", "fore_aft_max_abs"), applies=level, missing="no loaded foot"))
        checks.append(Check.measure(
            "lateral_force", fig["forces_bw"]["lateral_max_abs"], lim.lateral, "BW",
            "largest mediolateral force of a foot, level ground", source=SOURCES["lateral_force"], warning=True,
            capture=_get(cap, "forces_bw", "lateral_max_abs"), applies=level, missing="no loaded foot"))
        checks.append(Check.measure(
            "vertical_force_peak", fig["forces_bw"]["vertical_max"], lim.peak_vertical, "BW",
            "largest vertical force of a foot, level ground",
            source=SOURCES["vertical_force_shape"], warning=True, capture=_get(cap, "forces_bw", "vertical_max"),
            applies=level, missing="no loaded foot"))
        humps = [min(s["loading_peak_bw"], s["push_off_peak_bw"]) - s["valley_bw"]
                 for s in fig.get("vertical_force_shape") or []]
        cap_humps = [min(s["loading_peak_bw"], s["push_off_peak_bw"]) - s["valley_bw"]
                     for s in (_get(cap, "vertical_force_shape") or [])]
        plates_valley = bool(_get(cap, "plates")) and bool(cap_humps) and min(cap_humps) >= lim.plates_hump
        checks.append(Check.measure(
            "vertical_force_shape", min(humps) if humps else None, lim.hump, "BW",
            "smallest height of a stance's loading or push-off peak above its mid-stance valley, level ground"
            + (" (the capture's plates show the valley)" if plates_valley else ""),
            source=SOURCES["vertical_force_shape"], warning=not plates_valley, at_least=True,
            capture=min(cap_humps) if cap_humps else None, applies=level,
            missing="no stance with a loading and a push-off peak"))
        checks.append(Check.measure(
            "fore_aft_pattern", _fig(fig, "fore_aft_pattern", "max_sign_changes"), lim.fore_aft_changes, "changes",
            f"most sign changes of a foot's fore-aft force within one stance (crossing ±{lim.fore_aft_band:g} BW "
            f"while the foot carries over {lim.fore_aft_load:g} BW), level ground", source=SOURCES["fore_aft_pattern"],
            capture=_get(cap, "fore_aft_pattern", "max_sign_changes"), applies=level,
            missing="no stance carrying the load"))
        rf = fig["required_friction"]
        cap_rf = _get(cap, "required_friction", "max")
        checks.append(Check.measure(
            "friction_margin", rf["max"] / rf["mu"], lim.friction_use, "μ",
            f"largest friction a foot loaded over {lim.friction_load:g} BW needs, as a fraction of μ",
            source=SOURCES["friction_margin"], capture=None if cap_rf is None else cap_rf / rf["mu"]))
        checks.append(Check.measure(
            "push", _fig(fig, "push", "min"), lim.push, "f_z·leg",
            "least horizontal force of a loaded foot along the line from the foot to the centre of mass",
            source=SOURCES["push"], warning=True, at_least=True, capture=_get(cap, "push", "min"),
            missing="no loaded foot"))
    st = fig.get("stairs_geometry")
    if st:
        checks.append(Check.measure(
            "nosing_clearance", _fig(st, "nosing_clearance", "min_m"), lim.nosing_clearance_m, "m",
            "least height of a swinging sole corner above a nosing it passes, where it crosses the riser's plane "
            "(along the spline between the frames; negative: through the riser)", source=SOURCES["nosing_clearance"],
            at_least=True, missing="no swing passes a nosing"))
        checks.append(Check.measure(
            "stance_over_nosing", _fig(st, "tread", "max_over_nosing_m"), lim.tread_overhang_m, "m",
            "furthest a stance sole's corner stands beyond its tread's nosing (over the step below)",
            source=SOURCES["stance_on_tread"], missing="no stance on a tread"))
        checks.append(Check.measure(
            "stance_into_riser", _fig(st, "tread", "max_into_riser_m"), lim.tread_riser_m, "m",
            "furthest a stance sole's corner reaches into the riser of the step above its tread",
            source=SOURCES["stance_on_tread"], missing="no stance on a tread"))
        ref = STAIRS_SWING[st["direction"]]
        for joint in ("knee", "hip"):
            lo_, hi_ = ref[joint]
            checks.append(Check.measure(
                f"stairs_swing_{joint}", _fig(st, "swing_peaks", f"{joint}_min_deg"), lo_, "deg",
                f"least, over the swings, of the peak swing {joint} flexion (people going {st['direction']}: "
                f"{lo_:g}-{hi_:g}°)", source=SOURCES["stairs_swing"], warning=True, at_least=True,
                missing="no swing"))
    slope = fig["slope_along_deg"]
    lean, tut_lean = fig["trunk_lean_deg"]["mean"], _get(tut, "trunk_lean_deg", "mean")
    if tut_lean is not None and abs(slope) > lim.level_deg:
        back = (tut_lean - lean) if slope > 0 else (lean - tut_lean)  # leaning back uphill, forward downhill
        checks.append(Check.measure(
            "trunk_lean", back, lim.lean_tol_deg, "deg",
            (f"trunk ({fig['trunk_lean_deg']['segment']}) lean against gravity {lean:+.1f}° vs the tutor's "
             f"{tut_lean:+.1f}° on a {slope:+.1f}° slope: degrees further "
             + ("back" if slope > 0 else "forward")), source=SOURCES["trunk_lean"]))
    pr = fig["pelvis_range_deg"]
    cpr = _get(cap, "pelvis_range_deg") or {}
    for ax, limv in (("pitch", lim.pelvis_pitch_range_deg), ("roll", lim.pelvis_roll_range_deg),
                     ("yaw", lim.pelvis_yaw_range_deg)):
        checks.append(Check.measure(f"pelvis_{ax}_range", pr[ax], max(limv, cpr.get(ax, 0.0) + 5.0), "deg",
                                    f"pelvis {ax} range over the cycle"
                                    + (" (about the heading's trend)" if ax == "yaw" else "")
                                    + " (limit: the published range, or the capture's + 5°)",
                                    source=SOURCES["pelvis_ranges"], warning=True, capture=cpr.get(ax)))
    checks.append(Check.measure(
        "foot_heading", _fig(fig, "foot_heading_deg", "max_abs_loaded"), lim.foot_heading_deg, "deg",
        "largest heading difference between a loaded foot and the pelvis", source=SOURCES["foot_heading"], warning=True,
        capture=_get(cap, "foot_heading_deg", "max_abs_loaded"), missing="no loaded foot"))
    return {c.name: c for c in checks}


def motion_figures(motion: Motion, lim: NaturalnessLimits = NaturalnessLimits()) -> dict[str, Any]:
    """``gait_figures`` of a motion (its stored ground reactions, its environment)."""
    env = motion.environment
    if motion.contacts is None:
        raise ValueError("naturalness needs a contact schedule")
    forces = None if motion.wrenches is None else np.asarray(motion.wrenches)[:, 3:6]
    return gait_figures(motion.character, motion.q, motion.fps, motion.contacts, forces=forces, gravity=env.gravity,
                        mu=env.friction, weight=body_weight(motion), ground=ground_of(motion),
                        cyclic=motion.cyclic, lim=lim, flight=flight_of(motion))


def naturalness_report(motion: Motion, reference: Mapping[str, Any] | None = None,
                       lim: NaturalnessLimits = NaturalnessLimits()) -> dict[str, Any]:
    """The naturalness section of the validation report: every check as a figure with its limit,
    its source and the capture's own figure; ``reference`` defaults to the motion's context
    ``gait_reference`` ({"capture": …, "tutor": …} figures). ``passed`` is None when the motion
    cannot be checked (no contact schedule, or feet without a heel and a toe point)."""
    return naturalness_checks(motion, reference, lim).to_dict()


@register_check(section="naturalness", verdict="natural", order=20)
def _naturalness_section(ctx: Context) -> SectionResult:
    return naturalness_checks(ctx.motion, lim=ctx.limits_for("naturalness", NaturalnessLimits()))


def naturalness_checks(motion: Motion, reference: Mapping[str, Any] | None = None,
                       lim: NaturalnessLimits = NaturalnessLimits()) -> SectionResult:
    """The naturalness checks of a motion (and the section's limits, notes and figures)."""
    t0 = time.perf_counter()
    out: dict[str, Any] = {"limits": asdict(lim), "notes": []}
    if motion.contacts is None or not motion.character.has_soles:
        out["notes"].append("no contact schedule, or feet without a heel and a toe contact point: "
                            "naturalness not checked")
        out["time_s"] = time.perf_counter() - t0
        return SectionResult((), out, checked=False, unchecked=None)
    if reference is None:
        ref = motion.context.gait_reference
        reference = None if ref is None else ref.to_dict()
    fig = motion_figures(motion, lim)
    checks = checks_of(fig, reference=reference, lim=lim)
    if reference is None or reference.get("capture") is None:
        out["notes"].append("no figures of the captured walk recorded: checked against the published limits only")
    out["figures"] = jsonable(fig)
    out["time_s"] = time.perf_counter() - t0
    return SectionResult(tuple(checks.values()), out)


# --- the captured walk ------------------------------------------------------------------------------


def plate_forces(measured, T: int) -> np.ndarray | None:
    """(2, 3, T) the force plates' per-foot forces on a cycle's frames, NaN where the plates are
    incomplete (``MeasuredGRF.valid`` False); None without plates."""
    if measured is None:
        return None
    F = np.array(measured.force, dtype=float)
    if F.shape != (2, 3, T):
        return None
    F[:, :, ~np.asarray(measured.valid, dtype=bool)] = np.nan
    return F


def capture_figures(character, q: np.ndarray, fps: float, contacts: np.ndarray, measured=None,
                    lim: NaturalnessLimits = NaturalnessLimits()) -> dict[str, Any]:
    """``gait_figures`` of a captured cycle (the capture skeleton, its plates where complete): the
    capture column of every check."""
    fig = gait_figures(character, q, fps, contacts, forces=plate_forces(measured, q.shape[1]), lim=lim)
    fig["plates"] = measured is not None
    return jsonable(fig)


def against_plates(forces: np.ndarray, measured, q: np.ndarray, weight: float) -> dict[str, Any] | None:
    """A motion's per-foot vertical and fore-aft forces against the force plates on the same frames
    (complete plates only): RMS error and peaks, in body weights (fore-aft along the direction of
    travel)."""
    P = plate_forces(measured, q.shape[1])
    if P is None:
        return None
    N = q.shape[1] - 2
    path = path_heading(q, N)
    fwd = np.stack([np.cos(path), np.sin(path), np.zeros(q.shape[1])])
    out: dict[str, Any] = {}
    for k, side in enumerate(FEET):
        ok = np.all(np.isfinite(P[k]), axis=0)
        ok[N:] = False
        if ok.sum() < 3:
            continue
        row: dict[str, Any] = {"frames": int(ok.sum())}
        for name, comp in (("vertical", lambda F: F[2]), ("fore_aft", lambda F: fwd[0] * F[0] + fwd[1] * F[1])):
            a, b = comp(forces[k])[ok] / weight, comp(P[k])[ok] / weight
            row[name] = {"rms_bw": float(np.sqrt(np.mean((a - b) ** 2))), "max_bw": float(a.max()),
                         "min_bw": float(a.min()), "plates_max_bw": float(b.max()), "plates_min_bw": float(b.min())}
        out[side] = row
    return out or None


def joint_rms_deg(character, q: np.ndarray, capture_character, q_capture: np.ndarray,
                  exclude: tuple[str, ...] = ()) -> dict[str, Any]:
    """RMS difference (deg) over the cycle between a motion's joint angles and the capture's own,
    per coordinate the two share (hinges, root excluded) and overall; the pelvis's three rotations
    apart; ``exclude``: coordinates the capture did not measure (still arms given a swing)."""
    N = q.shape[1] - 2
    per: dict[str, float] = {}
    for i, name in enumerate(character.coordinate_names):
        if i < 3 or name not in capture_character.coordinate_names or name in exclude:
            continue
        d = q[i, :N] - q_capture[capture_character.coordinate_names.index(name), :N]
        per[name] = float(np.degrees(np.sqrt(np.mean(d ** 2))))
    joints = [v for k, v in per.items() if not k.startswith("root_")]
    pelvis = [v for k, v in per.items() if k.startswith("root_")]
    return {"overall": float(np.sqrt(np.mean(np.square(joints)))) if joints else None,
            "pelvis": float(np.sqrt(np.mean(np.square(pelvis)))) if pelvis else None, "per_coordinate": per}
