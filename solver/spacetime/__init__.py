"""Spacetime optimization of a motion (docs/method.md (M5)) with CasADi + IPOPT: a realistic transcription
(C² cubic spline, dynamics at frames and midpoints) of named terms with exact sparse derivatives.

* ``types``: Environment, Weights, Realism bounds; ProblemData, WarmStart, SolverOptions (what a solve
  takes), SolveResult; IPOPT defaults;
* ``frame``: the generic functions of a frame, a pair of frames, a spline segment;
* ``derivatives``: the mapped-derivative scatter engine;
* ``layout``: how motions, wrenches and weights map onto x and p; ``callback``: stopping a solve;
* ``problem``: the NLP of one structure, re-solved with new parameters;
* ``compiled``: the derivative functions in machine code, cached per character (opt-in).
"""

from solver.spacetime import compiled
from solver.spacetime.derivatives import MAP_THREADS
from solver.spacetime.frame import FrameFunctions, frame_functions
from solver.spacetime.layout import MARKER_SCALE
from solver.spacetime.problem import ROOT_PERIODIC, SpacetimeProblem
from solver.spacetime.types import (
                                    DEFAULT_IPOPT,
                                    STANDARD_GRAVITY,
                                    SUCCESS_STATUSES,
                                    Environment,
                                    ProblemData,
                                    Realism,
                                    SolveResult,
                                    SolverOptions,
                                    WarmStart,
                                    Weights,
)

__all__ = ["DEFAULT_IPOPT", "MAP_THREADS", "MARKER_SCALE", "ROOT_PERIODIC", "STANDARD_GRAVITY", "SUCCESS_STATUSES",
           "Environment", "FrameFunctions", "ProblemData", "Realism", "SolveResult",
           "SolverOptions", "SpacetimeProblem", "WarmStart", "Weights", "compiled", "frame_functions"]
