"""motionx's solver: one captured walk → physically plausible new walks.

The front door (docs/api.md)::

    import solver
    capture = solver.load_trial("walk.bvh", mass=70)           # OpenSim, C3D, BVH, DeepMimic
    tutor = solver.make_tutor(capture)                         # one gait cycle made plausible
    walk = solver.extrapolate(tutor.motion, solver.Target(slope_deg=10))  # every λ optimum kept
    lib = solver.solve_library(tutor.motion, solver.grid_cells({"slope_deg": [-10, 10]}))
    report = solver.validate(walk.steps[-1].motion)            # our checks and the MuJoCo replay
    solver.export_motion(walk.steps[-1].motion, "gltf", "walk.glb")
    walk.save("out/slope10")                                   # results save themselves

Names are loaded on first use, so ``import solver.x`` stays light. Pure computation: this
package never imports web, queue, database or settings code.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # the real types for mypy and IDEs; at run time the names load on first use
    from solver.capture import Capture
    from solver.continuation import ExtrapolationResult, StepControl, Target, extrapolate
    from solver.export import export_motion
    from solver.io import load_trial
    from solver.library import LibraryResult, grid_cells, list_cells, solve_library
    from solver.motion import Motion
    from solver.native import enable as enable_native
    from solver.pipeline import TutorResult, make_tutor
    from solver.plausibility import Tolerances
    from solver.spacetime import Weights
    from solver.status import Status
    from solver.validation import validate

#: the front door: name -> the module that defines it
_FRONT_DOOR = {
    # load
    "load_trial": "solver.io", "Capture": "solver.capture", "Motion": "solver.motion",
    # tutor
    "make_tutor": "solver.pipeline", "TutorResult": "solver.pipeline", "Weights": "solver.spacetime",
    # extrapolate
    "extrapolate": "solver.continuation", "Target": "solver.continuation", "StepControl": "solver.continuation",
    "ExtrapolationResult": "solver.continuation",
    # library
    "solve_library": "solver.library", "grid_cells": "solver.library", "list_cells": "solver.library",
    "LibraryResult": "solver.library",
    # validate, export
    "validate": "solver.validation", "Tolerances": "solver.plausibility", "export_motion": "solver.export",
    # one status type; native code
    "Status": "solver.status", "enable_native": "solver.native",
}
_ALIASES = {"enable_native": "enable"}

#: the names above, written out so that type checkers see them re-exported (a test keeps the two equal)
__all__ = ["Capture", "ExtrapolationResult", "LibraryResult", "Motion", "Status", "StepControl", "Target",
           "Tolerances", "TutorResult", "Weights", "enable_native", "export_motion", "extrapolate", "grid_cells",
           "list_cells", "load_trial", "make_tutor", "solve_library", "validate"]


def __getattr__(name: str) -> Any:
    module = _FRONT_DOOR.get(name)
    if module is None:
        raise AttributeError(f"module 'solver' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), _ALIASES.get(name, name))
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
