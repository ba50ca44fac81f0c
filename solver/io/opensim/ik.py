"""Markers (``.trc``) + a scaled model (``.osim``) -> coordinates, by OpenSim's inverse kinematics.

OpenSim users often have the markers and a scaled model, not the IK. The inverse kinematics
is OpenSim's own (``InverseKinematicsSolver``, what the InverseKinematicsTool runs; in the
child process of :mod:`solver.io.opensim.worker`): the model's joints — coupled knee
translations, patella-free splines, welded and locked joints, constraints — are evaluated
exactly by the software that defines them, which a re-implementation could only approximate
(docs/import.md compares the two on the shared treadmill trial).

Every model marker with data in the file takes part, weight 1 (OpenSim's default without an
IK task set) or ``weights`` (marker -> weight, e.g. the lab's IK task set). Gaps (NaN) weigh
0 where they are. ``reweight`` robust passes (default 0) then weigh each marker by the
inverse square of its RMS residual in the previous pass (floor 5 mm), so that markers that do
not move with their bone (skin, an acromion marker on a torso without shoulder joints) stop
pulling the skeleton. On the shared treadmill trial that brings the pelvis tilt and hip
flexion closer to the trial's own IK (7.4° -> 2.2° RMS) but the ground-reaction estimate
from the result gets worse (fy 11 % -> 25 %, CoP 3.5 -> 8.6 cm: fewer markers carry the
fit, the accelerations are noisier), hence off by default (docs/import.md).

The marker fit error is reported in ``capture.source["ik"]``: RMS and max over every marker
and frame (mm), RMS per marker, the weights used, markers of the file the model does not
have, model markers without data.
"""

from __future__ import annotations

from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from solver.io.opensim.base import OpenSimError

#: robust reweighting passes after the first (uniform or given weights) solve
DEFAULT_REWEIGHT = 0


def read_trc_header(path: str | Path) -> dict[str, str]:
    """The key/value line of a ``.trc`` header (DataRate, NumFrames, NumMarkers, Units, ...)."""
    p = Path(path)
    try:
        lines = p.read_text(errors="replace").splitlines()[:3]
    except OSError as e:
        raise OpenSimError(f"cannot read {p}: {e.strerror or e}") from None
    if len(lines) < 3 or not lines[0].startswith("PathFileType"):
        raise OpenSimError(f"{p}: not a .trc marker file (the first line must start with 'PathFileType')")
    keys, vals = lines[1].split("\t"), lines[2].split("\t")
    return {k.strip(): v.strip() for k, v in zip(keys, vals) if k.strip()}


def solve_ik(model: str | Path, trc: str | Path, *, weights: Mapping[str, float] | None = None,
             reweight: int | None = None, t0: float | None = None, t1: float | None = None
             ) -> tuple[dict[str, Any], dict[str, Any]]:
    """OpenSim's inverse kinematics of ``trc`` with ``model``, then the model evaluated along it.

    Returns the worker's result (as :func:`solver.io.opensim.worker.run_worker`, plus
    ``ik_times``, ``ik_q``) and the ``source`` entries describing the fit.
    """
    from solver.io.opensim.worker import run_worker  # lazy: the child-process launcher, only when OpenSim runs

    p = Path(trc)
    if not p.is_file():
        raise OpenSimError(f"marker file not found: {p}")
    head = read_trc_header(p)
    if weights is not None:
        bad = {k: v for k, v in weights.items() if not (isinstance(v, (int, float)) and np.isfinite(v) and v >= 0)}
        if bad:
            raise OpenSimError(f"marker weights must be finite and >= 0, got {bad}")
    n = DEFAULT_REWEIGHT if reweight is None else int(reweight)
    if not 0 <= n <= 10:
        raise OpenSimError(f"ik_reweight must be 0-10 passes, got {reweight}")
    res = run_worker(str(model), ik={"trc": str(p), "weights": dict(weights or {}), "reweight": n, "t0": t0, "t1": t1})
    # .trc times are often rounded (60 Hz written as 0.017, 0.033, ...): the header's rate
    # rebuilds them when every time is within a quarter sample of it
    t = np.asarray(res["ik_times"], dtype=float)
    try:
        rate = float(head.get("DataRate", "nan"))
    except ValueError:
        rate = float("nan")
    if np.isfinite(rate) and rate > 0 and t.size > 1:
        k = np.rint((t - t[0]) * rate)
        regular = t[0] + k / rate
        if np.array_equal(k, np.arange(t.size)) and np.max(np.abs(regular - t)) < 0.25 / rate:
            res["ik_times"] = regular
    err = np.asarray(res["ik_marker_error"], dtype=float)  # (T, markers) m
    names = list(res["ik_markers"])
    per = np.sqrt(np.nanmean(err**2, axis=0))
    info = {
        "trc": str(p.resolve()),
        "units": head.get("Units"),
        "frames": int(err.shape[0]),
        "markers": names,
        "weights": dict(zip(names, (round(float(w), 6) for w in res["ik_weights"]))),
        "reweight_passes": n,
        "marker_error_mm": {"rms": 1e3 * float(np.sqrt(np.nanmean(err**2))), "max": 1e3 * float(np.nanmax(err)),
                            "mean": 1e3 * float(np.nanmean(err))},
        "per_marker_rms_mm": {m: round(1e3 * float(v), 2) for m, v in zip(names, per)},
        "rms_per_pass_mm": [round(1e3 * v, 3) for v in res["ik_rms_per_pass_m"]],
        "file_markers_not_in_model": list(res["ik_unused_file_markers"]),
        "model_markers_without_data": list(res["ik_model_markers_without_data"]),
    }
    return res, {"ik": info, "motion_from": "inverse kinematics of the .trc (OpenSim)"}
