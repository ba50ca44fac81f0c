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
    "stairs_up_0.15": Target(step_height_m=0.15),
    "stairs_down_0.15": Target(step_height_m=-0.15),
}
#: the full body (30 frames/s): curve π/2 and stairs (how high a step the full body
#: reaches; ε = 0.02 bounds an impasse's search)
FULL_BODY = {
    "curve_90": (Target(curve_deg=90.0), {}),
    "stairs_up_0.15": (Target(step_height_m=0.15), {"eps": 0.02}),
    "stairs_down_0.15": (Target(step_height_m=-0.15), {"eps": 0.02}),
}
IMPOSSIBLE = {  # must end in an impasse; ε = 0.02 keeps the bench short
    "uphill_80": Target(slope_deg=80.0),
    "downhill_80": Target(slope_deg=-80.0),
    "curve_720": Target(curve_deg=720.0),
}


DEFAULT = StepControl().method  # the controller extrapolate() uses unless told otherwise


def _run(tutor, target, method: str, **control) -> dict:
    t = time.perf_counter()
    res = extrapolate(tutor, target, StepControl(method=method, **control))
    plausible = all(s.motion.report["plausible"] for s in res.steps)
    last = res.steps[-1].motion if res.steps else None
    realism = None
    if last is not None and last.report.get("realism"):
        realism = {k: v["value"] for k, v in last.report["realism"].get("checks", {}).items()}
    return {"status": res.status, "lambda_reached": res.lam_reached, "solves": res.solves,
            "accepted": len(res.steps), "time_s": time.perf_counter() - t, "all_plausible": plausible,
            "final_environment": last.provenance.get("environment_values") if last is not None else None,
            "final_realism": realism}


def run() -> dict:
    out: dict = {}
    tr = trials()
    for name in ("deepmimic_walk", "c3d_pig"):
        tutor = make_tutor(load_trial(tr[name]), character="halfboy", fps=15.0).motion
        rows: dict = {label: {m: _run(tutor, tgt, m) for m in ("thesis", "adaptive")} for label, tgt in TIMED.items()}
        if name == "deepmimic_walk":  # reach: the default controller
            rows.update({label: {DEFAULT: _run(tutor, tgt, DEFAULT)} for label, tgt in REACH.items()})
            rows.update({label: {DEFAULT: _run(tutor, tgt, DEFAULT, eps=0.02)} for label, tgt in IMPOSSIBLE.items()})
        out[f"{name}/halfboy_15fps"] = rows
    # full body, 30 frames/s: curve π/2 (both controllers) and stairs (the default)
    full = make_tutor(load_trial(tr["c3d_pig"]), character="fullbody", fps=30.0).motion
    out["c3d_pig/fullbody_30fps"] = {
        label: {m: _run(full, tgt, m, **ctl) for m in ((DEFAULT, "adaptive") if label == "curve_90" else (DEFAULT,))}
        for label, (tgt, ctl) in FULL_BODY.items()}
    return out
