"""Service load (issue: the service): GET latency and job throughput on loopback.

For 1 and 2 Celery workers, the compose topology as processes (``service.topology.Stack``:
Redis with AOF, PostgreSQL — SQLite if the server is unreachable —, the API under uvicorn,
N workers). Measured from concurrent HTTP clients (threads, one keep-alive connection each)
in this process, on the same 2-core machine as the server:

- ``get_one_client`` / ``get_idle``: one client, then C clients, cycling over GET /jobs/{id},
  /motions/{id}?format=motion, /jobs/{id}/motions and /motions/{id} (JSON clip), no job running;
- ``jobs``: J small real extrapolation jobs (a friction target from the tutor of the
  DeepMimic walk) submitted at once; jobs/s from the first submission to the last success,
  with ``get_under_load``: the latency of the clients polling GET /jobs/{id} meanwhile.

Environment: MOTIONX_BENCH_JOBS (default 8), MOTIONX_BENCH_CLIENTS (default 8),
MOTIONX_BENCH_SECONDS (idle GET phase, default 5).
"""

from __future__ import annotations

import multiprocessing
import os
import secrets
import statistics
import tempfile
import threading
import time
from pathlib import Path

import httpx

BENCH_TARGET = {"target": {"friction": 0.7}, "control": {"delta0": 0.5}}


def _pct(xs: list[float], p: float) -> float:
    xs = sorted(xs)
    if not xs:
        return float("nan")
    k = min(len(xs) - 1, max(0, int(round(p / 100.0 * (len(xs) - 1)))))
    return xs[k]


def _summary(lat_s: list[float], wall: float) -> dict:
    ms = [1e3 * x for x in lat_s]
    return {"requests": len(ms), "p50_ms": round(_pct(ms, 50), 2), "p99_ms": round(_pct(ms, 99), 2),
            "mean_ms": round(statistics.fmean(ms), 2) if ms else None, "req_per_s": round(len(ms) / wall, 1)}


def tutor_motion_json() -> str:
    """The tutor of the DeepMimic walk (the same input as the reliability tests)."""
    from service.examples import data_dir
    from solver.io import load_trial
    from solver.pipeline import capture_motion, make_tutor

    d = data_dir() / "deepmimic_humanoid3d_walk"
    res = make_tutor(capture_motion(load_trial([d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt"])),
                     character="halfboy", fps=15.0)
    if res.status != "succeeded":
        raise RuntimeError(f"tutor failed: {res.message}")
    return res.motion.to_json()


def _client_proc(base: str, key: str, paths: list[str], threads: int, offset: int, go, stop, out) -> None:
    """One client process: ``threads`` keep-alive connections issuing GETs from ``go`` to ``stop``."""
    lat: list[float] = []
    errors = [0]
    lock = threading.Lock()

    def loop(i: int) -> None:
        mine: list[float] = []
        with httpx.Client(base_url=base, headers={"X-API-Key": key}, timeout=30) as c:
            c.get("/health")  # connect before the clock starts
            go.wait()
            k = i
            while not stop.is_set():
                t = time.perf_counter()
                r = c.get(paths[k % len(paths)])
                mine.append(time.perf_counter() - t)
                if r.status_code != 200:
                    errors[0] += 1
                k += 1
        with lock:
            lat.extend(mine)

    ts = [threading.Thread(target=loop, args=(offset + i,)) for i in range(threads)]
    for t in ts:
        t.start()
    out.put("ready")
    for t in ts:
        t.join()
    out.put((lat, errors[0]))


class _Clients:
    """``clients`` concurrent HTTP clients spread over a few processes (no shared GIL)."""

    def __init__(self, base: str, key: str, paths: list[str], clients: int) -> None:
        ctx = multiprocessing.get_context("spawn")
        self.go, self.stop, self.out = ctx.Event(), ctx.Event(), ctx.Queue()
        nproc = min(clients, 4)
        per = [clients // nproc + (1 if i < clients % nproc else 0) for i in range(nproc)]
        self.procs = [ctx.Process(target=_client_proc,
                                  args=(base, key, paths, n, sum(per[:i]), self.go, self.stop, self.out))
                      for i, n in enumerate(per)]
        for p in self.procs:
            p.start()
        for _ in self.procs:
            assert self.out.get(timeout=120) == "ready"
        time.sleep(0.2)
        self.t0 = time.perf_counter()
        self.go.set()

    def finish(self) -> tuple[list[float], int, float]:
        self.stop.set()
        wall = time.perf_counter() - self.t0
        lat, errors = [], 0
        for _ in self.procs:
            part, e = self.out.get(timeout=120)
            lat.extend(part)
            errors += e
        for p in self.procs:
            p.join(30)
        return lat, errors, wall


def _wait_jobs(c: httpx.Client, ids: list[str], timeout: float) -> dict[str, dict]:
    deadline = time.monotonic() + timeout
    done: dict[str, dict] = {}
    while len(done) < len(ids):
        if time.monotonic() > deadline:
            raise TimeoutError(f"{len(ids) - len(done)} job(s) unfinished after {timeout:g} s")
        for j in ids:
            if j not in done:
                body = c.get(f"/jobs/{j}").json()
                if body["status"] not in ("queued", "running"):
                    done[j] = body
        time.sleep(0.05)
    return done


def measure(workers: int, tutor_json: str, *, jobs: int, clients: int, seconds: float, database_url: str | None,
            tmp: Path) -> dict:
    from service.topology import Stack

    stack = Stack(data_dir=tmp / f"w{workers}", workers=workers, database_url=database_url,
                  extra_env={"MOTIONX_JOB_LEASE_S": "10"})
    stack.start()
    key = stack.api_keys
    out: dict = {"workers": workers}
    try:
        with httpx.Client(base_url=stack.base_url, headers={"X-API-Key": key}, timeout=60) as c:
            r = c.post("/motions", content=tutor_json, headers={"content-type": "application/json"})
            r.raise_for_status()
            mid = r.json()["id"]
            warm = c.post(f"/motions/{mid}/extrapolate", json=BENCH_TARGET).json()["id"]
            first = _wait_jobs(c, [warm], 300)[warm]  # warms every worker's solver caches a little
            out["single_job_s"] = _job_seconds(first)
            first_step = c.get(f"/jobs/{warm}/motions").json()["items"][-1]["id"]
            # idle GETs
            paths = [f"/jobs/{warm}", f"/motions/{mid}?format=motion", f"/jobs/{warm}/motions",
                     f"/motions/{first_step}"]
            cl = _Clients(stack.base_url, key, paths, 1)
            time.sleep(min(seconds, 3.0))
            lat, errs, wall = cl.finish()
            out["get_one_client"] = {**_summary(lat, wall), "clients": 1, "errors": errs}
            cl = _Clients(stack.base_url, key, paths, clients)
            time.sleep(seconds)
            lat, errs, wall = cl.finish()
            out["get_idle"] = {**_summary(lat, wall), "clients": clients, "errors": errs,
                               "paths": ["/jobs/{id}", "/motions/{id}?format=motion", "/jobs/{id}/motions",
                                         "/motions/{id} (JSON clip)"]}
            # job throughput, with the clients polling the jobs meanwhile
            t0 = time.perf_counter()
            ids = [c.post(f"/motions/{mid}/extrapolate", json=BENCH_TARGET).json()["id"] for _ in range(jobs)]
            cl = _Clients(stack.base_url, key, [f"/jobs/{j}" for j in ids], clients)
            results = _wait_jobs(c, ids, 600)
            wall = time.perf_counter() - t0
            lat, errs, lat_wall = cl.finish()
            ok = sum(1 for b in results.values() if b["status"] == "succeeded")
            out["jobs"] = {"submitted": jobs, "succeeded": ok, "wall_s": round(wall, 2),
                           "jobs_per_s": round(ok / wall, 3), "target": BENCH_TARGET,
                           "mean_job_s": round(statistics.fmean(_job_seconds(b) for b in results.values()), 3)}
            out["get_under_load"] = {**_summary(lat, lat_wall), "clients": clients, "errors": errs}
    finally:
        stack.stop()
    return out


def _job_seconds(job: dict) -> float:
    from datetime import datetime

    def ts(s):
        return datetime.fromisoformat(s.replace("Z", "+00:00")).timestamp()

    return round(ts(job["finished_at"]) - ts(job["started_at"]), 3)


def run() -> dict:
    from service.topology import create_postgres_database, drop_postgres_database

    jobs = int(os.environ.get("MOTIONX_BENCH_JOBS", "8"))
    clients = int(os.environ.get("MOTIONX_BENCH_CLIENTS", "8"))
    seconds = float(os.environ.get("MOTIONX_BENCH_SECONDS", "5"))
    admin = os.environ.get("MOTIONX_TEST_PG_ADMIN", "postgresql://postgres@127.0.0.1:5432/postgres")
    tutor = tutor_motion_json()
    out: dict = {"clients": clients, "note": "loopback, clients and servers share the 2 cores"}
    with tempfile.TemporaryDirectory(prefix="motionx-bench-") as tmp:
        for workers in (1, 2):
            name = f"motionx_bench_{secrets.token_hex(4)}"
            try:
                url = create_postgres_database(admin, name)
                out["database"] = "postgresql"
            except Exception:  # no PostgreSQL here: the embedded SQLite
                url, name = None, None
                out["database"] = "sqlite"
            try:
                out[f"workers_{workers}"] = measure(workers, tutor, jobs=jobs, clients=clients, seconds=seconds,
                                                    database_url=url, tmp=Path(tmp))
            finally:
                if name:
                    drop_postgres_database(admin, name)
    return out
