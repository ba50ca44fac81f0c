"""Ctrl-C (SIGINT) and SIGTERM end `motionx tutor`, `library` and `demo` cleanly: the running
IPOPT solve stops at its next iteration, what was written so far stays, the summary says
"canceled" and the exit status is 130 (SIGINT) or 143 (SIGTERM) — also when the signal comes
before solving begins. (`motionx extrapolate`: tests/test_cli_tutor.py.)

The signal is sent on an event the process shows — a line it prints, or its SIGTERM handler
being installed (``SigCgt`` in /proc/PID/status) — never after a fixed sleep."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from solver.motion import Motion

EXIT = {"SIGINT": 130, "SIGTERM": 143}
REASON = {"SIGINT": "interrupted (Ctrl-C)", "SIGTERM": "terminated (SIGTERM)"}
TIMEOUT = 600  # s: generous, the signal is sent on events, not after a delay


def _exe() -> str:
    return shutil.which("motionx") or str(Path(sys.executable).with_name("motionx"))


class Run:
    """`motionx ARGS` as a child process whose stdout and stderr lines are collected as they come."""

    def __init__(self, *args, env: dict | None = None) -> None:
        self.p = subprocess.Popen([_exe(), *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                  text=True, env=env)
        self.out: list[str] = []
        self.err: list[str] = []
        self._readers = [threading.Thread(target=self._read, args=(f, lines), daemon=True)
                         for f, lines in ((self.p.stdout, self.out), (self.p.stderr, self.err))]
        for t in self._readers:
            t.start()

    @staticmethod
    def _read(f, lines: list[str]) -> None:
        for line in f:
            lines.append(line)

    def wait_for(self, seen, what: str) -> None:
        """Until ``seen()`` is true; the process must still be running then."""
        deadline = time.monotonic() + TIMEOUT
        while not seen():
            assert self.p.poll() is None, f"ended before {what}:\n{''.join(self.out)}\n{''.join(self.err)}"
            assert time.monotonic() < deadline, f"no {what} in {TIMEOUT} s"
            time.sleep(0.02)
        assert self.p.poll() is None, f"ended before it could be signalled:\n{''.join(self.err)}"

    def line(self, pattern: str, stream: str = "err") -> None:
        lines = self.err if stream == "err" else self.out
        self.wait_for(lambda: any(re.search(pattern, ln) for ln in list(lines)), repr(pattern))

    def handler_installed(self) -> None:
        """Until the process catches SIGTERM: the command's signal handling is in place (before
        any input is read)."""
        self.wait_for(lambda: bool(_caught(self.p.pid) & (1 << (signal.SIGTERM - 1))), "SIGTERM handler")

    def signal(self, name: str) -> tuple[int, str, str]:
        self.p.send_signal(getattr(signal, name))
        try:
            code = self.p.wait(timeout=TIMEOUT)
        finally:
            self.p.kill()
        for t in self._readers:
            t.join(timeout=30)
        return code, "".join(self.out), "".join(self.err)


def _caught(pid: int) -> int:
    """The signals a process catches (``SigCgt`` of /proc/PID/status), as a bit mask."""
    try:
        text = Path(f"/proc/{pid}/status").read_text()
    except OSError:
        return 0
    return int(re.search(r"^SigCgt:\s*([0-9a-f]+)", text, re.M).group(1), 16)


@pytest.fixture(scope="module")
def trial(shared_data) -> list[Path]:
    d = shared_data / "deepmimic_humanoid3d_walk"
    return [d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt"]


@pytest.fixture(scope="module")
def tutor_file(trial, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("tutor") / "tutor.json"
    r = subprocess.run([_exe(), "tutor", *map(str, trial), "--character", "halfboy", "--fps", "15", "--out", str(out)],
                       capture_output=True,
                       text=True, timeout=TIMEOUT)
    assert r.returncode == 0, r.stderr + r.stdout
    return out


# --- tutor ------------------------------------------------------------------------------------------


def _canceled_tutor(code: int, out: str, err: str, sig: str, written: Path) -> dict:
    assert code == EXIT[sig], err
    assert "Traceback" not in err, err
    info = json.loads(out)
    assert info["status"] == "canceled" and info["message"].startswith(REASON[sig]), info
    assert info["input"]["format"] == "deepmimic"  # the input summary is kept
    assert not written.exists()  # no half-made tutor
    return info


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_signal_while_the_tutor_is_solved_cancels_it(trial, tmp_path, sig):
    """The signal comes once the tutor says it is solving: IPOPT stops at its next iteration,
    the result is "canceled" (not "failed", no second attempt), nothing is written."""
    out = tmp_path / "t.json"
    run = Run("tutor", *trial, "--character", "halfboy", "--fps", "15", "--out", out, "--json")
    run.line(r"^motionx tutor: solving")
    info = _canceled_tutor(*run.signal(sig), sig, out)
    attempts = (info["stats"].get("correct") or {}).get("attempts") or []
    assert len(attempts) <= 1  # a canceled correction is not tried again from zero wrenches
    when = info["message"].removeprefix(f"{REASON[sig]}, ")
    assert re.fullmatch(r"canceled (before|during|after) the (simplification|correction)", when), info
    if " during " in when:  # the solve that ran when the signal came stopped at its next iteration
        solves = [info["stats"].get("simplify", {}).get("status"), *(a["status"] for a in attempts)]
        assert "User_Requested_Stop" in solves, info["stats"]


def test_a_signal_before_the_tutor_is_solved_cancels_it_too(trial, tmp_path):
    """SIGTERM as soon as the command handles it, while the trial is imported: the same clean
    end (143, "canceled", nothing written), no traceback."""
    out = tmp_path / "t.json"
    run = Run("tutor", *trial, "--character", "halfboy", "--fps", "15", "--out", out, "--json")
    run.handler_installed()
    _canceled_tutor(*run.signal("SIGTERM"), "SIGTERM", out)


def test_make_tutor_stops_at_the_next_iteration_once_canceled(trial):
    """``make_tutor(should_cancel=…)``: once the callable turns true the simplification's IPOPT
    stops at its next iteration and the tutor is "canceled", with no correction after it."""
    from solver.io import load_trial
    from solver.pipeline import make_tutor

    calls = []

    def cancel() -> bool:
        calls.append(1)
        return len(calls) > 3  # polled at every IPOPT iteration

    res = make_tutor(load_trial(trial), fps=15.0, should_cancel=cancel, character="halfboy")
    assert res.status == "canceled" and res.motion is None, res.message
    assert res.message == "canceled during the simplification"
    simp = res.stats["simplify"]
    assert simp["status"] == "User_Requested_Stop" and simp["iterations"] <= 4, simp
    assert "correct" not in res.stats
    # never canceled: the same call makes the tutor
    assert make_tutor(load_trial(trial), character="halfboy", fps=15.0,
                      should_cancel=lambda: False).status == "succeeded"


# --- library ----------------------------------------------------------------------------------------


def _canceled_library(code: int, err: str, sig: str, out: Path) -> dict:
    assert code == EXIT[sig], err
    assert "Traceback" not in err, err
    assert f"motionx library: {REASON[sig]}" in err
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["status"] == "canceled" and manifest["summary"]["canceled"] >= 1, manifest["summary"]
    for cell in manifest["cells"]:  # every file the manifest names is there
        for key in ("motion", "clip"):
            if (cell.get("files") or {}).get(key):
                assert (out / cell["files"][key]).is_file(), cell
    return manifest


@pytest.mark.parametrize("sig", ["SIGINT", "SIGTERM"])
def test_a_signal_cancels_the_library_keeping_the_cells_solved(tutor_file, tmp_path, sig):
    """The signal comes once the first cell is done (the flat cell, nearest the tutor): the
    running cell stops at its next IPOPT iteration, the cells not started are canceled, the
    first cell's motion and clip are written and the manifest says "canceled"."""
    out = tmp_path / "lib"
    run = Run("library", tutor_file, "--slopes", "0,10,25", "--delta0", "0.005", "--eps", "0.001", "--out", out)
    run.line(r"^cell 1/3 slope0: succeeded")
    code, _, err = run.signal(sig)
    manifest = _canceled_library(code, err, sig, out)
    cells = {c["key"]: c for c in manifest["cells"]}
    assert cells["slope0"]["status"] == "succeeded" and cells["slope25"]["status"] == "canceled", cells
    assert Motion.load(out / "slope0.motion.json").provenance["lambda"] == pytest.approx(1.0)
    assert json.loads((out / "slope0.clip.json").read_text())


def test_a_signal_before_the_library_is_solved_cancels_every_cell(tutor_file, tmp_path):
    out = tmp_path / "lib"
    run = Run("library", tutor_file, "--slopes", "0,10", "--out", out)
    run.handler_installed()
    code, _, err = run.signal("SIGINT")
    manifest = _canceled_library(code, err, "SIGINT", out)
    assert {c["status"] for c in manifest["cells"]} == {"canceled"}


# --- demo -------------------------------------------------------------------------------------------


@pytest.mark.parametrize("sig, when", [("SIGINT", r"downhill .* running .* ([2-9]|\d\d) steps"),
                                       ("SIGTERM", r"downhill .* tutor ")],
                         ids=["SIGINT-extrapolating", "SIGTERM-making-the-tutor"])
def test_a_signal_cancels_the_demo_keeping_what_its_jobs_reached(shared_data, tmp_path, sig, when):
    """The demo's job is canceled through the service (it stops at its next IPOPT iteration,
    in the tutor or in the walk), what it reached is downloaded into --out, summary.json says
    "canceled", the demo says where and exits 130 (143)."""
    out = tmp_path / "demo"
    env = dict(os.environ, MOTIONX_DATA=str(shared_data), TMPDIR=str(tmp_path), PYTHONUNBUFFERED="1")
    run = Run("demo", "--no-library", "--curve", "0", "--step-height", "0", "--fullbody-slope", "0", "--out", out,
              env=env)
    run.line(when, stream="out")
    code, stdout, err = run.signal(sig)
    assert code == EXIT[sig], stdout[-3000:] + err[-3000:]
    assert "Traceback" not in err, err
    assert f"[demo] {REASON[sig]}: stopped; what the jobs reached is in {out}/" in stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["status"] == "canceled" and summary["message"] == REASON[sig]
    (job,) = summary["jobs"]
    assert job["name"] == "downhill" and job["status"] == "canceled"
    assert json.loads((out / "downhill" / "job.json").read_text())["status"] == "canceled"
    steps = sorted((out / "downhill").glob("step_*.motion.json"))
    assert len(steps) == job["motions"]
    if sig == "SIGINT":  # canceled in the walk: the λ optima before the signal are kept
        assert len(steps) >= 2 and 0 < job["lambda_reached"] < 1, job
        assert [Motion.load(f).provenance["lambda"] for f in steps][-1] == pytest.approx(job["lambda_reached"])
    assert not any(p.name.startswith("motionx-demo-") for p in tmp_path.iterdir())  # the service's folder is gone
