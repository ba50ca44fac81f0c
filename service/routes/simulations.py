"""/motions/{id}/simulation: a stored motion performed in MuJoCo (service.simulation).

The simulation is background work (tens of seconds of CPU): a job of kind ``simulation`` run
by the service's runner (the local job processes, or Celery workers), one at a time per
motion. Its report and files are stored in SQL and served from there.
"""

from __future__ import annotations

from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse, Response

from service import simulation, store, work
from service.deps import DatabaseDep, OwnerDep, RunnerDep, SettingsDep
from service.problems import Problem, known_id, not_found
from service.schemas import SimulationIn, SimulationOut
from service.views import simulation_out
from service.work import Compute

router = APIRouter(tags=["simulations"])

_ACTIVE = ("queued", "running")


def _answer(s, sim) -> dict:
    status, message = store.simulation_state(s, simulation=sim)
    files = store.simulation_files(s, simulation_id=sim.id) if status == "succeeded" else {}
    return simulation_out(sim, status, message, files)


@router.post(
    "/motions/{motion_id}/simulation",
    status_code=202,
    response_model=SimulationOut,
    summary="simulate the motion in MuJoCo (background work; one at a time per motion)",
    description="Performs the motion in MuJoCo with contacts on under the balancing tracking controller for "
                f"`cycles` gait cycles ({simulation.MIN_CYCLES}..{simulation.MAX_CYCLES}, default "
                f"{simulation.DEFAULT_CYCLES}; it stops early when the character falls, which is a result, not an "
                "error). The motion must be one gait cycle with contacts and foot wrenches (a tutor or a λ optimum), "
                "else 422. While a simulation of the motion is queued or running, asking again returns it. Follow "
                "it with GET on the same path (Location).",
    responses={202: {"headers": {"Location": {"schema": {"type": "string"}}}},
               404: {"description": "no such motion for this key"},
               422: {"description": "cycles outside the range, or a motion that cannot be simulated"}},
)
async def start_simulation(motion_id: str, request: Request, owner: OwnerDep, db: DatabaseDep, runner: RunnerDep,
                           settings: SettingsDep, body: SimulationIn | None = None) -> JSONResponse:
    known_id("motion", motion_id)
    cycles = (body or SimulationIn()).cycles

    def load() -> bytes:
        with db.read() as s:
            row = store.get_motion(s, motion_id=motion_id, owner=owner)
            if row is None:
                raise not_found("motion", motion_id)
            return row.data

    data = await run_in_threadpool(load)
    compute: Compute = request.app.state.compute
    why = await compute.run(work.simulation_check, data, what="the simulation check")
    if why:
        raise Problem(422, f"motion {motion_id} cannot be simulated: {why}")

    def create() -> tuple[dict, str | None]:
        with db.write() as s:
            row = store.get_motion(s, motion_id=motion_id, owner=owner, lock=True)
            if row is None:
                raise not_found("motion", motion_id)
            last = store.latest_simulation(s, motion_id=motion_id, owner=owner)
            if last is not None and store.simulation_state(s, simulation=last)[0] in _ACTIVE:
                return _answer(s, last), None  # one at a time per motion: the running one
            job = store.create_job(s, owner=owner, motion_id=motion_id, kind="simulation",
                                   spec={"simulation": {"cycles": cycles}}, runner=runner.name,
                                   max_attempts=settings.job_max_attempts)
            sim = store.create_simulation(s, owner=owner, motion_id=motion_id, job_id=job.id, cycles=cycles)
            return _answer(s, sim), job.id

    out, job_id = await run_in_threadpool(create)
    if job_id is not None:
        await run_in_threadpool(runner.submit, job_id)  # broker down: queued in SQL, the sweep dispatches it
    return JSONResponse(out, status_code=202, headers={"Location": out["links"]["self"]})


def _latest(s, motion_id: str, owner: str, hint: str = ""):
    """The motion's latest simulation, or a 404 (no such motion for this key, or never simulated)."""
    if store.get_motion(s, motion_id=motion_id, owner=owner) is None:
        raise not_found("motion", motion_id)
    sim = store.latest_simulation(s, motion_id=motion_id, owner=owner)
    if sim is None:
        raise Problem(404, f"motion {motion_id} has not been simulated{hint}")
    return sim


@router.get("/motions/{motion_id}/simulation", response_model=SimulationOut,
            summary="the motion's latest simulation: status, and when it succeeded its report and downloads",
            responses={404: {"description": "no such motion for this key, or never simulated"}})
def get_simulation(motion_id: str, owner: OwnerDep, db: DatabaseDep) -> dict:
    known_id("motion", motion_id)
    with db.read() as s:
        return _answer(s, _latest(s, motion_id, owner, " (POST to this path simulates it)"))


@router.get("/motions/{motion_id}/simulation/{name}",
            summary="a file of the motion's latest simulation: " + ", ".join(simulation.FILES),
            responses={200: {"content": {mt: {} for mt in dict.fromkeys(simulation.FILES.values())}},
                       404: {"description": "no such motion, simulation or file"}})
def get_simulation_file(motion_id: str, name: str, owner: OwnerDep, db: DatabaseDep) -> Response:
    known_id("motion", motion_id)
    if name not in simulation.FILES:
        raise Problem(404, f"no simulation file {name[:80]!r}: one of " + ", ".join(simulation.FILES))
    with db.read() as s:
        sim = _latest(s, motion_id, owner)
        f = store.simulation_file(s, simulation_id=sim.id, name=name)
        if f is None:
            raise Problem(404, f"simulation {sim.id} has no {name} (yet: status {sim.status})")
        data, media_type = f.data, f.media_type
    return Response(data, media_type=media_type,
                    headers={"Content-Disposition": f'attachment; filename="{motion_id}.{name}"'})
