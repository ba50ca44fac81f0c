"""How far the fit can be trusted (:func:`solver.io.fit.fit_track`): marker registration and
marker error, the anatomy's plausibility, and the verdict.

* **Marker registration.** Each of the file's markers (``SkeletonTrack.markers``: C3D) sits on
  one segment of the fitted skeleton, at the per-axis median over the trial of its coordinates in
  that segment's fitted frame. Its error at a frame is the distance between that registered point,
  carried by the fitted motion, and the marker itself: the residual that scaling, the landmark
  model (hip regression, knee and ankle centres) and IK leave — soft tissue, a marker that is not
  where its role says, a marker on the wrong segment or side. Figures: ``marker_rms_mm`` (RMS
  over every marker and frame), ``per_marker_mm`` (label -> role, segment, RMS, max, where it
  sits on its segment) and ``per_segment_mm`` (RMS over the markers of each segment).
* **Anatomy** (``anatomy``): what a fit with markers in the wrong place shows even when the RMS
  looks fine, because a marker set consistently wrong is registered consistently: knee
  hyperextension (most negative knee flexion), the range of knee ab/adduction (a knee whose
  flexion axis is wrong bends sideways), hip, knee and ankle rotation (a segment turned about its
  long axis), the heading of each foot in stance against the walking path (the pelvis' travel,
  averaged over a second; its facing when it travels less than 0.3 m/s), the pelvis' tilt from
  upright and the left/right difference of segment lengths.
* **Verdict** (``verdict``): ``ok`` when the marker RMS is within ``limit_mm`` (default
  :data:`FIT_LIMIT_MM`, AddBiomechanics' and OpenSim's 2 cm) and no anatomical figure is past its
  limit; ``problems`` says what is not. The fit refuses a capture whose verdict is not ok
  (:class:`PoorFitError`) unless told to accept it.

Limits (module constants, docs/import.md): :data:`FIT_LIMIT_MM` 20 mm marker RMS;
:data:`KNEE_HYPEREXTENSION_LIMIT_DEG` 10°; :data:`KNEE_ADDUCTION_RANGE_LIMIT_DEG` 30°;
:data:`HIP_ROTATION_LIMIT_DEG` 50°; :data:`AXIAL_ROTATION_LIMIT_DEG` 75° (knee, ankle);
:data:`FOOT_HEADING_LIMIT_DEG` 40°; :data:`PELVIS_TILT_LIMIT_DEG` 45°;
:data:`LENGTH_ASYMMETRY_LIMIT_PCT` 10 % (thigh, shank), 25 % (foot).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from solver.character import Character
from solver.kinematics import contact_points, segment_frames

#: marker RMS (mm) above which a fit is refused (AddBiomechanics reports < 2 cm; OpenSim's best
#: practice 1-2 cm)
FIT_LIMIT_MM = 20.0
#: most knee hyperextension (deg, negative knee flexion) a fit may show (walking: 0-5°)
KNEE_HYPEREXTENSION_LIMIT_DEG = 10.0
#: widest range of knee ab/adduction (deg) over the trial (walking with skin markers: 10-20°)
KNEE_ADDUCTION_RANGE_LIMIT_DEG = 30.0
#: largest hip rotation (deg) either way (walking: within ±20° of a neutral that marker placement
#: and femoral anteversion may move by 20°)
HIP_ROTATION_LIMIT_DEG = 50.0
#: largest angle (deg) between a loaded foot's heading and the walking path (foot progression
#: angle: 0-20° out-toeing, pathological in- or out-toeing up to 30°)
FOOT_HEADING_LIMIT_DEG = 40.0
#: largest median angle (deg) between the pelvis' up axis and the vertical (standing pelvic tilt
#: 5-15°; a pelvis whose left and right markers are swapped stands upside down)
PELVIS_TILT_LIMIT_DEG = 45.0
#: largest left/right difference of segment lengths (% of their mean): thigh and shank (joint
#: centre to joint centre; people < 3 %), foot (ankle centre to metatarsal heads: also where the
#: toe marker was put; the shared trials 7-14 %)
LENGTH_ASYMMETRY_LIMIT_PCT = {"thigh": 10.0, "shank": 10.0, "foot": 25.0}
#: largest knee or ankle rotation (deg) either way: a shank or foot turned about its long axis
#: (lateral and medial markers swapped turn it by 180°; walking: within ±50° of neutral with
#: tibial torsion and toe-out)
AXIAL_ROTATION_LIMIT_DEG = 75.0
#: pelvis speed (m/s) below which the path is the pelvis' facing (treadmill, in-place clip)
PATH_MIN_SPEED = 0.3
#: markers named per problem
WORST_NAMED = 3

SIDE_NAME = {"r": "right", "l": "left"}


def _rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e**2))) if e.size else math.nan


def marker_figures(ch: Character, q: np.ndarray, markers: Mapping[str, Any]) -> dict[str, Any] | None:
    """Register each marker (``label -> TrackMarker``) on its fitted segment and measure it (see
    the module doc). None without markers; markers on segments the character lacks (the upper
    body of a lower-body fit) are listed under ``markers_not_fitted``."""
    if not markers:
        return None
    names = [s.name for s in ch.segments]
    rots, poss = segment_frames(ch, q)
    per: dict[str, dict[str, Any]] = {}
    by_segment: dict[str, list[np.ndarray]] = {}
    errors: list[np.ndarray] = []
    skipped: dict[str, str] = {}
    for label, m in markers.items():
        if m.segment not in names:
            skipped[label] = f"{m.segment} is not a segment of {ch.name}"
            continue
        k = names.index(m.segment)
        x = np.asarray(m.xyz, dtype=float)
        local = np.einsum("jit,jt->it", rots[k], x - poss[k])
        seen = np.all(np.isfinite(local), axis=0)
        if not seen.any():
            skipped[label] = "never seen"
            continue
        p = np.median(local[:, seen], axis=1)
        model = poss[k] + np.einsum("ijt,j->it", rots[k], p)
        e = 1e3 * np.linalg.norm(model[:, seen] - x[:, seen], axis=0)
        per[label] = {"role": m.role, "segment": m.segment, "rms": round(_rms(e), 2), "max": round(float(e.max()), 2),
                      "on_segment_m": [round(float(v), 4) for v in p]}
        by_segment.setdefault(m.segment, []).append(e)
        errors.append(e)
    if not errors:
        return None
    allerr = np.concatenate(errors)
    return {
        "marker_rms_mm": round(_rms(allerr), 2),
        "marker_error_mm": {"rms": round(_rms(allerr), 2), "mean": round(float(allerr.mean()), 2),
                            "max": round(float(allerr.max()), 2)},
        "per_marker_mm": dict(sorted(per.items(), key=lambda kv: -kv[1]["rms"])),
        "per_segment_mm": {s: round(_rms(np.concatenate(v)), 2) for s, v in sorted(by_segment.items())},
        "markers_not_fitted": skipped,
    }


def _moving_mean(x: np.ndarray, n: int) -> np.ndarray:
    """Centred moving mean over ``n`` frames along the last axis (fewer at the ends)."""
    n = min(n, x.shape[-1])
    if n <= 1:
        return x
    kernel = np.ones(n)
    num = np.stack([np.convolve(r, kernel, mode="same") for r in x.reshape(-1, x.shape[-1])])
    den = np.convolve(np.ones(x.shape[-1]), kernel, mode="same")
    return (num / den).reshape(x.shape)


def _path_direction(ch: Character, q: np.ndarray, times: np.ndarray, rots: np.ndarray) -> tuple[np.ndarray, str]:
    """Unit horizontal walking direction (2, T): the pelvis' travel averaged over a second, or
    its facing (x axis, averaged the same way) when it travels slower than ``PATH_MIN_SPEED``."""
    T = times.size
    dt = float(np.median(np.diff(times))) if T > 1 else 1.0
    n = max(int(round(1.0 / dt)), 1)
    root = q[:2] if tuple(ch.coordinate_names[:2]) == ("root_tx", "root_ty") else None
    if root is not None and T > 2:
        v = _moving_mean(np.gradient(root, times, axis=1), n)
        speed = np.linalg.norm(v, axis=0)
        if float(np.median(speed)) >= PATH_MIN_SPEED:
            return v / np.maximum(speed, 1e-9), "pelvis travel"
    facing = _moving_mean(rots[0][:2, 0], n)  # the root segment: the pelvis
    return facing / np.maximum(np.linalg.norm(facing, axis=0), 1e-9), "pelvis facing"


def anatomy(ch: Character, q: np.ndarray, times: np.ndarray) -> dict[str, Any]:
    """Plausibility figures of the fitted motion (degrees), per side ``right`` / ``left``:
    ``knee_hyperextension`` (−min knee flexion, 0 when never extended past straight),
    ``knee_adduction_range`` (1st-99th percentile span), ``hip_rotation_max`` (99th percentile
    of |rotation|), ``foot_heading`` (median signed angle, toes out positive, between the foot's
    heel-to-toe line and the path over the frames the foot is down) — each figure the skeleton
    has."""
    names = list(ch.coordinate_names)
    rots, _ = segment_frames(ch, q)
    segs = [s.name for s in ch.segments]
    out: dict[str, Any] = {}
    path, path_from = _path_direction(ch, q, times, rots)
    out["path_from"] = path_from
    cps = contact_points(ch, q)  # (C, 3, T)
    cnames = [c.name for c in ch.contacts]
    for s in ("r", "l"):
        fig: dict[str, float] = {}

        def deg(coord: str) -> np.ndarray | None:
            return np.degrees(q[names.index(coord)]) if coord in names else None

        knee = deg(f"knee_angle_{s}")
        if knee is not None:
            fig["knee_hyperextension"] = round(max(0.0, -float(np.percentile(knee, 1))), 1)
        add = deg(f"knee_adduction_{s}")
        if add is not None:
            fig["knee_adduction_range"] = round(float(np.percentile(add, 99) - np.percentile(add, 1)), 1)
        for joint in ("hip", "knee", "ankle"):
            rot = deg(f"{joint}_rotation_{s}")
            if rot is not None:
                fig[f"{joint}_rotation_max"] = round(float(np.percentile(np.abs(rot), 99)), 1)
        foot = f"foot_{s}"
        rows = [i for i, c in enumerate(cnames) if c.endswith(f"_{s}")]
        if foot in segs and rows:
            fx = rots[segs.index(foot)][:2, 0]
            low = np.min(cps[rows, 2], axis=0)
            down = low < np.percentile(low, 5) + 0.02
            ang = np.degrees(np.arctan2(path[0] * fx[1] - path[1] * fx[0], np.sum(path * fx, axis=0)))
            toe_out = ang if s == "l" else -ang  # left foot turned left / right foot turned right: out
            ok = down & (np.linalg.norm(fx, axis=0) > 0.3)  # a foot near vertical has no heading
            if ok.any():
                fig["foot_heading"] = round(float(np.median(toe_out[ok])), 1)
        out[SIDE_NAME[s]] = fig
    if segs[0] == "pelvis":
        up = rots[0][2, 2]  # the pelvis' up axis against the vertical
        out["both"] = {"pelvis_from_vertical": round(float(np.degrees(np.arccos(np.clip(np.median(up), -1, 1)))), 1)}
    asym = {}
    for kind in ("thigh", "shank", "foot"):
        if f"{kind}_r" in segs and f"{kind}_l" in segs:
            a, b = ch.segment(f"{kind}_r").length, ch.segment(f"{kind}_l").length
            asym[kind] = round(100.0 * abs(a - b) / (0.5 * (a + b)), 1)
    if asym:
        out.setdefault("both", {})["length_asymmetry_pct"] = asym
    return out


#: anatomical figure -> (limit constant, what it means when past the limit, the segments it blames)
_CHECKS = {
    "knee_hyperextension": ("KNEE_HYPEREXTENSION_LIMIT_DEG", "knee hyperextended {v:.0f}°", ("thigh", "shank")),
    "knee_adduction_range": ("KNEE_ADDUCTION_RANGE_LIMIT_DEG",
                             "knee ab/adduction spans {v:.0f}°: the knee bends sideways (its flexion axis is wrong)",
                             ("thigh", "shank")),
    "hip_rotation_max": ("HIP_ROTATION_LIMIT_DEG", "hip rotation reaches {v:.0f}°", ("pelvis", "thigh")),
    "knee_rotation_max": ("AXIAL_ROTATION_LIMIT_DEG",
                          "knee rotation reaches {v:.0f}°: the shank is turned about its long axis",
                          ("thigh", "shank")),
    "ankle_rotation_max": ("AXIAL_ROTATION_LIMIT_DEG",
                           "ankle rotation reaches {v:.0f}°: the foot is turned about the shank", ("shank", "foot")),
    "foot_heading": ("FOOT_HEADING_LIMIT_DEG", "foot heads {v:+.0f}° off the walking path while down (toes out +)",
                     ("shank", "foot")),
}


def verdict(figures: Mapping[str, Any] | None, anat: Mapping[str, Any], *, limit_mm: float = FIT_LIMIT_MM,
            marker_rms_mm: float | None = None, measured_on: str = "markers",
            markers: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """``{"ok", "marker_rms_mm", "limit_mm", "measured_on", "problems", "blame"}``: ``problems``
    one sentence each; ``blame`` the markers (label -> role) on the segments that do not fit.
    ``marker_rms_mm`` is the registered markers' RMS (``figures``) or the one given (a source's own
    marker IK); None when the source has no markers (only the anatomy is judged then)."""
    problems: list[str] = []
    blame: dict[str, str] = {}
    per = dict((figures or {}).get("per_marker_mm") or {})
    rms = figures["marker_rms_mm"] if figures else marker_rms_mm
    if rms is not None and not rms <= limit_mm:
        worst = list(per.items())[:WORST_NAMED]
        segs = sorted((figures or {}).get("per_segment_mm", {}).items(), key=lambda kv: -kv[1])[:WORST_NAMED]
        text = f"marker RMS {rms:.1f} mm exceeds the {limit_mm:g} mm limit"
        if worst:
            text += "; worst markers " + ", ".join(f"{lbl} ({v['role']}) {v['rms']:.0f} mm" for lbl, v in worst)
            text += "; worst segments " + ", ".join(f"{s} {v:.0f} mm" for s, v in segs)
            blame.update({lbl: v["role"] for lbl, v in worst})
        problems.append(text)
    limits = globals()
    both = dict(anat.get("both") or {})
    if "pelvis_from_vertical" in both and both["pelvis_from_vertical"] > PELVIS_TILT_LIMIT_DEG:
        problems.append(f"the pelvis stands {both['pelvis_from_vertical']:.0f}° from upright (limit "
                        f"{PELVIS_TILT_LIMIT_DEG:g}°): its left and right markers are swapped")
        blame.update({lbl: m.role for lbl, m in (markers or {}).items() if m.segment == "pelvis" and m.role})
    for kind, pct in (both.get("length_asymmetry_pct") or {}).items():
        if pct > LENGTH_ASYMMETRY_LIMIT_PCT[kind]:
            problems.append(f"the left and right {kind} lengths differ by {pct:.0f} % (limit "
                            f"{LENGTH_ASYMMETRY_LIMIT_PCT[kind]:g} %)")
            blame.update({lbl: m.role for lbl, m in (markers or {}).items()
                          if m.segment.startswith(kind) and m.role})
    for side in ("right", "left"):
        for key, value in (anat.get(side) or {}).items():
            const, what, seg_kinds = _CHECKS[key]
            if abs(value) > limits[const]:
                problems.append(f"{side} " + what.format(v=value) + f" (limit {limits[const]:g}°)")
                segs_blamed = {f"{k}_{side[0]}" if k != "pelvis" else k for k in seg_kinds}
                for lbl, m in (markers or {}).items():
                    if m.segment in segs_blamed and m.role:
                        blame[lbl] = m.role
    return {"ok": not problems, "marker_rms_mm": rms, "limit_mm": limit_mm, "measured_on": measured_on,
            "problems": problems, "blame": blame}
