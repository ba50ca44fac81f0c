"""The OpenSim export's folder: :func:`write_opensim` writes the model, its coordinates, the
ground reactions, ExternalLoads, the inverse-dynamics setup, ``summary.json`` and ``README.md``
(:func:`readme`); :func:`to_opensim` returns that folder as a zip archive."""

from __future__ import annotations

import io
import json
import math
import tempfile
import time
import zipfile
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from solver.export.opensim.base import (
    CAPTURE_LOWPASS_HZ,
    COORDINATES_FILE,
    CYCLES,
    EXTERNAL_LOADS_FILE,
    GRF_FILE,
    ID_OUTPUT_FILE,
    LOWPASS_HZ,
    RATE_HZ,
    README_FILE,
    SETUP_FILE,
    SUMMARY_FILE,
    OpenSimExportError,
    _cycle,
    exportable,
    source_rig,
)
from solver.export.opensim.calibration import OpenSimCalibration, trunk_parts, virtual_markers
from solver.export.opensim.child import run_child
from solver.export.opensim.files import (
    external_loads_xml,
    id_setup_xml,
    repaired_model_text,
    with_gravity,
    write_mot,
    write_trc,
)
from solver.export.opensim.generic import generic_rig
from solver.export.opensim.ground import (
    FOOT_HALF_WIDTH_M,
    GRF_LABELS,
    LARGE_COP_SHIFT_MM,
    MIN_LOAD_FRACTION,
    _adjustment_figures,
    _grf_table,
    cop_outside_feet,
    footprints,
    grf_columns,
    reduce_residuals_on_feet,
    wrenches_to_input,
)
from solver.export.opensim.residuals import _capture_reference, figures_of, opensim_residuals, run_inverse_dynamics
from solver.export.opensim.sampling import cycle_samples, export_frame
from solver.motion import Motion


def write_opensim(motion: Motion, folder: str | Path, *, cycles: int = CYCLES, rate: float = RATE_HZ,
                  lowpass: float | None = LOWPASS_HZ, reduce_residuals: bool = True,
                  model: str = "source") -> dict[str, Any]:
    """Write ``motion`` on its source OpenSim model into ``folder`` (created; see
    :mod:`solver.export.opensim` for every file) and return the summary (also ``summary.json``):
    files, sampling, the inverse-kinematics fit, the residuals of OpenSim's InverseDynamicsTool on
    the files as written (and, with ``reduce_residuals``, before the ground reactions were
    adjusted, with the adjustment's size)."""
    from solver.io.opensim.base import OpenSimError
    from solver.io.opensim.rig import unpack_model

    t_begin = time.perf_counter()
    if model not in ("source", "generic"):
        raise OpenSimExportError(f"model must be 'source' (the trial's own OpenSim model) or 'generic' (gait2354 "
                                 f"scaled to the motion's character), got {model!r}")
    if model == "generic":
        from solver.io.opensim.base import OpenSimError as _OpenSimError

        exportable(motion)
        try:
            with tempfile.TemporaryDirectory(prefix="motionx-osim-generic-") as scratch:
                generic = generic_rig(motion, scratch)
        except _OpenSimError as e:
            raise OpenSimExportError(str(e)) from None
        # written in OpenSim's own axes: the source's ground frame (BVH's y up, centimetres…) is not the model's
        motion = motion.evolve(context=motion.context.with_(rig=generic, frame=generic.frame))
    rig = source_rig(motion)
    if not (isinstance(cycles, int) and not isinstance(cycles, bool) and 1 <= cycles <= 10):
        raise OpenSimExportError(f"cycles must be an integer from 1 to 10, got {cycles!r}")
    if not (isinstance(rate, (int, float)) and math.isfinite(rate) and 10.0 <= rate <= 1000.0):
        raise OpenSimExportError(f"rate must be 10-1000 Hz, got {rate!r}")
    if lowpass is not None and not (isinstance(lowpass, (int, float)) and not isinstance(lowpass, bool)
                                    and math.isfinite(lowpass) and 0.0 < lowpass <= 0.5 * rate):
        raise OpenSimExportError(f"lowpass must be None (no filter) or a cut-off in (0, rate/2] Hz, got {lowpass!r}")
    if not isinstance(reduce_residuals, bool):
        raise OpenSimExportError(f"reduce_residuals must be true or false, got {reduce_residuals!r}")
    folder = Path(folder).resolve()
    folder.mkdir(parents=True, exist_ok=True)
    model_info = rig.model
    text, repaired = repaired_model_text(unpack_model(model_info["osim_xz_b64"]))
    model_file = Path(str(model_info.get("file") or "model.osim")).name
    if not model_file.endswith(".osim"):
        model_file += ".osim"
    frame, gravity = export_frame(motion)
    text, model_gravity = with_gravity(text, gravity)
    (folder / model_file).write_bytes(text)
    timing: dict[str, float] = {}
    try:
        # the model's bodies along the captured trial, then against our segments (the rig's calibration)
        tk = time.perf_counter()
        cal = rig.calibrated(motion).calibration
        assert isinstance(cal, OpenSimCalibration) and cal.model is not None  # the format's calibration (fitted)
        model_ev = cal.model
        timing["evaluate_capture_s"] = time.perf_counter() - tk
        cyc = motion.context.cycle
        assert cyc is not None and cyc.t_start is not None  # exportable
        torso, parts = trunk_parts(rig, motion.character)
        t, q, w, D = cycle_samples(motion, cycles, float(rate))
        W, P = cal.pose(motion, rig, t, q, D)
        defs, xyz = virtual_markers(list(rig.bodies), model_ev.body_com, W, P)
        with tempfile.TemporaryDirectory(prefix="motionx-osim-ik-") as scratch:
            trc = Path(scratch) / "virtual_markers.trc"
            write_trc(trc, [m[0] for m in defs], t, xyz, float(rate))
            tk = time.perf_counter()
            ik = run_child({"job": "ik", "model": str(folder / model_file), "markers": defs, "xyz": xyz.tolist(),
                            "weights": {},  # every virtual marker weighs 1 (OpenSim's default)
                            "trc": str(trc), "t0": float(t[0]), "t1": float(t[-1]),
                            "out": str((folder / COORDINATES_FILE).resolve()), "scratch": scratch})
            timing["inverse_kinematics_s"] = time.perf_counter() - tk
        # ground reactions in the model's ground frame, on the motion's ground plane there
        t_abs = cyc.t_start + t
        # the motion stands its contact points on z = 0, the capture's soles were that much lower:
        # the floor (the trial's plates) is z = -shift in the motion's world
        m_frame, c_frame = motion.frame, rig.frame
        shift = float((m_frame.R.T @ (m_frame.offset - c_frame.offset))[2]) * m_frame.unit_m
        normal = frame.R @ np.array([0.0, 0.0, 1.0])
        origin = frame.point_to_input(np.tile([0.0, 0.0, -shift], (t.size, 1)), t_abs)
        min_load = MIN_LOAD_FRACTION * float(np.linalg.norm(gravity)) * motion.character.total_mass
        w_in = wrenches_to_input(w, t_abs, frame)
        naive = grf_columns(w_in, normal, origin, min_load)
        write_mot(folder / GRF_FILE, "grf", GRF_LABELS, t, _grf_table(naive), in_degrees=False)
        (folder / EXTERNAL_LOADS_FILE).write_text(external_loads_xml(rig.feet, GRF_FILE))
        window = (D, 2 * D) if cycles >= 3 else (float(t[0]), float(t[-1]))
        (folder / SETUP_FILE).write_text(id_setup_xml(model_file, COORDINATES_FILE, EXTERNAL_LOADS_FILE, *window,
                                                      lowpass=lowpass))
        residuals: dict[str, Any] = {}
        adjustment: dict[str, Any] | None = None
        cols = naive
        if reduce_residuals:
            # OpenSim's ID over every row (the naive loads), then the wrench it still needs, on the feet
            full = "setup_id_all_rows.xml"
            (folder / full).write_text(id_setup_xml(model_file, COORDINATES_FILE, EXTERNAL_LOADS_FILE,
                                                    float(t[0]), float(t[-1]), lowpass=lowpass,
                                                    output="inverse_dynamics_all.sto"))
            tk = time.perf_counter()
            ans = run_inverse_dynamics(folder, full)
            timing["inverse_dynamics_naive_s"] = time.perf_counter() - tk
            for name in (full, "inverse_dynamics_all.sto"):
                (folder / name).unlink(missing_ok=True)
            keep = (np.asarray(ans["times"]) >= window[0] - 1e-9) & (np.asarray(ans["times"]) <= window[1] + 1e-9)
            residuals["before_reduction"] = figures_of(folder, {**ans, "times": np.asarray(ans["times"])[keep],
                                                                "data": np.asarray(ans["data"])[keep]})
            w_new, added = reduce_residuals_on_feet(w_in, ans, t, min_load)
            cols = grf_columns(w_new, normal, origin, min_load)
            write_mot(folder / GRF_FILE, "grf", GRF_LABELS, t, _grf_table(cols), in_degrees=False)
            inside = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
            prints = footprints(list(rig.bodies), model_ev.body_com, W, P, rig.feet)
            out_before = cop_outside_feet(naive, prints, inside, min_load)
            out_after = cop_outside_feet(cols, prints, inside, min_load)
            per_foot = _adjustment_figures(naive, cols, t, window, min_load)
            weight = float(np.linalg.norm(gravity)) * motion.character.total_mass
            large = [side for side, v in per_foot.items()
                     if v["cop_shift_mm"]["max"] > LARGE_COP_SHIFT_MM or v["force_change_N"]["max"] > 0.1 * weight]
            adjustment = {"per_foot": per_foot,
                          "large": bool(large),
                          "note": (f"the ground reaction of the {' and '.join(large)} foot moved by more than "
                                   f"{LARGE_COP_SHIFT_MM:g} mm or 10 % of the body weight: this model cannot follow "
                                   "the motion's character closely (its joints, or trunk segments the character "
                                   "moves and the model holds rigid); the files balance on the model but the "
                                   "adjusted ground reactions are not the motion's") if large else None,
                          "cop_outside_footprint_mm": {
                              side: {"before": 1e3 * out_before[f], "after": 1e3 * out_after[f]}
                              for f, side in enumerate(("right", "left"))},
                          "footprint": f"heel-to-toe line widened by {1e3 * FOOT_HALF_WIDTH_M:g} mm each side",
                          "added_force_N": {"max": float(np.linalg.norm(added[inside, 3:], axis=1).max()),
                                            "rms": float(np.sqrt(np.mean(np.sum(added[inside, 3:]**2, axis=1))))}}
        tk = time.perf_counter()
        residuals["as_written"] = opensim_residuals(folder)
        timing["inverse_dynamics_s"] = time.perf_counter() - tk
        other = CAPTURE_LOWPASS_HZ if lowpass is None else None  # the same files under the other filter choice
        extra = "setup_id_other_filter.xml"
        (folder / extra).write_text(id_setup_xml(model_file, COORDINATES_FILE, EXTERNAL_LOADS_FILE, *window,
                                                 lowpass=other, output="inverse_dynamics_other_filter.sto"))
        try:
            residuals["as_written_other_filter"] = opensim_residuals(folder, extra)
        finally:
            for name in (extra, "inverse_dynamics_other_filter.sto"):
                (folder / name).unlink(missing_ok=True)
        for name in (ID_OUTPUT_FILE, "opensim.log"):  # outputs of running the setup, not part of the export
            (folder / name).unlink(missing_ok=True)
        tk = time.perf_counter()
        reference = _capture_reference(rig, folder / model_file, _cycle(motion), dict(model_ev.coordinates))
        timing["capture_inverse_dynamics_s"] = time.perf_counter() - tk
    except OpenSimError as e:
        raise OpenSimExportError(str(e)) from None
    timing["total_s"] = time.perf_counter() - t_begin
    translational = {n for n, r in model_ev.coordinates.items() if not r}
    ik_rms = np.asarray(ik["marker_rms_m"], dtype=float)
    ik_max = np.asarray(ik["marker_max_m"], dtype=float)
    summary = {
        "format": "motionx.opensim-export",
        "version": 1,
        "motion": {"step": motion.provenance.get("step"), "lambda": motion.provenance.get("lambda"),
                   "character": motion.character.name, "fps": motion.fps, "frames": motion.T,
                   "cycle_s": D, "source_cycle": cyc.to_dict()},
        "model": {"file": model_file, "name": model_info.get("name"), "sha256_source": model_info.get("sha256"),
                  "socket_paths_repaired": repaired, "gravity_changed": model_gravity,
                  "generic": rig.generic},
        "files": {"model": model_file, "coordinates": COORDINATES_FILE, "ground_reactions": GRF_FILE,
                  "external_loads": EXTERNAL_LOADS_FILE, "inverse_dynamics_setup": SETUP_FILE},
        "sampling": {"rate_hz": float(rate), "cycles": cycles, "rows": int(t.size),
                     "time_s": [float(t[0]), float(t[-1])], "analysed_cycle_s": list(window),
                     "interpolation": motion.interpolation},
        "ground_frame": {"axes": "OpenSim ground: x forward, y up, z right",
                         "ground_normal": normal.round(9).tolist(), "ground_point_m": origin[0].round(6).tolist(),
                         "contact_plane_shift_m": shift, "gravity_m_s2": gravity.round(6).tolist(),
                         "belt_velocity_m_s": frame.vector_to_input(frame.velocity).tolist(),
                         "feet": dict(rig.feet)},
        "inverse_kinematics": {"tool": "OpenSim InverseKinematicsTool", "virtual_markers": len(defs),
                               "bodies_marked": sorted({m[1] for m in defs}),
                               "anchors": {**dict(cal.bodies.anchors),
                                           **({torso: "+".join(p for p, _ in parts)} if torso is not None else {})},
                               "calibration": {"harmonics": cal.bodies.harmonics,
                                               "smoothing_rms_deg": cal.bodies.fit_rms_deg,
                                               "smoothing_rms_mm": cal.bodies.fit_rms_mm},
                               "marker_rms_mm": {"mean": 1e3 * float(ik_rms.mean()), "max": 1e3 * float(ik_rms.max())},
                               "marker_max_mm": 1e3 * float(ik_max.max()),
                               "refinement_iterations_max": ik.get("refine_iterations_max"),
                               "refinement_last_step_max": ik.get("refine_last_step_max"),
                               "coordinates_outside_model_range_deg_or_m": {
                                   n: round(float(np.degrees(v)) if n not in translational else float(v), 4)
                                   for n, v in ik["outside_range"].items()},
                               "worst_markers_rms_mm": {n: round(1e3 * v, 2) for n, v in sorted(
                                   ik["per_marker_rms_m"].items(), key=lambda kv: -kv[1])[:5]}},
        "residual_reduction": adjustment,
        "residuals": residuals,
        "capture_residuals": reference,
        "opensim_version": _opensim_version(),
        "timing_s": {k: round(v, 3) for k, v in timing.items()},
    }
    (folder / SUMMARY_FILE).write_text(json.dumps(summary, indent=1, default=float) + "\n")
    (folder / README_FILE).write_text(readme(summary))
    return summary


def _opensim_version() -> str | None:
    try:
        from importlib.metadata import version

        return version("opensim")
    except Exception:
        return None


def readme(summary: Mapping[str, Any]) -> str:
    """The folder's README: what the files are and what OpenSim's inverse dynamics says of them."""
    res = summary["residuals"]["as_written"]
    before = summary["residuals"].get("before_reduction")
    f = summary["files"]
    repaired = " (3.x socket paths rewritten to /bodyset/...)" if summary["model"]["socket_paths_repaired"] else ""
    filt = ("coordinates not filtered (samples of a smooth motion)" if res["lowpass_hz"] <= 0 else
            f"coordinates low-passed at {res['lowpass_hz']:g} Hz")
    lines = [
        "# A motionx motion on your OpenSim model", "",
        f"Motion: {summary['motion']['step']} (λ = {summary['motion']['lambda']}), character "
        f"{summary['motion']['character']}, gait cycle {summary['motion']['cycle_s']:.3f} s; model "
        f"`{f['model']}`.", "",
        "| file | content |", "|---|---|",
        f"| `{f['model']}` | the trial's model{repaired} |",
        f"| `{f['coordinates']}` | the model's coordinates (degrees, metres), {summary['sampling']['cycles']} gait "
        f"cycles at {summary['sampling']['rate_hz']:g} Hz, by OpenSim's InverseKinematicsTool (refined) |",
        f"| `{f['ground_reactions']}` | ground reactions per foot: force (N), centre of pressure on the floor (m), "
        "free moment (N·m), OpenSim ground (x forward, y up, z right) |",
        f"| `{f['external_loads']}` | the forces applied to {', '.join(summary['ground_frame']['feet'].values())} |",
        f"| `{f['inverse_dynamics_setup']}` | OpenSim's InverseDynamicsTool on these files, {filt}, over the middle "
        f"cycle {res['time_range_s'][0]:.3f}-{res['time_range_s'][1]:.3f} s |",
        "| `summary.json` | everything below, and more |", "",
        "Run the inverse dynamics yourself: `opensim-cmd run-tool setup_id.xml` (in this folder), or",
        "`opensim.InverseDynamicsTool('setup_id.xml').run()` from Python.", "",
        "## Residuals (OpenSim's InverseDynamicsTool on these files)", "",
        "Hicks et al. 2015: peak residual force <= 5 % of the peak net external force, peak residual moment",
        "<= 1 % of centre-of-mass height x peak net external force.", "",
        "| | peak residual force (N) | limit (N) | peak residual moment (N·m) | limit (N·m) | meets |",
        "|---|---|---|---|---|---|",
    ]
    other = summary["residuals"].get("as_written_other_filter")
    rows: list[tuple[str, Mapping[str, Any]]] = [("before ground-reaction adjustment", before)] if before else []
    rows.append(("as written", res))
    if other:
        rows.append(("as written, " + ("not filtered" if other["lowpass_hz"] <= 0 else
                                       f"coordinates low-passed at {other['lowpass_hz']:g} Hz"), other))
    cap = summary.get("capture_residuals") or {}
    if cap.get("available"):
        rows.append((f"the trial's own IK and plates ({cap['time_range_s'][0]:.2f}-{cap['time_range_s'][1]:.2f} s, "
                     f"{cap['lowpass_hz']:g} Hz)", cap))
    for name, r in rows:
        lines.append(f"| {name} | {r['peak_residual_force_vector_N']:.2f} | {r['force_limit_N']:.1f} | "
                     f"{r['peak_residual_moment_Nm']:.2f} | {r['moment_limit_Nm']:.2f} | "
                     f"{'yes' if r['meets_hicks_2015'] else 'no'} |")
    adj = summary.get("residual_reduction")
    if adj:
        lines += ["", "The ground reactions were adjusted by the external wrench OpenSim's inverse dynamics still",
                  "needed on this model (its arms, trunk and joints are not those of the motion's character);",
                  "by at most: " + "; ".join(
                      f"{side} foot {v['force_change_N']['max']:.1f} N, centre of pressure "
                      f"{v['cop_shift_mm']['max']:.1f} mm, free moment {v['free_moment_change_Nm']['max']:.2f} N·m"
                      for side, v in adj["per_foot"].items()) + "."]
        if adj.get("note"):
            lines += ["", "**Large adjustment**: " + adj["note"] + "."]
    return "\n".join(lines) + "\n"


def to_opensim(motion: Motion, *, cycles: int = CYCLES, rate: float = RATE_HZ, lowpass: float | None = LOWPASS_HZ,
               reduce_residuals: bool = True, model: str = "source") -> bytes:
    """The folder :func:`write_opensim` writes, as a zip archive (``export_motion(motion,
    "opensim")``; with ``path=DIR`` it is unpacked into DIR)."""
    with tempfile.TemporaryDirectory(prefix="motionx-osim-export-") as d:
        write_opensim(motion, d, cycles=cycles, rate=rate, lowpass=lowpass, reduce_residuals=reduce_residuals,
                      model=model)
        buf = io.BytesIO()
        with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as z:
            for p in sorted(Path(d).iterdir()):
                if p.is_file():
                    z.write(p, p.name)
        return buf.getvalue()
