"""``motionx demo``: the main job end to end on the embedded defaults (``make demo``).

Starts ``motionx serve`` (SQLite + local process pool) on a free port in a temporary data
directory, uploads a real captured walk over HTTP (the DeepMimic walk shipped in ``data/``
by default) and queues, on that one capture: a downhill slope, a full-body walk up a small
slope (the ``fullbody`` character), a curve and stairs, then a small motion library (3 slopes ×
3 curves, one job per cell, queued with them so that the workers never idle). The service makes
each tutor once (``service.store.claim_tutor``): the first job makes the HalfBoy tutor while the
full-body job makes its own beside it, and every other job and cell takes the stored tutor
(waiting for it while it is being made). The demo follows the jobs with a progress bar and
downloads into ``--out``, per job: every λ optimum (``step_NNN_lambda_L.motion.json``,
``.clip.json``, ``.glb``, ``.bvh``, ``.validation.json``, named as ``motionx extrapolate`` names
them; the full-body job's also on the input's own rig — for a DeepMimic input ``.rig.glb``,
its character's skeleton and shapes skinned, and ``.deepmimic.txt``, a DeepMimic motion for the
same character file; ``.rig.glb`` and ``.rig.bvh`` for a BVH input), ``progress.csv`` and
``progress.png``, and the final motion's GRF, residual and filmstrip plots; then the library's
``library/manifest.json`` and ``library/library.glb`` (one looping animation per cell;
``--no-library`` skips it); then prints a short summary, with which job made each tutor and
which took it from the store (``summary.json``: ``tutors``).

Ctrl-C or SIGTERM while the jobs run cancels them (each stops at its next IPOPT iteration),
downloads what they reached into ``--out`` with ``summary.json`` saying "canceled", and exits
130 (143). The service is stopped (its whole process group, waited for) when the demo ends,
fails, or receives Ctrl-C or SIGTERM; the temporary data directory is removed unless ``--keep-temp``.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path

from tqdm import tqdm

from service import examples
from service.cli import (
    CliError,
    Terminated,
    add_command,
    add_import_options,
    cancel_on_signals,
    import_options,
    stop_on_signals,
)
from service.commands.outputs import written_here
from service.topology import Proc, TopologyError, free_port, motionx_cmd, wait_api
from solver.outputs import progress_csv, step_stem
from solver.status import TERMINAL, Status

#: what each λ optimum is downloaded as: (export query, file suffix)
EXPORTS = (("format=motion", "motion.json"), ("format=json", "clip.json"), ("format=gltf", "glb"),
           ("format=bvh", "bvh"))
#: what the full-body job's λ optima are downloaded as too: on the input's own rig (its skeleton
#: and shapes), by the upload's input format (its ``input.format``); other inputs: none
SOURCE_RIG_EXPORTS = {
    "deepmimic": (("format=gltf&rig=source", "rig.glb"), ("format=deepmimic", "deepmimic.txt")),
    "bvh": (("format=gltf&rig=source", "rig.glb"), ("format=bvh&rig=source", "rig.bvh")),
}
#: the plots of a job's final motion: (endpoint name, file)
MOTION_PLOTS = (("grf", "grf.png"), ("residuals", "residuals.png"), ("filmstrip", "filmstrip.png"))
#: the demo's walk, in the trials folder (``service.examples.data_dir()``)
DEMO_TRIAL = ("deepmimic_humanoid3d_walk", ("humanoid3d_walk.txt", "humanoid3d_character.txt"))
JOB_NAMES = ("downhill", "uphill", "fullbody", "curve", "stairs")
#: without a terminal, a running job's progress line is repeated this often (its clock moves)
LOG_EVERY_S = 5.0
#: after Ctrl-C or SIGTERM, how long the canceled jobs are given to stop (each stops at its next
#: IPOPT iteration) before what they reached is downloaded
CANCEL_GRACE_S = 60.0
#: a summary's status from its jobs' and library's: the first of these found, else succeeded
WORST_FIRST = ("canceled", "failed", "impasse")


def _default_trial() -> list[Path]:
    folder, names = DEMO_TRIAL
    d = examples.data_dir() / folder
    files = [d / n for n in names]
    if all(f.is_file() for f in files):
        return files
    raise CliError(f"no input given and the demo walk is not in {d} (the repository's data/ folder, or "
                   f"$MOTIONX_DATA/{folder}); pass trial files, or set MOTIONX_DATA to a folder that holds {folder}/")


@dataclass
class _Job:
    name: str
    target: dict
    tutor: dict  # the job's tutor options (character, fps)
    url: str = ""
    rig_exports: tuple[tuple[str, str], ...] = ()  # (export query, file suffix) on the input's own rig
    state: dict = field(default_factory=dict)
    started: float | None = None  # time.monotonic() when first seen running
    finished: float | None = None  # ... and finished

    @property
    def done(self) -> bool:
        return self.state.get("status") in TERMINAL

    def seen(self, state: dict) -> None:
        """Records a polled state and the local clock of the job: it starts when the job is
        first seen running (or finished) and stops when it is seen finished."""
        self.state = state
        now = time.monotonic()
        if self.started is None and state.get("status") not in ("queued", None):
            self.started = now
        if self.finished is None and self.done:
            self.finished = now

    @property
    def elapsed(self) -> float:
        if self.started is None:
            return 0.0
        return (self.finished or time.monotonic()) - self.started


def _targets(args: argparse.Namespace) -> list[_Job]:
    """The jobs in the order they are queued: the full-body job second, so that its own tutor
    is made beside the first job's (the other jobs and the library cells share that one)."""
    tutor = {"character": args.character, "fps": args.fps}
    jobs = []
    if args.slope:
        jobs.append(_Job("downhill" if args.slope < 0 else "uphill", {"slope_deg": args.slope}, tutor))
    if args.curve:
        jobs.append(_Job("curve", {"curve_deg": args.curve}, tutor))
    if args.step_height:
        jobs.append(_Job("stairs", {"step_height_m": args.step_height}, tutor))
    if args.fullbody_slope:
        jobs.insert(1, _Job("fullbody", {"slope_deg": args.fullbody_slope}, {"character": "fullbody", "fps": args.fps}))
    if not jobs:
        raise CliError("nothing to do: give a non-zero --slope, --curve, --step-height and/or --fullbody-slope")
    return jobs


def _clear_earlier_run(out: Path) -> None:
    """Removes what an earlier demo wrote into ``out`` (its job folders' files, its summary),
    so that no stale λ files sit next to this run's; anything else stays."""
    for name in JOB_NAMES:
        if (out / name).is_dir():
            for p in written_here(out / name):
                p.unlink()
    (out / "summary.json").unlink(missing_ok=True)


def _upload_fields(args: argparse.Namespace) -> dict[str, str]:
    """The importer options given as the upload's form fields (POST /motions)."""
    fields = {}
    for name, v in import_options(args).items():
        if name == "belt_speed" and v == "auto":
            raise CliError("--belt-speed auto is not taken by the service: give the belt speed in m/s")
        if name == "markers":
            from solver.io.c3d.markers import parse_mapping

            try:
                v = ",".join(f"{role}={label}" for role, label in parse_mapping(v).items())
            except ValueError as e:
                raise CliError(f"--markers: {e}") from None
        fields[name] = str(v).lower() if isinstance(v, bool) else str(v)
    return fields


def cmd_demo(args: argparse.Namespace) -> int:
    files = [Path(p) for p in args.inputs] if args.inputs else _default_trial()
    for f in files:
        if not f.is_file():
            raise CliError(f"input not found: {f}")
    jobs = _targets(args)
    args.form = _upload_fields(args)
    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {out} exists and is not a directory")
    out.mkdir(parents=True, exist_ok=True)
    _clear_earlier_run(out)
    with stop_on_signals() as guard:
        data_dir = tempfile.mkdtemp(prefix="motionx-demo-")
        server = None
        try:
            port = free_port()
            key = "demo-" + os.urandom(8).hex()
            env = dict(os.environ, MOTIONX_API_KEYS=key, MOTIONX_DATA_DIR=data_dir)
            env.pop("MOTIONX_DATABASE_URL", None)
            env.pop("DATABASE_URL", None)
            (out / "server.log").unlink(missing_ok=True)
            server = Proc("api", motionx_cmd("serve", "--port", str(port)), env, out / "server.log").start()
            return _run(args, files, jobs, out, server, f"http://127.0.0.1:{port}", key, data_dir)
        finally:
            # a second Ctrl-C or SIGTERM must not cut the cleanup short; it is bounded: SIGTERM
            # to the service's process group, waited for, SIGKILL after 20 s
            guard.shield()
            if server is not None:
                server.stop()
            if args.keep_temp:
                print(f"[demo] kept the service's data directory {data_dir} (--keep-temp)", flush=True)
            else:
                shutil.rmtree(data_dir, ignore_errors=True)


def _run(args, files: list[Path], jobs: list[_Job], out: Path, server: Proc, base: str, key: str,
         data_dir: str) -> int:
    import httpx

    t0 = time.perf_counter()
    try:
        wait_api(base, server, timeout=120)
    except TopologyError as e:
        raise CliError(f"the service did not start (see {out / 'server.log'}): {str(e)[:500]}") from None
    with httpx.Client(base_url=base, headers={"X-API-Key": key}, timeout=120.0) as http:
        print(f"[demo] service up at {base} (SQLite in {data_dir}, local runner)", flush=True)
        # from here Ctrl-C or SIGTERM cancels the jobs (each stops at its next IPOPT iteration) and
        # what they reached is downloaded into --out, summary.json saying "canceled"
        with cancel_on_signals() as cancel:
            summary = _work(args, http, files, jobs, out, key, t0, cancel)
        if cancel.exit_status is not None:
            print(f"[demo] {cancel.reason}: stopped; what the jobs reached is in {out}/ (summary.json)", flush=True)
            return cancel.exit_status
        ok = Status(summary["status"]).ok
        if args.serve:
            print(f"[demo] the web page: {base}/ui/#key={key}  (Ctrl-C or SIGTERM stops the service)", flush=True)
            try:
                server.proc.wait()
                print(f"[demo] the service exited (status {server.proc.returncode}); see {out / 'server.log'}",
                      file=sys.stderr)
                return 1
            except (KeyboardInterrupt, Terminated):
                print("[demo] stopping the service", flush=True)
        return 0 if ok else 1


def _work(args, http, files: list[Path], jobs: list[_Job], out: Path, key: str, t0: float, cancel) -> dict:
    """Upload, queue the jobs and the library, follow them and download what they reached into
    ``out``; ``cancel()`` true (Ctrl-C, SIGTERM): nothing more is queued, the unfinished jobs are
    canceled, and what they reached is downloaded. Returns the summary it writes."""
    up = http.post("/motions", files=[("files", (f.name, f.read_bytes())) for f in files],
                   data={"name": "demo capture", **args.form})
    _check(up, 201, "upload")
    motion = up.json()
    print(f"[demo] uploaded {', '.join(f.name for f in files)} -> motion {motion['id']} "
          f"({motion['kind']}, {motion['frames']} frames)")
    tutor = {"character": args.character, "fps": args.fps}
    rig_format = (motion.get("input") or {}).get("format")
    for j in jobs:
        if j.name == "fullbody":
            j.rig_exports = SOURCE_RIG_EXPORTS.get(rig_format, ())
            if not j.rig_exports:
                print(f"[demo] job fullbody: the demo exports onto the input's own rig for "
                      f"{' and '.join(SOURCE_RIG_EXPORTS)} inputs, not {rig_format or 'a motion file'}: its results "
                      "come out on the synthesis character only")
    for j in jobs:
        if cancel():
            break
        r = http.post(f"/motions/{motion['id']}/extrapolate", json={"target": j.target, "tutor": j.tutor},
                      headers={"Idempotency-Key": f"{key}-{j.name}"})
        _check(r, 202, f"extrapolate ({j.name})")
        j.url = r.headers["Location"]
        j.seen(r.json())
        print(f"[demo] job {j.name}: {j.target} on {j.tutor['character']} queued at {j.url}")
    # the library's cells queue behind the jobs: a worker freed by a short job takes a cell
    library = _queue_library(http, motion["id"], tutor) if args.library and not cancel() else None
    queued = [j for j in jobs if j.url]
    _follow(http, queued, deadline=time.monotonic() + args.timeout, cancel=cancel)
    if cancel() and library is not None:  # its cells stop too while the jobs' results are downloaded
        http.post(f"/libraries/{library['id']}/cancel")
    summary = {"input": [f.name for f in files], "character": args.character, "fps": args.fps,
               "jobs": [_download(http, j, out / j.name) for j in queued]}
    if library is not None:
        summary["library"] = _library(http, library, out / "library", t0,
                                      deadline=time.monotonic() + args.timeout, cancel=cancel)
    summary["tutors"] = _tutors(http, queued, library)
    summary["wall_time_s"] = round(time.perf_counter() - t0, 2)
    found = {j["status"] for j in summary["jobs"]} | ({summary["library"]["status"]} if library else set())
    summary["status"] = "canceled" if cancel() else next((s for s in WORST_FIRST if s in found), "succeeded")
    if cancel():
        summary["message"] = cancel.reason
    (out / "summary.json").write_text(json.dumps(summary, indent=2))
    _print_summary(summary, out)
    return summary


#: the demo's small motion library: 3 slopes × 3 curves, HalfBoy
LIBRARY_GRID = {"slope_deg": [-5.0, 0.0, 5.0], "curve_deg": [-30.0, 0.0, 30.0]}


def _queue_library(http, motion_id: str, tutor: dict) -> dict:
    """Queue the small library (one job per cell)."""
    r = http.post(f"/motions/{motion_id}/library", json={"grid": LIBRARY_GRID, "tutor": tutor})
    _check(r, 202, "library")
    lib = r.json()
    print(f"[demo] library {lib['id']}: {len(lib['cells'])} cells (slopes {LIBRARY_GRID['slope_deg']} × curves "
          f"{LIBRARY_GRID['curve_deg']}) queued", flush=True)
    return lib


def _library(http, lib: dict, out: Path, t0: float, deadline: float, cancel=lambda: False) -> dict:
    """Follow the library's overall progress, download its manifest and GLB; its time runs
    from the demo's start (``t0``), since its cells share the workers with the jobs. ``cancel()``
    true: the library is canceled and followed until its cells have stopped."""
    last, canceling = None, False
    while True:
        if cancel() and not canceling:
            canceling, deadline = True, min(deadline, time.monotonic() + CANCEL_GRACE_S)
            r = http.post(f"/libraries/{lib['id']}/cancel")
            if r.status_code not in (202, 409):  # 409: finished already
                _check(r, 202, "library cancel")
        lib = http.get(f"/libraries/{lib['id']}").json()
        pr = lib["progress"]
        line = (f"[demo] library: {pr['done']}/{pr['cells']} cells done ({pr['succeeded']} succeeded, "
                f"{pr['impasse']} at impasse, {pr['failed']} failed), {100 * pr['fraction']:.0f} %")
        if line != last:
            print(line, flush=True)
            last = line
        if Status(lib["status"]).terminal:
            break
        if time.monotonic() > deadline:
            if canceling:
                break
            raise CliError("the library did not finish before the demo's deadline (--timeout)")
        time.sleep(1.0)
    out.mkdir(parents=True, exist_ok=True)
    manifest = http.get(f"/libraries/{lib['id']}/manifest")
    _check(manifest, 200, "library manifest")
    (out / "manifest.json").write_text(json.dumps(manifest.json(), indent=2))
    glb = http.get(f"/libraries/{lib['id']}/library.glb")
    if not (canceling and glb.status_code == 409):  # 409: no cell has a motion (yet)
        _check(glb, 200, "library GLB")
        (out / "library.glb").write_bytes(glb.content)
    realistic = sum(1 for c in lib["cells"] if c["plausible"])
    print(f"[demo] library {lib['status']}: {realistic}/{len(lib['cells'])} cells realistic, done "
          f"{time.perf_counter() - t0:.1f} s after the demo's start; wrote {out}/manifest.json and library.glb",
          flush=True)
    return {"id": lib["id"], "status": lib["status"], "cells": len(lib["cells"]), "realistic": realistic,
            "grid": LIBRARY_GRID, "time_s": round(time.perf_counter() - t0, 2)}


def _tutors(http, jobs: list[_Job], library: dict | None) -> list[dict]:
    """Each tutor the jobs and the library's cells used: the job that made it (its tutor
    progress point is the pipeline's, ``tutor succeeded``) and those that took it from the
    store (``tutor made by job …``; the service makes a tutor once, service.store.claim_tutor)."""
    states = [(j.name, j.state) for j in jobs]
    if library is not None:
        for c in library.get("cells", []):
            r = http.get(f"/jobs/{c['job_id']}")
            _check(r, 200, "library cell")
            states.append((f"library {c['key']}", r.json()))
    names = {s.get("id"): name for name, s in states}
    tutors: dict[str, dict] = {}
    for name, s in states:
        point = next((p for p in s.get("progress") or [] if p.get("phase") == "tutor"), None)
        if not s.get("tutor_motion_id") or point is None:
            continue
        t = tutors.get(s["tutor_motion_id"])
        if t is None:
            r = http.get(f"/motions/{s['tutor_motion_id']}")
            _check(r, 200, "tutor")
            t = tutors[s["tutor_motion_id"]] = {"id": s["tutor_motion_id"], "character": r.json()["character"],
                                                "made_by": [], "taken_from_store_by": []}
        if point["status"] == "tutor succeeded":
            t["made_by"].append({"job": name, "time_s": round(point["wall_time"], 2),
                                 "iterations": point["iterations"]})
        else:
            maker = point["status"].removeprefix("tutor made by job ") if point["status"].startswith(
                "tutor made by job ") else None  # None: stored before the demo's jobs
            t["taken_from_store_by"].append({"job": name, "maker": names.get(maker, maker),
                                             "waited_s": round(point["wall_time"], 2)})
    return list(tutors.values())


def _check(resp, code: int, what: str) -> None:
    if resp.status_code != code:
        raise CliError(f"{what} failed: HTTP {resp.status_code} {resp.text[:500]}")


def _bar(job: _Job, width: int = 24, clock: bool = True) -> str:
    """One job's progress as text: λ bar, status (``tutor`` while the tutor is being made),
    environment value reached, steps, and the job's elapsed time on the demo's clock (it
    runs from the moment the job is seen running, the tutor phase included)."""
    from service.plots import number_text

    s = job.state
    lam = float(s.get("lam_reached") or 0.0)
    prog = s.get("progress") or []
    status = s.get("status", "?")
    if status == "running" and not any(p.get("phase") == "extrapolate" for p in prog):
        status = "tutor" if not prog else "starting"
    env = next((p.get("environment") or {} for p in reversed(prog) if p.get("accepted") and p.get("environment")), {})
    shown = [f"{k}={number_text(env[k])}" for k in job.target if k in env]
    meter = tqdm.format_meter(lam, 1.0, 0, bar_format=f"[{{bar:{width}}}]", ascii=".#")
    text = f"{job.name:9s} {meter} λ={lam:.3f} {status:9s} {' '.join(shown):17s} {s.get('steps', 0):2d} steps"
    return f"{text} {job.elapsed:5.1f}s" if clock else text


class _Lines:
    """On a terminal, one tqdm line per job redrawn in place (``show``); closed on exit."""

    def __init__(self, n: int) -> None:
        self.bars = [tqdm(file=sys.stdout, position=i, bar_format="[demo] {desc}", dynamic_ncols=True)
                     for i in range(n)]

    def show(self, lines: list[str]) -> None:
        for bar, line in zip(self.bars, lines):
            bar.set_description_str(line)

    def __enter__(self) -> _Lines:
        return self

    def __exit__(self, *exc) -> None:
        for bar in self.bars:
            bar.close()


def _job_time(progress: list[dict]) -> float:
    """Seconds of work in a job's progress curve: the tutor's points count from the job's
    start, the extrapolation's from its own start (after the tutor)."""
    tutor = [p["wall_time"] for p in progress if p.get("phase") == "tutor"]
    ext = [p["wall_time"] for p in progress if p.get("phase") == "extrapolate"]
    return (tutor[-1] if tutor else 0.0) + (ext[-1] if ext else 0.0)


def _follow(http, jobs: list[_Job], deadline: float, cancel=lambda: False) -> None:
    """Polls every job until all are finished, drawing a progress bar per job: redrawn in
    place on a terminal, one line per change otherwise (logs). Once ``cancel()`` is true the
    unfinished jobs are canceled (each stops at its next IPOPT iteration) and followed until
    they have stopped, for at most ``CANCEL_GRACE_S``."""
    if not sys.stdout.isatty():
        return _poll(http, jobs, deadline, cancel, None)
    with _Lines(len(jobs)) as shown:
        return _poll(http, jobs, deadline, cancel, shown)


def _poll(http, jobs: list[_Job], deadline: float, cancel, shown: _Lines | None) -> None:
    last: list[str] = []
    logged: dict[int, float] = {}
    canceling = False
    while True:
        if cancel() and not canceling:
            canceling, deadline = True, min(deadline, time.monotonic() + CANCEL_GRACE_S)
            print(f"[demo] {getattr(cancel, 'reason', '') or 'canceled'}: canceling the jobs", flush=True)
            for j in jobs:
                if not j.done:
                    r = http.post(f"{j.url}/cancel")
                    if r.status_code not in (202, 409):  # 409: finished already
                        _check(r, 202, f"cancel ({j.name})")
        for j in jobs:
            if not j.done:
                r = http.get(j.url)
                _check(r, 200, "job status")
                j.seen(r.json())
        lines = [_bar(j) for j in jobs]
        if shown is not None:
            shown.show(lines)
        else:  # logs: a line when a job's state changes, and every LOG_EVERY_S while it runs
            states = [_bar(j, clock=False) for j in jobs]
            now = time.monotonic()
            for i, (old, new, line) in enumerate(zip(last or [""] * len(jobs), states, lines)):
                if old != new or (not jobs[i].done and now - logged.get(i, now) >= LOG_EVERY_S):
                    print(f"[demo] {line}", flush=True)
                    logged[i] = now
            last = states
        if all(j.done for j in jobs):
            return
        if time.monotonic() > deadline:
            if canceling:
                return
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
    (out / "progress.csv").write_text(progress_csv(s.get("progress") or []))
    r = http.get(f"{job.url}/plots/progress.png")
    if r.status_code == 200 or s.get("status") != "canceled":  # a job canceled early may have no curve
        _check(r, 200, "progress plot")
        (out / "progress.png").write_bytes(r.content)
    if s.get("tutor_motion_id"):
        r = http.get(f"/motions/{s['tutor_motion_id']}?format=motion")
        _check(r, 200, "tutor")
        (out / "tutor.motion.json").write_bytes(r.content)
    motions = _pages(http, f"{job.url}/motions?limit=200")
    reports = []
    for m in motions:
        stem = step_stem(m["step"], m["lam"] if m.get("lam") is not None else float("nan"))
        for query, suffix in EXPORTS + job.rig_exports:
            r = http.get(f"/motions/{m['id']}?{query}")
            _check(r, 200, f"export {query}")
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
        "name": job.name, "target": job.target, "character": job.tutor["character"], "status": s["status"],
        "message": s.get("message") or "", "rig_exports": [suffix for _, suffix in job.rig_exports],
        "lambda_reached": s.get("lam_reached"),
        "reached": {k: env[k] for k in job.target if k in env},
        "motions": len(motions), "solves": s.get("solves"),
        "job_time_s": round(_job_time(prog), 2),
        "plausible": sum(bool(rep.get("plausible")) for rep in reports),
        "natural": sum(bool(rep.get("natural")) for rep in reports),
        "max_root_residual_rel_weight": max((rep["root_residual"]["max_force_rel_weight"] for rep in reports),
                                            default=None),
        "max_mujoco_agreement_rel_weight": max(
            (rep["mujoco_replay"]["agreement_force_rel_weight"] for rep in reports), default=None),
        "dir": str(out),
    }


def _print_summary(summary: dict, out: Path) -> None:
    from service.plots import environment_text

    print(f"[demo] {'job':9s} {'status':9s} {'λ':>6s} {'reached':>18s} {'motions':>7s} {'plausible':>9s} "
          f"{'natural':>9s} {'time':>6s} {'max residual/weight':>19s}")
    for j in summary["jobs"]:
        reached = environment_text(j["reached"])
        res = j["max_root_residual_rel_weight"]
        print(f"[demo] {j['name']:9s} {j['status']:9s} {j['lambda_reached']:6.3f} {reached:>18s} "
              f"{j['motions']:7d} {j['plausible']:>4d}/{j['motions']:<4d} {j['natural']:>4d}/{j['motions']:<4d} "
              f"{j['job_time_s']:5.1f}s "
              f"{'-' if res is None else format(res, '.1e'):>19s}")
    for t in summary.get("tutors", []):
        made = ", ".join(f"{m['job']} ({m['time_s']:.1f} s, {m['iterations']} iterations)" for m in t["made_by"])
        takers = [u["job"] for u in t["taken_from_store_by"]]
        cells = sum(1 for u in takers if u.startswith("library "))
        shared = [u for u in takers if not u.startswith("library ")] + ([f"{cells} library cells"] if cells else [])
        print(f"[demo] tutor {t['character']}: made {len(t['made_by'])}× by {made or '-'}"
              + (f"; taken from the store by {', '.join(shared)}" if shared else ""))
    print(f"[demo] total {summary['wall_time_s']:.1f} s; in {out}/<job>/: every λ optimum as "
          f"step_NNN_lambda_L.motion.json, .clip.json, .glb, .bvh, .validation.json; progress.csv, progress.png, "
          f"final.grf.png, final.residuals.png, final.filmstrip.png (summary.json)")
    for j in summary["jobs"]:
        if j["rig_exports"]:
            print(f"[demo] {out}/{j['name']}/: each λ optimum also on the input's own rig, as "
                  f"{', '.join('.' + k for k in j['rig_exports'])}")


def register(sub: argparse._SubParsersAction) -> None:
    s = add_command(sub, "demo", "the main job end to end through the embedded service (make demo)", """\
Start `motionx serve` on its embedded defaults (SQLite + local process pool, in a temporary
folder, on a free port), upload a captured walk over HTTP (default: the DeepMimic walk in
data/), ask for a downhill slope, a full-body walk up a small slope, a curve and stairs, and a
3 × 3 motion library (slopes × curves), follow the jobs with a progress bar and
download every λ optimum (motion file, JSON clip, GLB, BVH, plausibility report; the full-body
job's also on the input's own rig: for a DeepMimic input a skinned GLB of its character and a
DeepMimic motion file), the progress curve (CSV, PNG) and the final motion's plots into
--out/<job>/. Each tutor is made once and shared by the jobs that need it. Ctrl-C or SIGTERM
cancels the jobs, downloads what they reached (summary.json: status canceled) and exits 130
(143). The service is stopped and its temporary folder removed at the end, on Ctrl-C and on
SIGTERM.""")
    s.add_argument("inputs", nargs="*", metavar="INPUT",
                   help="trial files, as for `motionx tutor` (default: the DeepMimic walk in data/)")
    s.add_argument("--out", default="out/demo", metavar="DIR",
                   help="where results are written (an earlier demo's files there are replaced)")
    s.add_argument("--slope", type=float, default=-11.25, metavar="DEG",
                   help="target slope in degrees, negative = downhill; 0 = no slope job")
    s.add_argument("--curve", type=float, default=90.0, metavar="DEG",
                   help="target curve in degrees, positive = left; 0 = no curve job")
    s.add_argument("--step-height", type=float, default=0.10, metavar="M",
                   help="stairs: riser height in metres, negative = down; 0 = no stairs job")
    s.add_argument("--character", choices=["halfboy", "fullbody"], default="halfboy",
                   help="synthesis character of the tutor (of the jobs but the full-body one, and of the library)")
    s.add_argument("--fullbody-slope", type=float, default=5.0, metavar="DEG",
                   help="the full-body job: the walk on the fullbody character up (or, negative, down) this slope, "
                        "each λ optimum also on the input's own rig (DeepMimic input: a skinned GLB of its "
                        "character and a DeepMimic motion file); 0 = no full-body job")
    s.add_argument("--fps", type=float, choices=[15.0, 30.0], default=15.0, help="frames per second of the tutor")
    add_import_options(s)
    s.add_argument("--timeout", type=float, default=900.0, metavar="S", help="seconds to wait for the jobs")
    s.add_argument("--no-library", dest="library", action="store_false",
                   help="skip the small motion library (3 slopes × 3 curves, queued with the jobs; default: it runs)")
    s.add_argument("--serve", action="store_true", help="keep the service running afterwards and print the web "
                   "page's address (Ctrl-C or SIGTERM stops it)")
    s.add_argument("--keep-temp", action="store_true",
                   help="keep the service's temporary data directory (SQLite database, stored motions) at the end")
    s.set_defaults(func=cmd_demo)
