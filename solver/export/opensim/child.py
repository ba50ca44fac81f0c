"""OpenSim in a child process (CasADi and OpenSim cannot share one: see
:mod:`solver.io.opensim.worker`). :func:`run_child` runs one job there and returns its answer;
:func:`child_main` is the child's entry point, running the jobs: OpenSim's inverse kinematics on
virtual markers refined by Gauss–Newton (``ik``), its inverse dynamics with the twists of the
model's free root joint (``id``), coupled coordinates set by their constraints (``couple``), a
model scaled (``scale``) or given new masses (``masses``)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from solver.export.opensim.base import OpenSimExportError

CHILD_TIMEOUT_S = 600.0


def run_child(job: Mapping[str, Any]) -> dict[str, Any]:
    """Run one OpenSim job (:func:`child_main`) in a child process; its JSON answer."""
    from solver.io.opensim.worker import readable  # the worker's message cleaning

    with tempfile.TemporaryDirectory(prefix="motionx-osim-export-") as d:
        out = os.path.join(d, "answer.json")
        root = str(Path(__file__).resolve().parents[3])
        env = dict(os.environ)
        env["PYTHONPATH"] = root + (os.pathsep + env["PYTHONPATH"] if env.get("PYTHONPATH") else "")
        code = "from solver.export.opensim.child import child_main; child_main()"
        try:
            proc = subprocess.run([sys.executable, "-c", code], input=json.dumps({**job, "answer": out}), text=True,
                                  capture_output=True, env=env, timeout=CHILD_TIMEOUT_S, cwd=d)  # OpenSim's log there
        except subprocess.TimeoutExpired:
            raise OpenSimExportError(f"OpenSim's {job['job']} did not finish within {CHILD_TIMEOUT_S:.0f} s") from None
        if proc.returncode != 0:
            err = Path(out + ".err")
            msg = err.read_text() if err.exists() else (proc.stderr.strip().splitlines() or ["(no message)"])[-1]
            if "No module named 'opensim'" in proc.stderr:
                msg = "the 'opensim' package is not installed (pip install opensim)"
            raise OpenSimExportError(f"OpenSim's {job['job']} failed: {readable(msg)}")
        return dict(json.loads(Path(out).read_text()))


def child_main() -> None:  # pragma: no cover - runs in the child process (exercised by every export test)
    """Child entry: a JSON job on stdin (``ik``, ``id``, ``couple``, ``scale``, ``masses``), its answer as JSON."""
    import opensim as osim  # first heavy import of the process: OpenSim's casadi wins

    osim.Logger.setLevelString("error")
    osim.Logger.removeFileSink()  # no opensim.log in the working directory
    job = json.loads(sys.stdin.read())
    try:
        answer = {"ik": _child_ik, "id": _child_id, "couple": _child_couple, "scale": _child_scale,
                  "masses": _child_masses}[job["job"]](osim, job)
        Path(job["answer"]).write_text(json.dumps(answer))
    except Exception as e:
        Path(job["answer"] + ".err").write_text(str(e))
        sys.exit(3)


def _child_ik(osim, job):  # pragma: no cover - child
    """OpenSim's InverseKinematicsTool on virtual markers added to a scratch copy of the model,
    its solution refined to the optimum of the same weighted marker cost (:func:`_refine`), the
    coordinates file written with the tool's own header."""
    model = osim.Model(job["model"])
    for name, body, local in job["markers"]:
        model.addMarker(osim.Marker(name, model.getBodySet().get(body), osim.Vec3(*local)))
    cs = model.getCoordinateSet()
    for i in range(cs.getSize()):  # the motion's pose, even where it leaves a coordinate's range
        cs.get(i).set_clamped(False)
    model.finalizeConnections()
    scratch = job["scratch"]
    marked = os.path.join(scratch, "model_with_virtual_markers.osim")
    model.printToXML(marked)
    weights = {name: float(job["weights"].get(name, 1.0)) for name, _, _ in job["markers"]}
    tasks = osim.IKTaskSet()
    for name, w in weights.items():
        task = osim.IKMarkerTask()
        task.setName(name)
        task.setApply(True)
        task.setWeight(w)
        tasks.cloneAndAppend(task)
    tool = osim.InverseKinematicsTool()
    tool.set_model_file(marked)
    tool.setMarkerDataFileName(job["trc"])
    tool.set_IKTaskSet(tasks)
    tool.setStartTime(float(job["t0"]))
    tool.setEndTime(float(job["t1"]))
    tool.setOutputMotionFileName(os.path.join(scratch, "ik_tool.mot"))
    tool.setResultsDir(scratch)
    t = time.perf_counter()
    if not tool.run():
        raise RuntimeError("the InverseKinematicsTool did not run")
    tool_s = time.perf_counter() - t
    t = time.perf_counter()
    answer = _refine(osim, marked, os.path.join(scratch, "ik_tool.mot"), job["markers"], weights,
                     np.asarray(job["xyz"], dtype=float), job["out"])
    answer.update({"tool_s": tool_s, "refine_s": time.perf_counter() - t})
    return answer


def _couplers(osim, model, names):  # pragma: no cover - child
    """The model's enforced CoordinateCouplerConstraints: (dependent index, independent indices, function)."""
    out = []
    for i in range(model.getConstraintSet().getSize()):
        ccc = osim.CoordinateCouplerConstraint.safeDownCast(model.getConstraintSet().get(i))
        if ccc is not None and ccc.get_isEnforced():
            ind = ccc.getIndependentCoordinateNames()
            out.append((names.index(ccc.getDependentCoordinateName()),
                        [names.index(ind.get(k)) for k in range(ind.getSize())], ccc.getFunction()))
    return out


def _coupled(osim, couplers, q):  # pragma: no cover - child
    """``q`` (model order, radians/metres) with every coupled coordinate set by its coupler."""
    for d, ind, fn in couplers:
        v = osim.Vector(len(ind), 0.0)
        for k, j in enumerate(ind):
            v.set(k, float(q[j]))
        q[d] = fn.calcValue(v)
    return q


def _child_couple(osim, job):  # pragma: no cover - child
    """A coordinates file with every coupled coordinate set by its CoordinateCouplerConstraint
    (a file whose ``knee_angle_r_beta`` merely repeats ``knee_angle_r`` violates the constraint,
    and the inverse dynamics answers with the constraint's forces in the pelvis residuals)."""
    model = osim.Model(job["model"])
    state = model.initSystem()
    cs = model.getCoordinateSet()
    coords = [cs.get(i) for i in range(cs.getSize())]
    names = [c.getName() for c in coords]
    couplers = _couplers(osim, model, names)
    with open(job["coordinates"]) as f:
        lines = f.read().splitlines()
    end = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader")
    labels = lines[end + 1].split()
    rows = np.array([[float(x) for x in ln.split()] for ln in lines[end + 2:] if ln.strip()])
    deg = any(ln.replace(" ", "").lower() == "indegrees=yes" for ln in lines[:end])
    rot = [c.getMotionType() == osim.Coordinate.Rotational for c in coords]
    changed = []
    for d, ind, _ in couplers:
        if names[d] not in labels or any(names[j] not in labels for j in ind):
            continue
        changed.append(names[d])
        for r in rows:
            q = np.array([c.getDefaultValue() for c in coords])
            for j in [*ind, d]:
                v = r[labels.index(names[j])]
                q[j] = np.radians(v) if deg and rot[j] else v
            v = _coupled(osim, couplers, q)[d]
            r[labels.index(names[d])] = np.degrees(v) if deg and rot[d] else v
    del state
    body = ["\t".join(f"{v:.8f}" for v in row) for row in rows]
    with open(job["out"], "w") as f:
        f.write("\n".join(lines[:end + 2] + body) + "\n")
    return {"coupled": changed}


def _refine(osim, model_path, tool_mot, markers, weights, xyz, out):  # pragma: no cover - child
    """Gauss-Newton on the weighted marker cost from the InverseKinematicsTool's solution, frame by
    frame, OpenSim evaluating the model (its assembler stops up to ~2 mm short of the optimum even
    on markers the model can fit exactly, which shows as ±1° jitter in the coordinates). Coupled
    coordinates follow their CoordinateCouplerConstraint. No coordinate is clamped to its range
    (a clamp is a kink in the motion, i.e. an acceleration spike); those that leave it are
    reported (``outside_range``: the largest excursion, radians or metres)."""
    model = osim.Model(model_path)
    state = model.initSystem()
    cs = model.getCoordinateSet()
    coords = [cs.get(i) for i in range(cs.getSize())]
    names = [c.getName() for c in coords]
    couplers = _couplers(osim, model, names)
    dependent = {d for d, _, _ in couplers}
    free = [i for i, c in enumerate(coords) if not c.getLocked(state) and i not in dependent]
    lo = np.array([c.getRangeMin() for c in coords])
    hi = np.array([c.getRangeMax() for c in coords])
    bodies = [model.getBodySet().get(b) for b in dict.fromkeys(m[1] for m in markers)]
    bidx = {b.getName(): k for k, b in enumerate(bodies)}
    mb = np.array([bidx[m[1]] for m in markers])
    local = np.array([m[2] for m in markers], dtype=float)
    sw = np.sqrt(np.array([weights[m[0]] for m in markers]))[:, None]
    with open(tool_mot) as f:
        lines = f.read().splitlines()
    end = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader")
    labels = lines[end + 1].split("\t")
    rows = np.array([[float(x) for x in ln.split()] for ln in lines[end + 2:] if ln.strip()])
    deg = any(ln.strip().lower() == "indegrees=yes" for ln in lines[:end])
    col = [labels.index(n) for n in names]
    Q = rows[:, col].copy()
    rot = [c.getMotionType() == osim.Coordinate.Rotational for c in coords]
    if deg:
        Q[:, rot] = np.radians(Q[:, rot])

    def place(q):
        _coupled(osim, couplers, q)
        for i, c in enumerate(coords):
            c.setValue(state, float(q[i]), False)
        model.realizePosition(state)
        R = np.empty((len(bodies), 3, 3))
        P = np.empty((len(bodies), 3))
        for k, b in enumerate(bodies):
            tr = b.getTransformInGround(state)
            r = tr.R()
            R[k] = [[r.get(a, c) for c in range(3)] for a in range(3)]
            P[k] = tr.p().to_numpy()
        return P[mb] + np.einsum("mij,mj->mi", R[mb], local)

    h = 1e-7
    errs = np.empty((Q.shape[0], len(markers)))
    iterations, last_steps = [], []
    for k in range(Q.shape[0]):
        q = Q[k].copy()
        base = place(q.copy())
        n_it = 0
        size = np.inf
        for _ in range(4):  # Gauss-Newton, each Jacobian reused for a few steps (the start is close)
            J = np.empty((base.size, len(free)))
            for a, i in enumerate(free):
                qp = q.copy()
                qp[i] += h
                J[:, a] = (sw * (place(qp) - base)).ravel() / h
            pinv = np.linalg.pinv(J)
            done = False
            for _ in range(4):
                step = -pinv @ (sw * (base - xyz[k])).ravel()
                q[free] = q[free] + step
                base = place(q.copy())
                n_it += 1
                size = float(np.max(np.abs(step)))
                if size < 1e-9:
                    done = True
                    break
            if done:
                break
        iterations.append(n_it)
        last_steps.append(size)
        final = place(q)  # couplers applied
        Q[k] = [c.getValue(state) for c in coords]
        errs[k] = np.linalg.norm(final - xyz[k], axis=1)
    out_rows = rows.copy()
    vals = Q.copy()
    if deg:
        vals[:, rot] = np.degrees(vals[:, rot])
    out_rows[:, col] = vals
    body = ["\t".join(f"{v:16.8f}" for v in row) for row in out_rows]
    with open(out, "w") as f:
        f.write("\n".join(lines[:end + 2] + body) + "\n")
    below, above = np.maximum(lo - Q, 0.0), np.maximum(Q - hi, 0.0)
    outside = {names[i]: float(max(below[:, i].max(), above[:, i].max())) for i in range(len(names))
               if below[:, i].max() > 1e-9 or above[:, i].max() > 1e-9}
    return {"outside_range": outside, "refine_iterations_max": int(max(iterations)),
            "refine_last_step_max": float(max(last_steps)),
            "marker_rms_m": np.sqrt(np.mean(errs**2, axis=1)).tolist(), "marker_max_m": errs.max(axis=1).tolist(),
            "per_marker_rms_m": dict(zip((m[0] for m in markers), np.sqrt(np.mean(errs**2, axis=0)).tolist()))}


def _child_scale(osim, job):  # pragma: no cover - child
    """A model scaled body by body (OpenSim's ``Model.scale``: joint locations, muscle paths,
    masses and inertias; the mass distribution kept, the total set to ``mass``), printed to ``out``."""
    model = osim.Model(job["model"])
    state = model.initSystem()
    scales = osim.ScaleSet()
    for body, f in job["factors"].items():
        sc = osim.Scale()
        sc.setSegmentName(body)
        sc.setScaleFactors(osim.Vec3(*f))
        sc.setApply(True)
        scales.cloneAndAppend(sc)
    if not model.scale(state, scales, True, float(job["mass"])):
        raise RuntimeError("OpenSim could not scale the generic model")
    model.setName(job["name"])
    model.printToXML(job["out"])
    return {"mass": model.getTotalMass(model.initSystem())}


def _child_masses(osim, job):  # pragma: no cover - child
    """A model with its bodies' masses, centres of mass and inertias (body frame, about the
    centre of mass) set as given, printed to ``out``."""
    model = osim.Model(job["model"])
    for body, (m, c, inertia) in job["bodies"].items():
        b = model.getBodySet().get(body)
        b.setMass(float(m))
        b.setMassCenter(osim.Vec3(*c))
        i = np.asarray(inertia, dtype=float)
        b.setInertia(osim.Inertia(i[0, 0], i[1, 1], i[2, 2], i[0, 1], i[0, 2], i[1, 2]))
    model.finalizeConnections()
    model.printToXML(job["out"])
    return {"mass": model.getTotalMass(model.initSystem())}


def _labels(sto) -> list[str]:  # pragma: no cover - child
    a = sto.getColumnLabels()
    return [a.get(i) for i in range(a.getSize())]


def _coordinate_rows(osim, model, path):  # pragma: no cover - child
    """The rows of a coordinates file (radians, metres) in the model's coordinate order."""
    sto = osim.Storage(path)
    if sto.isInDegrees():
        model.getSimbodyEngine().convertDegreesToRadians(sto)
    labels = _labels(sto)
    cs = model.getCoordinateSet()
    coords = [cs.get(i) for i in range(cs.getSize())]
    times, rows = [], []
    for k in range(sto.getSize()):
        sv = sto.getStateVector(k)
        data = sv.getData()
        times.append(sv.getTime())
        rows.append({c.getName(): data.get(labels.index(c.getName()) - 1) for c in coords
                     if c.getName() in labels})
    return coords, times, rows


def _child_pelvis_twists(osim, model_path, coordinates):  # pragma: no cover - child
    """Per coordinates row: the twist (ω, v at ground's origin) each coordinate of the model's
    free root joint gives the whole model, and the whole-body centre of mass."""
    model = osim.Model(model_path)
    state = model.initSystem()
    root_joint = next(j for j in (model.getJointSet().get(i) for i in range(model.getJointSet().getSize()))
                      if j.getParentFrame().findBaseFrame().getName() == "ground")
    names = [root_joint.get_coordinates(i).getName() for i in range(root_joint.numCoordinates())]
    body = root_joint.getChildFrame().findBaseFrame()
    coords, times, rows = _coordinate_rows(osim, model, coordinates)
    by_name = {c.getName(): c for c in coords}
    h = 1e-6
    twists, com = [], []

    def pose():
        model.realizePosition(state)
        tr = body.getTransformInGround(state)
        R = np.array([[tr.R().get(i, j) for j in range(3)] for i in range(3)])
        return R, tr.p().to_numpy()

    for row in rows:
        for n, v in row.items():
            by_name[n].setValue(state, v, False)
        model.realizePosition(state)
        com.append(list(model.calcMassCenterPosition(state).to_numpy()))
        G = []
        for n in names:
            c = by_name[n]
            v0 = c.getValue(state)
            c.setValue(state, v0 + h, False)
            Rp, pp = pose()
            c.setValue(state, v0 - h, False)
            Rm, pm = pose()
            c.setValue(state, v0, False)
            Om = ((Rp - Rm) / (2 * h)) @ (0.5 * (Rp + Rm)).T
            w = np.array([Om[2, 1] - Om[1, 2], Om[0, 2] - Om[2, 0], Om[1, 0] - Om[0, 1]]) / 2
            v = (pp - pm) / (2 * h) - np.cross(w, 0.5 * (pp + pm))
            G.append([*w.tolist(), *v.tolist()])
        twists.append(G)
    return {"root_coordinates": names, "twist_times": times, "twists": twists, "com": com,
            "mass": model.getTotalMass(state)}


def _child_id(osim, job):  # pragma: no cover - child
    """OpenSim's InverseDynamicsTool from a setup file, run in its folder: the output table; with
    ``twists``, also :func:`_child_pelvis_twists` along the setup's coordinates."""
    setup = os.path.abspath(job["setup"])
    os.chdir(os.path.dirname(setup))
    tool = osim.InverseDynamicsTool(os.path.basename(setup))
    t = time.perf_counter()
    if not tool.run():
        raise RuntimeError("the InverseDynamicsTool did not run")
    elapsed = time.perf_counter() - t
    out = os.path.join(tool.getResultsDir(), tool.getOutputGenForceFileName())
    sto = osim.Storage(out)
    labels = _labels(sto)[1:]
    times, data = [], []
    for k in range(sto.getSize()):
        sv = sto.getStateVector(k)
        times.append(sv.getTime())
        data.append([sv.getData().get(i) for i in range(sv.getSize())])
    answer = {"labels": labels, "times": times, "data": data, "time_s": elapsed, "output": os.path.abspath(out)}
    if job.get("twists"):
        answer.update(_child_pelvis_twists(osim, tool.getModelFileName(), tool.getCoordinatesFileName()))
    return answer
