"""Forward simulation in MuJoCo (``mjcf.simulate.simulate``, docs/simulation.md): the DeepMimic
walk's tutors, HalfBoy and full body (15 fps), each simulated for 10 gait cycles, stopping at the
first fall. Per motion: cycles walked, fall (and why), joint tracking RMS, foot force RMS, the
largest peak-torque ratio to the inverse dynamics' peaks, the wall and CPU time of the
simulation (``time.process_time``, this process: the controller is single-threaded) and the
real-time factor in CPU time (simulated s / CPU s) beside the wall-clock one.
"""

from __future__ import annotations

import time

import solver
from bench.trials import data_dir
from mjcf.simulate import simulate

CYCLES = 10
FPS = 15


def run() -> dict:
    d = data_dir() / "deepmimic_humanoid3d_walk"
    trial = solver.load_trial([d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt"])
    rows = {}
    for name, character in (("HalfBoy tutor", "halfboy"), ("full-body tutor", "fullbody")):
        tutor = solver.make_tutor(trial, character=character, fps=FPS)
        if tutor.status != "succeeded":
            rows[name] = {"error": f"tutor {tutor.status}: {tutor.message}"}
            continue
        wall, cpu = time.perf_counter(), time.process_time()
        res = simulate(tutor.motion, CYCLES)
        wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
        r = res.report
        simulated_s = float(r["simulated_s"])
        rows[name] = {
            "cycles_requested": CYCLES,
            "cycles_walked": round(float(r["cycles_walked"]), 3),
            "fell": bool(r["fell"]),
            "fall_reason": (r.get("fall") or {}).get("reason"),
            "joint_tracking_rms_deg": round(float(r["joint_tracking_rms_deg"]), 3),
            "foot_force_rms_bw": round(float(r["foot_force_rms_bw"]), 4),
            "peak_torque_ratio_max": round(float(r["peak_torque_ratio_max"]), 3),
            "simulated_s": round(simulated_s, 3),
            "wall_s": round(wall, 2),
            "cpu_s": round(cpu, 2),
            "realtime_factor_cpu": round(simulated_s / cpu, 3) if cpu > 0 else None,
            "realtime_factor_wall": round(simulated_s / wall, 3) if wall > 0 else None,
        }
    return {"cycles": CYCLES, "fps": FPS, "motions": rows}


if __name__ == "__main__":
    import json

    print(json.dumps(run(), indent=1))
