"""Tutor pipeline timings (issue: spacetime optimization): import, NLP build, simplify, correct."""

from __future__ import annotations

import time

from bench.trials import trials
from solver.io import load_trial
from solver.pipeline import make_tutor, problem_for
from solver.spacetime import frame_functions


def run() -> dict:
    out: dict = {}
    for name, paths in trials().items():
        t = time.perf_counter()
        cap = load_trial(paths)
        t_import = time.perf_counter() - t
        for kind, fps in (("halfboy", 15.0), ("fullbody", 30.0)):
            t = time.perf_counter()
            res = make_tutor(cap, character=kind, fps=fps)
            total = time.perf_counter() - t
            row: dict = {"import_s": t_import, "status": res.status, "total_s": total}
            if res.motion is not None:
                m = res.motion
                ff = frame_functions(m.character)
                prob = problem_for(m.character, m.T, m.fps, m.contacts)
                st = res.stats
                row.update({
                    "frames": m.T, "coordinates": m.n, "variables": prob.nx, "constraints": prob.ng,
                    "build_frame_functions_s": ff.build_time, "build_nlp_s": prob.build_time,
                    "simplify_s": st["simplify"]["time_s"], "simplify_iterations": st["simplify"]["iterations"],
                    "estimate_s": st["estimate"]["time_s"],
                    "correct_s": st["correct"]["attempts"][-1]["time_s"],
                    "correct_iterations": st["correct"]["attempts"][-1]["iterations"],
                    "marker_distance_to_capture_mm": st["marker_distance_to_capture_mm"],
                    "root_residual_rel_weight": m.report["root_residual"]["max_force_rel_weight"],
                    "plausible": m.report["plausible"],
                    "realism": {k: v["value"] for k, v in (m.report.get("realism") or {}).get("checks", {}).items()},
                })
            elif res.stats:
                row["correct_iterations"] = sum(a.get("iterations") or 0 for a in
                                                (res.stats.get("correct") or {}).get("attempts") or [])
            out[f"{name}/{kind}"] = row
    return out
