"""The residuals of OpenSim's InverseDynamicsTool on a folder, against Hicks et al. (2015)
(:func:`opensim_residuals`, :func:`residual_figures`), and those of a trial's own inverse
dynamics on its coordinates and force plates (:func:`capture_residuals`)."""

from __future__ import annotations

import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from solver.checks import Check
from solver.export.opensim.base import CAPTURE_LOWPASS_HZ, EXTERNAL_LOADS_FILE, SETUP_FILE, OpenSimExportError
from solver.export.opensim.child import run_child
from solver.export.opensim.files import external_loads_xml, id_setup_xml, repaired_model_text, write_mot

if TYPE_CHECKING:
    from solver.io.opensim.rig import OpenSimRig

#: a plate carrying less vertical force (N) than this is off in the trial's own check
PLATE_MIN_N = 20.0
#: Hicks et al. 2015, "Is my model good enough?" (J Biomech Eng 137(2)), Table 2: peak
#: residual force ≤ 5 % of the peak net external force; peak residual moment ≤ 1 % of
#: (centre-of-mass height × peak net external force)
HICKS_FORCE_FRACTION = 0.05
HICKS_MOMENT_FRACTION = 0.01


def _setup_fields(setup: Path) -> dict[str, str]:
    root = ET.parse(setup).getroot()
    tool = root.find("InverseDynamicsTool")
    if tool is None:
        raise OpenSimExportError(f"{setup}: not an InverseDynamicsTool setup")
    return {el.tag: (el.text or "").strip() for el in tool}


def _grf_in_range(folder: Path, fields: Mapping[str, str], t0: float, t1: float) -> tuple[np.ndarray, np.ndarray]:
    """The ground reactions an ExternalLoads file applies (net force (S, 3) and the foot
    forces' rows) over [t0, t1]."""
    from solver.io.opensim.external_loads import external_loads
    from solver.io.opensim.storage import read_mot

    xml = folder / fields["external_loads_file"]
    specs = external_loads(xml)
    datafile = (ET.parse(xml).getroot().findtext(".//datafile") or "").strip()
    sto = read_mot(xml.parent / datafile)
    keep = (sto.time >= t0 - 1e-9) & (sto.time <= t1 + 1e-9)
    F = np.zeros((int(keep.sum()), 3))
    for s in specs:
        F += np.stack([sto.column(s.force + c)[keep] for c in "xyz"], axis=1)
    return sto.time[keep], F


def residual_figures(labels: Sequence[str], data: np.ndarray, root_coordinates: Sequence[str],
                     net_force: np.ndarray, com_height: float) -> dict[str, Any]:
    """Hicks et al. (2015) figures from an inverse-dynamics table: peak and RMS of every root
    coordinate's generalised force, against 5 % of the peak net external force (forces) and
    1 % of centre-of-mass height × that force (moments)."""
    peak_ext = float(np.max(np.linalg.norm(net_force, axis=1))) if net_force.size else 0.0
    f_lim = HICKS_FORCE_FRACTION * peak_ext
    m_lim = HICKS_MOMENT_FRACTION * com_height * peak_ext
    forces, moments = {}, {}
    fvec = []
    for c in root_coordinates:
        lab_f, lab_m = f"{c}_force", f"{c}_moment"
        if lab_f in labels:
            col = data[:, list(labels).index(lab_f)]
            forces[c] = {"peak_N": float(np.max(np.abs(col))), "rms_N": float(np.sqrt(np.mean(col**2)))}
            fvec.append(col)
        elif lab_m in labels:
            col = data[:, list(labels).index(lab_m)]
            moments[c] = {"peak_Nm": float(np.max(np.abs(col))), "rms_Nm": float(np.sqrt(np.mean(col**2)))}
    peak_f = max((v["peak_N"] for v in forces.values()), default=float("nan"))
    peak_fvec = float(np.max(np.linalg.norm(np.stack(fvec, axis=1), axis=1))) if fvec else float("nan")
    peak_m = max((v["peak_Nm"] for v in moments.values()), default=float("nan"))
    source = "Hicks et al. 2015 (J Biomech Eng 137(2):020905), Table 2"
    checks = (
        Check.measure("hicks_force", None if np.isnan(peak_fvec) else peak_fvec, f_lim, "N",
                      "peak magnitude of the pelvis residual force vector, against 5 % of the peak net external force",
                      source=source),
        Check.measure("hicks_moment", None if np.isnan(peak_m) else peak_m, m_lim, "N·m",
                      "peak rotational pelvis generalised force, against 1 % of centre-of-mass height x the peak "
                      "net external force", source=source),
    )
    return {
        "forces": forces, "moments": moments,
        "peak_net_external_force_N": peak_ext, "com_height_m": com_height,
        "peak_residual_force_N": peak_f, "peak_residual_force_vector_N": peak_fvec,
        "peak_residual_moment_Nm": peak_m,
        "force_limit_N": f_lim, "moment_limit_Nm": m_lim,
        "force_percent_of_peak_external": 100.0 * peak_fvec / peak_ext if peak_ext else float("nan"),
        "moment_percent_of_com_height_x_peak_external": 100.0 * peak_m / (com_height * peak_ext)
        if peak_ext and com_height else float("nan"),
        "checks": {c.name: c.to_dict() for c in checks},
        "meets_hicks_2015": not any(c.failed for c in checks),
        "criteria": "Hicks et al. 2015 (J Biomech Eng 137(2):020905), Table 2: peak residual force <= 5 % of the "
                    "peak net external force (here the largest magnitude of the pelvis residual force vector); "
                    "peak residual moment <= 1 % of centre-of-mass height x peak net external force (each "
                    "rotational pelvis coordinate's generalised force)",
    }


def run_inverse_dynamics(folder: str | Path, setup: str = SETUP_FILE) -> dict[str, Any]:
    """OpenSim's InverseDynamicsTool on a folder's setup (child process): the generalised forces
    (``labels``, ``times``, ``data``), and at every row of the coordinates file the twists of the
    model's free root joint's coordinates (``twists`` (rows, 6, 6): ω, v at ground's origin),
    the whole-body centre of mass (``com``) and the model's mass."""
    setup_path = Path(folder).resolve() / setup
    if not setup_path.is_file():
        raise OpenSimExportError(f"no inverse-dynamics setup {setup_path}")
    ans = run_child({"job": "id", "setup": str(setup_path), "twists": True})
    ans["fields"] = _setup_fields(setup_path)
    return ans


def figures_of(folder: str | Path, ans: Mapping[str, Any]) -> dict[str, Any]:
    """:func:`residual_figures` of an inverse-dynamics run (:func:`run_inverse_dynamics`) on a
    folder: net external force from its ExternalLoads over the analysed rows, centre-of-mass
    height = its mean over those rows above the floor (the ground reactions' point height)."""
    folder = Path(folder).resolve()
    fields = ans["fields"]
    times = np.asarray(ans["times"], dtype=float)
    data = np.asarray(ans["data"], dtype=float)
    _, F = _grf_in_range(folder, fields, float(times[0]), float(times[-1]))
    tc = np.asarray(ans["twist_times"], dtype=float)
    keep = (tc >= times[0] - 1e-9) & (tc <= times[-1] + 1e-9)
    com_h = float(np.mean(np.asarray(ans["com"], dtype=float)[keep, 1]) - _floor_height(folder, fields))
    out = residual_figures(ans["labels"], data, ans["root_coordinates"], F, com_h)
    out.update({"time_range_s": [float(times[0]), float(times[-1])], "rows": int(times.size),
                "id_time_s": round(float(ans["time_s"]), 3), "model_mass_kg": float(ans["mass"]),
                "lowpass_hz": float(fields.get("lowpass_cutoff_frequency_for_coordinates") or -1)})
    return out


def opensim_residuals(folder: str | Path, setup: str = SETUP_FILE) -> dict[str, Any]:
    """OpenSim's InverseDynamicsTool run on a folder's setup as written (in a child process),
    and the residuals of the model's free root joint (the pelvis) against Hicks et al. (2015)
    (:func:`residual_figures`, :func:`figures_of`)."""
    return figures_of(folder, run_inverse_dynamics(folder, setup))


def _floor_height(folder: Path, fields: Mapping[str, str]) -> float:
    from solver.io.opensim.external_loads import external_loads
    from solver.io.opensim.storage import read_mot

    xml = folder / fields["external_loads_file"]
    specs = external_loads(xml)
    sto = read_mot(xml.parent / (ET.parse(xml).getroot().findtext(".//datafile") or "").strip())
    ys, ws = [], []
    for s in specs:
        fy = sto.column(s.force + "y")
        on = fy > 100.0
        ys.append(sto.column(s.point + "y")[on])
        ws.append(fy[on])
    y, w = np.concatenate(ys), np.concatenate(ws)
    return float(np.sum(y * w) / np.sum(w)) if w.size else 0.0


def trial_folder(folder: str | Path, model: str | Path, coordinates: str | Path, grf: str | Path,
                 external_loads: str | Path | None = None, *, feet: Mapping[str, str] | None = None) -> dict[str, Any]:
    """A trial's files written to ``folder`` as OpenSim's tools take them: ``model.osim`` (a 3.x
    model's socket paths repaired as for an export), ``coordinates.mot`` (coupled coordinates set by
    their CoordinateCouplerConstraint, :func:`~solver.export.opensim.child._child_couple`),
    ``grf.mot`` (a plate carrying less than ``PLATE_MIN_N`` vertically zeroed: force, point, torque,
    as force-plate thresholds do: its centre of pressure is meaningless, 33 km away in the
    loaded-walking trial's file, and would turn a few newtons of noise into kilonewton-metres) and
    ``EXTERNAL_LOADS_FILE`` applying it. Without an ExternalLoads file the GRF columns are told by
    their names (``ground_force_r_vx``…) and applied to ``feet`` (default ``calcn_r``, ``calcn_l``).
    Returns the coupled coordinates recomputed and the plate threshold (N)."""
    from solver.io.opensim.base import OpenSimError
    from solver.io.opensim.external_loads import external_loads as read_loads
    from solver.io.opensim.external_loads import guess_force_specs
    from solver.io.opensim.storage import read_mot

    folder = Path(folder)
    feet = dict(feet or {"right": "calcn_r", "left": "calcn_l"})
    try:
        sto = read_mot(grf)
        specs = read_loads(external_loads) if external_loads is not None else guess_force_specs(sto)
        cols = []
        for sp in specs:
            t_id = next((c for c in (sp.torque + "_", sp.torque) if sp.torque and all(
                c + a in sto.labels for a in "xyz")), "")
            cols.append((sp.side, sp.force, sp.point, t_id))
        text, _ = repaired_model_text(Path(model).read_bytes())
        (folder / "model.osim").write_bytes(text)
        coupled = run_child({"job": "couple", "model": str(folder / "model.osim"),
                             "coordinates": str(Path(coordinates).resolve()),
                             "out": str(folder / "coordinates.mot")})["coupled"]
        data = np.array(sto.data, copy=True)
        for _, f_id, p_id, t_id in cols:  # a plate under no load: its point is meaningless (far away)
            idx = [sto.labels.index(f_id + a) for a in "xyz"] + [sto.labels.index(p_id + a) for a in "xyz"]
            idx += [sto.labels.index(t_id + a) for a in "xyz"] if t_id else []
            off = sto.column(f_id + "y") < PLATE_MIN_N
            data[np.ix_(np.flatnonzero(off), np.asarray(idx, dtype=int))] = 0.0
        write_mot(folder / "grf.mot", "grf", sto.labels, sto.time, data, in_degrees=False)
        (folder / EXTERNAL_LOADS_FILE).write_text(external_loads_xml(feet, "grf.mot", cols))
    except OpenSimError as e:
        raise OpenSimExportError(str(e)) from None
    return {"coupled_coordinates_recomputed": coupled, "plates_below_N_zeroed": PLATE_MIN_N}


def capture_residuals(model: str | Path, coordinates: str | Path, grf: str | Path,
                      external_loads: str | Path | None = None, *, t0: float, t1: float,
                      lowpass: float = CAPTURE_LOWPASS_HZ, feet: Mapping[str, str] | None = None
                      ) -> dict[str, Any]:
    """The residuals of a trial's own inverse dynamics — its coordinates file and force plates on
    its model — by OpenSim's InverseDynamicsTool over [t0, t1] (s), coordinates low-passed at
    ``lowpass`` Hz as OpenSim's examples do (:func:`residual_figures`), on the trial's files in a
    scratch folder (:func:`trial_folder`: the model repaired, coupled coordinates set, plates
    under no load zeroed)."""
    from solver.io.opensim.base import OpenSimError

    with tempfile.TemporaryDirectory(prefix="motionx-osim-capture-") as d:
        folder = Path(d)
        prepared = trial_folder(folder, model, coordinates, grf, external_loads, feet=feet)
        (folder / SETUP_FILE).write_text(id_setup_xml("model.osim", "coordinates.mot", EXTERNAL_LOADS_FILE,
                                                      t0, t1, lowpass=lowpass))
        try:
            out = opensim_residuals(folder)
        except OpenSimError as e:
            raise OpenSimExportError(str(e)) from None
        out.update(prepared)
        return out


def _capture_reference(rig: OpenSimRig, model_path: Path, cycle: tuple[float, float],
                       rotational: Mapping[str, bool]) -> dict[str, Any]:
    """The trial's own residuals over the captured cycle where the plates are complete, when the
    trial's GRF file is still where it was imported from; otherwise why not (``rotational``:
    coordinate name -> whether OpenSim says it is a rotation)."""
    plates = rig.plates or {}
    grf = plates.get("grf")
    if not grf or not Path(grf).is_file():
        return {"available": False, "why": "the trial's force-plate file is not available" if grf else
                "the trial has no force plates"}
    xml = plates.get("external_loads")
    if xml and not Path(xml).is_file():
        return {"available": False, "why": "the trial's ExternalLoads file is not available"}
    t0, t1 = cycle[0], cycle[0] + cycle[1]
    span = plates.get("complete_s")
    if span:
        t0, t1 = max(t0, float(span[0])), min(t1, float(span[1]))
    if t1 - t0 < 0.2:
        return {"available": False, "why": "the plates do not cover the captured cycle"}
    with tempfile.TemporaryDirectory(prefix="motionx-osim-capture-") as d:
        names = list(rig.coordinate_names)
        values = np.array(rig.coordinates, dtype=float)
        rot = np.array([bool(rotational[n]) for n in names], dtype=bool)
        values[:, rot] = np.degrees(values[:, rot])
        mot = Path(d) / "capture_coordinates.mot"
        write_mot(mot, "Coordinates", names, rig.times, values, in_degrees=True)
        out = capture_residuals(model_path, mot, grf, xml, t0=t0, t1=t1, feet=rig.feet)
    out["available"] = True
    out["what"] = ("the trial's own coordinates and force plates on its model, OpenSim's InverseDynamicsTool, "
                   f"coordinates low-passed at {out['lowpass_hz']:g} Hz, over the captured cycle where every loaded "
                   "foot is on a plate")
    return out
