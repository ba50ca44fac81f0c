"""Extrapolation timings and reach (issue: continuation), both step controllers."""

from __future__ import annotations

import time

from bench.trials import trials
from solver.continuation import StepControl, Target, extrapolate
from solver.io import load_trial
from solver.pipeline import make_tutor

TIMED = {  # the targets (HalfBoy, 15 frames/s)
    "uphill_11.25": Target(slope_deg=11.25),
    "downhill_11.25": Target(slope_deg=-11.25),
    "curve_90": Target(curve_deg=90.0),
}
REACH = {  # further than the thesis
    "uphill_20": Target(slope_deg=20.0),
    "downhill_20": Target(slope_deg=-20.0),
    "uphill_45": Target(slope_deg=45.0),
    "downhill_45": Target(slope_deg=-45.0),
    "curve_180": Target(curve_deg=180.0),
    "moon_gravity": Target(gravity=1.62),
    "friction_0.3": Target(friction=0.3),
    "curve_90_on_uphill_10": Target(slope_deg=10.0, curve_deg=90.0),
}


def _run(tutor, target, method: str) -> dict:
    t = time.perf_counter()
    res = extrapolate(tutor, target, StepControl(method=method))
    plausible = all(s.motion.report["plausible"] for s in res.steps)
    return {"status": res.status, "lambda_reached": res.lam_reached, "solves": res.solves,
            "accepted": len(res.steps), "time_s": time.perf_counter() - t, "all_plausible": plausible,
            "final_environment": res.steps[-1].motion.provenance.get("environment_values") if res.steps else None}


def run() -> dict:
    out: dict = {}
    tr = trials()
    for name in ("deepmimic_walk", "c3d_pig"):
        tutor = make_tutor(load_trial(tr[name]), character="halfboy", fps=15.0).motion
        rows: dict = {}
        for label, tgt in {**TIMED, **REACH}.items():
            rows[label] = {m: _run(tutor, tgt, m) for m in ("thesis", "adaptive")}
        out[f"{name}/halfboy_15fps"] = rows
    # full body, 30 frames/s: curve π/2
    full = make_tutor(load_trial(tr["c3d_pig"]), character="fullbody", fps=30.0).motion
    out["c3d_pig/fullbody_30fps"] = {"curve_90": {m: _run(full, Target(curve_deg=90.0), m)
                                                  for m in ("thesis", "adaptive")}}
    return out
