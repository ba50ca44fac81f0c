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
from typing import Any

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

__all__ = sorted(_FRONT_DOOR)


def __getattr__(name: str) -> Any:
    module = _FRONT_DOOR.get(name)
    if module is None:
        raise AttributeError(f"module 'solver' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), _ALIASES.get(name, name))
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(__all__))
