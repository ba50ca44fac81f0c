"""The fitting step shared by every importer: SkeletonTrack -> Capture.

Public API (stable; the C3D, OpenSim, DeepMimic and BVH readers all call it)::

    fit_track(track: SkeletonTrack, *, lower_only: bool | None = None,
              orientation_weight: float = 0.05) -> Capture

* ``track``: landmarks (3, T) in OUR world frame (Z up, X forward, Y left, metres; NaN where
  a landmark is missing at a frame), optional segment orientations (3, 3, T), subject mass,
  optional per-segment masses (our segment names), measured GRF, contact schedule. See
  :mod:`solver.io.track` for the landmark names.
* ``lower_only``: ``None`` = automatic (whole body when the track has every upper-body
  landmark, otherwise lower body); ``True`` = the ``capture-lower`` topology, the pelvis
  carrying head, arms and trunk (their masses lumped as :func:`merge_segments` does);
  ``False`` = whole body (an error if the track has no upper body).
* ``orientation_weight``: metres of landmark error one unit of ``‖R_model − R_track‖_F``
  is worth (0.05: 1° ≈ 1.2 mm). Orientations resolve axial rotations that joint-centre
  landmarks cannot see.

What it does:

1. **Segment frames** per frame: the track's orientation when given, otherwise a frame built
   from landmarks (bone along ``z``, hinge axis ``y`` from the parent, ``x`` forward; the
   foot's ``x`` runs heel -> toe so "foot flat" is the neutral pose).
2. **Dimensions** from the data: every joint offset, bone tip and attached landmark is the
   per-axis *median* over the trial of its coordinates in its segment's frame (robust to
   outliers and gaps). The topology, coordinate names, axes and limits are those of
   ``capture_full()`` / ``capture_lower()``; only the numbers are the subject's.
3. **Masses** from ``track.segment_masses`` (a source model), otherwise Winter's table ×
   ``track.mass``; a track with neither is refused. Inertias are the prolate ellipsoids of
   docs/method.md (M1.1)-(M1.3) unless ``track.source["segment_inertias"]`` gives ``{segment: {"com": (3,),
   "inertia": (3, 3)}}`` (segment frame, about the COM) for segments whose frame comes
   from a track orientation.
4. **Feet**: the box spans heel -> toe (foot frame), is ``track.source["foot_width"]`` or
   Winter's 0.055 H wide, from the sole (lowest of the heel/toe landmarks) to a quarter of
   the ankle height above the ankle; heel and toe contact points sit 1 cm inside (docs/method.md (M1)).
5. **Inverse kinematics**: residuals (landmarks, weighted orientations) are built once as
   CasADi SX expressions from :mod:`solver.kinematics`; each frame is solved by
   Levenberg-Marquardt, started from the analytic joint angles of the segment frames
   (relative rotations decomposed on each joint's hinge axes) shifted by 2π multiples to be
   continuous with the previous frame. Joint limits are ignored during IK; the character's
   limits are widened (5° margin) where the data exceed them, and the widening recorded.
6. ``capture.source["fit"]``: landmark error (mm) overall and per landmark, orientation
   error (deg) per segment, widened limits, timings.
7. **Quality** (:mod:`solver.io.fit_quality`): the track's markers registered on the fitted
   skeleton (marker RMS overall, per marker, per segment), the anatomy's plausibility figures and
   the verdict ``source["fit"]["verdict"]``. ``fit_tolerance_mm`` is the marker RMS limit (default
   :data:`~solver.io.fit_quality.FIT_LIMIT_MM`, 20 mm); a verdict that is not ok raises
   :class:`PoorFitError` for a track with markers (``accept_poor_fit=None``), never
   (``True``: a warning) or always (``False``).
"""

from __future__ import annotations

import logging
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

from solver.capture import Capture
from solver.character import (
    WINTER_LENGTH,
    ContactPoint,
    FootBox,
    SegmentSpec,
    build_character,
    capture_full,
    capture_lower,
    merge_segments,
    winter_density,
    winter_mass,
)
from solver.errors import InputError
from solver.io.fit_ik import _solve_ik, _widen_limits, decompose_hinges
from solver.io.fit_quality import FIT_LIMIT_MM, anatomy, marker_figures, verdict
from solver.io.track import LOWER_LANDMARKS, UPPER_LANDMARKS, SkeletonTrack

log = logging.getLogger(__name__)

__all__ = ["FIT_LIMIT_MM", "SEGMENT_LANDMARKS", "FitError", "PoorFitError", "decompose_hinges", "fit_track"]


class FitError(InputError):
    """The track cannot be fitted (missing data, unknown mass, ...); the message says why
    (``parameter`` names the argument that would fix it, e.g. "mass")."""


class PoorFitError(FitError):
    """The fit is not to be trusted: its marker RMS exceeds the limit (``fit_tolerance_mm``,
    default :data:`~solver.io.fit_quality.FIT_LIMIT_MM`) or its anatomy is implausible (knees
    bending sideways or hyperextended, hips rotated, feet off the path). The message names the
    problems and the markers on the segments concerned."""


SIDES = ("r", "l")
UPPER_SEGMENTS = ("abdomen", "thorax", "head") + tuple(
    f"{s}_{side}" for side in SIDES for s in ("clavicle", "upper_arm", "forearm", "hand")
)
LEG_SEGMENTS = tuple(f"{s}_{side}" for side in SIDES for s in ("thigh", "shank", "foot", "toes"))

#: segment -> (origin landmark, tip landmark, Winter kind). ``@thorax_joint`` and
#: ``@clavicle_*`` are virtual points derived from the landmarks (see ``_virtual_points``).
SEGMENT_LANDMARKS: dict[str, tuple[str, str | None, str]] = {
    "pelvis": ("pelvis", "lumbar", "pelvis"),
    "abdomen": ("lumbar", "@thorax_joint", "abdomen"),
    "thorax": ("@thorax_joint", "neck", "thorax"),
    "head": ("neck", "head_top", "head_neck"),
    **{
        k: v
        for side in SIDES
        for k, v in {
            f"clavicle_{side}": (f"@clavicle_{side}", f"shoulder_{side}", "clavicle"),
            f"upper_arm_{side}": (f"shoulder_{side}", f"elbow_{side}", "upper_arm"),
            f"forearm_{side}": (f"elbow_{side}", f"wrist_{side}", "forearm"),
            f"hand_{side}": (f"wrist_{side}", f"hand_{side}", "hand"),
            f"thigh_{side}": (f"hip_{side}", f"knee_{side}", "thigh"),
            f"shank_{side}": (f"knee_{side}", f"ankle_{side}", "shank"),
            f"foot_{side}": (f"ankle_{side}", f"mtp_{side}", "foot"),
            f"toes_{side}": (f"mtp_{side}", f"toe_{side}", "toes"),
        }.items()
    },
}

#: Landmarks fixed on a segment that are neither its origin nor its tip.
EXTRA_LANDMARKS = {"sternum": "thorax", "heel_r": "foot_r", "heel_l": "foot_l"}

#: Fraction of lumbar -> neck at which the thorax joint sits (capture_full: 0.10 H / 0.24 H).
THORAX_JOINT_FRACTION = 0.10 / 0.24
#: Hip joint centre height as a fraction of body height (Winter: greater trochanter 0.530 H).
HIP_HEIGHT_FRACTION = 0.530
CONTACT_INSET = 0.01


# --- small vector helpers (batched over time: arrays (3, T), frames (3, 3, T)) ------------


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=0)
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / np.where(n > 1e-12, n, np.nan)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return np.cross(a, b, axis=0)


def _frame_zy(z: np.ndarray, y_ref: np.ndarray, x_ref: np.ndarray | None = None) -> np.ndarray:
    """Frame with z along ``z`` and y as close as possible to ``y_ref`` (fallback x_ref)."""
    z = _unit(z)
    y = y_ref - np.sum(y_ref * z, axis=0) * z
    if x_ref is not None:
        bad = np.linalg.norm(y, axis=0) < 0.3 * np.linalg.norm(y_ref, axis=0)
        if np.any(bad):
            x = x_ref - np.sum(x_ref * z, axis=0) * z
            y_alt = _cross(z, x)
            y = np.where(bad[None, :], y_alt, y)
    y = _unit(y)
    x = _cross(y, z)
    return np.stack([x, y, z], axis=1)  # columns x, y, z


def _frame_xy(x: np.ndarray, y_ref: np.ndarray) -> np.ndarray:
    """Frame with x along ``x`` and y as close as possible to ``y_ref``."""
    x = _unit(x)
    y = _unit(y_ref - np.sum(y_ref * x, axis=0) * x)
    z = _cross(x, y)
    return np.stack([x, y, z], axis=1)


def _local(R: np.ndarray, origin: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Coordinates (3, T) of world points p in the frames (R, origin)."""
    return np.einsum("jit,jt->it", R, p - origin)


def _median_local(R: np.ndarray, origin: np.ndarray, p: np.ndarray, what: str) -> np.ndarray:
    loc = _local(R, origin, p)
    ok = np.all(np.isfinite(loc), axis=0)
    if not np.any(ok):
        raise FitError(f"cannot measure {what}: no frame where the landmarks and the segment frame are all known "
                       "(two of the joints that place them coincide, or one is missing in every frame): name the "
                       "joints that play the roles in a joint mapping, or import the lower body only",
                       parameter="joints")
    return np.median(loc[:, ok], axis=1)


# --- joint-angle decomposition ------------------------------------------------------------


# --- the fit --------------------------------------------------------------------------------


def _check_track(track: SkeletonTrack) -> tuple[np.ndarray, dict[str, np.ndarray], dict[str, np.ndarray]]:
    times = np.asarray(track.times, dtype=float)
    if times.ndim != 1 or times.size == 0:
        raise FitError("the track has no frames")
    if not np.all(np.isfinite(times)):
        raise FitError("the track's times contain NaN or infinite values")
    if times.size >= 2 and not np.all(np.diff(times) > 0):
        raise FitError("the track's times must increase strictly")
    lm = {k: np.asarray(v, dtype=float) for k, v in track.landmarks.items()}
    for name, p in lm.items():
        if np.any(np.isinf(p)):
            raise FitError(f"landmark {name!r} has infinite coordinates")
        if not np.any(np.all(np.isfinite(p), axis=0)):
            raise FitError(f"landmark {name!r} is missing (NaN) at every frame")
    ori = {k: np.asarray(v, dtype=float) for k, v in track.orientations.items()}
    for name, r in ori.items():
        ok = np.all(np.isfinite(r), axis=(0, 1))
        if not np.any(ok):
            raise FitError(f"orientation of segment {name!r} is missing (NaN) at every frame")
        rr = r[:, :, ok]
        err = np.abs(np.einsum("jit,jkt->ikt", rr, rr) - np.eye(3)[:, :, None]).max()
        if err > 1e-3 or np.any(np.linalg.det(np.moveaxis(rr, 2, 0)) < 0):
            raise FitError(f"orientation of segment {name!r} is not a rotation matrix at some frame")
    return times, lm, ori


def _virtual_points(lm: dict[str, np.ndarray]) -> None:
    if "lumbar" in lm and "neck" in lm:
        lm["@thorax_joint"] = lm["lumbar"] + THORAX_JOINT_FRACTION * (lm["neck"] - lm["lumbar"])


def _segment_frames(
    segs: list[str], lm: dict[str, np.ndarray], ori: dict[str, np.ndarray], T: int
) -> tuple[dict[str, np.ndarray], dict[str, str]]:
    """World frames (3, 3, T) of every segment and where each came from ("track"/"landmarks")."""
    F: dict[str, np.ndarray] = {}
    src: dict[str, str] = {}
    up = np.tile(np.array([[0.0], [0.0], [1.0]]), (1, T))

    def get(name: str) -> np.ndarray:
        return F[name]

    for s in segs:
        if s in ori:
            F[s], src[s] = ori[s], "track"
            continue
        src[s] = "landmarks"
        side = s[-1]
        if s == "pelvis":
            y = _unit(lm["hip_l"] - lm["hip_r"])
            ref_up = lm["lumbar"] - lm["pelvis"] if "lumbar" in lm else up
            x = _unit(_cross(y, ref_up))
            F[s] = np.stack([x, y, _cross(x, y)], axis=1)
        elif s == "abdomen":
            F[s] = _frame_zy(lm["neck"] - lm["lumbar"], get("pelvis")[:, 1], get("pelvis")[:, 0])
        elif s == "thorax":
            yref = lm["shoulder_l"] - lm["shoulder_r"] if "shoulder_l" in lm else get("abdomen")[:, 1]
            F[s] = _frame_zy(lm["neck"] - lm["lumbar"], yref, get("abdomen")[:, 0])
        elif s == "head":
            F[s] = _frame_zy(lm["head_top"] - lm["neck"], get("thorax")[:, 1], get("thorax")[:, 0])
        elif s.startswith("clavicle"):
            F[s] = get("thorax")
        elif s.startswith("upper_arm"):
            F[s] = _frame_zy(lm[f"shoulder_{side}"] - lm[f"elbow_{side}"], get("thorax")[:, 1], get("thorax")[:, 0])
        elif s.startswith("forearm"):
            p = get(f"upper_arm_{side}")
            F[s] = _frame_zy(lm[f"elbow_{side}"] - lm[f"wrist_{side}"], p[:, 1], p[:, 0])
        elif s.startswith("hand"):
            p = get(f"forearm_{side}")
            F[s] = _frame_zy(lm[f"wrist_{side}"] - lm[f"hand_{side}"], p[:, 1], p[:, 0])
        elif s.startswith("thigh"):
            p = get("pelvis")
            F[s] = _frame_zy(lm[f"hip_{side}"] - lm[f"knee_{side}"], p[:, 1], p[:, 0])
        elif s.startswith("shank"):
            p = get(f"thigh_{side}")
            F[s] = _frame_zy(lm[f"knee_{side}"] - lm[f"ankle_{side}"], p[:, 1], p[:, 0])
        elif s.startswith("foot"):
            F[s] = _frame_xy(lm[f"toe_{side}"] - lm[f"heel_{side}"], get(f"shank_{side}")[:, 1])
        elif s.startswith("toes"):
            F[s] = _frame_xy(lm[f"toe_{side}"] - lm[f"mtp_{side}"], get(f"foot_{side}")[:, 1])
        else:  # pragma: no cover - the topology is fixed above
            raise FitError(f"no frame rule for segment {s!r}")
    return F, src


def _masses(track: SkeletonTrack, segs: list[str], lower_topology: bool) -> tuple[dict[str, float], float, str]:
    given = dict(track.segment_masses or {})
    known = set(SEGMENT_LANDMARKS)
    unknown = sorted(set(given) - known)
    if unknown:
        raise FitError(f"segment_masses names unknown segments {unknown}; known: {sorted(known)}")
    for k, v in given.items():
        if not (np.isfinite(v) and v >= 0):
            raise FitError(f"segment mass of {k!r} must be finite and >= 0, got {v}")
    total = track.mass
    if total is not None and not (np.isfinite(total) and total > 0):
        raise FitError(f"subject mass must be a positive number of kg, got {total}")
    if total is None and given:
        total = float(sum(given.values()))
    if total is None:
        fmt = str(track.source.get("format") or "")
        fmt = {"bvh": "BVH", "c3d": "C3D", "opensim": "OpenSim", "deepmimic": "DeepMimic"}.get(fmt, fmt)
        raise FitError(f"subject mass unknown: the {fmt + ' ' if fmt else ''}input does not state it",
                       parameter="mass", unit="kg")
    out: dict[str, float] = {}
    if lower_topology:
        legs = {s: given.get(s, winter_mass(SEGMENT_LANDMARKS[s][2], total)) for s in LEG_SEGMENTS}
        out.update(legs)
        out["pelvis"] = total - sum(legs.values())
        if out["pelvis"] <= 0:
            raise FitError(f"segment masses of the legs ({sum(legs.values()):.1f} kg) exceed the subject mass "
                           f"{total} kg")
        how = "segment_masses (legs) + remainder in pelvis" if given else "Winter table"
    else:
        for s in segs:
            out[s] = float(given[s]) if s in given else winter_mass(SEGMENT_LANDMARKS[s][2], total)
        missing = [s for s in segs if s not in given]
        if given and missing:
            # the source model had no such segment: share the rest of the mass by Winter's ratios
            rest = total - sum(given[s] for s in segs if s in given)
            w = sum(winter_mass(SEGMENT_LANDMARKS[s][2], 1.0) for s in missing)
            if rest > 0:
                for s in missing:
                    out[s] = rest * winter_mass(SEGMENT_LANDMARKS[s][2], 1.0) / w
        how = "segment_masses" if given and not missing else ("segment_masses + Winter" if given else "Winter table")
    return out, float(total), how


def fit_track(
    track: SkeletonTrack, *, lower_only: bool | None = None, orientation_weight: float = 0.05,
    fit_tolerance_mm: float = FIT_LIMIT_MM, accept_poor_fit: bool | None = None,
) -> Capture:
    """Build the subject's capture skeleton and solve IK for every frame (see module doc)."""
    t_start = time.perf_counter()
    if not (isinstance(fit_tolerance_mm, (int, float)) and fit_tolerance_mm > 0):
        raise FitError(f"fit_tolerance_mm must be a positive number of mm, got {fit_tolerance_mm!r}")
    times, lm, ori = _check_track(track)
    T = times.size
    has_upper = track.has_upper_body
    if lower_only is False and not has_upper:
        missing = [n for n in UPPER_LANDMARKS if n not in lm]
        raise FitError(f"lower_only=False needs the upper-body landmarks; missing {missing}")
    lower = bool(lower_only) or not has_upper
    full_geometry = has_upper  # measure the upper body whenever the data have it
    unknown_ori = sorted(set(ori) - set(SEGMENT_LANDMARKS))
    if unknown_ori:
        raise FitError(f"orientations given for unknown segments {unknown_ori}; known: {sorted(SEGMENT_LANDMARKS)}")
    ignored = sorted(set(lm) - set(LOWER_LANDMARKS) - set(UPPER_LANDMARKS))
    if ignored:
        log.info("fit_track: landmarks not used by the capture skeleton: %s", ignored)

    ref = capture_full() if full_geometry else capture_lower()
    segs = [s.name for s in ref.segments]
    _virtual_points(lm)
    F, frame_src = _segment_frames(segs, lm, ori, T)
    if full_geometry:
        # clavicle joints: on the thorax mid-line at the shoulders' mean height and depth
        th = F["thorax"]
        o_th = lm["@thorax_joint"]
        loc = [_median_local(th, o_th, lm[f"shoulder_{s}"], f"shoulder_{s} on the thorax") for s in SIDES]
        cj = 0.5 * (loc[0] + loc[1])
        cj[1] = 0.0
        p = o_th + np.einsum("ijt,j->it", th, cj)
        for s in SIDES:
            lm[f"@clavicle_{s}"] = p

    origin = {s: lm[SEGMENT_LANDMARKS[s][0]] for s in segs}
    height = _height(track, lm, F, origin, segs, full_geometry)

    offset, tip, attach = _geometry(ref, segs, lm, F, origin, height, full_geometry)

    # --- masses, inertias -------------------------------------------------------------------
    masses, total, mass_how = _masses(track, segs, lower_topology=not full_geometry)
    specs = _segment_specs(ref, offset, tip, masses, dict((track.source or {}).get("segment_inertias", {}) or {}),
                           frame_src)

    width = float((track.source or {}).get("foot_width") or WINTER_LENGTH["foot_width"] * height)
    contacts, feet, foot_report = _feet(attach, offset, tip, width)

    name = "capture-full" if full_geometry else "capture-lower"
    ch = build_character(name, specs, contacts, feet, height=height,
                         description=f"{name} fitted to {track.source.get('format', 'a track')}, "
                                     f"{height:.3f} m, {total:.2f} kg")
    if lower and full_geometry:
        ch = merge_segments(ch, UPPER_SEGMENTS, name="capture-lower")
        ch = replace(ch, description=ch.description.replace("capture-full", "capture-lower")
                     + " (head, arms and trunk lumped in the pelvis)")

    # --- inverse kinematics ---------------------------------------------------------------------
    t_ik = time.perf_counter()
    kept = {x.name for x in ch.segments}
    attach = {n: a for n, a in attach.items() if a[0] in kept}
    if "abdomen" in offset and "abdomen" not in kept:  # the lumbar joint is a point of the pelvis
        attach["lumbar"] = ("pelvis", offset["abdomen"])
    q, ik_report = _solve_ik(ch, times, lm, F, origin, ori, attach, orientation_weight)
    t_done = time.perf_counter()
    ch, widened = _widen_limits(ch, q)

    report = dict(ik_report)
    solve_s = report.pop("_solve_s")
    report.update({
        "topology": ch.name,
        "frames_from": {s: frame_src[s] for s in segs if s in {x.name for x in ch.segments}},
        "masses_from": mass_how,
        "total_mass_kg": float(ch.total_mass),
        "height_m": float(height),
        "feet": foot_report,
        "widened_limits": widened,
        "build_s": round(t_ik - t_start, 4),
        "ik_s": round(t_done - t_ik, 4),
        "ik_ms_per_frame": round(1e3 * solve_s / T, 3),
        "ik_setup_s": round(t_done - t_ik - solve_s, 4),
    })
    _judge(report, ch, q, times, track, attach, fit_tolerance_mm, accept_poor_fit)
    source = dict(track.source or {})
    source.pop("segment_inertias", None)
    source["fit"] = report
    log.info("fit_track: %s, %d frames, landmark error mean %.1f mm max %.1f mm, IK %.2f ms/frame",
             ch.name, T, report["landmark_error_mm"]["mean"], report["landmark_error_mm"]["max"],
             report["ik_ms_per_frame"])
    contacts_sched = None if track.contacts is None else np.asarray(track.contacts, dtype=bool)
    if contacts_sched is not None and contacts_sched.shape != (len(ch.contacts), T):
        raise FitError(f"track.contacts must be (4, T={T}) (heel_r, toe_r, heel_l, toe_l), got {contacts_sched.shape}")
    return Capture(character=ch, q=q, times=times, frame=track.frame, source=source,
                   contacts=contacts_sched, measured=track.measured)


def _judge(report: dict, ch, q: np.ndarray, times: np.ndarray, track: SkeletonTrack, attach: dict,
           limit_mm: float, accept: bool | None) -> None:
    """The fit's figures and verdict into ``report`` (:mod:`solver.io.fit_quality`); a
    :class:`PoorFitError` when the verdict is not ok — by default for a track with markers, whose
    fit is ours to vouch for (``accept``: True never, False always)."""
    figures = marker_figures(ch, q, track.markers)
    anat = anatomy(ch, q, times)
    ik = dict((track.source or {}).get("ik") or {})
    rms, on = None, "no markers in the source: anatomy only"
    if figures:
        on = "the file's markers, registered on the fitted skeleton"
        report.update(figures)
    else:
        if ik.get("marker_error_mm"):
            rms, on = round(float(ik["marker_error_mm"]["rms"]), 2), "OpenSim inverse kinematics of the model's markers"
        per_lm = report["per_landmark_mm"]
        by_seg: dict[str, list[float]] = {}
        for name, (seg, _) in attach.items():
            if name in per_lm:
                by_seg.setdefault(seg, []).append(per_lm[name]["rms"])
        report["marker_rms_mm"] = rms
        report["per_segment_mm"] = {k: round(float(np.sqrt(np.mean(np.square(v)))), 2)
                                    for k, v in sorted(by_seg.items())}
        report["per_segment_from"] = "landmarks"
    report["anatomy"] = anat
    v = verdict(figures, anat, limit_mm=float(limit_mm), marker_rms_mm=rms, measured_on=on, markers=track.markers)
    blame = v.pop("blame")
    report["verdict"] = v
    if v["ok"]:
        return
    src = track.source or {}
    name = Path(str(src["path"])).name if src.get("path") else f"the {src.get('format') or 'input'} trial"
    msg = f"{name}: the fit cannot be trusted: " + "; ".join(v["problems"])
    if blame:
        msg += ". Markers on what does not fit: " + ", ".join(f"{r}={lbl}" for lbl, r in blame.items())
    refuse = bool(track.markers) if accept is None else not accept
    if not refuse:
        log.warning("%s (imported %s: the verdict says not ok, so its tutors are never natural)", msg,
                    "as asked" if accept else "anyway: the source has no markers")
        return
    raise PoorFitError(
        msg + ". A marker in the wrong role (swapped sides, lateral for medial, a mislabelled or misplaced marker) "
        "does this: check those markers and map them (docs/c3d.md); accept_poor_fit=True imports the trial anyway "
        "(its tutors are then never natural), fit_tolerance_mm= raises the marker RMS limit",
        parameter="markers" if track.markers else None)


def _geometry(ref, segs, lm, F, origin, height, full_geometry):
    """The capture skeleton's geometry in segment frames (medians over the trial): each joint's
    offset on its parent, each segment's tip, and the landmarks IK matches (segment, point)."""
    by_name = {s.name: s for s in ref.segments}
    offset: dict[str, np.ndarray] = {}
    tip: dict[str, np.ndarray] = {}
    for s in segs:
        par = by_name[s].parent
        if par is not None:
            offset[s] = _median_local(F[par], origin[par], origin[s], f"the {s} joint on {par}")
        tname = SEGMENT_LANDMARKS[s][1]
        if tname is not None and tname in lm:
            tip[s] = _median_local(F[s], origin[s], lm[tname], f"{tname} on {s}")
    if not full_geometry:  # lower-body data: Winter's HAT ellipsoid above the hips
        tip["pelvis"] = np.array([0.0, 0.0, 2 * 0.18 * height])
    elif np.linalg.norm(tip["pelvis"]) < 0.02:  # lumbar landmark on the hips: capture_full's pelvis
        log.info("fit_track: lumbar landmark within 2 cm of the mid-hips; pelvis length 0.10 H")
        tip["pelvis"] = np.array([0.0, 0.0, 0.10 * height])
    # landmark -> (segment, point in segment coordinates): what IK matches
    attach: dict[str, tuple[str, np.ndarray]] = {}
    for s in segs:
        o_name, t_name, _ = SEGMENT_LANDMARKS[s]
        if not o_name.startswith("@"):
            attach.setdefault(o_name, (s, np.zeros(3)))
    for s in segs:
        t_name = SEGMENT_LANDMARKS[s][1]
        if t_name is not None and not t_name.startswith("@") and t_name in lm and s != "pelvis":
            attach.setdefault(t_name, (s, tip[s]))
    for n, seg in EXTRA_LANDMARKS.items():
        if n in lm and seg in F:
            attach[n] = (seg, _median_local(F[seg], origin[seg], lm[n], f"{n} on {seg}"))
    return offset, tip, attach


def _segment_specs(ref, offset, tip, masses, inertias, frame_src) -> list[SegmentSpec]:
    """One :class:`SegmentSpec` per segment of the reference skeleton: the measured geometry,
    the masses, and the source model's inertias where the segment's frame is the track's."""
    specs = []
    for rs in ref.segments:
        d = tip[rs.name]
        length = float(np.linalg.norm(d))
        if length < 1e-3:
            raise FitError(f"segment {rs.name!r} has zero length in the data ({SEGMENT_LANDMARKS[rs.name][:2]})")
        kind = SEGMENT_LANDMARKS[rs.name][2]
        com = inertia = None
        if rs.name in inertias and frame_src.get(rs.name) == "track":
            com = np.array(inertias[rs.name]["com"], dtype=float).reshape(3)
            inertia = np.array(inertias[rs.name]["inertia"], dtype=float).reshape(3, 3)
        specs.append(
            SegmentSpec(
                rs.name, rs.parent, tuple(offset.get(rs.name, np.zeros(3))), rs.dofs, length, masses[rs.name],
                tuple(d / length), winter_density(kind), com=com, inertia=inertia,
            )
        )
    return specs


def _feet(attach, offset, tip, width: float):
    """Each foot's box (heel -> toe, sole to a quarter of the ankle height) and its heel and
    toe contact points, with the feet's figures for the report."""
    contacts, feet, foot_report = [], [], {}
    for side in SIDES:
        full = "right" if side == "r" else "left"
        heel = attach[f"heel_{side}"][1]
        toe = offset[f"toes_{side}"] + tip[f"toes_{side}"]
        sole = min(heel[2], toe[2])
        top = 0.25 * max(-sole, 0.02)
        if toe[0] - heel[0] < 0.05:
            raise FitError(f"{full} foot: heel->toe length {toe[0] - heel[0]:.3f} m is not a foot "
                           "(check the landmarks)")
        yc = 0.5 * (heel[1] + toe[1])
        feet.append(FootBox(full, f"foot_{side}", np.array([(heel[0] + toe[0]) / 2, yc, (sole + top) / 2]),
                            np.array([(toe[0] - heel[0]) / 2, width / 2, (top - sole) / 2])))
        contacts += [
            ContactPoint(f"heel_{side}", full, f"foot_{side}",
                         np.array([heel[0] + CONTACT_INSET, yc, sole + CONTACT_INSET])),
            ContactPoint(f"toe_{side}", full, f"foot_{side}",
                         np.array([toe[0] - CONTACT_INSET, yc, sole + CONTACT_INSET])),
        ]
        foot_report[full] = {"length_m": float(toe[0] - heel[0]), "width_m": width, "ankle_height_m": float(-sole)}
    return contacts, feet, foot_report


#: the height from legs, trunk and head must agree with the legs' alone (hip height 0.530 H) within this
HEIGHT_AGREEMENT = 0.3


def _height(track, lm, F, origin, segs, full_geometry) -> float:
    if track.height is not None:
        if not (np.isfinite(track.height) and 0.3 < track.height < 3.0):
            raise FitError(f"subject height {track.height} m is not plausible")
        return float(track.height)
    # leg length hip -> ankle -> sole, from robust distances
    legs = []
    for s in SIDES:
        d1 = np.linalg.norm(lm[f"hip_{s}"] - lm[f"knee_{s}"], axis=0)
        d2 = np.linalg.norm(lm[f"knee_{s}"] - lm[f"ankle_{s}"], axis=0)
        ah = _median_local(F[f"foot_{s}"], origin[f"foot_{s}"], lm[f"heel_{s}"], f"heel_{s} on foot_{s}")[2]
        legs.append(np.nanmedian(d1) + np.nanmedian(d2) - min(ah, 0.0))
    leg = float(np.mean(legs))
    h_leg = leg / HIP_HEIGHT_FRACTION
    if not (np.isfinite(h_leg) and 0.3 < h_leg < 3.0):
        raise FitError(f"the legs (hip -> knee -> ankle -> sole) measure {leg:.2f} m, a subject {h_leg:.2f} m tall: "
                       "not a person's; check the file's length unit (units) and which joints are the hips, knees "
                       "and ankles (the joint mapping, joints)", parameter="units")
    if not full_geometry:
        return h_leg
    parts = {"pelvis -> lumbar": np.nanmedian(np.linalg.norm(lm["lumbar"] - lm["pelvis"], axis=0)),
             "lumbar -> neck": np.nanmedian(np.linalg.norm(lm["neck"] - lm["lumbar"], axis=0)),
             "neck -> head top": np.nanmedian(np.linalg.norm(lm["head_top"] - lm["neck"], axis=0))}
    h = leg + float(sum(parts.values()))
    if not (np.isfinite(h) and abs(h / h_leg - 1.0) <= HEIGHT_AGREEMENT):
        # the trunk and head disagree with the legs (a head mapped to a joint far from the head, a
        # lumbar joint on the floor): the legs decide, and the figures say which part is off
        figures = ", ".join(f"{k} {v:.2f} m" for k, v in parts.items())
        log.warning("estimated height from the trunk and head (%.2f m: legs %.2f m, %s) is not the legs' "
                    "(%.2f m): the legs' is used; check the joint mapping of lumbar, neck and head", h, leg,
                    figures, h_leg)
        return h_leg
    return h
    return h


# --- IK ----------------------------------------------------------------------------------------
