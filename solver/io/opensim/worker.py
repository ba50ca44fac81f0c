"""OpenSim in a short-lived child process: model evaluation and inverse kinematics.

The ``opensim`` wheel ships its own ``libcasadi.so.3.7`` with the same soname as CasADi's
but other symbols, so the two cannot live in one process (either import order fails).
:func:`run_worker` starts ``python -c "from solver.io.opensim.worker import main; main()"``,
sends a JSON request on stdin and reads numpy arrays back from an ``.npz`` file. Nothing
imported before ``opensim`` in the child may import CasADi.

Jobs (one child, in this order):

* ``ik`` (optional): OpenSim's inverse kinematics (``InverseKinematicsSolver``, what the
  InverseKinematicsTool runs) of a ``.trc`` against the model's marker set: every model
  marker with data in the file, weight 1 (OpenSim's default) or the weights given, the
  model's constraints enforced exactly, accuracy 1e-5; then ``reweight`` passes that weigh
  each marker by the inverse square of its RMS residual of the previous pass (floor 5 mm):
  markers that do not move with the bone they are attached to (skin, a shoulder marker on
  an arm-less torso) stop pulling the skeleton. Returns the coordinates (radians, metres)
  and each marker's error per frame, then evaluates them as below.
* ``evaluate``: body frames in ground for every frame of a coordinate trajectory
  (``initSystem``, coordinate values, ``realizePosition``, ``getTransformInGround``), joint
  child frames in ground, the default pose, body masses/centres of mass/inertias.

Models in the old 3.x format whose upgrade fails ``initSystem()`` (e.g.
``Rajagopal2016_subject05_v30516.osim``: joint sockets ``../pelvis``) are repaired in memory
(:func:`repair_model_xml`).
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import numpy as np

from solver.io.opensim.base import OpenSimError

WORKER_TIMEOUT_S = 300.0
#: residual floor (m) of the robust IK reweighting: markers fitting better than this weigh alike
IK_REWEIGHT_FLOOR_M = 0.005
IK_ACCURACY = 1e-5


def repair_model_xml(src: str, dst: str, *, keep_markers: bool = False) -> None:
    """Rewrite a 3.x-era model whose sockets name bodies as ``../body``: socket paths
    ``(../)+body`` become ``/bodyset/body``; forces, probes, contact geometry, controllers and
    components (irrelevant to kinematics and inertia) are dropped, markers too unless kept."""
    tree = ET.parse(src)
    root = tree.getroot()
    model = root.find("Model")
    if model is None:
        raise OpenSimError(f"{src}: no <Model> element")
    bodies = {b.get("name") for b in model.iter("Body")}
    drop = ["ForceSet", "ProbeSet", "ContactGeometrySet", "ControllerSet", "ComponentSet"]
    if not keep_markers:
        drop.append("MarkerSet")
    for tag in drop:
        el = model.find(tag)
        objs = el.find("objects") if el is not None else None
        if objs is not None:
            for c in list(objs):
                objs.remove(c)
    for el in model.iter():
        if el.tag.startswith("socket_") and el.tag.endswith("connectee_name") and el.text:
            m = re.fullmatch(r"(?:\.\./)+(\w+)", el.text.strip())
            if m:
                name = m.group(1)
                if name == "ground":
                    el.text = "/ground"
                elif name in bodies:
                    el.text = "/bodyset/" + name
    tree.write(dst)


# --- the child --------------------------------------------------------------------------------


def main() -> None:  # pragma: no cover - runs in the child process (exercised by every OpenSim test)
    """Child process entry: read the request on stdin, write ``out`` (.npz) or ``out.err``."""
    import opensim as osim  # first import of the process: its casadi wins

    osim.Logger.setLevelString("error")
    osim.Logger.removeFileSink()  # no opensim.log in the working directory
    req = json.loads(sys.stdin.read())
    out: dict[str, Any] = {}
    notes: list[str] = []
    arrays: dict[str, np.ndarray] = {}
    try:
        model, state = _load_model(osim, req["model"], notes, keep_markers=req.get("ik") is not None)
        if req.get("ik") is not None:
            times, cols, values = _inverse_kinematics(osim, model, state, req["ik"], out, arrays)
            req = {**req, "columns": cols, "values": values, "in_degrees": False}
            state = model.initSystem()
        _evaluate(osim, model, state, req, out, arrays, notes)
        np.savez(req["out"], meta=json.dumps(out), **arrays)  # type: ignore[arg-type]  # numpy stubs: **arrays
    except Exception as e:
        with open(req["out"] + ".err", "w") as f:
            f.write(str(e))
        sys.exit(3)


def _load_model(osim, path: str, notes: list[str], *, keep_markers: bool):  # pragma: no cover - child
    def load(p: str):
        m = osim.Model(p)
        return m, m.initSystem()

    try:
        return load(path)
    except Exception as first:
        fd, tmp = tempfile.mkstemp(suffix=".osim")
        os.close(fd)
        try:
            repair_model_xml(path, tmp, keep_markers=keep_markers)
            res = load(tmp)
        except Exception as second:
            raise RuntimeError(f"OpenSim cannot initialize the model: {first}; after repair: {second}") from None
        finally:
            os.unlink(tmp)
        notes.append("model repaired in memory (3.x socket paths -> /bodyset/...; forces"
                     + ("" if keep_markers else ", markers") + " dropped)")
        return res


def _inverse_kinematics(osim, model, state, ik: Mapping[str, Any], out: dict, arrays: dict):  # pragma: no cover
    ms = model.getMarkerSet()
    model_markers = [ms.get(i).getName() for i in range(ms.getSize())]
    if not model_markers:
        raise RuntimeError("the model has no markers (MarkerSet): inverse kinematics of a .trc needs the "
                           "model's marker set (a scaled model with its markers placed)")
    table = osim.TimeSeriesTableVec3(ik["trc"])
    trc_markers = list(table.getColumnLabels())
    used = [m for m in model_markers if m in trc_markers]
    if len(used) < 3:
        raise RuntimeError(f"only {len(used)} of the model's markers have data in {Path(ik['trc']).name} "
                           f"(model markers: {model_markers}; file markers: {trc_markers})")
    cs = model.getCoordinateSet()
    coords = [cs.get(i) for i in range(cs.getSize())]
    given = dict(ik.get("weights") or {})
    unknown = sorted(set(given) - set(used))
    if unknown:
        raise RuntimeError(f"marker weights given for {unknown}, which are not markers of both the model and "
                           f"the file (usable: {used})")
    base = {m: float(given.get(m, 1.0)) for m in used}
    weights = dict(base)
    t0, t1 = ik.get("t0"), ik.get("t1")

    def solve(w: Mapping[str, float]):
        ws = osim.SetMarkerWeights()
        for name, v in w.items():
            ws.cloneAndAppend(osim.MarkerWeight(name, v))
        mref = osim.MarkersReference(ik["trc"], ws)
        solver = osim.InverseKinematicsSolver(model, mref, osim.SimTKArrayCoordinateReference(), float("inf"))
        solver.setAccuracy(IK_ACCURACY)
        times = np.asarray(mref.getMarkerTable().getIndependentColumn(), dtype=float)
        keep = np.ones(times.size, bool)
        if t0 is not None:
            keep &= times >= t0 - 1e-9
        if t1 is not None:
            keep &= times <= t1 + 1e-9
        times = times[keep]
        if times.size < 2:
            raise RuntimeError(f"fewer than 2 marker frames in the time range {t0}-{t1} s")
        st = model.initSystem()
        st.setTime(float(times[0]))
        solver.assemble(st)
        names = [solver.getMarkerNameForIndex(i) for i in range(solver.getNumMarkersInUse())]
        q = np.zeros((times.size, len(coords)))
        err = np.full((times.size, len(names)), np.nan)
        e = osim.SimTKArrayDouble()
        for k, t in enumerate(times):
            st.setTime(float(t))
            solver.track(st)
            q[k] = [c.getValue(st) for c in coords]
            solver.computeCurrentMarkerErrors(e)
            err[k] = [e.getElt(i) for i in range(e.size())]
        return times, q, err, names

    passes = []
    times, q, err, names = solve(weights)
    passes.append(float(np.sqrt(np.nanmean(err**2))))
    for _ in range(int(ik.get("reweight", 0))):
        rms = np.sqrt(np.nanmean(err**2, axis=0))
        weights = {m: base[m] * float((IK_REWEIGHT_FLOOR_M / max(r, IK_REWEIGHT_FLOOR_M)) ** 2)
                   for m, r in zip(names, rms)}
        top = max(weights.values())
        weights = {m: v / top for m, v in weights.items()}
        times, q, err, names = solve(weights)
        passes.append(float(np.sqrt(np.nanmean(err**2))))
    out["ik_markers"] = names
    out["ik_weights"] = [weights[m] for m in names]
    out["ik_unused_file_markers"] = [m for m in trc_markers if m not in used]
    out["ik_model_markers_without_data"] = [m for m in model_markers if m not in used]
    out["ik_rms_per_pass_m"] = passes
    arrays["ik_times"] = times
    arrays["ik_q"] = q
    arrays["ik_marker_error"] = err
    return times, [c.getName() for c in coords], q.tolist()


def _evaluate(osim, model, state, req, out: dict, arrays: dict, notes: list[str]) -> None:  # pragma: no cover
    cs = model.getCoordinateSet()
    coords = [cs.get(i) for i in range(cs.getSize())]
    names = [c.getName() for c in coords]
    rot = [c.getMotionType() == osim.Coordinate.Rotational for c in coords]
    out["coord_names"] = names
    out["coord_rotational"] = rot
    out["coord_constrained"] = [bool(c.isConstrained(state)) or bool(c.getLocked(state)) for c in coords]
    out["coord_default"] = [c.getDefaultValue() for c in coords]
    bodies = [model.getBodySet().get(i) for i in range(model.getBodySet().getSize())]
    out["body_names"] = [b.getName() for b in bodies]
    out["body_mass"] = [b.getMass() for b in bodies]
    out["body_com"] = [list(b.getMassCenter().to_numpy()) for b in bodies]
    inert = []
    for b in bodies:
        i = b.getInertia()
        mo, pr = i.getMoments().to_numpy(), i.getProducts().to_numpy()
        inert.append([[mo[0], pr[0], pr[1]], [pr[0], mo[1], pr[2]], [pr[1], pr[2], mo[2]]])
    out["body_inertia"] = inert  # about the body's COM, body axes (OpenSim convention)
    joints = [model.getJointSet().get(i) for i in range(model.getJointSet().getSize())]
    out["joint_names"] = [j.getName() for j in joints]
    out["joint_child"] = [j.getChildFrame().findBaseFrame().getName() for j in joints]
    out["joint_parent"] = [j.getParentFrame().findBaseFrame().getName() for j in joints]
    values = np.asarray(req["values"], dtype=float).reshape(len(req["values"]), -1)  # (T, K)
    cols = req["columns"]
    known = [k for k, c in enumerate(cols) if c in names]  # the parent reports the others
    idx = [names.index(cols[k]) for k in known]
    values = values[:, known] if values.size else np.zeros((0, 0))
    deg = req.get("in_degrees")
    if deg is None:  # the header does not say: rotations beyond 2π can only be degrees
        rot_cols = [j for j, c_i in enumerate(idx) if rot[c_i]]
        deg = bool(rot_cols) and float(np.abs(values[:, rot_cols]).max()) > 2 * np.pi
        notes.append(f"angle unit not stated in the header: {'degrees' if deg else 'radians'} "
                     "inferred from the values")
    out["in_degrees"] = bool(deg)
    if deg:
        for j, c_i in enumerate(idx):
            if rot[c_i]:
                values[:, j] = np.radians(values[:, j])
    T = values.shape[0]
    B, J = len(bodies), len(joints)
    R = np.zeros((T, B, 3, 3))
    P = np.zeros((T, B, 3))
    JC = np.zeros((T, J, 3))
    for k in range(T):
        for c_i, v in zip(idx, values[k]):
            coords[c_i].setValue(state, float(v), False)
        model.realizePosition(state)
        for b_i, b in enumerate(bodies):
            tr = b.getTransformInGround(state)
            R[k, b_i] = _mat33(tr.R())
            P[k, b_i] = tr.p().to_numpy()
        for j_i, j in enumerate(joints):
            JC[k, j_i] = j.getChildFrame().getPositionInGround(state).to_numpy()
    # default pose (composite inertias, offsets)
    st0 = model.initializeState()
    R0, P0 = np.zeros((B, 3, 3)), np.zeros((B, 3))
    model.realizePosition(st0)
    for b_i, b in enumerate(bodies):
        tr = b.getTransformInGround(st0)
        R0[b_i] = _mat33(tr.R())
        P0[b_i] = tr.p().to_numpy()
    out["model_name"] = model.getName()
    out["total_mass"] = model.getTotalMass(state)
    out["notes"] = notes
    arrays.update(R=R, P=P, JC=JC, R0=R0, P0=P0)


def _mat33(rot) -> np.ndarray:  # pragma: no cover - child process
    return np.array([[rot.get(i, j) for j in range(3)] for i in range(3)])


# --- the parent -------------------------------------------------------------------------------


#: the parts of OpenSim's and Simbody's C++ exception texts that name their own code, not the file
_INTERNALS = (r"std::exception in '[^']*':\s*", r"SimTK Exception thrown at [\w./]+:\d+:\s*",
              r"Error detected by Simbody method [\w:~]+\(\):\s*", r"\(Required condition '[^']*' was not met\.\)",
              r"\s*(?:Thrown at|In) [\w./]+\.(?:cpp|h):\d+(?: in '?[^'\n]*'?)?\.?")


def readable(msg: str) -> str:
    """The child's error as a reader's message: what the C++ exception says about the file,
    without the source files, line numbers and method names of OpenSim's code; a message
    that still names them is replaced by a sentence that does not."""
    for pat in _INTERNALS:
        msg = re.sub(pat, " ", msg)
    msg = re.sub(r"\s+", " ", msg).strip()
    if re.search(r"\.(?:cpp|h):\d+|\w::\w", msg) or not msg:
        return "OpenSim refused the file (not a valid OpenSim model or motion)"
    return msg


def run_worker(model_path: str, columns: Sequence[str] = (), values: np.ndarray | None = None,
               in_degrees: bool | None = None, *, ik: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Evaluate ``model_path`` along ``values`` (T, K) of ``columns`` — or, with ``ik``
    (``{"trc": path, "weights": {...}, "reweight": n, "t0": s, "t1": s}``), along the
    inverse kinematics of a ``.trc`` — in a child process; returns plain arrays and metadata."""
    what = "solve the inverse kinematics of" if ik is not None else "evaluate"
    with tempfile.TemporaryDirectory(prefix="motionx-osim-") as d:
        out = os.path.join(d, "result.npz")
        vals = np.zeros((0, 0)) if values is None else np.asarray(values, dtype=float)
        req = {"model": str(Path(model_path).resolve()), "columns": list(columns), "values": vals.tolist(),
               "in_degrees": in_degrees, "out": out,
               "ik": None if ik is None else {**ik, "trc": str(Path(ik["trc"]).resolve())}}
        root = str(Path(__file__).resolve().parents[3])
        env = dict(os.environ)
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        code = "from solver.io.opensim.worker import main; main()"
        try:
            proc = subprocess.run([sys.executable, "-c", code], input=json.dumps(req), text=True,
                                  capture_output=True, env=env, timeout=WORKER_TIMEOUT_S)
        except subprocess.TimeoutExpired:
            raise OpenSimError(f"OpenSim did not {what} {model_path} within {WORKER_TIMEOUT_S:.0f} s") from None
        if proc.returncode != 0:
            err = Path(out + ".err")
            msg = err.read_text() if err.exists() else (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
            if "No module named 'opensim'" in proc.stderr:
                msg = "the 'opensim' package is not installed (pip install opensim)"
            raise OpenSimError(f"OpenSim could not {what} {model_path}: {readable(msg)}")
        with np.load(out) as z:
            res: dict[str, Any] = {k: z[k] for k in z.files if k != "meta"}
            res.update(json.loads(str(z["meta"])))
    return res
