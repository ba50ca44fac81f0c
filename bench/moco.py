"""Side by side with OpenSim Moco: MocoTrack and the motionx tutors on the same OpenSim walk, back to back.

For each shipped OpenSim walk (``TRIALS``; ``MOTIONX_BENCH_MOCO_TRIALS``, comma-separated names,
restricts a run), in this order:

* the motionx tutors, full body at 30 frames/s and HalfBoy at 15 (``solver.pipeline.make_tutor``,
  as section ``tutor`` runs them): CPU seconds of the whole call (this process's, and any child it
  waits for), wall seconds, the IPOPT iterations of the simplification and of the correction, the
  status, and the joints' RMS to the capture as the tutor reports it (``joint_rms_to_capture_deg``);
* OpenSim's MocoTrack (``bench.moco_track``, in a process of its own: OpenSim's CasADi cannot share
  one with ours) on the trial's model made torque-driven, the plates applied, tracking the trial's
  coordinates over the cycle the full-body tutor stands for (its ``context.cycle``: start and
  period on the trial's clock, to the millisecond), one mesh interval per 1/30 s of it,
  convergence tolerance 1e-2, L-BFGS Hessian, one thread: the child's CPU seconds (all of it:
  import, model processing, solve; and the solve's own), wall seconds, iterations, status, the
  RMS of the tracked coordinates to the trial's, the pelvis residual forces it needed.

Every run records the load average before and after it; the section records the machine (CPU,
the BLAS MUMPS runs on, cores). The ratio is MocoTrack's CPU seconds over each tutor's. A MocoTrack
that cannot run (no ``opensim``, a solver failure, a timeout) is recorded as its status and
message; the section goes on."""

from __future__ import annotations

import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

from bench.trials import shared_trials

#: the shipped OpenSim walks (names of ``bench.trials.shared_trials``)
TRIALS = ("opensim_treadmill", "opensim_overground")
#: the motionx tutors measured: (character, frames/s)
CHARACTERS = (("fullbody", 30.0), ("halfboy", 15.0))
#: MocoTrack's mesh: one interval per 1/MESH_FPS s of the cycle (as the full-body tutor's frames)
MESH_FPS = 30.0
#: what MocoTrack is asked (``bench.moco_track.DEFAULTS`` gives the rest)
MOCO_OPTIONS = {"convergence_tolerance": 1e-2, "hessian": "limited-memory"}
MOCO_TIMEOUT_S = 1800.0


def cpu_seconds() -> float:
    """CPU seconds (user + system) of this process and of the children it has waited for."""
    own = resource.getrusage(resource.RUSAGE_SELF)
    kids = resource.getrusage(resource.RUSAGE_CHILDREN)
    return own.ru_utime + own.ru_stime + kids.ru_utime + kids.ru_stime


def measured(fn: Callable[[], Any]) -> tuple[Any, dict]:
    """``fn()`` and its CPU and wall seconds, with the load average before and after."""
    load0, c, w = os.getloadavg(), cpu_seconds(), time.perf_counter()
    out = fn()
    return out, {"cpu_s": cpu_seconds() - c, "wall_s": time.perf_counter() - w,
                 "load_before": [round(x, 2) for x in load0], "load_after": [round(x, 2) for x in os.getloadavg()]}


def machine() -> dict:
    """The CPU (OpenBLAS's kernel, the BLAS MUMPS runs on: ``bench.machine.cpu``), cores, platform."""
    from bench.machine import cpu

    return {"cores": os.cpu_count(), "platform": platform.platform(), "python": platform.python_version(), **cpu()}


def tutor_row(capture: Any, character: str, fps: float) -> dict:
    """One motionx tutor, timed."""
    from solver.pipeline import make_tutor

    try:
        res, row = measured(lambda: make_tutor(capture, character=character, fps=fps))
    except Exception as e:  # recorded, never the bench's end
        return {"status": "error", "message": f"{type(e).__name__}: {e}"}
    st = res.stats or {}
    attempts = (st.get("correct") or {}).get("attempts") or []
    row.update({"status": str(res.status), "message": res.message or None,
                "simplify_iterations": (st.get("simplify") or {}).get("iterations"),
                "correct_iterations": sum(a.get("iterations") or 0 for a in attempts),
                "correct_attempts": len(attempts),
                "correct_wall_s": sum(a.get("time_s") or 0.0 for a in attempts)})
    if res.motion is not None:
        m, rms = res.motion, st.get("joint_rms_to_capture_deg") or {}
        cyc = m.context.cycle
        row.update({"fps": m.fps, "frames": m.T, "coordinates": m.n,
                    "cycle": None if cyc is None else {"t_start": cyc.t_start, "period_s": cyc.period_s},
                    "joint_rms_to_capture_deg": {"overall": rms.get("overall"), "pelvis": rms.get("pelvis")}})
    return row


def prepare(folder: Path, files: list[Path], capture: Any) -> dict:
    """The trial's files for MocoTrack in ``folder``: model, plates and ExternalLoads as the
    trial's own inverse dynamics takes them (``trial_folder``), and the coordinates as
    ``bench.moco_track.REFERENCE`` with their header stating whether the angles are degrees (the
    importer's reading: the treadmill walk's file says it in prose only)."""
    from bench.moco_track import REFERENCE
    from solver.export.opensim.files import write_mot
    from solver.export.opensim.residuals import trial_folder
    from solver.io.opensim.storage import read_mot

    model, coordinates, grf = files[:3]
    xml = next((f for f in files[3:] if f.suffix.lower() == ".xml"), None)
    out = trial_folder(folder, model, coordinates, grf, xml)
    sto = read_mot(folder / "coordinates.mot")
    write_mot(folder / REFERENCE, "coordinates", sto.labels, sto.time, sto.data,
              in_degrees=bool(capture.source.get("angles_in_degrees", True)))
    return out


def run_moco(job: Mapping[str, Any], timeout: float = MOCO_TIMEOUT_S) -> dict:
    """MocoTrack on a prepared folder (``job``: ``folder``, ``t0``, ``t1``, ``mesh_interval`` and
    options of ``bench.moco_track``) in a child process: its answer with the child's CPU and
    wall seconds and the load average around it, ``status`` "succeeded" or "failed"; a child
    that fails or does not finish is recorded as ``status`` "error" / "timeout" with its message."""
    root = str(Path(__file__).resolve().parents[1])
    env = dict(os.environ)
    env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
    for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS"):
        env[name] = "1"  # one thread, as the tutors' BLAS
    with tempfile.TemporaryDirectory(prefix="motionx-bench-moco-") as scratch:
        answer = Path(scratch) / "answer.json"
        cwd = job["folder"] if Path(str(job.get("folder", ""))).is_dir() else scratch  # OpenSim's files there

        def child() -> subprocess.CompletedProcess | None:
            try:
                return subprocess.run([sys.executable, "-m", "bench.moco_track"], input=json.dumps(
                    {**job, "answer": str(answer)}), text=True, capture_output=True, env=env, cwd=cwd,
                    timeout=timeout)
            except subprocess.TimeoutExpired:
                return None

        proc, row = measured(child)
        row = {"cpu_s": row["cpu_s"], "wall_s": row["wall_s"], "load_before": row["load_before"],
               "load_after": row["load_after"]}
        if proc is None:
            return {**row, "status": "timeout", "message": f"MocoTrack did not finish within {timeout:.0f} s"}
        err = answer.with_suffix(".err")
        if proc.returncode != 0 or not answer.is_file():
            msg = err.read_text() if err.is_file() else (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
            if "No module named 'opensim'" in msg:
                msg = "the 'opensim' package is not installed (pip install opensim)"
            return {**row, "status": "error", "message": msg}
        ans = json.loads(answer.read_text())
        return {**row, **ans, "status": "succeeded" if ans.get("success") else "failed"}


def moco_job(folder: Path, t_start: float, period: float) -> dict:
    """MocoTrack's job over one cycle: [t_start, t_start + period] to the millisecond (with the
    guess from the reference, MocoTrack refuses a window its mesh ends a rounding error short of),
    one mesh interval per 1/``MESH_FPS`` s."""
    t0, t1 = round(t_start, 3), round(t_start + period, 3)
    n = max(1, round((t1 - t0) * MESH_FPS))
    return {"folder": str(folder), "t0": t0, "t1": t1, "mesh_interval": (t1 - t0) / n, "mesh_intervals": n,
            **MOCO_OPTIONS}


def trial_row(files: list[Path], opts: Mapping[str, Any]) -> dict:
    """One walk: the tutors, then MocoTrack over the full-body tutor's cycle, and the ratios."""
    from solver.gait import extract_cycle
    from solver.io import load_trial

    capture = load_trial(files, **opts)
    row: dict = {"motionx": {kind: tutor_row(capture, kind, fps) for kind, fps in CHARACTERS}}
    with tempfile.TemporaryDirectory(prefix="motionx-bench-moco-trial-") as d:
        try:
            cycle = row["motionx"]["fullbody"].get("cycle")
            if cycle is None:  # the full-body tutor failed: the cycle it would have stood for
                cyc, _ = extract_cycle(capture, dict(CHARACTERS)["fullbody"], start="auto")
                c = cyc.source.get("cycle") or {}
                cycle = {"t_start": c.get("t_start"), "period_s": c.get("period_s")}
            row["cycle"] = cycle
            row["moco_files"] = prepare(Path(d), files, capture)
            job = moco_job(Path(d), float(cycle["t_start"]), float(cycle["period_s"]))
            row["moco_job"] = {k: v for k, v in job.items() if k != "folder"}
            row["moco"] = run_moco(job)
        except Exception as e:  # recorded, never the bench's end
            row["moco"] = {"status": "error", "message": f"{type(e).__name__}: {e}"}
    row["ratio_moco_cpu_to_motionx_cpu"] = ratios(row)
    return row


def ratios(row: Mapping[str, Any]) -> dict[str, float | None]:
    """MocoTrack's CPU seconds over each tutor's, where both succeeded."""
    moco = row.get("moco") or {}
    moco_cpu = moco.get("cpu_s") if moco.get("status") == "succeeded" else None
    return {kind: (moco_cpu / r["cpu_s"] if moco_cpu and r.get("status") == "succeeded" and r.get("cpu_s") else None)
            for kind, r in (row.get("motionx") or {}).items()}


def run() -> dict:
    only = [t for t in os.environ.get("MOTIONX_BENCH_MOCO_TRIALS", "").split(",") if t]
    out: dict = {"machine": machine(), "load_average": [round(x, 2) for x in os.getloadavg()],
                 "moco_setup": {
                     "model": "the trial's model, locked joints welded, muscles removed (ModOpRemoveMuscles), a "
                              "CoordinateActuator on every other coordinate, the pelvis's too (ModOpAddReserves(250), "
                              "unbounded)",
                     "loads": "the trial's plates (ModOpAddExternalLoads), a plate under 20 N zeroed",
                     "reference": "the trial's coordinates low-passed at 6 Hz, speeds tracked too; MocoTrack's "
                                  "weights (states 1, control effort 0.001) and guess",
                     "solver": "MocoCasADiSolver, Hermite-Simpson, convergence tolerance 1e-2, limited-memory "
                               "Hessian, parallel 0, one BLAS thread",
                     "mesh": f"one interval per 1/{MESH_FPS:g} s of the full-body tutor's cycle"},
                 "trials": {}}
    for name, (files, opts) in shared_trials().items():
        if name not in TRIALS or (only and name not in only):
            continue
        try:
            out["trials"][name] = trial_row(files, opts)
        except Exception as e:  # a trial that cannot be loaded: recorded
            out["trials"][name] = {"error": f"{type(e).__name__}: {e}"}
    out["load_average_end"] = [round(x, 2) for x in os.getloadavg()]
    return out


def summary(results: Mapping[str, Any]) -> list[str]:
    """One line per trial: MocoTrack's and the tutors' CPU seconds (iterations) and the ratios."""
    lines = []
    for name, row in (results.get("trials") or {}).items():
        m = row.get("moco") or {}
        parts = [f"{name}: MocoTrack {m.get('status')} {_f(m.get('cpu_s'))} CPU-s ({m.get('iterations')} its)"]
        for kind, r in (row.get("motionx") or {}).items():
            ratio = (row.get("ratio_moco_cpu_to_motionx_cpu") or {}).get(kind)
            parts.append(f"{kind} {r.get('status')} {_f(r.get('cpu_s'))} CPU-s ({r.get('correct_iterations')} its), "
                         f"ratio {_f(ratio)}")
        lines.append("; ".join(parts))
    return lines


def _f(x: float | None) -> str:
    return "–" if x is None else f"{x:.1f}"


if __name__ == "__main__":  # python -m bench.moco: a run without writing results
    print("\n".join(summary(run())))
