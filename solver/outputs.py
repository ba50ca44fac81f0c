"""How a walk in λ is written to a folder, one way for the Python front door, the command line
and the demo.

Every λ optimum is ``step_NNN_lambda_L.<kind>``: ``NNN`` the accepted step (000 is λ = 0, the
base problem), ``L`` its λ with four decimals, ``<kind>`` e.g. ``motion.json`` (motion file v2).
Beside them: ``progress.csv`` (the progress curve, one row per solve) and ``summary.json``.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Mapping

from solver import axes as registry

#: the environment columns of progress.csv
ENVIRONMENT_KEYS = registry.names()  # one column per homotopy axis (solver.axes)
PROGRESS_COLUMNS = ("phase", "wall_time_s", "lambda", *ENVIRONMENT_KEYS, "iterations", "accepted", "status",
                    "lambda_reached")


def step_stem(step: int, lam: float) -> str:
    """``step_003_lambda_1.0000``: the name of the λ optimum of accepted step ``step``."""
    return f"step_{int(step):03d}_lambda_{float(lam):.4f}"


def _num(v, fmt: str) -> str:
    if v is None:
        return "nan"
    v = float(v) + 0.0  # -0.0 -> 0.0
    return "nan" if not math.isfinite(v) else format(v, fmt)


def progress_csv(records: Iterable[Mapping]) -> str:
    """The progress curve as CSV, one row per solve (``PROGRESS_COLUMNS``). ``records`` are the
    API's job ``progress`` points or ``dataclasses.asdict(ProgressRecord)`` (phase
    "extrapolate" when absent); an environment value a record lacks is ``nan``."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(PROGRESS_COLUMNS)
    for r in records:
        env = r.get("environment") or {}
        w.writerow([r.get("phase", "extrapolate"), _num(r["wall_time"], ".4f"), _num(r["lam"], ".6f"),
                    *[_num(env.get(k), ".6g") for k in ENVIRONMENT_KEYS], int(r.get("iterations") or 0),
                    int(bool(r["accepted"])), r.get("status") or "", _num(r["lam_reached"], ".6f")])
    return buf.getvalue()
