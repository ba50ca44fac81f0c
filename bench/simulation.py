"""Forward simulation in MuJoCo (``mjcf.simulate.simulate``, docs/simulation.md) on every shared
trial's HalfBoy tutor (15 fps, ``bench.trials.shared_trials``): each simulated for 10 gait cycles
continuously from mid stance (stopping at the first fall) and, the report's ``resync``, each of
10 cycles started afresh from the reference's state and tracked to its end with the penalized
root residual. Per tutor: cycles walked, fall (and why), joint tracking RMS, foot force RMS, the
largest peak-torque ratio; cycles completed from the reference state and the residual's RMS in
body weights; the start's vertical force against the stored one over the first 10 ms; the stored
centres of pressure off the simulated sole (all stance frames; frames with the sole flat); the
reference's lowest sole corner in swing; and the CPU time per simulated second of each run
(``time.process_time``, this process: the controller is single-threaded). The same for the
DeepMimic tutor's λ = 1 optima of the performability targets (slope ±11.25°, curve 90°, stairs
±0.10 m, speed ×0.8 and ×1.2).
"""

from __future__ import annotations

import time

import solver
from bench.trials import shared_trials
from mjcf.cycle import cycle_controller, feasible_cycle
from mjcf.simulate import simulate
from solver.continuation import Target
from solver.motion import Motion

CYCLES = 10
FPS = 15


#: the λ = 1 optima of the performability targets, simulated for the DeepMimic walk's tutor
OPTIMA = {"uphill_11.25": Target(slope_deg=11.25), "downhill_11.25": Target(slope_deg=-11.25),
          "curve_90": Target(curve_deg=90.0), "stairs_up_0.10": Target(step_height_m=0.10),
          "stairs_down_0.10": Target(step_height_m=-0.10), "speed_0.8": Target(speed_scale=0.8),
          "speed_1.2": Target(speed_scale=1.2)}
OPTIMA_OF = "deepmimic_walk"


def _run_figures(r: dict) -> dict:
    """A continuous run's figures from its report: how far it walked, its fall, its tracking."""
    return {"cycles_walked": round(float(r["cycles_walked"]), 3), "fell": bool(r["fell"]),
            "fall_reason": (r.get("fall") or {}).get("reason"),
            "joint_tracking_rms_deg": round(float(r["joint_tracking_rms_deg"]), 3),
            "foot_force_rms_bw": round(float(r["foot_force_rms_bw"]), 4),
            "peak_torque_ratio_max": round(float(r["peak_torque_ratio_max"]), 3)}


def _row(motion: Motion) -> dict:
    wall, cpu = time.perf_counter(), time.process_time()
    res = simulate(motion, CYCLES)
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    r = res.report
    rs, start, agree = r["resync"], r["start"], r["agreement"]
    simulated_s = float(r["simulated_s"])
    resync_s = sum(c["walked"] for c in rs["per_cycle"]) * float(r["cycle_duration_s"])
    cpu_continuous = cpu - float(rs["cpu_s"])
    return {
        "cycles_requested": CYCLES,
        **_run_figures(r),
        "resync_cycles": rs["cycles"],
        "resync_completed": rs["completed"],
        "resync_closed": rs["closed"],
        "resync_end_error": {k: round(float(v), 3) for k, v in rs["per_cycle"][0]["end_error"].items()},
        "residual_root_wrench_rms_bw": round(float(rs["residual_root_wrench_rms_bw"]), 4),
        "residual_root_wrench_rms_bw_worst_cycle": round(max(c["residual_root_wrench_rms_bw"]
                                                             for c in rs["per_cycle"]), 4),
        "start_stored_vertical_force_bw": round(float(start["stored_vertical_force_bw"]), 3),
        "start_first_10ms_max_difference_bw": round(float(start["first_10ms_max_difference_bw"]), 3),
        "start_first_60ms_rms_difference_bw": round(float(start["first_60ms_rms_difference_bw"]), 3),
        "cop_outside_sole_fraction": round(float(agree["sole"]["cop_outside_fraction"]), 3),
        "cop_outside_flat_sole_fraction": round(float(agree["sole"]["cop_outside_fraction_flat"]), 3),
        "swing_min_corner_height_mm": round(1e3 * float(agree["swing_clearance"]["min_corner_height_m"]), 1),
        "simulated_s": round(simulated_s, 3),
        "wall_s": round(wall, 2),
        "cpu_s": round(cpu, 2),
        "cpu_per_simulated_s": round(cpu_continuous / simulated_s, 3) if simulated_s > 0 else None,
        "resync_cpu_per_simulated_s": round(float(rs["cpu_s"]) / resync_s, 3) if resync_s > 0 else None,
        "offline_cycle": _cycle_row(motion),
    }


def _cycle_row(motion: Motion) -> dict:
    """The offline cycle (``mjcf.cycle.feasible_cycle``) and its controller's continuous run."""
    cpu = time.process_time()
    cyc = feasible_cycle(motion)
    cpu = time.process_time() - cpu
    rec = cyc.record
    if rec["status"] != "computed":
        return {"status": rec["status"], "message": rec.get("message", ""), "cpu_s": round(cpu, 2)}
    run_cpu = time.process_time()
    r = simulate(motion, CYCLES, controller=cycle_controller(cyc), resync=False).report
    run_cpu = time.process_time() - run_cpu
    simulated_s = float(r["simulated_s"])
    return {
        "status": rec["status"],
        "iterations": rec["iterations"],
        "cpu_s": round(cpu, 2),
        "linearization_cpu_s": round(float(rec["linearization_cpu_s"]), 2),
        "residual_rms_bw_before": round(float(rec["residual_rms_bw_before"]), 5),
        "residual_rms_bw_after": round(float(rec["residual_rms_bw_after"]), 5),
        "end_error_before": {k: round(float(v), 4) for k, v in rec["end_error_before"].items()},
        "end_error_after": {k: round(float(v), 4) for k, v in rec["end_error_after"].items()},
        **_run_figures(r),
        "cpu_per_simulated_s": round(run_cpu / simulated_s, 3) if simulated_s > 0 else None,
    }


def run() -> dict:
    rows: dict[str, dict] = {}
    for name, (files, opts) in shared_trials().items():
        tutor = solver.make_tutor(solver.load_trial(files, **opts), character="halfboy", fps=FPS)
        if tutor.status != "succeeded":
            rows[name] = {"error": f"tutor {tutor.status}: {tutor.message}"}
            continue
        rows[name] = _row(tutor.motion)
        if name != OPTIMA_OF:
            continue
        for label, target in OPTIMA.items():
            ext = solver.extrapolate(tutor.motion, target)
            if ext.status != "succeeded" or not ext.steps or ext.lam_reached < 1.0:
                rows[f"{name} {label}"] = {"error": f"extrapolation {ext.status} at λ {ext.lam_reached:.3f}"}
                continue
            rows[f"{name} {label}"] = _row(ext.steps[-1].motion)
    return {"cycles": CYCLES, "fps": FPS, "motions": rows}


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=1))
