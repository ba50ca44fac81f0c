"""Naturalness on every shared trial (issue: natural walks): the tutor and the λ optimum of each
target, judged by the naturalness checks (and still by the realism checks), beside the
captured walk's own figures; the tutor's joint angles against the capture's and its ground
reactions against the force plates where the trial has them."""

from __future__ import annotations

import time

from bench.trials import shared_trials
from solver.continuation import StepControl, Target, extrapolate
from solver.io import load_trial
from solver.pipeline import make_tutor

TARGETS = {
    "uphill_11.25": Target(slope_deg=11.25), "downhill_11.25": Target(slope_deg=-11.25),
    "uphill_20": Target(slope_deg=20.0), "downhill_20": Target(slope_deg=-20.0),
    "curve_90": Target(curve_deg=90.0),
    "stairs_up_0.10": Target(step_height_m=0.10), "stairs_down_0.10": Target(step_height_m=-0.10),
    "speed_0.8": Target(speed_scale=0.8), "speed_1.2": Target(speed_scale=1.2),
}


def _checks(report: dict) -> dict:
    nat = report.get("naturalness") or {}
    return {"natural": report.get("natural"), "plausible": report.get("plausible"), "failed": nat.get("failed"),
            "warnings": nat.get("warnings"),
            "values": {k: c["value"] for k, c in (nat.get("checks") or {}).items() if c.get("applies", True)}}


def run() -> dict:
    out: dict = {}
    for name, (files, opts) in shared_trials().items():
        t = time.perf_counter()
        res = make_tutor(load_trial(files, **opts), character="halfboy", fps=15.0)
        row: dict = {"tutor_status": res.status, "tutor_s": time.perf_counter() - t}
        if res.motion is None:
            out[name] = row
            continue
        tutor = res.motion
        st = res.stats
        capture = (tutor.provenance.get("gait_reference") or {}).get("capture") or {}
        row.update({
            "tutor": _checks(tutor.report),
            "capture": {k: c.get("capture") for k, c in tutor.report["naturalness"]["checks"].items()},
            "capture_has_plates": capture.get("plates"),
            "tutor_iterations": st["correct"]["attempts"][-1]["iterations"],
            "marker_distance_to_capture_mm": st["marker_distance_to_capture_mm"],
            "joint_rms_to_capture_deg": {k: v for k, v in st["joint_rms_to_capture_deg"].items()
                                         if k != "per_coordinate"},
            "grf_against_plates": st.get("grf_against_plates"),
            "targets": {},
        })
        for label, target in TARGETS.items():
            t = time.perf_counter()
            ext = extrapolate(tutor, target, StepControl())
            last = ext.steps[-1].motion if ext.steps else None
            row["targets"][label] = {
                "status": ext.status, "lambda_reached": ext.lam_reached, "time_s": time.perf_counter() - t,
                "solves": ext.solves, "iterations": sum(max(r.iterations, 0) for r in ext.records),
                "every_step_plausible_and_natural": all(s.motion.report["plausible"] and s.motion.report["natural"]
                                                        for s in ext.steps),
                "reached": None if last is None else last.provenance.get("environment_values"),
                "rejections": [r.status for r in ext.records if not r.accepted][-6:],
                "last": None if last is None else _checks(last.report),
            }
        out[name] = row
    return out
