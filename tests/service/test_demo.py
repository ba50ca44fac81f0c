"""``make demo`` end to end: ``motionx demo`` with its defaults (the DeepMimic walk shipped in
data/, a downhill slope of −11.25°, a full-body walk up 5°, a 90° curve and stairs of 0.10 m
over HTTP on the embedded service, and a 3 × 3 library) writes every λ motion, its exports
(the full-body job's also on the DeepMimic character itself), plausibility reports, progress
curve and plots, and a summary that states what was reached and that each tutor was made once.
The files are checked with their own formats' readers, not by name only.

One run serves every test: ``motionx demo --serve``, stopped with SIGTERM once the web page
is up, as a user's ``kill`` would — then no process of the service may be left and no
temporary folder. The output folder starts with an earlier run's leftovers in it."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import httpx
import numpy as np
import pytest

from solver.character import FULL_SUPERFLUOUS
from solver.motion import motion_from_dict

PNG = b"\x89PNG\r\n\x1a\n"
STEP_KINDS = ("motion.json", "clip.json", "glb", "bvh", "validation.json")


def _proc_stat(pid: int) -> tuple[int, int, str] | None:
    """(ppid, session id, state) of a live process, None when it is gone (or a zombie)."""
    try:
        text = Path(f"/proc/{pid}/stat").read_text()
    except (FileNotFoundError, ProcessLookupError):
        return None
    fields = text[text.rindex(")") + 2:].split()
    state, ppid, sid = fields[0], int(fields[1]), int(fields[3])
    return None if state in ("Z", "X") else (ppid, sid, state)


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode(errors="replace")
    except OSError:
        return ""


def _all_pids() -> list[int]:
    return [int(p) for p in os.listdir("/proc") if p.isdigit()]


def process_tree(root: int) -> set[int]:
    """Every live descendant of ``root`` (by parent), and every process in the session of
    one of them (children that a process started in its own session, or that were re-parented)."""
    stats = {pid: s for pid in _all_pids() if (s := _proc_stat(pid)) is not None}
    tree, grew = {root}, True
    while grew:
        new = {pid for pid, (ppid, _, _) in stats.items() if ppid in tree} - tree
        grew = bool(new)
        tree |= new
    sessions = {stats[p][1] for p in tree if p in stats and p != root}
    tree |= {pid for pid, (_, sid, _) in stats.items() if sid in sessions}
    return tree - {root}


def alive(pids: set[int]) -> set[int]:
    return {p for p in pids if _proc_stat(p) is not None}


@pytest.fixture(scope="module")
def demo_run(tmp_path_factory, shared_data):
    base = tmp_path_factory.mktemp("demo")
    out, tmp = base / "out", base / "tmp"
    tmp.mkdir()
    # leftovers of an earlier run (and a file of the user's, which must stay)
    (out / "downhill").mkdir(parents=True)
    for stale in ("step_009_lambda_0.9000.motion.json", "step_009_lambda_0.9000.glb"):
        (out / "downhill" / stale).write_text("{}")
    (out / "downhill" / "notes.txt").write_text("mine")
    exe = Path(sys.executable).with_name("motionx")
    env = dict(os.environ, MOTIONX_DATA=str(shared_data), TMPDIR=str(tmp), PYTHONUNBUFFERED="1")
    p = subprocess.Popen([str(exe), "demo", "--serve", "--out", str(out)], env=env, stdout=subprocess.PIPE,
                         stderr=subprocess.PIPE, text=True)
    watchdog = threading.Timer(600, p.kill)
    watchdog.start()
    lines, page = [], None
    for line in p.stdout:  # until the web page is served (or the demo ends)
        lines.append(line)
        if "[demo] the web page: " in line:
            page = line.split("[demo] the web page: ")[1].split()[0]
            break
    tree, health, cmds = set(), None, []
    if page:
        tree = process_tree(p.pid)
        cmds = [_cmdline(pid) for pid in tree]
        health = httpx.get(page.split("/ui/")[0] + "/health", timeout=10).status_code
        p.send_signal(signal.SIGTERM)
    rest, err = p.communicate(timeout=120)
    watchdog.cancel()
    deadline = time.monotonic() + 30
    while alive(tree) and time.monotonic() < deadline:
        time.sleep(0.2)
    return SimpleNamespace(returncode=p.returncode, stdout="".join(lines) + rest, stderr=err, out=out, tmp=tmp,
                           page=page, health=health, tree=tree, commands=cmds, left=alive(tree))


def test_demo_reaches_every_target_and_prints_a_summary(demo_run):
    r, out = demo_run, demo_run.out
    assert r.page, r.stdout[-3000:] + r.stderr[-3000:]
    summary = json.loads((out / "summary.json").read_text())
    assert summary["input"] == ["humanoid3d_walk.txt", "humanoid3d_character.txt"]
    jobs = {j["name"]: j for j in summary["jobs"]}
    assert set(jobs) == {"downhill", "fullbody", "curve", "stairs"}
    assert jobs["downhill"]["target"] == {"slope_deg": -11.25}
    assert jobs["fullbody"]["target"] == {"slope_deg": 5.0} and jobs["fullbody"]["character"] == "fullbody"
    assert jobs["curve"]["target"] == {"curve_deg": 90.0}
    assert jobs["stairs"]["target"] == {"step_height_m": 0.1}
    for name, j in jobs.items():
        assert j["status"] == "succeeded", (name, j)
        assert j["lambda_reached"] == pytest.approx(1.0)
        key, value = next(iter(j["target"].items()))
        assert j["reached"][key] == pytest.approx(value, abs=1e-9)
        assert j["motions"] >= 2 and j["plausible"] == j["natural"] == j["motions"], j
        assert j["max_root_residual_rel_weight"] < 1e-6
    # the printed summary names every job with its λ, the values reached (not rounded:
    # -11.25, not -11.2) and where the files are
    tail = r.stdout[r.stdout.index("[demo] job "):]
    assert "downhill" in tail and "curve" in tail and "1.000" in tail and str(out) in r.stdout
    assert "slope -11.25°" in tail and "curve 90°" in tail and "stairs" in tail
    # the stairs' last optimum stands on treads one riser apart (one per stance), as the
    # page's 3D preview draws them
    last = sorted((out / "stairs").glob("step_*.validation.json"))[-1]
    treads = json.loads(last.read_text())["environment"]["treads"]
    heights = sorted({round(t["center"][2], 6) for t in treads})
    assert len(treads) >= 2 and np.allclose(np.diff(heights), 0.1), treads
    # a progress bar was drawn while polling (one line per change when not on a terminal),
    # the tutor phase named as such
    assert r.stdout.count("λ=") >= 4 and "#" in r.stdout
    assert "slope_deg=-11.25 " in r.stdout
    # the small motion library: 9 cells, every one realistic or honestly at impasse, its
    # manifest and one looping animation per cell in the GLB
    lib = summary["library"]
    assert lib["cells"] == 9 and lib["status"] in ("succeeded", "impasse"), lib
    manifest = json.loads((out / "library" / "manifest.json").read_text())
    cells = manifest["cells"]
    assert len(cells) == 9 and all(c["status"] in ("succeeded", "impasse") for c in cells), cells
    glb = (out / "library" / "library.glb").read_bytes()
    assert glb[:4] == b"glTF" and int.from_bytes(glb[8:12], "little") == len(glb)
    assert "[demo] library " in r.stdout and "cells realistic" in r.stdout


def test_sigterm_stops_the_demo_and_its_service_and_removes_the_temporary_folder(demo_run):
    r = demo_run
    assert r.page and r.health == 200, r.stdout[-3000:] + r.stderr[-3000:]
    # the service (and its job processes) were running while the page was served ...
    assert any("service.cli serve" in c for c in r.commands), r.commands
    # ... SIGTERM to the demo stopped them all, and the demo ended normally after the jobs succeeded
    assert r.left == set(), f"left behind: {r.left}"
    assert r.returncode == 0, r.stderr[-3000:]
    assert "[demo] stopping the service" in r.stdout and "Traceback" not in r.stderr
    assert not any(p.name.startswith("motionx-demo-") for p in r.tmp.iterdir()), list(r.tmp.iterdir())
    # the service's data directory was named in the output, and is gone
    used = r.stdout.split("(SQLite in ")[1].split(",")[0]
    assert Path(used).parent == r.tmp and not Path(used).exists()


def test_demo_replaces_an_earlier_runs_files_only(demo_run):
    d = demo_run.out / "downhill"
    assert not (d / "step_009_lambda_0.9000.motion.json").exists() and not (d / "step_009_lambda_0.9000.glb").exists()
    assert (d / "notes.txt").read_text() == "mine"


def test_demo_files_are_what_they_claim(demo_run):
    from solver.export.clip import validate_clip

    out = demo_run.out
    summary = json.loads((out / "summary.json").read_text())
    for job in ("downhill", "curve"):
        d = out / job
        motions = sorted(d.glob("step_*_lambda_*.motion.json"))
        assert len(motions) >= 2
        # one naming scheme with `motionx extrapolate`: step_NNN_lambda_L.<kind>, every kind per step
        assert {p.name for p in d.iterdir() if p.name.startswith("step_")} == {
            f"{m.name[: -len('.motion.json')]}.{kind}" for m in motions for kind in STEP_KINDS}
        lams = []
        for i, mf in enumerate(motions):
            stem = mf.name[: -len(".motion.json")]
            m = motion_from_dict(json.loads(mf.read_text()))
            assert m.provenance["step"] == "extrapolate"
            _, step, _, lam = stem.split("_")
            assert int(step) == i and float(lam) == pytest.approx(m.provenance["lambda"], abs=1e-4)
            lams.append(m.provenance["lambda"])
            clip = json.loads((d / f"{stem}.clip.json").read_text())
            validate_clip(clip)
            assert clip["frame_count"] == m.T
            glb = (d / f"{stem}.glb").read_bytes()
            assert glb[:4] == b"glTF" and int.from_bytes(glb[4:8], "little") == 2
            assert int.from_bytes(glb[8:12], "little") == len(glb)
            bvh = (d / f"{stem}.bvh").read_text()
            assert bvh.startswith("HIERARCHY") and f"Frames: {m.T}" in bvh
            rep = json.loads((d / f"{stem}.validation.json").read_text())
            assert rep["plausible"] is True and rep["natural"] is True
        assert lams == sorted(lams) and max(lams) == pytest.approx(1.0)
        # the last λ motion of the job stands on the target ground
        env = m.context.axis_values
        want = next(j["target"] for j in summary["jobs"] if j["name"] == job)
        for k, v in want.items():
            assert env[k] == pytest.approx(v)
        for png in ("progress.png", "final.grf.png", "final.residuals.png", "final.filmstrip.png"):
            data = (d / png).read_bytes()
            assert data[:8] == PNG and len(data) > 5000, (job, png)
        record = json.loads((d / "job.json").read_text())
        assert record["status"] == "succeeded"
        # progress.csv: the job's progress curve, the tutor phase first, as `extrapolate` writes it
        with (d / "progress.csv").open() as f:
            rows = list(csv.DictReader(f))
        # + the tutor phase and λ = 0 (the tutor itself: a record, no solve)
        assert len(rows) == len(record["progress"]) == record["solves"] + 2
        assert rows[0]["phase"] == "tutor" and {r["phase"] for r in rows[1:]} == {"extrapolate"}
        key, value = next(iter(want.items()))
        assert float(rows[-1][key]) == pytest.approx(value) and float(rows[-1]["lambda_reached"]) == 1.0
        motion_from_dict(json.loads((d / "tutor.motion.json").read_text()))


def test_the_demo_clock_runs_during_the_tutor_phase():
    """While the job makes its tutor (no progress point yet) its line says so and its time moves."""
    from service.commands.demo import _bar, _Job

    job = _Job("downhill", {"slope_deg": -11.25}, {"character": "halfboy", "fps": 15.0})
    job.seen({"status": "queued", "progress": []})
    assert job.elapsed == 0.0
    job.seen({"status": "running", "progress": [], "steps": 0})
    first = _bar(job)
    time.sleep(0.25)
    second = _bar(job)
    assert " tutor " in first and first != second
    assert job.elapsed >= 0.25  # the sleep's lower bound; its upper one is the machine's
    job.seen({"status": "succeeded", "progress": [], "steps": 4, "lam_reached": 1.0})
    frozen = job.elapsed
    time.sleep(0.1)
    assert job.elapsed == frozen


def _glb_json(data: bytes) -> dict:
    """The JSON chunk of a GLB (after checking its header)."""
    assert data[:4] == b"glTF" and int.from_bytes(data[4:8], "little") == 2
    assert int.from_bytes(data[8:12], "little") == len(data)
    n = int.from_bytes(data[12:16], "little")
    assert data[16:20] == b"JSON"
    return json.loads(data[20:20 + n])


def test_the_fullbody_job_comes_out_on_the_deepmimic_character(demo_run, shared_data):
    """The full-body walk up 5°: each λ optimum of the fullbody character (43 coordinates), also
    as a skinned GLB of the DeepMimic humanoid's own skeleton and shapes and a DeepMimic motion
    for its character file, which the DeepMimic importer reads back."""
    from solver.io import load_trial
    from solver.io.deepmimic import read_deepmimic_character

    out = demo_run.out
    summary = json.loads((out / "summary.json").read_text())
    job = next(j for j in summary["jobs"] if j["name"] == "fullbody")
    assert job["status"] == "succeeded" and job["lambda_reached"] == pytest.approx(1.0), job
    assert job["reached"]["slope_deg"] == pytest.approx(5.0)
    assert job["motions"] >= 2 and job["plausible"] == job["natural"] == job["motions"], job
    assert job["rig_exports"] == ["rig.glb", "deepmimic.txt"]
    character = shared_data / "deepmimic_humanoid3d_walk" / "humanoid3d_character.txt"
    sk = read_deepmimic_character(character)
    d = out / "fullbody"
    motions = sorted(d.glob("step_*_lambda_*.motion.json"))
    assert len(motions) == job["motions"]
    assert {p.name for p in d.iterdir() if p.name.startswith("step_")} == {
        f"{m.name[: -len('.motion.json')]}.{kind}" for m in motions
        for kind in (*STEP_KINDS, "rig.glb", "deepmimic.txt")}
    for mf in motions:
        stem = mf.name[: -len(".motion.json")]
        m = motion_from_dict(json.loads(mf.read_text()))
        kept = [c for c in m.character.coordinate_names if c in FULL_SUPERFLUOUS]  # those the capture uses
        assert m.character.name == "fullbody" and m.n == 43 + len(kept) and kept  # (DeepMimic: its ankles)
        # the DeepMimic motion: the character's frame layout, looping, read back by the importer
        text = (d / f"{stem}.deepmimic.txt").read_text()
        dm = json.loads(text)
        assert dm["Loop"] == "wrap" and {len(f) for f in dm["Frames"]} == {sk.frame_size}
        back = load_trial([d / f"{stem}.deepmimic.txt", character])
        assert len(dm["Frames"]) == back.T
        # the GLB on the humanoid's own skeleton: a skin whose joints are its joints, shapes on them
        gltf = _glb_json((d / f"{stem}.rig.glb").read_bytes())
        names = [n.get("name") for n in gltf["nodes"]]
        assert gltf["skins"] and gltf["meshes"] and len(gltf["animations"]) == 1
        assert [names[j] for j in gltf["skins"][0]["joints"]] == list(sk.names), names
    assert len({p.name for p in d.glob("*.png")}) == 4  # progress + the final motion's three plots


def test_each_tutor_is_made_once(demo_run):
    """The HalfBoy tutor is made by one job; the other HalfBoy jobs and the library's cells take it
    from the store (their tutor progress point names its maker). The full-body job makes its own."""
    out = demo_run.out
    summary = json.loads((out / "summary.json").read_text())
    tutors = {t["character"]: t for t in summary["tutors"]}
    assert set(tutors) == {"halfboy", "fullbody"}
    half, full = tutors["halfboy"], tutors["fullbody"]
    assert [m["job"] for m in full["made_by"]] == ["fullbody"] and full["taken_from_store_by"] == []
    assert len(half["made_by"]) == 1 and half["made_by"][0]["iterations"] > 0, half
    maker = half["made_by"][0]["job"]
    takers = [u["job"] for u in half["taken_from_store_by"]]
    assert sorted(t for t in takers if not t.startswith("library ")) == sorted(
        {"downhill", "curve", "stairs"} - {maker})
    assert sum(t.startswith("library ") for t in takers) == 9
    assert {u["maker"] for u in half["taken_from_store_by"]} == {maker}
    # the jobs' own records say the same: one tutor computation among the HalfBoy jobs, one tutor
    records = {name: json.loads((out / name / "job.json").read_text()) for name in ("downhill", "curve", "stairs")}
    points = {name: [p for p in r["progress"] if p["phase"] == "tutor"] for name, r in records.items()}
    assert all(len(p) == 1 for p in points.values()), points
    assert [n for n, p in points.items() if p[0]["status"] == "tutor succeeded"] == [maker]
    assert {r["tutor_motion_id"] for r in records.values()} == {half["id"]}
    assert all(p[0]["iterations"] == 0 and p[0]["status"] == f"tutor made by job {records[maker]['id']}"
               for n, p in points.items() if n != maker)
    assert "[demo] tutor halfboy: made 1× by " in demo_run.stdout
