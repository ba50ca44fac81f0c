"""Motion libraries in the service: one job per cell, the library derived from its cells.

``POST /motions/{id}/library`` inserts the library row and one queued job per cell in one
transaction (:func:`service.store.create_library`), nearest the tutor first, and dispatches
every cell job through the runner like any job — so a cell gets what a job gets: one attempt
at a time under a lease, re-dispatch when its worker dies, at most ``job_max_attempts``
attempts, λ optima upserted by (job, step) (exactly once), cooperative cancel, time and
memory limits. Nothing waits on a worker for the library: its status and progress are
computed from its cells' rows when read (:func:`library_out`).

A cell job starts from the stored optimum furthest along its own homotopy
(:func:`solver.library.best_start`: any cell's λ = 0 optimum skips the base problem; a solved
cell on its ray starts it part-way; its own earlier attempt's last optimum resumes it). That
optimum becomes the cell's step 0 (provenance ``warm_start``), so the cell's motions are the
optima of its own homotopy from there on.

A cell's clip is its last realistic optimum: at an impasse, the last λ it reached.
"""

from __future__ import annotations

import logging
from typing import Any

from service import store
from service.db import Database
from service.models import TERMINAL, JobRow, LibraryRow, MotionRow
from service.views import SECONDS_DECIMALS, iso, reported
from solver import library as L
from solver.status import Status, combined

log = logging.getLogger(__name__)


def cell_of(params: dict) -> L.Cell:
    return L.Cell(tuple((k, float(v)) for k, v in params.items()))


def plan(body: dict) -> tuple[dict, list[tuple[str, dict, dict]], list[str]]:
    """(library spec, [(cell key, parameters, job spec)] in the request's order, the keys in
    dispatch order: nearest the tutor first) of a request body;
    :class:`solver.library.LibraryError` when the method cannot take it."""
    if body.get("grid") is not None:
        cells = L.grid_cells(body["grid"])
    else:
        cells = L.list_cells(body.get("targets") or [])
    L.check_cells(cells)
    control, tutor = body.get("control") or {}, body.get("tutor") or {}
    spec = {"grid": body.get("grid"), "targets": body.get("targets"), "control": control, "tutor": tutor,
            "axes": sorted({k for c in cells for k, _ in c.params}, key=L.AXES.index)}
    out = []
    for c in cells:
        ctl = dict(control)
        if c.is_neutral():  # the tutor's own ground: one step from the base problem to λ = 1
            ctl["delta0"] = 1.0
            ctl["eps"] = min(float(ctl.get("eps", 0.005)), 1.0)
        out.append((c.key, c.values, {"target": c.target_kwargs(), "control": ctl, "tutor": tutor}))
    return spec, out, [c.key for c in L.order(cells)]


def warm_start(db: Database, job_id: str, ref: dict):
    """The best stored optimum for cell job ``job_id`` (``ref`` = its spec's ``library``), as
    (CellStart, Motion, validation, source job id, source step), or None."""
    with db.read() as s:
        lib = store.get_library(s, library_id=ref["id"], owner=None)
        if lib is None:
            return None
        cells = {c["job_id"]: cell_of(c["parameters"]) for c in lib.spec.get("cells", [])}
        me = cells.get(job_id)
        if me is None:
            return None
        best = None
        for j, step, lam, plausible, _ in store.stored_optima(s, job_ids=list(cells)):
            if plausible is False:
                continue
            t = L.on_ray(me, cells[j], lam)
            if t is not None and (best is None or (t, j == job_id) > (best[0], best[1] == job_id)):
                best = (t, j, step, lam)
        if best is None:
            return None
        t, j, step, lam = best
        row = store.step_row(s, job_id=j, step=step)
        if row is None:  # removed meanwhile (its attempt finished shorter)
            return None
        motion = store.load_motion(row)
        validation = row.validation
    ws = L.CellStart(float(t), cells[j].key, float(lam))
    return ws, motion, validation, j, step


def _cell_view(c: dict, job: JobRow | None, clip: tuple | None) -> dict:
    status = job.status if job is not None else "failed"
    return {
        "clip_motion_id": clip[4] if clip else None, "clip_lam": reported(clip[2]) if clip else None,
        "plausible": clip[3] if clip else None,
        "key": c["key"], "parameters": reported(c["parameters"]), "job_id": c["job_id"], "status": status,
        "at_impasse": status == "impasse", "lam_reached": reported(job.lam_reached) if job else 0.0,
        "steps": job.steps if job else 0, "solves": job.solves if job else 0,
        "attempts": job.attempts if job else 0, "message": job.message if job else "cell job missing",
        "started_at": iso(job.started_at) if job else None, "finished_at": iso(job.finished_at) if job else None,
        "wall_time_s": reported(job.finished_at - job.started_at, SECONDS_DECIMALS)
        if job and job.finished_at and job.started_at else None,
        "links": {"job": f"/jobs/{c['job_id']}", "motions": f"/jobs/{c['job_id']}/motions"},
    }


def status_of(cells: list[dict], cancel_requested: bool) -> Status:
    return combined((c["status"] for c in cells), cancel_requested=cancel_requested)


def library_out(session, row: LibraryRow) -> dict:
    """The library as the API shows it: status, overall progress, every cell's status and λ."""
    jobs = store.library_jobs(session, library=row)
    clip: dict[str, tuple] = {}  # job id -> its last realistic optimum (the highest step not marked implausible)
    for o in store.stored_optima(session, job_ids=list(jobs)):
        if o[3] is not False and (o[0] not in clip or o[1] > clip[o[0]][1]):
            clip[o[0]] = o
    cells = [_cell_view(c, jobs.get(c["job_id"]), clip.get(c["job_id"])) for c in row.spec.get("cells", [])]
    frac = [1.0 if c["status"] in TERMINAL else float(c["lam_reached"]) for c in cells]
    counts = {s: sum(1 for c in cells if c["status"] == s) for s in ("queued", "running", *sorted(TERMINAL))}
    finished = [jobs[c["job_id"]].finished_at for c in cells if c["job_id"] in jobs and jobs[c["job_id"]].finished_at]
    status = status_of(cells, row.cancel_requested)
    spec = row.spec
    return {
        "id": row.id, "status": status, "terminal": status in TERMINAL, "motion_id": row.motion_id,
        "axes": spec.get("axes", []),
        "grid": spec.get("grid"), "targets": spec.get("targets"), "control": spec.get("control", {}),
        "cancel_requested": row.cancel_requested, "created_at": iso(row.created_at),
        "finished_at": iso(max(finished)) if status in TERMINAL and finished else None,
        "progress": {"cells": len(cells), "done": sum(1 for c in cells if c["status"] in TERMINAL),
                     "fraction": reported(sum(frac) / len(frac)) if frac else 1.0, **counts},
        "cells": cells,
        "links": {"self": f"/libraries/{row.id}", "cancel": f"/libraries/{row.id}/cancel",
                  "manifest": f"/libraries/{row.id}/manifest", "glb": f"/libraries/{row.id}/library.glb",
                  "events": f"/libraries/{row.id}/events",
                  "source": f"/motions/{row.motion_id}"},
    }


def clips(session, row: LibraryRow) -> list[tuple[dict, Any]]:
    """(cell view, clip MotionRow or None) per cell: the clip is the cell's last realistic λ optimum
    (the highest step not marked implausible; see :func:`library_out`)."""
    view = library_out(session, row)
    return [(c, session.get(MotionRow, c["clip_motion_id"]) if c["clip_motion_id"] else None) for c in view["cells"]]


def manifest(session, row: LibraryRow) -> dict:
    """The manifest (solver.library.cell_entry per cell): parameters, status, files, realism."""
    view = library_out(session, row)
    entries = []
    for c, clip in clips(session, row):
        motion = store.load_motion(clip) if clip is not None else None
        files = {}
        if clip is not None:
            files = {"motion": f"/motions/{clip.id}?format=motion", "clip": f"/motions/{clip.id}?format=json",
                     "glb": f"/libraries/{row.id}/library.glb", "animation": c["key"]}
        entries.append(L.cell_entry(
            cell_of(c["parameters"]), status=c["status"], lam_reached=c["lam_reached"], message=c["message"],
            motion=motion, clip_lam=clip.lam if clip is not None else None, files=files,
            warm_start=_first_warm_start(session, c["job_id"]),
            solves=c["solves"], wall_time_s=c["wall_time_s"],
            report=(clip.validation if clip is not None and clip.validation else None),
            extra={"job_id": c["job_id"], "motion_id": clip.id if clip is not None else None,
                   "attempts": c["attempts"]}))
    return {"format": L.FORMAT, "version": L.VERSION, "id": row.id, "status": view["status"],
            "source": row.motion_id, "grid": {"axes": row.spec.get("grid"), "targets": row.spec.get("targets"),
                                              "cells": [c["key"] for c in view["cells"]]},
            "control": row.spec.get("control", {}), "cells": entries, "summary": L.summary(entries),
            "files": {"glb": f"/libraries/{row.id}/library.glb"}}


def _first_warm_start(session, job_id: str) -> dict | None:
    r = store.step_row(session, job_id=job_id, step=0)
    if r is None:
        return None
    prov = store.load_motion(r).provenance or {}
    return prov.get("warm_start")
