"""True to the subject (issue): the default tutor (full body, 30 frames/s) and HalfBoy's (15 frames/s)
of every shared trial and of the other labs' walks — the joints against the capture (overall, per
coordinate, the simplified's, the closed cycle's), the ground reactions against the force plates (RMS,
peaks, mid-stance valley), every naturalness check with the capture's own figure, the time — and the
λ = 1 optima of slope ±20°, curve 90°, speed ×0.8 and ×1.2 and stairs (0.17 m rise, 0.28 m going,
up and down), judged by the same checks (or the impasse at the last natural λ).

``MOTIONX_BENCH_FIDELITY_TRIALS`` (comma-separated names) and ``MOTIONX_BENCH_FIDELITY_TARGETS``
(``none``: the tutors only) restrict a run; ``MOTIONX_BENCH_FIDELITY_SAVE`` (a folder) keeps the
extrapolated trials' tutors and last optima as motion files (``NAME.tutor.json``, ``NAME.TARGET.json``:
``python -m bench.filmstrips --motions FOLDER`` draws them); the extrapolations run on the trials
named in ``EXTRAPOLATED`` (a full-body continuation takes minutes)."""

from __future__ import annotations

import os
import time

from bench.trials import other_labs, shared_trials
from solver.continuation import StepControl, Target, extrapolate
from solver.io import load_trial
from solver.pipeline import make_tutor

CHARACTERS = (("fullbody", 30.0), ("halfboy", 15.0))
TARGETS = {
    "uphill_20": Target(slope_deg=20.0), "downhill_20": Target(slope_deg=-20.0),
    "curve_90": Target(curve_deg=90.0),
    "speed_0.8": Target(speed_scale=0.8), "speed_1.2": Target(speed_scale=1.2),
    "stairs_up_0.17": Target(step_height_m=0.17, step_going_m=0.28),
    "stairs_down_0.17": Target(step_height_m=-0.17, step_going_m=0.28),
}
#: the trials whose default tutors are extrapolated (both OpenSim walks: the issue's fidelity figures)
EXTRAPOLATED = ("opensim_treadmill", "opensim_overground")


def checks(report: dict) -> dict:
    nat = report.get("naturalness") or {}
    return {"natural": report.get("natural"), "plausible": report.get("plausible"), "failed": nat.get("failed"),
            "warnings": nat.get("warnings"),
            "values": {k: c["value"] for k, c in (nat.get("checks") or {}).items() if c.get("applies", True)},
            "capture": {k: c.get("capture") for k, c in (nat.get("checks") or {}).items()}}


def valleys(motion) -> list[dict]:
    """Per stance: the loading peak, mid-stance valley and push-off peak of the vertical force (BW)."""
    fig = (motion.report.get("naturalness") or {}).get("figures") or {}
    return fig.get("vertical_force_shape") or []


def tutor_row(res, seconds: float) -> dict:
    row: dict = {"status": str(res.status), "time_s": seconds}
    if res.motion is None:
        return row
    st, m = res.stats, res.motion
    row.update({
        "fps": m.fps, "frames": m.T, "coordinates": m.n, "kept_coordinates": st.get("kept_coordinates"),
        "arm_swing": bool(st.get("arm_swing")),
        "iterations": [a["iterations"] for a in st["correct"]["attempts"]],
        "joint_rms_to_capture_deg": st["joint_rms_to_capture_deg"],
        "joint_rms_simplified_to_capture_deg": st["joint_rms_simplified_to_capture_deg"],
        "joint_rms_to_closed_cycle_deg": st.get("joint_rms_to_closed_cycle_deg"),
        "marker_distance_to_capture_mm": st["marker_distance_to_capture_mm"],
        "grf_against_plates": st.get("grf_against_plates"),
        "vertical_force_shape": valleys(m),
        "checks": checks(m.report),
        "active_bounds": m.provenance["solver"].get("active_bounds"),
    })
    return row


def run() -> dict:
    only = [t for t in os.environ.get("MOTIONX_BENCH_FIDELITY_TRIALS", "").split(",") if t]
    targets = [t for t in os.environ.get("MOTIONX_BENCH_FIDELITY_TARGETS", "").split(",") if t] or list(TARGETS)
    targets = [] if targets == ["none"] else targets
    save = os.environ.get("MOTIONX_BENCH_FIDELITY_SAVE")
    out: dict = {"load_average": os.getloadavg()}
    for name, (files, opts) in {**shared_trials(), **other_labs()}.items():
        if only and name not in only:
            continue
        capture = load_trial(files, **opts)
        row: dict = {"fit": (capture.source.get("fit") or {}).get("verdict")}
        for kind, fps in CHARACTERS:
            t = time.perf_counter()
            res = make_tutor(capture, character=kind, fps=fps)
            row[kind] = tutor_row(res, time.perf_counter() - t)
            if res.motion is None or name not in EXTRAPOLATED or kind != "fullbody":
                continue
            row[kind]["targets"] = {}
            if save:
                os.makedirs(save, exist_ok=True)
                res.motion.save(os.path.join(save, f"{name}.tutor.json"))
            for label in targets:
                t = time.perf_counter()
                ext = extrapolate(res.motion, TARGETS[label], StepControl())
                last = ext.steps[-1].motion if ext.steps else None
                row[kind]["targets"][label] = {
                    "status": str(ext.status), "lambda_reached": ext.lam_reached, "time_s": time.perf_counter() - t,
                    "solves": ext.solves, "rejections": [r.status for r in ext.records if not r.accepted][-6:],
                    "every_step_natural": all(s.motion.report["plausible"] and s.motion.report["natural"]
                                              for s in ext.steps),
                    "last": None if last is None else checks(last.report),
                    "active_bounds": None if last is None else last.provenance["solver"].get("active_bounds")}
                if save and last is not None:
                    last.save(os.path.join(save, f"{name}.{label}.json"))
                    with open(os.path.join(save, f"{name}.{label}.status"), "w") as f:
                        f.write(f"{ext.status}, λ = {ext.lam_reached:.3g}")
        out[name] = row
    out["load_average_end"] = os.getloadavg()
    return out


def summary(results: dict) -> list[str]:
    """One line per trial and character: joint RMS (captured coordinates), natural, time."""
    lines = []
    for name, row in results.items():
        if not isinstance(row, dict):
            continue
        for kind, _ in CHARACTERS:
            r = row.get(kind) or {}
            if "joint_rms_to_capture_deg" in r:
                lines.append(f"{name} {kind}: {r['joint_rms_to_capture_deg']['overall']:.2f} deg, "
                             f"natural {r['checks']['natural']}, {r['time_s']:.0f} s")
    return lines


if __name__ == "__main__":  # a quick look: python -m bench.fidelity
    print("\n".join(summary(run())))
