"""/motions/{id}/simulation: a stored motion performed in MuJoCo (service.simulation).

The simulation is background work (tens of seconds of CPU): a job of kind ``simulation`` run
by the service's runner (the local job processes, or Celery workers), one at a time per
motion. Its report and files are stored in SQL and served from there.
"""

from __future__ import annotations

from collections.abc import Iterator

from fastapi import APIRouter, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import JSONResponse, Response, StreamingResponse
from starlette.concurrency import iterate_in_threadpool

from service import quota, simulation, store, work
from service.deps import QUOTA_429, UNAVAILABLE_503, DatabaseDep, OwnerDep, RunnerDep, SettingsDep
from service.models import SimulationFileRow
from service.problems import Problem, known_id, not_found
from service.routes.motions import CHUNK
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
               422: {"description": "cycles outside the range, or a motion that cannot be simulated"},
               429: QUOTA_429, 503: UNAVAILABLE_503},
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
    why = await compute.run(work.simulation_check, data, what="the simulation check", owner=owner, request=request)
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
            quota.check_simulations(s, settings, owner=owner)
            job = store.create_job(s, owner=owner, motion_id=motion_id, kind="simulation",
                                   spec={"simulation": {"cycles": cycles}}, runner=runner.name,
                                   max_attempts=settings.job_max_attempts)
            sim = store.create_simulation(s, owner=owner, motion_id=motion_id, job_id=job.id, cycles=cycles)
            return _answer(s, sim), job.id

    out, job_id = await run_in_threadpool(create)
    if job_id is not None:
        await run_in_threadpool(runner.dispatch)  # the key's turn allowing; broker down: the sweep dispatches it
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
        sim_id, size, media_type = sim.id, int(f.size), f.media_type
    return StreamingResponse(iterate_in_threadpool(_file_chunks(db, sim_id, name, size)), media_type=media_type,
                             headers={"Content-Disposition": f'attachment; filename="{motion_id}.{name}"',
                                      "Content-Length": str(size)})


def _file_chunks(db, simulation_id: str, name: str, size: int) -> Iterator[bytes]:
    """A stored simulation file, read from SQL a chunk at a time (never whole in the API's memory)."""
    where = (SimulationFileRow.simulation_id == simulation_id, SimulationFileRow.name == name)
    for off in range(0, size, CHUNK):
        with db.read() as s:
            part = store.blob_chunk(s, SimulationFileRow.data, where, off, CHUNK)
        if not part:
            return
        yield part


@router.delete(
    "/motions/{motion_id}/simulation",
    status_code=204,
    response_class=Response,
    summary="delete the motion's simulations (the latest and the superseded ones) and their files",
    responses={204: {"description": "deleted"}, 404: {"description": "no such motion for this key, or never "
                                                                        "simulated"},
               409: {"description": "a simulation of the motion is still queued or running"}},
)
def delete_simulation(motion_id: str, owner: OwnerDep, db: DatabaseDep) -> Response:
    known_id("motion", motion_id)
    with db.write() as s:
        _latest(s, motion_id, owner)
        sims = store.motion_simulations(s, motion_id=motion_id)
        if any(store.simulation_state(s, simulation=x)[0] in _ACTIVE for x in sims):
            raise Problem(409, f"a simulation of motion {motion_id} is still queued or running; it can be deleted "
                          "once it has ended")
        jobs = [x.job_id for x in sims if (j := store.get_job(s, job_id=x.job_id, owner=None)) is not None
                and j.kind == "simulation"]
        store.delete_simulations(s, simulation_ids=[x.id for x in sims])
        if jobs:
            store.delete_all(s, store.deletion(s, jobs=jobs))
    return Response(status_code=204)
