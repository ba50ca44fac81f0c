"""The homotopy axes (one module each) and the generic target over them.

Adding an axis: a module here that registers an :class:`Axis` (name, unit, bounds, default,
doc, and its environment / guide / NLP effects), its import below, its test and its docs
entry (docs/continuation.md). The service's schemas, the CLI flags, the plots and the web
page read the registry.
"""

from solver.axes.base import (NLP_EFFECTS, Axis, Target, axes, axis, environment_at, guide_at, names, nlp_at,
                              register, values_at)

# registration order = display order
from solver.axes import slope as _slope  # noqa: E402,F401
from solver.axes import curve as _curve  # noqa: E402,F401
from solver.axes import friction as _friction  # noqa: E402,F401
from solver.axes import gravity as _gravity  # noqa: E402,F401
from solver.axes import speed as _speed  # noqa: E402,F401
from solver.axes import terrain as _terrain  # noqa: E402,F401

__all__ = ["NLP_EFFECTS", "Axis", "Target", "axes", "axis", "environment_at", "guide_at", "names", "nlp_at",
           "register", "values_at"]
