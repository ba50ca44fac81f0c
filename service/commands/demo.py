"""``motionx demo``: the main job end to end on the embedded defaults (``make demo``).

Starts ``motionx serve`` (SQLite + local process pool) on a free port in a temporary data
directory, uploads a real captured walk over HTTP, asks for an extrapolation (uphill 11.25°
by default, HalfBoy at 15 frames/s), follows the job's progress curve, and downloads the
tutor and every λ optimum (motion file v1, JSON clip, glTF, BVH) with its plausibility
report into ``--out``.
"""

from __future__ import annotations

import argparse
import json
import os
import socket
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from service.cli import CliError


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _default_trial() -> list[Path]:
    env = os.environ.get("MOTIONX_DATA")
    roots = [Path(env)] if env else []
    roots += [Path(__file__).resolve().parents[3] / "shared" / "data", Path("/work/shared/data")]
    for root in roots:
        d = root / "deepmimic_humanoid3d_walk"
        if d.is_dir():
            return [d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt"]
    raise CliError("no input given and the shared walking data was not found (set MOTIONX_DATA or pass files)")


def cmd_demo(args: argparse.Namespace) -> int:
    import httpx

    files = [Path(p) for p in args.inputs] if args.inputs else _default_trial()
    for f in files:
        if not f.is_file():
            raise CliError(f"input not found: {f}")
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    port = _free_port()
    key = "demo-" + os.urandom(8).hex()
    data_dir = tempfile.mkdtemp(prefix="motionx-demo-")
    env = dict(os.environ, MOTIONX_API_KEYS=key, MOTIONX_DATA_DIR=data_dir)
    env.pop("MOTIONX_DATABASE_URL", None)
    env.pop("DATABASE_URL", None)
    exe = Path(sys.executable).with_name("motionx")
    log = open(out / "server.log", "w")
    server = subprocess.Popen([str(exe), "serve", "--port", str(port)], env=env, stdout=log, stderr=subprocess.STDOUT)
    base = f"http://127.0.0.1:{port}"
    t0 = time.perf_counter()
    try:
        with httpx.Client(base_url=base, headers={"X-API-Key": key}, timeout=60.0) as http:
            _wait_ready(http, server, deadline=time.monotonic() + 120)
            print(f"[demo] service up at {base} (SQLite in {data_dir}, local runner)", flush=True)
            up = http.post("/motions", files=[("files", (f.name, f.read_bytes())) for f in files],
                           data={"name": "demo capture", **({"mass": str(args.mass)} if args.mass else {})})
            _check(up, 201, "upload")
            motion = up.json()
            print(f"[demo] uploaded {', '.join(f.name for f in files)} -> motion {motion['id']} ({motion['kind']})")
            body = {"target": {"slope_deg": args.slope, "curve_deg": args.curve},
                    "tutor": {"character": args.character, "fps": args.fps}}
            job = http.post(f"/motions/{motion['id']}/extrapolate", json=body, headers={"Idempotency-Key": key})
            _check(job, 202, "extrapolate")
            loc = job.headers["Location"]
            print(f"[demo] job queued at {loc}: {body['target']}")
            status = _follow(http, loc, deadline=time.monotonic() + args.timeout)
            motions = []
            url = f"{loc}/motions?limit=200"
            while url:
                page = http.get(url)
                _check(page, 200, "list motions")
                motions += page.json()["items"]
                url = page.json().get("next")
            for m in motions:
                stem = f"lambda_{m['lam']:.4f}" if m.get("lam") is not None else f"step_{m['step']}"
                (out / f"{stem}.motion.json").write_bytes(http.get(f"/motions/{m['id']}?format=motion").content)
            summary = {"status": status["status"], "lambda_reached": status.get("lam_reached"),
                       "steps": len(motions), "job": status.get("id"), "wall_time_s": round(time.perf_counter() - t0, 2)}
            if motions:
                last = motions[-1]["id"]
                for fmt, ext in (("json", "clip.json"), ("gltf", "gltf"), ("bvh", "bvh")):
                    r = http.get(f"/motions/{last}?format={fmt}")
                    _check(r, 200, f"export {fmt}")
                    (out / f"final.{ext}").write_bytes(r.content)
                val = http.get(f"/motions/{last}/validation")
                _check(val, 200, "validation")
                rep = val.json()
                (out / "final.validation.json").write_text(json.dumps(rep, indent=2))
                summary["final_plausible"] = rep.get("plausible")
                summary["final_root_residual_rel_weight"] = rep["root_residual"]["max_force_rel_weight"]
                summary["final_mujoco_agreement_rel_weight"] = rep["mujoco_replay"]["agreement_force_rel_weight"]
            if status.get("tutor_motion_id"):
                (out / "tutor.motion.json").write_bytes(
                    http.get(f"/motions/{status['tutor_motion_id']}?format=motion").content)
            (out / "job.json").write_text(json.dumps(status, indent=2))
            (out / "summary.json").write_text(json.dumps(summary, indent=2))
            print(f"[demo] {json.dumps(summary)}")
            print(f"[demo] results in {out}/")
            return 0 if status["status"] in ("succeeded", "impasse") else 1
    finally:
        server.terminate()
        try:
            server.wait(timeout=20)
        except subprocess.TimeoutExpired:
            server.kill()
        log.close()


def _check(resp, code: int, what: str) -> None:
    if resp.status_code != code:
        raise CliError(f"{what} failed: HTTP {resp.status_code} {resp.text[:500]}")


def _wait_ready(http, server, deadline: float) -> None:
    import httpx

    while time.monotonic() < deadline:
        if server.poll() is not None:
            raise CliError("the service exited at start (see server.log)")
        try:
            if http.get("/health").status_code == 200:
                return
        except httpx.HTTPError:
            pass
        time.sleep(0.3)
    raise CliError("the service did not start in time (see server.log)")


def _follow(http, loc: str, deadline: float) -> dict:
    seen = 0
    while time.monotonic() < deadline:
        r = http.get(loc)
        _check(r, 200, "job status")
        job = r.json()
        prog = job.get("progress") or []
        for p in prog[seen:]:
            mark = "ok" if p.get("accepted") else "retry"
            print(f"[demo]   {p.get('phase', ''):11s} λ={p.get('lam', 0):.3f} {mark:5s} {p.get('iterations')} it "
                  f"reached {p.get('lam_reached', 0):.3f} t={p.get('wall_time', 0):.2f}s", flush=True)
        seen = len(prog)
        if job["status"] in ("succeeded", "failed", "canceled", "impasse"):
            print(f"[demo] job {job['status']}: λ reached {job.get('lam_reached')} {job.get('message') or ''}")
            return job
        time.sleep(0.5)
    raise CliError("the job did not finish before the demo's deadline")


def register(sub: argparse._SubParsersAction) -> None:
    s = sub.add_parser("demo", help="the main job end to end through the embedded service (make demo)")
    s.add_argument("inputs", nargs="*", help="trial files (default: the shared DeepMimic walk)")
    s.add_argument("--out", default="out/demo", help="where results are written")
    s.add_argument("--slope", type=float, default=11.25, help="target slope in degrees (positive uphill)")
    s.add_argument("--curve", type=float, default=0.0, help="target curve in degrees")
    s.add_argument("--character", choices=["halfboy", "fullbody"], default="halfboy")
    s.add_argument("--fps", type=float, default=15.0)
    s.add_argument("--mass", type=float, default=None, help="subject mass (kg) if the input lacks it")
    s.add_argument("--timeout", type=float, default=900.0, help="seconds to wait for the job")
    s.set_defaults(func=cmd_demo)
