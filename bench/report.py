"""Markdown tables from bench/results.json (``python -m bench.report``) for the docs."""

from __future__ import annotations

import json
import sys
from pathlib import Path


def tutor_table(res: dict) -> str:
    rows = ["| trial | character | frames | variables / constraints | build (frame fns + NLP) | simplify "
            "| correct (IPOPT its) | marker distance to capture (mean / max) | root residual / weight "
            "| realistic (Newton / refined force, BW) |",
            "|---|---|---|---|---|---|---|---|---|---|"]
    for key, r in res.items():
        trial, kind = key.split("/")
        if r.get("status") != "succeeded":
            rows.append(f"| {trial} | {kind} | – | – | – | – | {r.get('status')} | – | – | – |")
            continue
        d = r["marker_distance_to_capture_mm"]
        rows.append(
            f"| {trial} | {kind} | {r['frames']} | {r['variables']} / {r['constraints']} | "
            f"{r['build_frame_functions_s']:.2f} + {r['build_nlp_s']:.2f} s | {r['simplify_s']:.2f} s | "
            f"{r['correct_s']:.2f} s ({r['correct_iterations']}) | {d['mean']:.1f} / {d['max']:.0f} mm | "
            f"{r['root_residual_rel_weight']:.0e} | {_realistic(r)} |")
    return "\n".join(rows)


def _realistic(r: dict) -> str:
    rl = r.get("realism") or {}
    if not rl:
        return "–"
    nan = float("nan")
    verdict = "yes" if r.get("plausible") else "NO"
    return f"{verdict} ({rl.get('newton_force', nan):.3f} / {rl.get('refined_force', nan):.3f})"


def continuation_table(res: dict) -> str:
    rows = ["| trial | target | Algorithm 3 (thesis, the default): status, λ, solves, time "
            "| adaptive: status, λ, solves, time |", "|---|---|---|---|"]
    for trial, targets in res.items():
        for tgt, r in targets.items():
            cells = []
            for m in ("thesis", "adaptive"):
                v = r.get(m)
                if v is None:
                    cells.append("–")
                    continue
                pl = "" if v["all_plausible"] else " (implausible step!)"
                cells.append(f"{v['status']}, {v['lambda_reached']:.3f}, {v['solves']}, {v['time_s']:.1f} s{pl}")
            rows.append(f"| {trial} | {tgt} | {cells[0]} | {cells[1]} |")
    return "\n".join(rows)


def compiled_table(res: dict) -> str:
    rows = ["| case | compile (fresh cache) / load (cached) | solve | VM: time (iterations) "
            "| compiled: time (iterations) | speed-up |", "|---|---|---|---|---|---|"]
    for case, r in res.items():
        if "vm" not in r:
            rows.append(f"| {case} | – | – | {r.get('status')} | – | – |")
            continue
        head = f"{r['compile_s']:.1f} s / {r['load_from_cache_s']:.2f} s"
        head += "" if r.get("compiled_ok") else " (FAILED)"
        for solve, v in r["vm"].items():
            c = r["compiled"][solve]
            its = v.get("iterations")
            ok = "" if v.get("all_plausible", True) and c.get("all_plausible", True) else " (implausible step!)"
            rows.append(f"| {case} | {head} | {solve} | {v['time_s']:.2f} s ({its}) | {c['time_s']:.2f} s "
                        f"({c.get('iterations')}){ok} | {v['time_s'] / c['time_s']:.2f}× |")
            head = ""
    return "\n".join(rows)


def blas_table(res: dict) -> str:
    rows = ["| correction (compiled derivatives) | CasADi's OpenBLAS: time (iterations), ms/iteration "
            "| scipy-openblas32: time (iterations), ms/iteration | per iteration |", "|---|---|---|---|"]
    for case, o in res.get("optimized", {}).items():
        b = res["casadi_openblas"][case]
        rows.append(f"| {case} | {b['time_s']:.2f} s ({b['iterations']}), {b['ms_per_iteration']:.1f} "
                    f"| {o['time_s']:.2f} s ({o['iterations']}), {o['ms_per_iteration']:.1f} "
                    f"| {o['speedup_per_iteration']:.2f}× |")
    return "\n".join(rows)


def rig_export_table(res: dict) -> str:
    rows = ["| motion | ankle joint from the motion's foot, stance (max, mm) | contact slide on the rig (max, mm) "
            "| locked joints vs the input at the same phase (RMS, °) | export (s) |", "|---|---|---|---|---|"]
    for name, r in res["motions"].items():
        rows.append(f"| {name} | {r['ankle_error_mm']:.1f} | {r['slide_mm']:.1f} | {r['locked_joints_rms_deg']:.3f} "
                    f"| {r['export_s']:.3f} |")
    return "\n".join(rows)


def simulation_table(res: dict) -> str:
    rows = ["| HalfBoy tutor | cycles walked (of requested) | fell (reason) | resync: cycles completed "
            "| root residual RMS (BW; worst cycle) | joint RMS (°) | foot force RMS (BW) | start: stored / max "
            "difference in 10 ms (BW) | CoP off the sole (all / flat stance) | swing: lowest sole corner (mm) "
            "| CPU s per simulated s (continuous; resync) |",
            "|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, r in res["motions"].items():
        if "error" in r:
            rows.append(f"| {name} | {r['error']} |" + "  |" * 9)
            continue
        fell = f"yes ({r['fall_reason'] or '?'})" if r["fell"] else "no"
        rows.append(f"| {name} | {r['cycles_walked']:.2f} ({r['cycles_requested']}) | {fell} "
                    f"| {r['resync_completed']} of {r['resync_cycles']} ({r.get('resync_closed', '–')}) "
                    f"| {r['residual_root_wrench_rms_bw']:.3f} ({r['residual_root_wrench_rms_bw_worst_cycle']:.3f}) "
                    f"| {r['joint_tracking_rms_deg']:.1f} | {r['foot_force_rms_bw']:.2f} "
                    f"| {r['start_stored_vertical_force_bw']:.2f} / {r['start_first_10ms_max_difference_bw']:.2f} "
                    f"| {100 * r['cop_outside_sole_fraction']:.0f} % "
                    f"/ {100 * r['cop_outside_flat_sole_fraction']:.0f} % "
                    f"| {r['swing_min_corner_height_mm']:.1f} "
                    f"| {_f(r['cpu_per_simulated_s'])}; {_f(r['resync_cpu_per_simulated_s'])} |")
    return "\n".join(rows) + "\n\n" + offline_cycle_table(res)


def offline_cycle_table(res: dict) -> str:
    """The offline cycle (``mjcf.cycle``) of each motion and its controller's continuous run."""
    rows = ["| HalfBoy tutor | offline cycle: CPU s (iterations) | root residual RMS (BW): tracker's cycle → "
            "offline | end vs start: joints RMS (°), joint velocities RMS (°/s): tracker's cycle → offline "
            "| cycle controller: cycles walked (of requested) | fell (reason) | joint RMS (°) | foot force RMS (BW) "
            "| CPU s per simulated s |",
            "|---|---|---|---|---|---|---|---|---|"]
    for name, row in res["motions"].items():
        r = row.get("offline_cycle")
        if r is None:
            continue
        if r.get("status") != "computed":
            rows.append(f"| {name} | {r.get('status')}: {r.get('message', '')} |" + "  |" * 7)
            continue
        b, a = r["end_error_before"], r["end_error_after"]
        fell = f"yes ({r['fall_reason'] or '?'})" if r["fell"] else "no"
        rows.append(f"| {name} | {r['cpu_s']:.1f} ({r['iterations']}) "
                    f"| {r['residual_rms_bw_before']:.4f} → {r['residual_rms_bw_after']:.5f} "
                    f"| {b['joint_rms_deg']:.2f}, {b['joint_velocity_rms_deg_s']:.1f} → "
                    f"{a['joint_rms_deg']:.3f}, {a['joint_velocity_rms_deg_s']:.2f} "
                    f"| {r['cycles_walked']:.2f} ({res['cycles']}) | {fell} | {r['joint_tracking_rms_deg']:.1f} "
                    f"| {r['foot_force_rms_bw']:.2f} | {_f(r['cpu_per_simulated_s'])} |")
    return "\n".join(rows)


def front_door_table(res: dict) -> str:
    rows = ["| docs/api.md's script (median, s) | `motionx tutor` + `motionx extrapolate --slope 10` (median, s) "
            "| ratio |", "|---|---|---|",
            f"| {res['script_s']:.2f} ({', '.join(f'{x:.2f}' for x in res['script_runs_s'])}) "
            f"| {res['cli_s']:.2f} ({', '.join(f'{x:.2f}' for x in res['cli_runs_s'])}) | {res['ratio']:.2f} |"]
    return "\n".join(rows)


def _f(x, fmt: str = "{:.2f}") -> str:
    return "–" if x is None else fmt.format(x)


def fidelity_table(res: dict) -> str:
    """The tutors: joints against the capture, naturalness, time."""
    rows = ["| trial | character | joints' RMS to the capture (simplified) | pelvis | worst joint | natural (failed; "
            "warnings) | mid-swing clearance | fit marker RMS | time (IPOPT its) |",
            "|---|---|---|---|---|---|---|---|---|"]
    for trial, row in res.items():
        if not isinstance(row, dict) or trial.startswith("load"):
            continue
        for kind in ("fullbody", "halfboy"):
            r = row.get(kind) or {}
            if "joint_rms_to_capture_deg" not in r:
                rows.append(f"| {trial} | {kind} | {r.get('status', '–')} | | | | | | |")
                continue
            jr, js = r["joint_rms_to_capture_deg"], r["joint_rms_simplified_to_capture_deg"]
            worst = max(jr["per_coordinate"].items(), key=lambda kv: kv[1])
            c = r["checks"]
            clr = (c.get("values") or {}).get("swing_clearance")
            fit = (row.get("fit") or {}).get("marker_rms_mm")
            rows.append(
                f"| {trial} | {kind} | {jr['overall']:.2f}° ({js['overall']:.2f}°) | {_f(jr.get('pelvis'))}° | "
                f"{worst[0]} {worst[1]:.1f}° | {'yes' if c['natural'] else 'NO'} "
                f"({', '.join(c['failed'] or []) or '–'}; "
                f"{', '.join(c['warnings'] or []) or '–'}) | {_f(None if clr is None else 1e3 * clr, '{:.1f}')} mm | "
                f"{_f(fit, '{:.1f}')} mm | {r['time_s']:.0f} s ({'/'.join(str(i) for i in r['iterations'])}) |")
    return "\n".join(rows)


def plates_table(res: dict, before: dict | None = None) -> str:
    """The tutors' ground reactions against the force plates they never saw (BW); with ``before``
    (an earlier fidelity run), each RMS and peak as before → after."""
    rows = ["| trial | character | foot | vertical RMS | fore-aft RMS | vertical peak (plates) | "
            "loading peak / valley / push-off (each stance) |", "|---|---|---|---|---|---|---|"]

    def was(trial: str, kind: str, side: str, *path: str) -> str:
        d = (((before or {}).get(trial) or {}).get(kind) or {}).get("grf_against_plates") or {}
        d = d.get(side) or {}
        for k in path:
            d = d.get(k) or {}
        return "" if before is None or not isinstance(d, float) else f"{d:.3f} → " if "rms_bw" in path else \
            f"{d:.2f} → "

    for trial, row in res.items():
        if not isinstance(row, dict) or trial.startswith("load"):
            continue
        for kind in ("fullbody", "halfboy"):
            r = row.get(kind) or {}
            pl = r.get("grf_against_plates")
            if not pl:
                continue
            shapes = r.get("vertical_force_shape") or []
            for side, d in pl.items():
                sh = [s for s in shapes if s.get("foot") == side]
                hump = "; ".join(f"{s['loading_peak_bw']:.2f} / {s['valley_bw']:.2f} / {s['push_off_peak_bw']:.2f}"
                                 for s in sh) or "–"
                rows.append(f"| {trial} | {kind} | {side} | {was(trial, kind, side, 'vertical', 'rms_bw')}"
                            f"{d['vertical']['rms_bw']:.3f} | {was(trial, kind, side, 'fore_aft', 'rms_bw')}"
                            f"{d['fore_aft']['rms_bw']:.3f} | {was(trial, kind, side, 'vertical', 'max_bw')}"
                            f"{d['vertical']['max_bw']:.2f} ({d['vertical']['plates_max_bw']:.2f}) | {hump} |")
    return "\n".join(rows)


def optima_table(res: dict) -> str:
    """The default tutors' extrapolations: where each ended, natural, the figures near a limit."""
    rows = ["| trial | target | status, λ | every step natural | failed at the impasse | swing clearance | "
            "crossover | joint speed | time |", "|---|---|---|---|---|---|---|---|---|"]
    for trial, row in res.items():
        if not isinstance(row, dict) or trial.startswith("load"):
            continue
        for label, t in ((row.get("fullbody") or {}).get("targets") or {}).items():
            v = ((t.get("last") or {}).get("values")) or {}
            rej = sorted({x.split(": ", 1)[1] for x in t.get("rejections") or [] if ": " in x})
            rows.append(f"| {trial} | {label} | {t['status']}, {t['lambda_reached']:.3f} | "
                        f"{'yes' if t['every_step_natural'] else 'NO'} | {'; '.join(rej) or '–'} | "
                        f"{_f(None if v.get('swing_clearance') is None else 1e3 * v['swing_clearance'], '{:.1f}')}"
                        " mm | "
                        f"{_f(None if v.get('crossover') is None else 1e3 * v['crossover'], '{:.0f}')} mm | "
                        f"{_f(v.get('joint_speed'), '{:.0f}')}°/s | {t['time_s']:.0f} s |")
    return "\n".join(rows)


#: the joint groups of ``joints_table`` (each the RMS over its coordinates: both sides)
JOINT_GROUPS = {"hip flexion": ("hip_flexion_r", "hip_flexion_l"),
                "hip adduction": ("hip_adduction_r", "hip_adduction_l"),
                "hip rotation": ("hip_rotation_r", "hip_rotation_l"), "knee": ("knee_angle_r", "knee_angle_l"),
                "ankle": ("ankle_angle_r", "ankle_angle_l"),
                "lumbar": ("lumbar_flexion", "lumbar_bending", "lumbar_rotation"),
                "thorax": ("thorax_flexion", "thorax_bending", "thorax_rotation")}


def joints_table(before: dict, after: dict,
                 trials: tuple[str, ...] = ("opensim_treadmill", "opensim_overground")) -> str:
    """Per joint, the tutors' RMS to the capture (°), before → after (two fidelity runs)."""
    import math

    def group(r: dict, names: tuple[str, ...]) -> float | None:
        pc = r["joint_rms_to_capture_deg"]["per_coordinate"]
        v = [pc[n] for n in names if n in pc]
        return math.sqrt(sum(x * x for x in v) / len(v)) if v else None

    rows = ["| trial | character | overall | pelvis | " + " | ".join(JOINT_GROUPS) + " |",
            "|---|---|---|---|" + "---|" * len(JOINT_GROUPS)]
    for trial in trials:
        for kind in ("fullbody", "halfboy"):
            b, a = (before.get(trial) or {}).get(kind) or {}, (after.get(trial) or {}).get(kind) or {}
            if "joint_rms_to_capture_deg" not in b or "joint_rms_to_capture_deg" not in a:
                continue
            jb, ja = b["joint_rms_to_capture_deg"], a["joint_rms_to_capture_deg"]
            cells = [f"{jb['overall']:.1f} → **{ja['overall']:.2f}**",
                     f"{_f(jb.get('pelvis'), '{:.1f}')} → {_f(ja.get('pelvis'), '{:.1f}')}"]
            cells += [f"{_f(group(b, n), '{:.1f}')} → {_f(group(a, n), '{:.1f}')}" for n in JOINT_GROUPS.values()]
            rows.append(f"| {trial} | {kind} | " + " | ".join(cells) + " |")
    return "\n".join(rows)


def moco_table(res: dict) -> str:
    """MocoTrack and the motionx tutors on the same walk: CPU seconds, iterations, fidelity, load."""
    rows = ["| trial | run | CPU s (wall s) | IPOPT iterations | status | joints' RMS to the trial (pelvis) "
            "| MocoTrack CPU ÷ this run's | load average before → after |", "|---|---|---|---|---|---|---|---|"]

    def load(r: dict) -> str:
        b, a = r.get("load_before"), r.get("load_after")
        return "–" if not b or not a else f"{b[0]:.1f} → {a[0]:.1f}"

    for trial, row in (res.get("trials") or {}).items():
        if "error" in row:
            rows.append(f"| {trial} | – | – | – | {row['error']} | – | – | – |")
            continue
        m = row.get("moco") or {}
        job = row.get("moco_job") or {}
        jr = m.get("joint_rms_to_reference_deg") or {}
        label = f"MocoTrack, torque-driven, plates given ({job.get('mesh_intervals', '–')} mesh intervals)"
        status = m.get("solver_status") if m.get("status") in ("succeeded", "failed") \
            else f"{m.get('status')}: {m.get('message')}"
        tr = jr.get("pelvis_translation_mm") or {}
        shift = "/".join(f"{v:.0f}" for v in tr.values())
        rows.append(f"| {trial} | {label} | {_f(m.get('cpu_s'), '{:.1f}')} ({_f(m.get('wall_s'), '{:.0f}')}) "
                    f"| {m.get('iterations', '–')} | {status} | {_f(jr.get('overall'))}° ({_f(jr.get('pelvis'))}°"
                    f"{f'; pelvis x/y/z {shift} mm' if shift else ''}) | – | {load(m)} |")
        for kind, r in (row.get("motionx") or {}).items():
            rms = r.get("joint_rms_to_capture_deg") or {}
            ratio = (row.get("ratio_moco_cpu_to_motionx_cpu") or {}).get(kind)
            its = f"{r.get('simplify_iterations', '–')} + {r.get('correct_iterations', '–')}"
            rows.append(f"| {trial} | motionx tutor, {kind} at {_f(r.get('fps'), '{:.1f}')} frames/s "
                        f"| {_f(r.get('cpu_s'), '{:.1f}')} ({_f(r.get('wall_s'), '{:.0f}')}) | {its} "
                        f"| {r.get('status')} | {_f(rms.get('overall'))}° ({_f(rms.get('pelvis'))}°) "
                        f"| {_f(ratio, '{:.1f}')} | {load(r)} |")
    return "\n".join(rows)


FILL = {"tutor": ("docs/spacetime.md", tutor_table), "continuation": ("docs/continuation.md", continuation_table),
        "compiled": ("docs/spacetime.md", compiled_table), "blas": ("docs/spacetime.md", blas_table),
        "front_door": ("docs/api.md", front_door_table),
        "rig_export": ("docs/export.md", rig_export_table),
        "simulation": ("docs/simulation.md", simulation_table),
        "fidelity": ("docs/naturalness.md", fidelity_table), "moco": ("docs/spacetime.md", moco_table)}


def fill(sec: dict, only: list[str] | None = None) -> None:
    """Rewrite the ``<!-- bench:NAME -->`` … ``<!-- /bench:NAME -->`` blocks of the docs (``only``:
    these sections)."""
    import re

    for name, (doc, fn) in FILL.items():
        if name not in sec or (only and name not in only):
            continue
        p = Path(doc)
        text = p.read_text()
        block = f"<!-- bench:{name} -->\n{fn(sec[name]['results'])}\n<!-- /bench:{name} -->"
        text = re.sub(rf"<!-- bench:{name} -->.*?<!-- /bench:{name} -->", lambda _: block, text, flags=re.S)
        p.write_text(text)


def main() -> int:
    args = [a for a in sys.argv[1:] if a.endswith(".json")]
    path = Path(args[0] if args else "bench/results.json")
    sec = json.loads(path.read_text())["sections"]
    if "--fill" in sys.argv:  # --fill [--only NAME ...]
        only = sys.argv[sys.argv.index("--only") + 1:] if "--only" in sys.argv else None
        fill(sec, only)
        return 0
    if "tutor" in sec:
        print("### Tutor\n\n" + tutor_table(sec["tutor"]["results"]) + "\n")
    if "continuation" in sec:
        print("### Continuation\n\n" + continuation_table(sec["continuation"]["results"]) + "\n")
    if "compiled" in sec:
        print("### Compiled derivatives\n\n" + compiled_table(sec["compiled"]["results"]) + "\n")
    if "blas" in sec:
        print("### Optimized BLAS\n\n" + blas_table(sec["blas"]["results"]) + "\n")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
