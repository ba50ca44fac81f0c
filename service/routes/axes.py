"""GET /axes: the homotopy axes of the solver (solver.axes), the one source of the target's
names, units, bounds and defaults — the web page builds its forms and labels from it. Like every
endpoint but /health, /openapi.json and /docs, it needs an API key."""

from __future__ import annotations

from typing import Any

from fastapi import APIRouter

from service.deps import OwnerDep
from solver import axes as registry

router = APIRouter(tags=["service"])


@router.get("/axes", summary="the homotopy axes a target may change")
def list_axes(owner: OwnerDep) -> dict[str, Any]:
    """Every registered axis: name (the target field), unit, doc, bounds, default (null: the
    tutor's own value), whether it can be a library grid axis, its CLI flag and label."""
    return {"axes": [ax.describe() for ax in registry.axes()]}
