"""Sharing the service: what key B sees while key A loads the service, as figures.

Not a section of ``make bench`` (it runs for several minutes): ``python -m bench.sharing [--only
heavy jobs storage gets]``, one JSON object on stdout. Each part starts its own ``motionx serve``
(the embedded default: SQLite, local runner, default settings but the API keys) on loopback:

- ``heavy``: A uploads two 29,000-frame motions (250 fps: 116 s, within the capture limits),
  then asks for their two filmstrips and 40 exports at once (distinct formats and options, so
  no cache or single flight answers them); meanwhile B uploads a small motion and exports it,
  again and again. Reported: B's latencies and statuses, A's statuses (429 with Retry-After).
  The 40 exports are 24 distinct ones (12 option sets x 2 motions); the repeats share a
  computation but count against A's quota of heavy requests like any request.
- ``jobs``: A starts 12 simulations of 100 cycles (12 tutors), then B starts a job: the delay
  from B's POST to its job's start (A's simulations are cancelled after).
- ``storage``: the database's live bytes (SQLite pages in use) and B's usage before a motion,
  with it (a job, its λ optima and a simulation) and after DELETE.
- ``gets``: p50 / p99 of GETs from 50 concurrent clients (4 processes), with the load average.
- ``faults``: on a PostgreSQL server of its own (``service.topology.PostgresServer``), four
  clients poll while the server is stopped for 3 s and started again and two jobs run; then the
  compute processes are SIGKILLed under three filmstrip requests. Reported: every status seen (no
  500), 503s without Retry-After, the jobs' ends and their λ optima (each step once).
"""

from __future__ import annotations

import argparse
import json
import os
import secrets
import sqlite3
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

import httpx

from bench.service import _Clients, _summary, tutor_motion_json

KEY_A, KEY_B = "bench-a-" + secrets.token_hex(6), "bench-b-" + secrets.token_hex(6)
JSON = {"content-type": "application/json"}


class Serve:
    def __init__(self, root: Path, env: dict[str, str] | None = None) -> None:
        from service.topology import Proc, free_port, motionx_cmd, wait_api

        self.dir = root
        port = free_port()
        e = dict(os.environ, MOTIONX_DATA_DIR=str(root), MOTIONX_API_KEYS=f"{KEY_A},{KEY_B}", PYTHONUNBUFFERED="1")
        e.pop("DATABASE_URL", None)
        e.update(env or {})
        self.proc = Proc("api", motionx_cmd("serve", "--port", str(port)), e, root / "api.log").start()
        self.base = f"http://127.0.0.1:{port}"
        wait_api(self.base, self.proc, timeout=120)
        self.a = httpx.Client(base_url=self.base, headers={"X-API-Key": KEY_A}, timeout=600)
        self.b = httpx.Client(base_url=self.base, headers={"X-API-Key": KEY_B}, timeout=600)

    def close(self) -> None:
        self.a.close()
        self.b.close()
        self.proc.stop()


def _motion(T: int, fps: float, seed: int) -> str:
    import numpy as np

    from solver.character import reference
    from solver.motion import Motion

    ch = reference("halfboy")
    q = 0.05 * np.random.default_rng(seed).standard_normal((ch.n, T))
    q[ch.index("root_tz")] += 0.9
    return Motion(character=ch, fps=fps, q=q, reference_name="halfboy", provenance={"step": "capture"}).to_json()


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def heavy(root: Path) -> dict:
    s = Serve(root)
    try:
        t = time.perf_counter()
        big = [s.a.post("/motions", content=_motion(29_000, 250.0, seed), headers=JSON) for seed in (1, 2)]
        upload_s = round(time.perf_counter() - t, 1)
        assert all(r.status_code == 201 for r in big), [r.text[:300] for r in big]
        ids = [r.json()["id"] for r in big]
        small = _motion(12, 15.0, 3)
        paths = [f"/motions/{m}/plots/filmstrip.png" for m in ids]
        opts = [f"format=json&decimals={d}" for d in range(1, 7)] + [f"format=bvh&units={u}" for u in ("cm", "m")]
        opts += ["format=gltf", "format=gltf&binary=false", "format=json&y_up=true", "format=bvh&decimals=4"]
        while len(paths) < 42:
            m = ids[len(paths) % 2]
            paths.append(f"/motions/{m}?{opts[(len(paths) // 2) % len(opts)]}")  # 24 distinct, repeats share
        a_out: list[tuple[int, float, str | None]] = []
        lock = threading.Lock()

        def a_get(p: str) -> None:
            t0 = time.perf_counter()
            r = s.a.get(p)
            with lock:
                a_out.append((r.status_code, time.perf_counter() - t0, r.headers.get("retry-after")))

        b_out: list[tuple[str, int, float]] = []
        stop = threading.Event()

        def b_loop() -> None:
            while not stop.is_set():
                t0 = time.perf_counter()
                r = s.b.post("/motions", content=small, headers=JSON)
                b_out.append(("upload", r.status_code, time.perf_counter() - t0))
                if r.status_code == 201:
                    t0 = time.perf_counter()
                    e = s.b.get(f"/motions/{r.json()['id']}?format=bvh")
                    b_out.append(("export", e.status_code, time.perf_counter() - t0))
                time.sleep(1.0)

        load0 = _load()
        threads = [threading.Thread(target=a_get, args=(p,)) for p in paths]
        tb = threading.Thread(target=b_loop)
        t = time.perf_counter()
        for th in threads:
            th.start()
        time.sleep(0.5)
        tb.start()
        for th in threads:
            th.join()
        a_wall = time.perf_counter() - t
        stop.set()
        tb.join()
        codes: dict[str, int] = {}
        for c, _, _ in a_out:
            codes[str(c)] = codes.get(str(c), 0) + 1
        lat = [x for _, c, x in b_out]
        return {
            "a_uploads_s": upload_s, "a_requests": len(a_out), "a_statuses": codes,
            "a_429_with_retry_after": sum(1 for c, _, ra in a_out if c == 429 and ra),
            "a_wall_s": round(a_wall, 1),
            "a_200_s": sorted(round(x, 1) for c, x, _ in a_out if c == 200),
            "b_requests": len(b_out), "b_statuses": sorted({c for _, c, _ in b_out}),
            "b_max_s": round(max(lat), 2), "b_median_s": round(statistics.median(lat), 2),
            "b_max_upload_s": round(max(x for k, _, x in b_out if k == "upload"), 2),
            "b_max_export_s": round(max((x for k, _, x in b_out if k == "export"), default=float("nan")), 2),
            "load_before": load0, "load_after": _load(),
        }
    finally:
        s.close()


def jobs(root: Path, tutor: str) -> dict:
    s = Serve(root)
    try:
        tutors = [s.a.post("/motions", content=tutor, headers=JSON).json()["id"] for _ in range(12)]
        sims = [s.a.post(f"/motions/{m}/simulation", json={"cycles": 100}) for m in tutors]
        assert all(r.status_code == 202 for r in sims), [r.text[:200] for r in sims]
        time.sleep(2.0)
        tb = s.b.post("/motions", content=tutor, headers=JSON).json()["id"]
        load0 = _load()
        t0 = time.time()
        job = s.b.post(f"/motions/{tb}/extrapolate", json={"target": {"friction": 0.7}, "control": {"delta0": 0.5}})
        assert job.status_code == 202, job.text
        jid = job.json()["id"]
        while True:
            j = s.b.get(f"/jobs/{jid}").json()
            if j["started_at"] is not None:
                break
            if time.time() - t0 > 600:
                raise RuntimeError("B's job did not start within 600 s")
            time.sleep(0.2)
        from datetime import datetime

        delay = datetime.fromisoformat(j["started_at"]).timestamp() - t0
        health = s.a.get("/health").json()["saturation"]
        for r in sims:
            s.a.post(f"/jobs/{r.json()['job_id']}/cancel")
        return {"a_simulations": len(sims), "b_job_start_delay_s": round(delay, 2), "saturation": health,
                "load": load0}
    finally:
        s.close()


def _live_bytes(db: Path) -> int:
    with sqlite3.connect(db) as c:
        page = c.execute("PRAGMA page_size").fetchone()[0]
        return (c.execute("PRAGMA page_count").fetchone()[0] - c.execute("PRAGMA freelist_count").fetchone()[0]) * page


def storage(root: Path, tutor: str) -> dict:
    s = Serve(root)
    try:
        s.b.post("/motions", content=_motion(60, 15.0, 5), headers=JSON)  # something else stored
        db = root / "motionx.db"
        before, usage0 = _live_bytes(db), s.b.get("/usage").json()["storage_bytes"]
        tid = s.b.post("/motions", content=tutor, headers=JSON).json()["id"]
        jid = s.b.post(f"/motions/{tid}/extrapolate", json={"target": {"friction": 0.7}, "control": {"delta0": 0.5},
                                                            "simulate_cycles": 5}).json()["id"]
        while s.b.get(f"/jobs/{jid}").json()["status"] in ("queued", "running"):
            time.sleep(0.5)
        with_it, usage1 = _live_bytes(db), s.b.get("/usage").json()["storage_bytes"]
        assert s.b.delete(f"/motions/{tid}").status_code == 204
        after, usage2 = _live_bytes(db), s.b.get("/usage").json()["storage_bytes"]
        return {"db_live_bytes": [before, with_it, after], "db_after_vs_before": round(after / before - 1, 4),
                "usage_bytes": [usage0, usage1, usage2]}
    finally:
        s.close()


def gets(root: Path, tutor: str, clients: int = 50, seconds: float = 10.0) -> dict:
    s = Serve(root)
    try:
        tid = s.b.post("/motions", content=tutor, headers=JSON).json()["id"]
        jid = s.b.post(f"/motions/{tid}/extrapolate", json={"target": {"friction": 0.7}, "control": {"delta0": 0.5}}
                       ).json()["id"]
        while s.b.get(f"/jobs/{jid}").json()["status"] in ("queued", "running"):
            time.sleep(0.5)
        paths = [f"/jobs/{jid}", f"/motions/{tid}?format=motion", f"/jobs/{jid}/motions", f"/motions/{tid}",
                 "/motions?limit=10"]
        for p in paths:  # the JSON clip computed once (then cached): 50 clients asking it at once would pass the
            s.b.get(p)  # key's quota of heavy requests in flight (429), which is not what is measured here
        load0 = _load()
        cl = _Clients(s.base, KEY_B, paths, clients)
        time.sleep(seconds)
        lat, errors, wall = cl.finish()
        return {"clients": clients, **_summary(lat, wall), "errors": errors, "load_before": load0,
                "load_after": _load()}
    finally:
        s.close()


def faults(root: Path, tutor: str) -> dict:
    import signal

    from service.topology import PostgresServer, create_postgres_database

    pg = PostgresServer().init()
    pg.start()
    try:
        url = create_postgres_database(pg.admin_url, "motionx_faults", exist_ok=False)
        s = Serve(root, {"DATABASE_URL": url})
        try:
            tid = s.a.post("/motions", content=tutor, headers=JSON).json()["id"]
            longs = [s.a.post("/motions", content=_motion(8000, 100.0, 20 + k), headers=JSON).json()["id"]
                     for k in range(3)]
            jobs = [s.a.post(f"/motions/{tid}/extrapolate", json=body).json()["id"] for body in (
                {"target": {"friction": 0.7}, "control": {"delta0": 0.5}},
                {"target": {"slope_deg": 4.0}, "control": {"delta0": 0.25}})]
            seen: dict[str, int] = {}
            missing_retry = [0]
            stop = threading.Event()
            lock = threading.Lock()

            def note(r: httpx.Response) -> None:
                with lock:
                    seen[str(r.status_code)] = seen.get(str(r.status_code), 0) + 1
                    if r.status_code == 503 and not r.headers.get("retry-after"):
                        missing_retry[0] += 1

            def poll() -> None:
                with httpx.Client(base_url=s.base, headers={"X-API-Key": KEY_A}, timeout=60) as c:
                    while not stop.is_set():
                        for p in (f"/motions/{tid}", f"/jobs/{jobs[0]}", "/motions?limit=5", "/usage", "/jobs"):
                            note(c.get(p))

            pollers = [threading.Thread(target=poll) for _ in range(4)]
            for t in pollers:
                t.start()
            time.sleep(1.0)
            t0 = time.perf_counter()
            pg.stop()
            time.sleep(3.0)
            pg.start()
            restart_s = round(time.perf_counter() - t0, 1)
            time.sleep(3.0)
            killed: list[int] = []
            for mid in longs:  # a compute process killed under a request
                res: list[httpx.Response] = []
                th = threading.Thread(target=lambda m=mid: res.append(s.a.get(f"/motions/{m}/plots/filmstrip.png")))
                th.start()
                while s.a.get("/health").json()["saturation"]["compute"]["running"] == 0 and th.is_alive():
                    time.sleep(0.05)
                for pid in _compute_pids(s.proc.pid):
                    os.kill(pid, signal.SIGKILL)
                    killed.append(pid)
                th.join()
                note(res[0])
            stop.set()
            for t in pollers:
                t.join()
            ends = {}
            for j in jobs:
                while (job := s.a.get(f"/jobs/{j}").json())["status"] in ("queued", "running"):
                    time.sleep(0.5)
                steps = [m["step"] for m in s.a.get(f"/jobs/{j}/motions?limit=1000").json()["items"]]
                ends[j] = {"status": job["status"], "attempts": job["attempts"], "steps": job["steps"],
                           "each_step_once": steps == list(range(job["steps"]))}
            log = s.proc.log_text()
            return {"statuses": seen, "503_without_retry_after": missing_retry[0], "pg_outage_s": restart_s,
                    "compute_processes_killed": len(killed), "jobs": ends,
                    "unhandled_errors_in_log": log.count("unhandled error on")}
        finally:
            s.close()
    finally:
        pg.remove()


def _compute_pids(api_pid: int) -> list[int]:
    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
                with open(f"/proc/{d}/cmdline", "rb") as f:
                    cmd = f.read()
            except (OSError, ValueError, IndexError):
                continue
            if ppid == api_pid and b"service.procpool" in cmd and b"service.uploads" in cmd:
                out.append(int(d))
    return out


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--only", nargs="*", default=["heavy", "jobs", "storage", "gets", "faults"])
    args = p.parse_args()
    out: dict = {"cpus": os.cpu_count()}
    tutor = tutor_motion_json() if set(args.only) - {"heavy"} else ""
    with tempfile.TemporaryDirectory(prefix="motionx-sharing-") as d:
        for name in args.only:
            root = Path(d) / name
            root.mkdir()
            fn = {"heavy": lambda r: heavy(r), "jobs": lambda r: jobs(r, tutor), "storage": lambda r: storage(r, tutor),
                  "gets": lambda r: gets(r, tutor), "faults": lambda r: faults(r, tutor)}[name]
            t = time.perf_counter()
            out[name] = fn(root)
            out[name]["wall_s"] = round(time.perf_counter() - t, 1)
            print(json.dumps({name: out[name]}), file=sys.stderr, flush=True)
    print(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
