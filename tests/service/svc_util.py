"""Helpers shared by the service tests (imported as ``svc_util``)."""

from __future__ import annotations

import secrets

import numpy as np
import shared_tutors

KEY_A, KEY_B = "test-key-a-" + secrets.token_hex(8), "test-key-b-" + secrets.token_hex(8)


def halfboy_motion(T: int = 12, *, capture: bool = True, seed: int = 0):
    """A small, valid motion file of the reference HalfBoy (upload/validation tests)."""
    from solver.character import reference
    from solver.motion import Motion

    ch = reference("halfboy")
    rng = np.random.default_rng(seed)
    q = 0.05 * rng.standard_normal((ch.n, T))
    return Motion(character=ch, fps=15.0, q=q, reference_name="halfboy",
                  provenance={"step": "capture"} if capture else {})


TERMINAL = ("succeeded", "failed", "canceled", "impasse")

#: a cheap but real job (~1 s): 3 λ steps from the DeepMimic tutor
CHEAP = {"target": {"friction": 0.7}, "control": {"delta0": 0.5}}
#: a longer one (~3-4 s), so a process can be killed in the middle of it
KILLABLE = {"target": {"slope_deg": 6.0, "friction": 0.6},  # Algorithm 3 from 0.01: 8 λ steps
            "control": {"method": "thesis", "delta0": 0.01, "eps": 0.001}}


def wait_job(client, job_id: str, *, timeout: float, until=None, interval: float = 0.05) -> dict:
    """Poll GET /jobs/{id} until ``until(job)`` (default: a terminal status); fails at the deadline."""
    import time

    until = until or (lambda j: j["status"] in TERMINAL)
    deadline = time.monotonic() + timeout
    while True:
        r = client.get(f"/jobs/{job_id}")
        assert r.status_code == 200, r.text
        job = r.json()
        if until(job):
            return job
        if time.monotonic() > deadline:
            raise AssertionError(f"job {job_id} not done after {timeout:g} s: {job['status']} {job['message']!r} "
                                 f"attempts={job['attempts']} steps={job['steps']}")
        time.sleep(interval)


def job_motions(client, job_id: str, page: int = 5) -> list[dict]:
    """Every λ optimum of a job (all pages) as motion files, with step and λ."""
    out, url = [], f"/jobs/{job_id}/motions?limit={page}"
    while url:
        body = client.get(url).json()
        for m in body["items"]:
            f = client.get(m["links"]["motion_file"]).json()
            out.append({"step": m["step"], "lam": m["lam"], "id": m["id"], "frames": f["frames"],
                        "wrenches": f.get("wrenches", {}).get("feet"), "contacts": f.get("contacts", {}).get("active")})
        url = body["next"]
    return out


def same_motions(a: list[dict], b: list[dict]) -> bool:
    key = ("step", "lam", "frames", "wrenches", "contacts")
    return [tuple(m[k] for k in key) for m in a] == [tuple(m[k] for k in key) for m in b]


def deepmimic_files(shared_data):
    d = shared_data / "deepmimic_humanoid3d_walk"
    return [("files", (p.name, p.read_bytes())) for p in (d / "humanoid3d_walk.txt", d / "humanoid3d_character.txt")]


def tutor_json(shared_data) -> str:
    """The tutor of the DeepMimic walk, made by the pipeline (solver.pipeline.make_tutor)."""
    res = shared_tutors.tutor(shared_data, as_motion=True)
    assert res.status == "succeeded", res.message
    return res.motion.to_json()


# --- processes (Linux /proc): what outlives what ----------------------------------------------


def alive(pid: int) -> bool:
    """A process that exists and is not a zombie (a killed child awaiting its reaper is gone)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


def children(pid: int) -> list[int]:
    """Live processes whose parent is ``pid``."""
    import os

    out = []
    for d in os.listdir("/proc"):
        if d.isdigit():
            try:
                with open(f"/proc/{d}/stat") as f:
                    fields = f.read().rsplit(")", 1)[1].split()
            except (FileNotFoundError, ProcessLookupError):
                continue
            if int(fields[1]) == pid and fields[0] != "Z":
                out.append(int(d))
    return out


def wait_gone(pids, timeout: float = 5.0) -> list[int]:
    """Waits until none of ``pids`` is alive; returns those still alive at the deadline."""
    import time

    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        if not [p for p in pids if alive(p)]:
            return []
        time.sleep(0.05)
    return [p for p in pids if alive(p)]


def cmdline(pid: int) -> str:
    try:
        with open(f"/proc/{pid}/cmdline", "rb") as f:
            return f.read().replace(b"\0", b" ").decode(errors="replace")
    except FileNotFoundError:
        return ""


def address_space_limit(pid: int) -> int | None:
    """The soft RLIMIT_AS of a process, bytes (None: unlimited)."""
    with open(f"/proc/{pid}/limits") as f:
        for line in f:
            if line.startswith("Max address space"):
                v = line.split()[3]
                return None if v == "unlimited" else int(v)
    return None

