"""The method's steps as plain functions: capture → simplify → estimate → correct (the tutor).

    capture_motion(capture) -> Motion                 a raw capture as a motion (step "capture")
    motion_capture(motion) -> Capture                 and back
    synthesis_character(capture_character, "halfboy" | "fullbody") -> (synthesis, capture-side)
    simplify(...), correct(...)                       the two spacetime problems of docs/method.md (M5.6), (M5.7)
    make_tutor(capture | capture motion, character=..., fps=...) -> TutorResult

A solver failure is a status (``TutorResult.status == "failed"``) with the last iterate kept
apart in ``last_iterate`` — never returned as the tutor.

The solves and their weights are in ``solver.pipeline_solves``, the cycle's ground calibration in
``solver.pipeline_calibration``; every name is importable from here.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from solver import native
from solver.capture import Capture, GroundFrame
from solver.character import FULL_SUPERFLUOUS, LOWER_SUPERFLUOUS, Character, merge_segments
from solver.environment import STANDARD_GRAVITY
from solver.gait import close_loop, ensure_double_support, extract_cycle, periodic_lowpass, tighten_contacts
from solver.gait.arms import arm_swing, arms_still
from solver.gait.cycles import LEAD_S
from solver.jsonable import jsonable
from solver.kinematics import centre_of_mass, markers
from solver.motion import Cycle, GaitReference, Motion, MotionContext
from solver.naturalness import against_plates, capture_figures, joint_rms_deg
from solver.pipeline_calibration import SOLE_LEVEL_TOL, contact_plane_calibration, sole_calibration
from solver.pipeline_solves import (
    STRAIGHT_WALK_DEG,
    TUTOR_WEIGHTS,
    TUTOR_WEIGHTS_OF,
    _select,
    correct,
    estimate_wrenches,
    heading_change_to_impose,
    problem_for,
    simplify,
    tutor_weights,
)
from solver.plausibility import report
from solver.rig import Rig, SkeletonRig, calibrate, unroll
from solver.spacetime import Environment, SolveResult, Weights
from solver.status import Status

__all__ = [
    "DEFAULT_CHARACTER", "DEFAULT_FPS", "KEEP_WHEN_USED", "SOLE_LEVEL_TOL", "STRAIGHT_WALK_DEG", "SYNTHESIS",
    "TUTOR_WEIGHTS", "TUTOR_WEIGHTS_OF", "UPPER_ROOT_SEGMENTS", "USED_DEG", "PipelineError", "PreparedCycle",
    "TutorResult", "capture_com", "capture_motion", "closed_cycle", "contact_plane_calibration", "correct",
    "default_fps", "estimate_wrenches", "fit_figures", "heading_change_to_impose", "make_tutor",
    "motion_capture", "prepare_cycle", "problem_for", "simplified_motion",
    "simplify", "sole_calibration", "synthesis_character", "tutor_rig", "tutor_weights", "used_coordinates",
]

log = logging.getLogger(__name__)

SYNTHESIS = ("halfboy", "fullbody")
#: the character and frame rate a tutor is made with by default, on evidence (docs/naturalness.md,
#: "The default character"): on the OpenSim walks the full body at 30 frames/s keeps the capture's joints
#: within 0.7-1.6° RMS where HalfBoy, whose trunk, head and arms are welded to its pelvis, moves them
#: 5-11°; HalfBoy stays the thesis's character, at 15 frames/s by default
DEFAULT_CHARACTER = "fullbody"
DEFAULT_FPS = {"fullbody": 30.0, "halfboy": 15.0}


def default_fps(character: str) -> float:
    """The frame rate a tutor of ``character`` is made at unless asked (``DEFAULT_FPS``)."""
    return DEFAULT_FPS.get(character, 15.0)
UPPER_ROOT_SEGMENTS = ("abdomen",)  # merging it lumps trunk, head and arms into the pelvis


class PipelineError(ValueError):
    """The input cannot go through the pipeline (the message says why)."""


@dataclass(frozen=True, eq=False)
class TutorResult:
    """A tutor, or why there is none: ``status`` succeeded (``motion`` is the tutor), failed or
    canceled (``motion`` is None; a failed solve's last iterate is kept apart)."""

    status: Status
    motion: Motion | None
    message: str = ""
    stats: Mapping[str, Any] = field(default_factory=dict)
    simplified: Motion | None = None
    last_iterate: Mapping[str, Any] | None = None  # failed solves only: kept apart, not a solution

    def __post_init__(self) -> None:
        object.__setattr__(self, "status", Status(self.status))

    def save(self, path: str | Path) -> Path:
        """Write the tutor as a motion file (its report inside); a result without a motion is refused."""
        if self.motion is None:
            raise PipelineError(f"no tutor to save: {self.status} ({self.message})")
        self.motion.save(path)
        return Path(path)


def _shifted_frame(frame: GroundFrame, h: float) -> GroundFrame:
    """The input frame of a motion lowered by h: p_input = (R (p + h e_z − v t) + offset) / unit."""
    return GroundFrame(R=frame.R, offset=frame.offset + frame.R @ np.array([0.0, 0.0, h]), unit_m=frame.unit_m,
                       velocity=frame.velocity, axes=frame.axes)


def capture_motion(capture: Capture) -> Motion:
    """A raw capture as a motion file (step "capture"): kinematics only, no wrenches."""
    fps = capture.fps
    dt = np.diff(capture.times)
    if np.max(np.abs(dt - 1.0 / fps)) > 0.05 / fps:
        raise PipelineError("capture times are not uniformly sampled; resample first")
    source, cycle = _source_and_cycle(capture.source)
    return Motion(
        character=capture.character,
        fps=fps,
        q=capture.q,
        contacts=capture.contacts,
        provenance=jsonable({"step": "capture", "source": source, "t0": float(capture.times[0]), "lambda": None}),
        context=MotionContext(frame=capture.frame, cycle=cycle,
                              rig=capture.rig),
    )


def motion_capture(motion: Motion) -> Capture:
    """Inverse of :func:`capture_motion`."""
    prov, ctx = motion.provenance, motion.context
    t0 = float(prov.get("t0") or 0.0)
    source = prov.get("source") or {}
    if ctx.cycle is not None:
        source = {**source, "cycle": ctx.cycle.to_dict()}
    return Capture(
        character=motion.character,
        q=motion.q,
        times=t0 + motion.times,
        frame=motion.frame,
        source=source,
        contacts=motion.contacts,
        rig=ctx.rig,
    )


def _source_and_cycle(source: Mapping[str, Any]) -> tuple[dict[str, Any], Cycle | None]:
    """A capture's source record without its cycle, and the cycle (the motion's context)."""
    src = dict(source)
    cyc = src.pop("cycle", None)
    return src, Cycle.from_dict(jsonable(cyc)) if isinstance(cyc, Mapping) else None


def tutor_rig(capture: Capture, cyc: Capture, syn: Character, q_sim: np.ndarray, fps: float,
              stats: dict[str, Any]) -> Rig | None:
    """The capture's rig as the tutor's context carries it: a skeleton calibrated against the
    simplified cycle (``solver.rig.calibrate``; a rig that cannot be calibrated costs only the
    rig export, noted in ``stats``); an OpenSim model as imported (the OpenSim export calibrates
    it against each motion it writes)."""
    rig = capture.rig
    if not isinstance(rig, SkeletonRig):
        return rig
    info = cyc.source.get("cycle") or {}
    try:
        t_start, period = float(info["t_start"]), float(info["period_s"])
        if capture.source.get("loop") == "wrap":
            disp = capture.frame.vector_from_input(rig.root[-1] - rig.root[0]) * capture.frame.unit_m
            disp[2] = 0.0
            rig = unroll(rig, 3, capture.frame.vector_to_input(disp) / capture.frame.unit_m)
        frame = _shifted_frame(capture.frame, stats.get("contact_plane_shift_mm", 0.0) / 1e3)
        simplified = Motion(syn, fps, q_sim, interpolation="cubic-spline", cyclic=True,
                            context=MotionContext(frame=frame, cycle=Cycle(t_start, period)))
        return calibrate(rig, simplified)
    except (KeyError, TypeError, ValueError) as e:
        stats["rig"] = f"the source rig could not be calibrated: {e}"
        log.warning("source rig not calibrated: %s", e)
        return None


#: superfluous coordinates the full body keeps when the capture uses them (``used_coordinates``):
#: the tibia's coupled rotation of an OpenSim knee, the subtalar joint and the ankle's rotation, the
#: elbow's carrying angle and the forearm's pronation. Knee ab/adduction and the toes stay locked
#: (a capture that bends its knees sideways has a bad fit, not a gait to keep)
KEEP_WHEN_USED = ("knee_rotation", "ankle_inversion", "ankle_rotation", "elbow_adduction", "elbow_rotation",
                  "wrist_rotation")
#: a coordinate is used when its range over the cycle, or its mean, exceeds this (degrees)
USED_DEG = 4.0


def used_coordinates(capture_character: Character, q: np.ndarray) -> tuple[str, ...]:
    """The ``KEEP_WHEN_USED`` coordinates the capture moves or holds away from zero over its cycle
    (``q``: the cycle, two overlap frames last): locked at 0 they would be made up for by their
    neighbours (an OpenSim walk's subtalar locked: the hip's rotation 9° off the capture)."""
    N = q.shape[1] - 2 if q.shape[1] > 4 else q.shape[1]
    out = []
    for i, name in enumerate(capture_character.coordinate_names):
        if name.rsplit("_", 1)[0] not in KEEP_WHEN_USED:
            continue
        x = np.degrees(q[i, :N])
        if np.ptp(x) > USED_DEG or abs(float(np.mean(x))) > USED_DEG:
            out.append(name)
    return tuple(out)


def synthesis_character(capture_character: Character, kind: str,
                        pose: Mapping[str, float] | None = None,
                        keep: tuple[str, ...] = ()) -> tuple[Character, Character]:
    """(synthesis character, capture character it is simplified from), same segments/markers.

    For HalfBoy the upper body is merged into the pelvis in ``pose`` (e.g. the subject's
    mean posture over the cycle: a walker leaning forward keeps the trunk's mass forward).
    The full body keeps the superfluous coordinates named in ``keep`` (``used_coordinates``:
    the ones the capture uses).
    """
    names = {s.name for s in capture_character.segments}
    if kind == "halfboy":
        cap = capture_character
        if "abdomen" in names:
            cap = merge_segments(capture_character, UPPER_ROOT_SEGMENTS, name=f"{capture_character.name}-lower",
                                 pose=pose)
        locked = [c for c in LOWER_SUPERFLUOUS if c in cap.coordinate_names]
        syn = cap.reduce(locked, name="halfboy")
        return syn, cap
    if kind == "fullbody":
        if "abdomen" not in names:
            raise PipelineError("a full-body tutor needs a whole-body capture (this one has no upper body)")
        locked = [c for c in FULL_SUPERFLUOUS if c in capture_character.coordinate_names and c not in keep]
        return capture_character.reduce(locked, name="fullbody"), capture_character
    raise PipelineError(f"unknown synthesis character {kind!r}; use one of {SYNTHESIS}")


@dataclass(frozen=True, eq=False)
class PreparedCycle:
    """One gait cycle of a capture ready for the synthesis character: the cycle (``cycle``, on
    the levelled capture skeleton), its contact schedule, the synthesis character, the capture
    skeleton reduced to it and its coordinates ``q`` (contact plane calibrated)."""

    cycle: Capture
    contacts: np.ndarray
    synthesis: Character
    capture_character: Character
    q: np.ndarray
    fps: float
    stats: Mapping[str, Any]


def prepare_cycle(capture: Capture, *, character: str = DEFAULT_CHARACTER, fps: float | None = None, cycle: int = 0,
                  start: str = "auto") -> PreparedCycle:
    """cycle → soles levelled → synthesis character → contact plane → double support: what the
    simplification starts from (``fps``: default ``default_fps(character)``)."""
    if fps is None:
        fps = default_fps(character)
    if not (math.isfinite(fps) and fps > 0):
        raise PipelineError(f"fps must be positive, got {fps}")
    stats: dict[str, Any] = {}
    t = time.perf_counter()
    cyc, contacts = extract_cycle(capture, fps, start=start, cycle=cycle)
    fps = float((cyc.source.get("cycle") or {}).get("fps") or fps)  # the subject's own period over the cycle's frames
    contacts = np.array(contacts, dtype=bool)
    contacts[:, -2:] = contacts[:, :2]  # the overlap frames repeat frames 1-2
    mean_pose = dict(zip(capture.character.coordinate_names, np.mean(cyc.q[:, :-2], axis=1)))
    levelled, soles = sole_calibration(capture.character, cyc.q, contacts)
    if soles:
        stats["sole_calibration"] = soles
    keep = used_coordinates(capture.character, cyc.q) if character == "fullbody" else ()
    if character == "fullbody" and arms_still(capture.character.coordinate_names, cyc.q):
        stats["arm_swing"] = arm_swing(capture.character.coordinate_names, cyc.q)[1]
    if keep:
        stats["kept_coordinates"] = list(keep)
    syn, cap_char = synthesis_character(levelled, character, pose=mean_pose, keep=keep)
    stats["cycle_s"] = time.perf_counter() - t
    q_cap = _select(levelled, cyc.q, cap_char)
    q_cap, shift = contact_plane_calibration(cap_char, q_cap, contacts)
    stats["contact_plane_shift_mm"] = 1e3 * shift
    contacts, lifted = tighten_contacts(cap_char, q_cap, contacts)
    if lifted:
        stats["contacts_lifted"] = lifted
    contacts, shared = ensure_double_support(cap_char, q_cap, contacts)
    if shared:
        stats["double_support_added"] = shared
    return PreparedCycle(cyc, contacts, syn, cap_char, q_cap, fps, stats)


def fit_figures(capture: Capture) -> dict[str, Any] | None:
    """The capture's skeleton fit as the tutor's gait reference records it (its marker RMS, mm, is
    the naturalness check ``fit_quality``): the fit's verdict when the importer gave one, else its
    landmark RMS; None when the capture was not fitted (a motion file)."""
    fit = capture.source.get("fit")
    if not isinstance(fit, Mapping):
        return None
    verdict = fit.get("verdict")
    if isinstance(verdict, Mapping) and verdict.get("marker_rms_mm") is not None:
        return dict(verdict)
    rms = (fit.get("landmark_error_mm") or {}).get("rms") if isinstance(fit.get("landmark_error_mm"), Mapping) else None
    return None if rms is None else {"marker_rms_mm": float(rms)}


def _source_provenance(capture: Capture, cyc: Capture) -> tuple[dict[str, Any], Cycle | None]:
    """Where a tutor comes from (the trial's format, files, subject) and the captured cycle it stands for."""
    cycle = capture.source.get("cycle") or cyc.source.get("cycle")
    return ({"format": capture.source.get("format"), "files": capture.source.get("files"),
             "subject": capture.source.get("subject")},
            Cycle.from_dict(jsonable(cycle)) if isinstance(cycle, Mapping) else None)


def _simplified(prep: PreparedCycle, q: np.ndarray, source: tuple[dict[str, Any], Cycle | None]) -> Motion:
    return Motion(prep.synthesis, prep.fps, q, contacts=prep.contacts,
                  provenance=jsonable({"step": "simplify", "source": source[0], "lambda": None}),
                  context=MotionContext(cycle=source[1]))


def closed_cycle(prep: PreparedCycle, character: Character | None = None) -> np.ndarray:
    """The captured cycle the tutor tracks, on ``character`` (default: the capture skeleton the
    synthesis character is reduced from; ``prep.cycle.character``: every segment): periodic, its
    seam blended into the captured motion around it (``solver.gait.close_loop``), low-passed as a
    periodic signal at 6-10 Hz (``solver.gait.periodic_lowpass``: the capture's noise and glitches),
    lowered with the contact plane; the yaw's drift removed on a straight walk (``STRAIGHT_WALK_DEG``)."""
    ch = prep.capture_character if character is None else character
    full = prep.cycle.character
    shift = float(prep.stats.get("contact_plane_shift_mm", 0.0)) / 1e3

    def on(q: np.ndarray | None) -> np.ndarray | None:
        if q is None:
            return None
        out = np.array(q if ch is full else _select(full, q, ch), dtype=float)
        out[2] -= shift
        return out

    q = on(prep.cycle.q)
    assert q is not None
    turning = abs(math.degrees(float(q[3, -2] - q[3, 0]))) >= STRAIGHT_WALK_DEG
    lead_in = on(prep.cycle.lead_in)
    if (prep.cycle.source.get("cycle") or {}).get("loop"):  # a looping clip: what leads into its first frame
        N = q.shape[1] - 2                                 # is its own last frames
        lead_in = q[:, max(0, N - int(round(LEAD_S * prep.fps))):N]
    closed = close_loop(q, keep_yaw=turning, lead_in=lead_in, lead_out=on(prep.cycle.lead_out))
    # still arms (a model or marker set without them) swing: as decided on the captured cycle
    closed, _ = arm_swing(ch.coordinate_names, closed, still=bool(prep.stats.get("arm_swing")))
    return periodic_lowpass(closed, prep.fps)


def capture_com(prep: PreparedCycle) -> np.ndarray:
    """(3, T) the captured subject's whole-body centre of mass over the closed cycle, on the capture
    skeleton with every segment (HalfBoy's trunk, head and arms where the subject had them),
    lowered with the contact plane, less its mean offset from the synthesis character's centre of
    mass at the capture's own angles: what the tutor's ``Weights.com_track`` keeps, and whose
    acceleration ``Weights.force_track`` keeps. The motion of the subject's centre of mass, not its
    place in a body built otherwise: HalfBoy, its trunk, head and arms welded to the pelvis in the
    mean posture, holds its centre of mass a little off the subject's, and crouched to put it there."""
    full = centre_of_mass(prep.cycle.character, closed_cycle(prep, prep.cycle.character))
    syn = centre_of_mass(prep.synthesis, _select(prep.capture_character, closed_cycle(prep), prep.synthesis))
    N = full.shape[1] - 2
    return full - np.mean(full[:, :N] - syn[:, :N], axis=1, keepdims=True)


def simplified_motion(source: Capture | Motion, *, character: str = DEFAULT_CHARACTER, fps: float | None = None,
                      cycle: int = 0, start: str = "auto", weights: Weights | None = None) -> Motion:
    """The simplified cycle alone (step "simplify": the capture's cycle fitted by the synthesis
    character, kinematics only, no forces), as ``make_tutor`` makes it before the correction."""
    capture = motion_capture(source) if isinstance(source, Motion) else source
    prep = prepare_cycle(capture, character=character, fps=fps, cycle=cycle, start=start)
    weights = tutor_weights(character) if weights is None else weights
    simp = simplify(prep.capture_character, closed_cycle(prep), prep.synthesis, prep.fps, weights=weights,
                    com=capture_com(prep))
    if not simp.success:
        raise PipelineError(f"simplification did not converge ({simp.status})")
    return _simplified(prep, simp.q, _source_provenance(capture, prep.cycle))


def make_tutor(
    source: Capture | Motion,
    *,
    character: str = DEFAULT_CHARACTER,
    fps: float | None = None,
    cycle: int = 0,
    start: str = "auto",
    max_iter: int = 1000,
    weights: Weights | None = None,
    should_cancel: Callable[[], bool] | None = None,
) -> TutorResult:
    """import → cycle → simplify → estimate → correct. ``source`` is a Capture, or a motion of
    step "capture" (e.g. stored by the service); ``character`` and ``fps``: by default the full
    body at 30 frames/s (``DEFAULT_CHARACTER``, ``default_fps``; the fps is then adjusted so that
    the cycle's frames span the subject's own period); ``weights``: the cost weights of the
    simplification and the correction (default: ``tutor_weights(character)``).
    ``should_cancel()`` is polled between the phases and at every IPOPT iteration: once true, the
    running solve stops at its next iteration and the result is "canceled" (no retry)."""
    native.ensure()
    t_start = time.perf_counter()

    def canceled(stats: Mapping[str, Any], phase: str, solved: SolveResult | None = None) -> TutorResult | None:
        """A canceled result when ``should_cancel()`` is true: "canceled before|during|after <phase>"."""
        if should_cancel is None or not should_cancel():
            return None
        when = "before" if solved is None else "during" if solved.status == "User_Requested_Stop" else "after"
        return TutorResult(Status.CANCELED, None, f"canceled {when} the {phase}", jsonable(stats))

    capture = motion_capture(source) if isinstance(source, Motion) else source
    weights = tutor_weights(character) if weights is None else weights
    stats: dict[str, Any] = {}
    if stop := canceled(stats, "simplification"):
        return stop
    prep = prepare_cycle(capture, character=character, fps=fps, cycle=cycle, start=start)
    stats.update(prep.stats)
    fps = prep.fps  # the requested rate, adjusted so that the cycle's frames span the subject's period
    cyc, contacts, syn, cap_char, q_cap = prep.cycle, prep.contacts, prep.synthesis, prep.capture_character, prep.q

    t = time.perf_counter()
    q_loop = closed_cycle(prep)  # what the tutor tracks: the captured cycle, its seam closed
    com = capture_com(prep)
    simp = simplify(cap_char, q_loop, syn, fps, weights=weights, should_cancel=should_cancel, com=com)
    stats["simplify"] = {"status": simp.status, "iterations": simp.iterations, "time_s": time.perf_counter() - t,
                         "marker_rms_mm": 1e3 * simp.marker_rms}
    if stop := canceled(stats, "simplification", simp):
        return stop
    if not simp.success:
        return TutorResult(Status.FAILED, None, f"simplification did not converge ({simp.status})", jsonable(stats),
                           last_iterate={"q": simp.q})
    q_sim = simp.q

    t = time.perf_counter()
    try:
        w0, est_summary = estimate_wrenches(syn, q_sim, fps, contacts)
    except ValueError as e:  # an estimation failure only costs the initial guess
        log.warning("contact estimation failed (%s); correcting from zero wrenches", e)
        w0, est_summary = None, {"error": str(e)}
    stats["estimate"] = {"time_s": time.perf_counter() - t, **est_summary}
    if stop := canceled(stats, "correction"):
        return stop

    t = time.perf_counter()
    env = Environment()
    attempts = []
    dpsi = heading_change_to_impose(q_cap, q_sim)
    stats["heading_change_deg"] = {"capture": math.degrees(float(q_cap[3, -2] - q_cap[3, 0])),
                                   "simplified": math.degrees(float(q_sim[3, -2] - q_sim[3, 0])),
                                   "tutor": math.degrees(dpsi)}
    q_joints = _select(cap_char, q_loop, syn)  # the capture's own angles: what the tutor keeps of its details
    res = correct(syn, q_sim, contacts, fps, init_wrenches=w0, env=env, max_iter=max_iter, heading_change=dpsi,
                  weights=weights, prior_q=q_joints, should_cancel=should_cancel, com=com)
    attempts.append({"init": "estimated wrenches", "status": res.status, "iterations": res.iterations,
                     "time_s": res.wall_time})
    if not res.success:
        stats["correct"] = {"time_s": time.perf_counter() - t, "attempts": attempts}
        if stop := canceled(stats, "correction", res):  # no second attempt
            return stop
        res2 = correct(syn, q_sim, contacts, fps, init_wrenches=None, env=env, max_iter=max_iter,
                       heading_change=dpsi, weights=weights, prior_q=q_joints, should_cancel=should_cancel,
                       com=com)
        attempts.append({"init": "zero wrenches", "status": res2.status, "iterations": res2.iterations,
                         "time_s": res2.wall_time})
        res = res2 if res2.success else res
        if not res.success and (stop := canceled(stats, "correction", res2)):
            return stop
    stats["correct"] = {"time_s": time.perf_counter() - t, "attempts": attempts,
                        "problem": {"variables": res.stats.get("n_variables"),
                                    "constraints": res.stats.get("n_constraints"),
                                    "build_s": res.stats.get("build_time")}}
    stats["total_s"] = time.perf_counter() - t_start
    src_prov = _source_provenance(capture, cyc)
    simplified = _simplified(prep, q_sim, src_prov)
    if not res.success:
        return TutorResult(Status.FAILED, None, f"correction did not converge ({res.status})", jsonable(stats),
                           simplified=simplified, last_iterate={"q": res.q, "wrenches": res.wrenches})
    # marker distance between the tutor and the capture (lower segments for HalfBoy)
    mk_cap = markers(cap_char, q_cap)
    mk_tut = markers(syn, res.q)
    dist = np.linalg.norm(mk_tut - mk_cap, axis=1)
    stats["marker_distance_to_capture_mm"] = {"mean": 1e3 * float(dist.mean()), "max": 1e3 * float(dist.max())}
    stats["marker_distance_to_simplified_mm"] = 1e3 * res.marker_rms
    # the capture's own gait features (naturalness checks are judged against them too), how far the
    # tutor's joints moved from the capture's, and its ground reactions against the plates
    # (still arms given a swing are not the capture's: left out)
    swung = tuple(c for c in cap_char.coordinate_names if c.startswith(("shoulder_", "elbow_"))) \
        if stats.get("arm_swing") else ()
    stats["joint_rms_to_capture_deg"] = joint_rms_deg(syn, res.q, cap_char, q_cap, swung)
    stats["joint_rms_simplified_to_capture_deg"] = joint_rms_deg(syn, q_sim, cap_char, q_cap, swung)
    stats["joint_rms_to_closed_cycle_deg"] = joint_rms_deg(syn, res.q, cap_char, q_loop, swung)
    assert res.wrenches is not None  # a dynamic solve
    plates = against_plates(res.wrenches[:, 3:], cyc.measured, res.q, syn.total_mass * STANDARD_GRAVITY)
    if plates:
        stats["grf_against_plates"] = plates
    tutor = Motion(
        syn, fps, res.q, contacts=contacts, wrenches=res.wrenches, interpolation="cubic-spline", cyclic=True,
        context=MotionContext(
            environment=env,
            frame=_shifted_frame(capture.frame, stats.get("contact_plane_shift_mm", 0.0) / 1e3),
            rig=tutor_rig(capture, cyc, syn, q_sim, fps, stats),
            cycle=src_prov[1],
            heading_change_deg=math.degrees(dpsi),
            gait_reference=GaitReference(
                capture=jsonable(capture_figures(cap_char, q_cap, fps, contacts, cyc.measured)),
                fit=jsonable(fit_figures(capture))),
        ),
        provenance=jsonable({
            "step": "tutor",
            "source": src_prov[0],
            "lambda": 0.0,
            "solver": res.solver_record(),
            "pipeline": stats,
        }),
    )
    tutor = tutor.evolve(report=report(tutor))
    return TutorResult(Status.SUCCEEDED, tutor, "", jsonable(stats), simplified=simplified)
