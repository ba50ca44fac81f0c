"""The service's plots: seconds to draw each PNG the API serves (``service.plots``: the GRF
and residual plots of a motion, the progress curve of a job) — the best of 3 after one warm
call (matplotlib's import and font cache are paid once per process).

On the DeepMimic walk's tutor (``make_tutor``'s defaults) and a cheap continuation from it
(friction 1 -> 0.7 and 4° uphill, Δ0 = 0.5), as ``tests/test_plots.py`` draws them.
"""

from __future__ import annotations

from dataclasses import asdict

from bench.trials import best_time, data_dir
from service.plots import grf_png, progress_png, residuals_png
from solver.continuation import StepControl, Target, extrapolate
from solver.io import load_trial
from solver.pipeline import capture_motion, make_tutor


def run() -> dict:
    d = data_dir() / "deepmimic_humanoid3d_walk"
    res = make_tutor(capture_motion(load_trial([d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt"])),
                     character="halfboy", fps=15.0)
    assert res.status == "succeeded", res.message
    tutor = res.motion
    target = Target(slope_deg=4.0, friction=0.7)
    cont = extrapolate(tutor, target, StepControl(delta0=0.5))
    records = [asdict(r) for r in cont.records]
    grf_png(tutor)  # warm
    return {
        "motion_frames": tutor.T,
        "progress_records": len(records),
        "grf_png_s": round(best_time(lambda: grf_png(tutor), 3), 4),
        "residuals_png_s": round(best_time(lambda: residuals_png(tutor), 3), 4),
        "progress_png_s": round(best_time(lambda: progress_png(records, target.to_dict()), 3), 4),
    }


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=1))
