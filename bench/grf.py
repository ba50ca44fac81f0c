"""Contact-force estimation throughput (issue: GRF estimation).

Frames per second of :func:`solver.contact.estimate_contact_wrenches` — central
differences, inverse dynamics, QP assembly and solve — on the shared trials' filtered
kinematics, as one clip and as the clip repeated end to end (a long recording: the
per-call overhead amortised), with the trial estimator's defaults (temporal prior on the
split at the 6 Hz cut-off, single-support CoPs kept in the feet: ``frames_per_s``) and as
one QP per frame, the thesis's form (``per_frame_frames_per_s``). Importing and filtering
are timed separately. The nested (thesis) form is timed on the double-support frames for
comparison (docs/method.md, Thesis figures: 20 frames/s).
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from bench.trials import best_time
from solver.contact import Status, estimate_capture, estimate_contact_wrenches, foot_schedule, lowpass_kinematics


def _data() -> Path:
    from tests.conftest import SHARED_DATA

    return SHARED_DATA


def _trials() -> dict:
    from solver.io.c3d import load_c3d
    from solver.io.opensim import load_opensim

    d = _data()
    tm = d / "opensim_gait2354_subject01_treadmill"
    lw = d / "opensim_loadedwalking_subject05"
    return {
        "treadmill_subject01": lambda: load_opensim(tm / "subject01.osim", tm / "subject01_walk1_ik.mot",
                                                    belt_speed="auto"),
        "overground_loadedwalking": lambda: load_opensim(
            lw / "Rajagopal2016_subject05_v30516.osim",
            lw / "loadedwalking_subject05_noload_free_trial03_ik_solution.mot"),
        "c3d_pig_flatfoot": lambda: load_c3d(d / "btk_pig_flatfoot_full" / "PiG_Motion-FlatFoot-Full.c3d"),
    }


def _tile(q: np.ndarray, fc: np.ndarray, reps: int) -> tuple[np.ndarray, np.ndarray]:
    """The clip played ``reps`` times end to end (root translation continued)."""
    step = q[:, -1] - q[:, 0] + (q[:, -1] - q[:, -2])
    qs = [q + k * step[:, None] for k in range(reps)]
    return np.concatenate(qs, axis=1), np.concatenate([fc] * reps, axis=1)


def run() -> dict:
    out: dict = {}
    for name, load in _trials().items():
        t = time.perf_counter()
        cap = load()
        t_import = time.perf_counter() - t
        tr = estimate_capture(cap, contacts="kinematics")  # warm-up (imports) and the schedule
        ch, fps = cap.character, cap.fps
        fc = foot_schedule(tr.contacts, ch)
        res: dict = {"character": ch.name, "coordinates": ch.n, "frames": cap.T, "import_s": round(t_import, 3)}
        res["filter_ms"] = 1e3 * best_time(lambda: lowpass_kinematics(ch, cap.q, fps), 5)
        opts = {"smoothing_hz": tr.estimate.smoothing_hz, "lateral_hz": tr.estimate.lateral_hz,
                "project_cop": True}  # estimate_capture's defaults
        t1 = best_time(lambda: estimate_contact_wrenches(ch, tr.q, fps, fc, **opts), 7)
        res["estimate_ms"] = 1e3 * t1
        res["frames_per_s"] = cap.T / t1
        t0 = best_time(lambda: estimate_contact_wrenches(ch, tr.q, fps, fc), 7)
        res["per_frame_estimate_ms"] = 1e3 * t0
        res["per_frame_frames_per_s"] = cap.T / t0
        est = estimate_contact_wrenches(ch, tr.q, fps, fc, **opts)
        res["double_support_frames"] = int(est.double_support.sum())
        res["qp_solved_frames"] = int(np.sum(est.status == Status.OPTIMAL))
        res["relaxed_frames"] = int(np.sum(est.status == Status.RELAXED))
        res["projected_frames"] = int(np.sum(est.status == Status.PROJECTED))
        reps = max(1, int(np.ceil(20000 / cap.T)))
        ql, fl = _tile(tr.q, fc, reps)
        tl = best_time(lambda: estimate_contact_wrenches(ch, ql, fps, fl, **opts), 3)
        res["long_frames"] = int(ql.shape[1])
        res["long_frames_per_s"] = ql.shape[1] / tl
        res["per_frame_long_frames_per_s"] = ql.shape[1] / best_time(
            lambda: estimate_contact_wrenches(ch, ql, fps, fl), 3)
        res["pipeline_frames_per_s"] = cap.T / best_time(lambda: estimate_capture(cap, contacts="kinematics"), 5)
        # the thesis's nested form, on a slice with double support
        ds = np.flatnonzero(est.double_support)
        a, b = max(ds[0] - 1, 0), min(ds[0] + 40, cap.T)
        tn = time.perf_counter()
        nested = estimate_contact_wrenches(ch, tr.q[:, a:b], fps, fc[:, a:b], method="nested")
        tn = time.perf_counter() - tn
        n_ds = int(nested.double_support.sum())
        res["nested_double_support_frames_per_s"] = n_ds / tn if n_ds else None
        out[name] = {k: (round(v, 3) if isinstance(v, float) else v) for k, v in res.items()}
    return out
