"""OpenSim Moco's MocoTrack on a trial folder, in a process of its own (``bench.moco`` starts it:
``python -m bench.moco_track`` with a JSON job on stdin; the ``opensim`` wheel's CasADi cannot share
a process with ours, :mod:`solver.io.opensim.worker`). Nothing here imports CasADi: of the solver,
only its OpenSim table reader.

The problem is exampleMocoTrack's torque-driven one, tracking the trial's coordinates instead of
markers: the trial's model (``model.osim``, written by ``bench.moco.prepare``) with its locked
joints welded (Moco refuses locked coordinates), the plates applied (``ModOpAddExternalLoads``),
the muscles removed (``ModOpRemoveMuscles``) and a CoordinateActuator on every coordinate, the
pelvis's residuals too (``ModOpAddReserves(250)``, unbounded; ``actuators="bounded_residuals"``:
the 4.6 example's ``ModOpAddResiduals(250, 50, 1)`` + ``ModOpAddReserves(250, 1)``). MocoTrack's
own weights (states 1, control effort 0.001) and guess; the reference is the trial's coordinates
(``REFERENCE``) low-passed at 6 Hz, their speeds tracked too, over [t0, t1] with the given mesh
interval; MocoCasADiSolver (Hermite–Simpson) on one thread, its convergence tolerance and Hessian
as the job says. The answer: the solve's CPU and wall seconds (this process's, around
``study.solve()``), its iterations, status and objective, the solution's RMS to the trial's
coordinates (not low-passed; at the mesh's points) as ``solver.naturalness.joint_rms_deg`` reports a
tutor's — the joints overall (coupled and locked coordinates left out), the pelvis's rotations
apart — the pelvis's translations (mm), and the pelvis residual forces and moments (N, N·m)."""

from __future__ import annotations

import json
import os
import sys
import time
from pathlib import Path

import numpy as np

from solver.io.opensim.storage import read_mot  # numpy only: no CasADi before OpenSim's

#: the coordinates tracked: the trial's (coupled coordinates set), its header stating inDegrees
REFERENCE = "reference.mot"
#: the job's keys and their defaults (``folder``, ``t0``, ``t1``, ``mesh_interval`` are required)
DEFAULTS = {"convergence_tolerance": 1e-2, "hessian": "limited-memory", "max_iterations": 1000, "lowpass_hz": 6.0,
            "guess_from_reference": False, "actuators": "reserves", "tracking_weight": 1.0}
#: the reserves' optimal force (N, N·m): a control of 1 is 250 N
OPTIMAL_FORCE = 250.0


def check_job(job: dict) -> dict:
    """The job with its defaults; a missing or unusable trial folder refused with what is missing."""
    for key in ("folder", "t0", "t1", "mesh_interval"):
        if key not in job:
            raise ValueError(f"the MocoTrack job names no {key!r}")
    folder = Path(job["folder"])
    missing = [f for f in ("model.osim", REFERENCE, "external_loads.xml") if not (folder / f).is_file()]
    if missing:
        raise FileNotFoundError(f"the MocoTrack trial folder {folder} lacks {', '.join(missing)} "
                                "(bench.moco.prepare writes them)")
    if not float(job["t1"]) > float(job["t0"]):
        raise ValueError(f"the tracked window is empty: t0 = {job['t0']}, t1 = {job['t1']}")
    return {**DEFAULTS, **job}


def track(osim, job: dict) -> dict:  # pragma: no cover - runs in the child (bench only)
    folder = Path(job["folder"])
    cpu0 = time.process_time()
    base = osim.Model(str(folder / "model.osim"))
    base.initSystem()
    cs = base.getCoordinateSet()
    coords = [cs.get(i) for i in range(cs.getSize())]
    welds = []
    for j in range(base.getJointSet().getSize()):
        joint = base.getJointSet().get(j)
        n = joint.numCoordinates()
        if n and all(joint.get_coordinates(k).get_locked() for k in range(n)):
            welds.append(joint.getName())
    locked = {c.getName() for c in coords if c.get_locked()}
    fs = base.updForceSet()
    dropped = []
    for i in reversed(range(fs.getSize())):  # an actuator of a welded joint's coordinate would not connect
        act = osim.CoordinateActuator.safeDownCast(fs.get(i))
        if act is not None and act.get_coordinate() in locked:
            dropped.append(act.getName())
            fs.remove(i)
    base.finalizeConnections()
    base.printToXML(str(folder / "model_moco.osim"))

    mp = osim.ModelProcessor(str(folder / "model_moco.osim"))
    if welds:
        names = osim.StdVectorString()
        for w in welds:
            names.append(w)
        mp.append(osim.ModOpReplaceJointsWithWelds(names))
    mp.append(osim.ModOpAddExternalLoads(str(folder / "external_loads.xml")))
    mp.append(osim.ModOpRemoveMuscles())
    if job["actuators"] == "bounded_residuals":  # exampleMocoTrack 4.6: pelvis forces within 50 N
        mp.append(osim.ModOpAddResiduals(250.0, 50.0, 1.0))
        mp.append(osim.ModOpAddReserves(250.0, 1.0))
    else:  # "reserves": a CoordinateActuator on every coordinate, the pelvis's too, unbounded
        mp.append(osim.ModOpAddReserves(OPTIMAL_FORCE))
    tool = osim.MocoTrack()
    tool.setName("motionx_bench_torque_driven_coordinate_tracking")
    tool.setModel(mp)
    ref = osim.TableProcessor(str(folder / REFERENCE))
    ref.append(osim.TabOpLowPassFilter(float(job["lowpass_hz"])))
    ref.append(osim.TabOpUseAbsoluteStateNames())
    tool.setStatesReference(ref)
    tool.set_states_global_tracking_weight(float(job["tracking_weight"]))
    tool.set_allow_unused_references(True)
    tool.set_track_reference_position_derivatives(True)
    tool.set_apply_tracked_states_to_guess(bool(job["guess_from_reference"]))
    tool.set_initial_time(float(job["t0"]))
    tool.set_final_time(float(job["t1"]))
    tool.set_mesh_interval(float(job["mesh_interval"]))
    study = tool.initialize()
    solver = osim.MocoCasADiSolver.safeDownCast(study.updSolver())
    solver.set_optim_convergence_tolerance(float(job["convergence_tolerance"]))
    solver.set_optim_hessian_approximation(str(job["hessian"]))
    solver.set_optim_max_iterations(int(job["max_iterations"]))
    solver.set_parallel(0)  # one thread: CPU seconds comparable with the tutor's
    solver.set_optim_ipopt_print_level(0)
    solver.set_verbosity(0)
    setup_cpu = time.process_time() - cpu0
    weight = base.getTotalMass(base.initSystem()) * 9.80665

    cpu, wall = time.process_time(), time.perf_counter()
    sol = study.solve()
    solve_cpu, solve_wall = time.process_time() - cpu, time.perf_counter() - wall
    out: dict = {"success": bool(sol.success()), "solver_status": str(sol.getStatus()),
                 "iterations": int(sol.getNumIterations()), "objective": float(sol.getObjective()),
                 "solve_cpu_s": solve_cpu, "solve_wall_s": solve_wall, "setup_cpu_s": setup_cpu,
                 "solver_duration_s": float(sol.getSolverDuration()),
                 "mesh_points": int(sol.getNumTimes()), "welded_joints": welds,
                 "actuators_of_welded_joints_removed": dropped,
                 "states": int(sol.getNumStates()), "controls": int(sol.getNumControls()), "body_weight_n": weight}
    sol.unseal()
    if job.get("solution"):
        sol.write(str(job["solution"]))
    try:
        out.update(_figures(osim, sol, folder, base, coords, mp))
    except Exception as e:  # the solve's own figures stand without them
        out["figures_error"] = f"{type(e).__name__}: {e}"
    return out


def _figures(osim, sol, folder: Path, base, coords, mp) -> dict:  # pragma: no cover - child
    """The solution's RMS to the reference and the pelvis's residual actuators' forces."""
    dependent = set()
    for i in range(base.getConstraintSet().getSize()):
        ccc = osim.CoordinateCouplerConstraint.safeDownCast(base.getConstraintSet().get(i))
        if ccc is not None and ccc.get_isEnforced():
            dependent.add(ccc.getDependentCoordinateName())
    root = next(base.getJointSet().get(j) for j in range(base.getJointSet().getSize())
                if base.getJointSet().get(j).getParentFrame().findBaseFrame().getName() == "ground")
    root_coords = {root.get_coordinates(k).getName() for k in range(root.numCoordinates())}
    out: dict = {}
    times = np.array(sol.getTimeMat()).ravel()
    sto = read_mot(folder / REFERENCE)  # its header states inDegrees (bench.moco.prepare writes it)
    labels, t_ref, ref_q, deg = sto.labels, sto.time, sto.data, bool(sto.in_degrees)
    per, trans = {}, {}
    for c in coords:
        name = c.getName()
        if name not in labels or name in dependent or c.get_locked():
            continue
        path = f"{c.getAbsolutePathString()}/value"
        q = np.array(sol.getStateMat(path)).ravel()
        r = np.interp(times, t_ref, ref_q[:, labels.index(name)])
        rot = c.getMotionType() == osim.Coordinate.Rotational
        if rot:
            d = np.degrees(q) - (r if deg else np.degrees(r))
            per[name] = float(np.sqrt(np.mean(d ** 2)))
        else:
            trans[name] = float(1e3 * np.sqrt(np.mean((q - r) ** 2)))
    joints = [v for k, v in per.items() if k not in root_coords]
    pelvis = [v for k, v in per.items() if k in root_coords]
    out["joint_rms_to_reference_deg"] = {
        "overall": float(np.sqrt(np.mean(np.square(joints)))) if joints else None,
        "pelvis": float(np.sqrt(np.mean(np.square(pelvis)))) if pelvis else None,
        "per_coordinate": per, "pelvis_translation_mm": trans}
    model = mp.process()
    model.initSystem()
    controls = set(sol.getControlNames())
    res: dict = {}
    for i in range(model.getForceSet().getSize()):
        act = osim.CoordinateActuator.safeDownCast(model.getForceSet().get(i))
        if act is None or act.get_coordinate() not in root_coords or act.getAbsolutePathString() not in controls:
            continue
        u = np.array(sol.getControlMat(act.getAbsolutePathString())).ravel() * act.getOptimalForce()
        res[act.get_coordinate()] = {"rms": float(np.sqrt(np.mean(u ** 2))), "max_abs": float(np.max(np.abs(u)))}
    out["pelvis_residuals"] = res
    out["reference"] = "the trial's coordinates (coupled coordinates set), not low-passed"
    return out


def main() -> None:  # pragma: no cover - the child's entry (bench only)
    job = json.loads(sys.stdin.read())
    answer = Path(job["answer"])
    try:
        job = check_job(job)
        import opensim as osim  # first heavy import of the process: OpenSim's casadi wins

        osim.Logger.setLevelString("error")
        osim.Logger.removeFileSink()
        out = track(osim, job)
        out["opensim"] = str(getattr(osim, "__version__", "?"))
        out["threads_env"] = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")}
        answer.write_text(json.dumps(out, allow_nan=True))
    except Exception as e:  # the parent records any failure as a status
        answer.with_suffix(".err").write_text(f"{type(e).__name__}: {e}")
        sys.exit(3)


if __name__ == "__main__":
    main()
