"""The homotopy axes (one module each) and the generic target over them.

Adding an axis: a module here that registers an :class:`Axis` (name, unit, bounds, default,
doc, and its environment / guide / NLP effects), its import below, its test and its docs
entry (docs/continuation.md). The service's schemas, the CLI flags, the plots and the web
page read the registry.
"""

# registration order = display order (CLI flags, schemas, plots, page): keep it, not sorted
# isort: off
from solver.axes import slope as _slope  # noqa: F401
from solver.axes import curve as _curve  # noqa: F401
from solver.axes import friction as _friction  # noqa: F401
from solver.axes import gravity as _gravity  # noqa: F401
from solver.axes import speed as _speed  # noqa: F401
from solver.axes import terrain as _terrain  # noqa: F401
# isort: on
from solver.axes.base import (
                              NLP_EFFECTS,
                              Axis,
                              Target,
                              axes,
                              axis,
                              environment_at,
                              guide_at,
                              names,
                              nlp_at,
                              register,
                              values_at,
)

__all__ = ["NLP_EFFECTS", "Axis", "Target", "axes", "axis", "environment_at", "guide_at", "names", "nlp_at",
           "register", "values_at"]
