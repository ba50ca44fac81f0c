"""The tutor's solves: the simplification and the correction (the two spacetime problems of
docs/method.md (M5.6), (M5.7)), their cost weights, the problems built once and re-solved, and
the contact wrenches estimated on the simplified motion as the correction's first guess (EFC,
docs/method.md (M4))."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from solver.character import Character
from solver.contact import estimate_contact_wrenches
from solver.environment import STANDARD_GRAVITY_VECTOR
from solver.kinematics import markers
from solver.motion import foot_schedule_of
from solver.spacetime import (
    Environment,
    ProblemData,
    SolveResult,
    SolverOptions,
    SpacetimeProblem,
    WarmStart,
    Weights,
)

#: the tutor's weights: the simplification and the correction track the capture's own joint
#: angles and pelvis rotations (1° weighs like 3 mm of marker distance, as MocoTrack tracks the
#: coordinates of its IK), the motion of its whole-body centre of mass (1 cm like 3 cm of marker
#: distance) and the ground force that moves it (``Weights.force_track``: the capture's kinematic
#: forces match the plates within ~0.05 BW), where the extrapolation's weak prior (``Weights()``:
#: 0.1 rad like 1 mm) only steadies what its guide's markers leave unobserved
TUTOR_WEIGHTS = Weights(coordinates=300.0, root_rotation=300.0, com_track=10.0)
#: per synthesis character: HalfBoy, whose trunk, head and arms are welded to its pelvis, cannot keep
#: both the subject's joints and the subject's centre of mass: it keeps the joints and the force's
#: shape (one braking → propulsion change per stance) at a tenth of the full body's force weight, not the
#: centre of mass's path, which made it crouch further (the overground walk's stance knees 23/20° where
#: the capture's are 10/14°; 18/17° with these weights)
#: HalfBoy's tutor leaves the feet's side of its pelvis to the joint angles it tracks (``pelvis_side``
#: off): held there, the overground walk's stance knees crouched 21/23° for feet 2.8 cm nearer the subject's
#: placement (the loaded foot 1.9 cm across the pelvis without it; the check allows 3 cm)
TUTOR_WEIGHTS_OF = {"fullbody": TUTOR_WEIGHTS,
                    "halfboy": Weights(coordinates=300.0, root_rotation=300.0, com_track=0.0, force_track=100.0,
                                       pelvis_side=0.0)}


def tutor_weights(character: str) -> Weights:
    """The tutor's cost weights for a synthesis character (``TUTOR_WEIGHTS_OF``)."""
    return TUTOR_WEIGHTS_OF.get(character, TUTOR_WEIGHTS)


def _select(src: Character, q: np.ndarray, dst: Character) -> np.ndarray:
    return np.stack([q[src.index(nm)] for nm in dst.coordinate_names])


def simplify(capture_character: Character, q_capture: np.ndarray, synthesis: Character, fps: float,
             *, weights: Weights = TUTOR_WEIGHTS, max_iter: int = 500,
             should_cancel: Callable[[], bool] | None = None, com: np.ndarray | None = None) -> SolveResult:
    """docs/method.md (M5.15), thesis Table 5.2: the synthesis character's motion closest to the capture's markers
    (superfluous coordinates locked at 0 = removed), cyclic, no forces. ``should_cancel()`` is
    polled at every IPOPT iteration (true: the solve ends with ``User_Requested_Stop``)."""
    T = q_capture.shape[1]
    problem = problem_for(synthesis, T, fps, None, dynamics=False)
    gm = markers(capture_character, q_capture).reshape(-1, T)
    init = _select(capture_character, q_capture, synthesis)
    return problem.solve(ProblemData(guide_markers=gm, weights=weights, guide_com=com), WarmStart(init),
                         SolverOptions(max_iter, should_stop=should_cancel))


def correct(synthesis: Character, q_sim: np.ndarray, contacts: np.ndarray, fps: float, *,
            init_wrenches: np.ndarray | None, env: Environment = Environment(),
            weights: Weights = TUTOR_WEIGHTS, max_iter: int = 1000, heading_change: float | None = None,
            prior_q: np.ndarray | None = None, should_cancel: Callable[[], bool] | None = None,
            com: np.ndarray | None = None) -> SolveResult:
    """Table 5.3: physically plausible motion closest to the simplified one (the tutor);
    ``prior_q``: the joint angles the coordinates prior keeps it near (default: the simplified's);
    ``com``: the centre of mass ``Weights.com_track`` keeps it near (default: the simplified's);
    ``should_cancel()``: polled at every IPOPT iteration, as in :func:`simplify`."""
    problem = problem_for(synthesis, q_sim.shape[1], fps, contacts)
    data = ProblemData(q_sim, env=env, weights=weights, heading_change=heading_change, prior_q=prior_q,
                       guide_com=com)
    return problem.solve(data, WarmStart(q_sim, init_wrenches), SolverOptions(max_iter, should_stop=should_cancel))


def heading_change_to_impose(q_capture: np.ndarray, q_simplified: np.ndarray) -> float:
    """The heading change over its cycle (rad) the tutor's optimizer is asked for: the
    simplified motion's (the cyclic fit to the capture's markers), or exactly 0 when the captured cycle turns less than
    ``STRAIGHT_WALK_DEG`` (a straight walk's drift is not a curve)."""
    if abs(math.degrees(float(q_capture[3, -2] - q_capture[3, 0]))) < STRAIGHT_WALK_DEG:
        return 0.0
    return float(q_simplified[3, -2] - q_simplified[3, 0])


#: a captured cycle turning less than this (degrees) becomes a straight tutor
STRAIGHT_WALK_DEG = 10.0

_PROBLEMS: dict[tuple, SpacetimeProblem] = {}
_MAX_CACHED = 8


def problem_for(character: Character, T: int, fps: float, contacts: np.ndarray | None, *,
                dynamics: bool = True, cyclic: bool = True, rising: bool = False) -> SpacetimeProblem:
    """Build (or reuse) the NLP of a structure: built once, re-solved with new parameters."""
    key = (id(character), T, float(fps), None if contacts is None else np.asarray(contacts, bool).tobytes(),
           dynamics, cyclic, rising)
    prob = _PROBLEMS.get(key)
    if prob is None or prob.character is not character or prob.stale:
        prob = SpacetimeProblem(character, T, fps, contacts, dynamics=dynamics, cyclic=cyclic, rising=rising)
        if len(_PROBLEMS) >= _MAX_CACHED:
            _PROBLEMS.pop(next(iter(_PROBLEMS)))
        _PROBLEMS[key] = prob
    return prob


def estimate_wrenches(character: Character, q: np.ndarray, fps: float, contacts: np.ndarray,
                      gravity=STANDARD_GRAVITY_VECTOR) -> tuple[np.ndarray, dict]:
    """EFC (docs/method.md (M4)) on the simplified motion: initial contact wrenches for the correction."""

    B = foot_schedule_of(character, contacts)
    est = estimate_contact_wrenches(character, q, fps, B, gravity=gravity)
    w = np.nan_to_num(np.asarray(est.wrenches), nan=0.0)
    # frames 0 and T-1 repeat T-2 and 1 in a cycle with two overlap frames
    w[:, :, 0] = w[:, :, -2]
    w[:, :, -1] = w[:, :, 1]
    return w, est.summary()
