"""``motionx demo``: the main job end to end on the embedded defaults (``make demo``).

Starts ``motionx serve`` (SQLite + local process pool) on a free port in a temporary data
directory, uploads a real captured walk over HTTP (the shared DeepMimic walk by default),
asks for two extrapolations of the same capture — a downhill slope and a curve — follows
both jobs with a progress bar, and downloads into ``--out``, per job: every λ optimum
(motion file v1, JSON clip, GLB, BVH) with its plausibility report, the progress curve and
the final motion's GRF and residual plots; then prints a short summary.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from service.cli import CliError
from service import examples
from service.topology import Proc, TopologyError, free_port, motionx_cmd, wait_api

TERMINAL = ("succeeded", "failed", "canceled", "impasse")
#: what each λ optimum is downloaded as: (query format, file suffix)
EXPORTS = (("motion", "motion.json"), ("json", "clip.json"), ("gltf", "glb"), ("bvh", "bvh"))
#: the plots of a job's final motion: (endpoint name, file)
MOTION_PLOTS = (("grf", "grf.png"), ("residuals", "residuals.png"))


def _default_trial() -> list[Path]:
    d = examples.data_dir() / "deepmimic_humanoid3d_walk"
    if d.is_dir():
        return [d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt"]
    raise CliError(f"no input given and the default trial is missing ({d}); pass trial files")


@dataclass
class _Job:
    name: str
    target: dict
    url: str = ""
    state: dict = field(default_factory=dict)

    @property
    def done(self) -> bool:
        return self.state.get("status") in TERMINAL


def _targets(args: argparse.Namespace) -> list[_Job]:
    jobs = []
    if args.slope:
        jobs.append(_Job("downhill" if args.slope < 0 else "uphill", {"slope_deg": args.slope}))
    if args.curve:
        jobs.append(_Job("curve", {"curve_deg": args.curve}))
    if not jobs:
        raise CliError("nothing to do: give a non-zero --slope and/or --curve")
    return jobs


def cmd_demo(args: argparse.Namespace) -> int:
    import httpx

    files = [Path(p) for p in args.inputs] if args.inputs else _default_trial()
    for f in files:
        if not f.is_file():
            raise CliError(f"input not found: {f}")
    jobs = _targets(args)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    port = free_port()
    key = "demo-" + os.urandom(8).hex()
    data_dir = tempfile.mkdtemp(prefix="motionx-demo-")
    env = dict(os.environ, MOTIONX_API_KEYS=key, MOTIONX_DATA_DIR=data_dir)
    env.pop("MOTIONX_DATABASE_URL", None)
    env.pop("DATABASE_URL", None)
    (out / "server.log").unlink(missing_ok=True)
    server = Proc("api", motionx_cmd("serve", "--port", str(port)), env, out / "server.log").start()
    base = f"http://127.0.0.1:{port}"
    t0 = time.perf_counter()
    try:
        try:
            wait_api(base, server, timeout=120)
        except TopologyError as e:
            raise CliError(f"the service did not start (see {out / 'server.log'}): {str(e)[:500]}") from None
        with httpx.Client(base_url=base, headers={"X-API-Key": key}, timeout=120.0) as http:
            print(f"[demo] service up at {base} (SQLite in {data_dir}, local runner)", flush=True)
            up = http.post("/motions", files=[("files", (f.name, f.read_bytes())) for f in files],
                           data={"name": "demo capture", **({"mass": str(args.mass)} if args.mass else {})})
            _check(up, 201, "upload")
            motion = up.json()
            print(f"[demo] uploaded {', '.join(f.name for f in files)} -> motion {motion['id']} "
                  f"({motion['kind']}, {motion['frames']} frames)")
            tutor = {"character": args.character, "fps": args.fps}
            for j in jobs:
                r = http.post(f"/motions/{motion['id']}/extrapolate", json={"target": j.target, "tutor": tutor},
                              headers={"Idempotency-Key": f"{key}-{j.name}"})
                _check(r, 202, f"extrapolate ({j.name})")
                j.url = r.headers["Location"]
                j.state = r.json()
                print(f"[demo] job {j.name}: {j.target} queued at {j.url}")
            _follow(http, jobs, deadline=time.monotonic() + args.timeout)
            summary = {"input": [f.name for f in files], "character": args.character, "fps": args.fps,
                       "jobs": [_download(http, j, out / j.name) for j in jobs]}
            summary["wall_time_s"] = round(time.perf_counter() - t0, 2)
            (out / "summary.json").write_text(json.dumps(summary, indent=2))
            _print_summary(summary, out)
            if args.serve:
                print(f"[demo] the web page: {base}/ui/#key={key}  (Ctrl-C stops the service)", flush=True)
                try:
                    server.proc.wait()
                except KeyboardInterrupt:
                    pass
            ok = all(j["status"] in ("succeeded", "impasse") for j in summary["jobs"])
            return 0 if ok else 1
    finally:
        server.stop()


def _check(resp, code: int, what: str) -> None:
    if resp.status_code != code:
        raise CliError(f"{what} failed: HTTP {resp.status_code} {resp.text[:500]}")


def _bar(job: _Job, width: int = 24) -> str:
    """One job's progress as text: λ bar, status, environment value reached, steps, time."""
    s = job.state
    lam = float(s.get("lam_reached") or 0.0)
    fill = round(lam * width)
    prog = s.get("progress") or []
    t = _job_time(prog)
    status = s.get("status", "?")
    if status == "running" and not any(p.get("phase") == "extrapolate" for p in prog):
        status = "tutor" if not prog else "starting"
    env = next((p.get("environment") or {} for p in reversed(prog) if p.get("accepted") and p.get("environment")), {})
    shown = [f"{k}={env[k]:.3g}" for k in job.target if k in env]
    return (f"{job.name:9s} [{'#' * fill}{'.' * (width - fill)}] λ={lam:.3f} {status:9s} "
            f"{' '.join(shown):16s} {s.get('steps', 0):2d} steps {t:5.1f}s")


def _job_time(progress: list[dict]) -> float:
    """Seconds of work in a job's progress curve: the tutor's points count from the job's
    start, the extrapolation's from its own start (after the tutor)."""
    tutor = [p["wall_time"] for p in progress if p.get("phase") == "tutor"]
    ext = [p["wall_time"] for p in progress if p.get("phase") == "extrapolate"]
    return (tutor[-1] if tutor else 0.0) + (ext[-1] if ext else 0.0)


def _follow(http, jobs: list[_Job], deadline: float) -> None:
    """Polls every job until all are finished, drawing a progress bar per job: redrawn in
    place on a terminal, one line per change otherwise (logs)."""
    tty = sys.stdout.isatty()
    last: list[str] = []
    while True:
        for j in jobs:
            if not j.done:
                r = http.get(j.url)
                _check(r, 200, "job status")
                j.state = r.json()
        lines = [_bar(j) for j in jobs]
        if tty:
            if last:
                sys.stdout.write(f"\x1b[{len(last)}F")
            sys.stdout.write("".join(f"\x1b[2K[demo] {ln}\n" for ln in lines))
            sys.stdout.flush()
        else:
            for old, new in zip(last or [""] * len(lines), lines):
                if old != new:
                    print(f"[demo] {new}", flush=True)
        last = lines
        if all(j.done for j in jobs):
            return
        if time.monotonic() > deadline:
            raise CliError("the jobs did not finish before the demo's deadline (--timeout)")
        time.sleep(0.5)


def _pages(http, url: str) -> list[dict]:
    items = []
    while url:
        page = http.get(url)
        _check(page, 200, "list motions")
        items += page.json()["items"]
        url = page.json().get("next")
    return items


def _download(http, job: _Job, out: Path) -> dict:
    """Writes a finished job's results into ``out`` and returns its summary."""
    out.mkdir(parents=True, exist_ok=True)
    s = job.state
    (out / "job.json").write_text(json.dumps(s, indent=2))
    r = http.get(f"{job.url}/plots/progress.png")
    _check(r, 200, "progress plot")
    (out / "progress.png").write_bytes(r.content)
    if s.get("tutor_motion_id"):
        r = http.get(f"/motions/{s['tutor_motion_id']}?format=motion")
        _check(r, 200, "tutor")
        (out / "tutor.motion.json").write_bytes(r.content)
    motions = _pages(http, f"{job.url}/motions?limit=200")
    reports = []
    for m in motions:
        stem = f"lambda_{m['lam']:.4f}" if m.get("lam") is not None else f"step_{m['step']}"
        for fmt, suffix in EXPORTS:
            r = http.get(f"/motions/{m['id']}?format={fmt}")
            _check(r, 200, f"export {fmt}")
            (out / f"{stem}.{suffix}").write_bytes(r.content)
        r = http.get(f"/motions/{m['id']}/validation")
        _check(r, 200, "validation")
        (out / f"{stem}.validation.json").write_text(json.dumps(r.json(), indent=2))
        reports.append(r.json())
    if motions:
        for name, file in MOTION_PLOTS:
            r = http.get(f"/motions/{motions[-1]['id']}/plots/{name}.png")
            _check(r, 200, f"{name} plot")
            (out / f"final.{file}").write_bytes(r.content)
    prog = s.get("progress") or []
    env = next((p.get("environment") or {} for p in reversed(prog) if p.get("accepted") and p.get("environment")), {})
    return {
        "name": job.name, "target": job.target, "status": s["status"], "message": s.get("message") or "",
        "lambda_reached": s.get("lam_reached"),
        "reached": {k: env[k] for k in job.target if k in env},
        "motions": len(motions), "solves": s.get("solves"),
        "job_time_s": round(_job_time(prog), 2),
        "plausible": sum(bool(rep.get("plausible")) for rep in reports),
        "max_root_residual_rel_weight": max((rep["root_residual"]["max_force_rel_weight"] for rep in reports),
                                            default=None),
        "max_mujoco_agreement_rel_weight": max(
            (rep["mujoco_replay"]["agreement_force_rel_weight"] for rep in reports), default=None),
        "dir": str(out),
    }


def _print_summary(summary: dict, out: Path) -> None:
    print(f"[demo] {'job':9s} {'status':9s} {'λ':>6s} {'reached':>18s} {'motions':>7s} {'plausible':>9s} "
          f"{'time':>6s} {'max residual/weight':>19s}")
    for j in summary["jobs"]:
        reached = ", ".join(f"{k} {v:.3g}" for k, v in j["reached"].items())
        res = j["max_root_residual_rel_weight"]
        print(f"[demo] {j['name']:9s} {j['status']:9s} {j['lambda_reached']:6.3f} {reached:>18s} "
              f"{j['motions']:7d} {j['plausible']:>4d}/{j['motions']:<4d} {j['job_time_s']:5.1f}s "
              f"{res if res is None else format(res, '.1e'):>19s}")
    print(f"[demo] total {summary['wall_time_s']:.1f} s; every λ motion (motion file, JSON clip, GLB, BVH, "
          f"plausibility) and the plots are in {out}/ (summary.json)")


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("demo", help="the main job end to end through the embedded service (make demo)")
    s.add_argument("inputs", nargs="*", help="trial files (default: the shared DeepMimic walk)")
    s.add_argument("--out", default="out/demo", help="where results are written")
    s.add_argument("--slope", type=float, default=-11.25, help="target slope in degrees (negative = downhill; 0 = none)")
    s.add_argument("--curve", type=float, default=90.0, help="target curve in degrees (positive = left; 0 = none)")
    s.add_argument("--character", choices=["halfboy", "fullbody"], default="halfboy")
    s.add_argument("--fps", type=float, default=15.0)
    s.add_argument("--mass", type=float, default=None, help="subject mass (kg) if the input lacks it")
    s.add_argument("--timeout", type=float, default=900.0, help="seconds to wait for the jobs")
    s.add_argument("--serve", action="store_true", help="keep the service running afterwards and print the web "
                   "page's address (Ctrl-C stops it)")
    s.set_defaults(func=cmd_demo)
