"""Motion libraries: time per cell and cells per minute, in one process and on the
distributed stack with 1, 2 and 4 Celery workers.

- ``in_process``: ``solver.library.solve_library`` (the engine of ``motionx library``) on the
  grid, one process: seconds per cell (mean, max), cells/min, how many cells were warm-started
  and from where;
- ``workers_N``: the ``motionx stack`` topology (PostgreSQL — SQLite if the server is
  unreachable —, Redis with AOF, the API, N workers of one process each), the same grid posted
  as ``POST /motions/{id}/library``: wall time from the POST to the library's terminal status,
  cells/min, the cells' own times (job start to finish), statuses; the speed-up against 1 worker.

The grid (environment): MOTIONX_BENCH_LIBRARY = ``5x5`` (default, the issue's must-reach:
slopes −15, −7.5, 0, 7.5, 15 × curves −90, −45, 0, 45, 90 on the HalfBoy, 25 cells; about 14
minutes for the four runs on a quiet 2-core machine) or ``small`` (slopes −5, 0, 5 × curves
−20, 0, 20, 9 cells); MOTIONX_BENCH_LIBRARY_WORKERS (default
``1,2,4``). The machine has 2 cores shared with the API, the database and the clients: 4
workers measure oversubscription, not scaling.
"""

from __future__ import annotations

import os
import secrets
import statistics
import tempfile
import time
from pathlib import Path

import httpx

GRIDS = {
    "small": {"slope_deg": [-5.0, 0.0, 5.0], "curve_deg": [-20.0, 0.0, 20.0]},
    "5x5": {"slope_deg": [-15.0, -7.5, 0.0, 7.5, 15.0], "curve_deg": [-90.0, -45.0, 0.0, 45.0, 90.0]},
}
TERMINAL = ("succeeded", "failed", "canceled", "impasse")


def _grid() -> tuple[str, dict]:
    name = os.environ.get("MOTIONX_BENCH_LIBRARY", "5x5")
    if name not in GRIDS:
        raise ValueError(f"MOTIONX_BENCH_LIBRARY must be one of {sorted(GRIDS)}, got {name!r}")
    return name, GRIDS[name]


def in_process(tutor_json: str, grid: dict) -> dict:
    from solver import library as L
    from solver.motion import Motion

    tutor = Motion.from_dict(__import__("json").loads(tutor_json))
    cells = L.grid_cells(grid)
    t0 = time.perf_counter()
    results = L.solve_library(tutor, cells).cells
    wall = time.perf_counter() - t0
    times = [r.wall_time_s for r in results]
    return {
        "cells": len(cells), "wall_s": round(wall, 2), "cells_per_min": round(60 * len(cells) / wall, 2),
        "cell_s_mean": round(statistics.fmean(times), 3), "cell_s_max": round(max(times), 3),
        "statuses": {s: sum(r.status == s for r in results) for s in TERMINAL},
        "lam_reached_min": round(min(r.lam_reached for r in results), 4),
        "warm_started": sum(r.warm_start is not None for r in results),
        "started_part_way": sum(r.warm_start is not None and r.warm_start.lam > 0 for r in results),
        "solves": sum(r.solves for r in results),
        "per_cell": {r.cell.key: {"status": r.status, "lam": round(r.lam_reached, 4), "s": round(r.wall_time_s, 3),
                                  "solves": r.solves,
                                  "warm_start": None if r.warm_start is None else
                                  [r.warm_start.source_cell, r.warm_start.lam]} for r in results},
    }


def on_stack(workers: int, tutor_json: str, grid: dict, database_url: str | None, tmp: Path) -> dict:
    from service.topology import Stack

    stack = Stack(data_dir=tmp / f"w{workers}", workers=workers, database_url=database_url,
                  extra_env={"MOTIONX_JOB_LEASE_S": "10"})
    stack.start()
    try:
        with httpx.Client(base_url=stack.base_url, headers={"X-API-Key": stack.api_keys}, timeout=60) as c:
            r = c.post("/motions", content=tutor_json, headers={"content-type": "application/json"})
            r.raise_for_status()
            mid = r.json()["id"]
            t0 = time.perf_counter()
            r = c.post(f"/motions/{mid}/library", json={"grid": grid})
            r.raise_for_status()
            lid = r.json()["id"]
            polls = 0
            while True:
                lib = c.get(f"/libraries/{lid}").json()
                polls += 1
                if lib["status"] in TERMINAL:
                    break
                if time.perf_counter() - t0 > 3600:
                    raise TimeoutError("library not done after 1 h")
                time.sleep(0.5)
            wall = time.perf_counter() - t0
            man = c.get(f"/libraries/{lid}/manifest").json()
            glb = c.get(f"/libraries/{lid}/library.glb")
    finally:
        stack.stop()
    cells = lib["cells"]
    times = [x["wall_time_s"] for x in cells if x["wall_time_s"] is not None]
    return {
        "workers": workers, "cells": len(cells), "status": lib["status"], "wall_s": round(wall, 2),
        "cells_per_min": round(60 * len(cells) / wall, 2),
        "cell_s_mean": round(statistics.fmean(times), 3) if times else None,
        "cell_s_max": round(max(times), 3) if times else None,
        "statuses": {s: lib["progress"][s] for s in TERMINAL}, "attempts": sum(x["attempts"] for x in cells),
        "warm_started": sum(e["warm_start"] is not None for e in man["cells"]),
        "realistic_cells": sum(bool(e["realism"] and e["realism"]["plausible"]) for e in man["cells"]),
        "glb_bytes": len(glb.content) if glb.status_code == 200 else None,
    }


def run() -> dict:
    from bench.service import tutor_motion_json
    from service.topology import create_postgres_database, drop_postgres_database

    name, grid = _grid()
    workers = [int(w) for w in os.environ.get("MOTIONX_BENCH_LIBRARY_WORKERS", "1,2,4").split(",")]
    admin = os.environ.get("MOTIONX_TEST_PG_ADMIN", "postgresql://postgres@127.0.0.1:5432/postgres")
    tutor = tutor_motion_json()
    out: dict = {"grid_name": name, "grid": grid, "note": "2 cores shared by API, database, Redis and workers"}
    out["in_process"] = in_process(tutor, grid)
    with tempfile.TemporaryDirectory(prefix="motionx-bench-library-") as tmp:
        for w in workers:
            db = f"motionx_bench_lib_{secrets.token_hex(4)}"
            try:
                url = create_postgres_database(admin, db)
                out["database"] = "postgresql"
            except Exception:  # no PostgreSQL here: the embedded SQLite
                url, db = None, None
                out["database"] = "sqlite"
            try:
                out[f"workers_{w}"] = on_stack(w, tutor, grid, url, Path(tmp))
            finally:
                if db:
                    drop_postgres_database(admin, db)
    base = out.get("workers_1", {}).get("wall_s")
    if base:
        out["speedup"] = {f"workers_{w}": round(base / out[f"workers_{w}"]["wall_s"], 2) for w in workers}
    return out
