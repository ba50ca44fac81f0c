"""Compiled derivative functions (solver.spacetime.compiled) against CasADi's virtual machine.

The same problems solved both ways on the same machine, one after the other: the tutor
corrections (HalfBoy 15 frames/s, full body 30 frames/s) and the issue's timed extrapolations
(HalfBoy: ±11.25°, curve 90°; full body: curve 90°). Also the one-off compile per character
(a fresh cache) and the load from a warm cache.
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

from bench.trials import trials
from solver.continuation import Target, extrapolate
from solver.io import load_trial
from solver.pipeline import correct, estimate_wrenches, make_tutor
from solver.spacetime import FrameFunctions, compiled, frame_functions

TARGETS = {"uphill_11.25": Target(slope_deg=11.25), "downhill_11.25": Target(slope_deg=-11.25),
           "curve_90": Target(curve_deg=90.0)}


def tutor_correction(res) -> dict:
    """The tutor's correction again (as make_tutor runs it: from the estimated wrenches)."""
    m = res.motion
    w0, _ = estimate_wrenches(m.character, res.simplified.q, m.fps, m.contacts)
    out = correct(m.character, res.simplified.q, m.contacts, m.fps, init_wrenches=w0,
                  heading_change=float(m.q[3, -2] - m.q[3, 0]))
    return {"time_s": out.wall_time, "iterations": out.iterations, "status": out.status}


def _extrapolate(tutor, target) -> dict:
    t = time.perf_counter()
    res = extrapolate(tutor, target)
    return {"status": res.status, "lambda_reached": res.lam_reached, "solves": res.solves,
            "iterations": sum(r.iterations for r in res.records), "time_s": time.perf_counter() - t,
            "all_plausible": all(s.motion.report["plausible"] for s in res.steps)}


def _case(capture, kind: str, fps: float, targets: dict, cache: Path) -> dict:
    compiled.enable(None)
    res = make_tutor(capture, character=kind, fps=fps)
    if res.motion is None:
        return {"status": res.status}
    tutor = res.motion
    row: dict = {"vm": {"correct": tutor_correction(res)}, "compiled": {}}
    row["vm"].update({k: _extrapolate(tutor, t) for k, t in targets.items()})
    compiled.enable(cache)
    ff = frame_functions(tutor.character)
    t = time.perf_counter()
    compiled.start(ff, wait=True)  # a fresh cache: generate, compile, check, load
    row["compile_s"] = time.perf_counter() - t
    t = time.perf_counter()
    again = FrameFunctions(tutor.character)
    t_build = time.perf_counter() - t
    t = time.perf_counter()
    compiled.start(again)  # a warm cache (a later process): load and check only
    row["load_from_cache_s"] = time.perf_counter() - t
    row["frame_functions_build_s"] = t_build
    row["compiled_ok"] = bool(ff.compiled and again.compiled)
    row["compiled"]["correct"] = tutor_correction(res)
    row["compiled"].update({k: _extrapolate(tutor, t) for k, t in targets.items()})
    compiled.enable(None)
    return row


def run() -> dict:
    tr = trials()
    out: dict = {}
    with tempfile.TemporaryDirectory() as tmp:
        cache = Path(tmp)
        for name in ("c3d_pig", "deepmimic_walk"):
            out[f"{name}/halfboy_15fps"] = _case(load_trial(tr[name]), "halfboy", 15.0, TARGETS, cache)
        out["c3d_pig/fullbody_30fps"] = _case(load_trial(tr["c3d_pig"]), "fullbody", 30.0,
                                              {"curve_90": TARGETS["curve_90"]}, cache)
    return out
