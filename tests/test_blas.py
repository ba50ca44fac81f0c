"""solver.spacetime.blas: MUMPS bound to scipy-openblas32's kernels through a soname shim.

Each case runs in a child process: the BLAS MUMPS binds to is decided when a process first
loads IPOPT, and the test process has long done so."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

SOLVE = r"""
import json, logging, sys
logging.basicConfig(level=logging.WARNING)
from solver.spacetime import blas
before = sys.argv[2] == "before"
import casadi as ca
import numpy as np
rng = np.random.default_rng(3)  # a small NLP with dense blocks (MUMPS calls dgemm_ on its fronts)
n, m = 120, 60
B, C = rng.normal(size=(n, n)) / np.sqrt(n), rng.normal(size=(m, n)) / np.sqrt(n)
x = ca.SX.sym("x", n)
nlp = {"x": x, "f": ca.sumsqr(x - rng.normal(size=n)) + 0.3 * ca.sum1(ca.cos(ca.mtimes(B, x))),
       "g": ca.mtimes(C, x) + 0.05 * ca.sin(x[:m])}
args = {"x0": np.zeros(n), "lbg": 0.0, "ubg": 0.0, "lbx": -3.0, "ubx": 3.0}
opts = {"ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.tol": 1e-10}
if before:
    ca.nlpsol("first", "ipopt", nlp, opts)(**args)
enabled = blas.enable(sys.argv[1]) if sys.argv[1] != "-" else False
solver = ca.nlpsol("s", "ipopt", nlp, opts)
sol = solver(**args)
print(json.dumps({"enabled": enabled, "loaded": str(blas.loaded()), "status": solver.stats()["return_status"],
                  "x": np.asarray(sol["x"]).ravel().tolist(), "f": float(sol["f"])}))
"""


def child(cache: str, *, when: str = "first", env: dict | None = None) -> tuple[dict, str]:
    e = dict(os.environ, PYTHONPATH=str(ROOT), OMP_NUM_THREADS="1", **(env or {}))
    r = subprocess.run([sys.executable, "-c", SOLVE, cache, when], env=e, capture_output=True, text=True,
                       timeout=300, cwd=ROOT)
    assert r.returncode == 0, r.stderr[-3000:]
    return json.loads(r.stdout.strip().splitlines()[-1]), r.stderr


def test_mumps_binds_to_the_optimized_blas_and_finds_the_same_optimum(tmp_path):
    ref, _ = child("-")  # CasADi's own OpenBLAS
    got, _ = child(str(tmp_path))  # builds the shim
    assert got["enabled"] and got["status"] == ref["status"] == "Solve_Succeeded"
    shim = Path(got["loaded"])
    assert shim.parent == tmp_path and shim.name.startswith("blas-")
    assert got["f"] == pytest.approx(ref["f"], rel=1e-9)
    assert max(abs(a - b) for a, b in zip(got["x"], ref["x"])) < 1e-6
    # a later process reuses the built shim, and the dynamic loader binds MUMPS' matrix product to it
    # (which jumps to scipy-openblas32); traced in that process, whose build step (nm, cc) does not run
    again, err = child(str(tmp_path), env={"LD_DEBUG": "bindings"})
    assert again["enabled"] and again["loaded"] == got["loaded"]
    assert any("libcoinmumps" in ln and str(shim) in ln and "`dgemm_'" in ln for ln in err.splitlines())
    assert again["x"] == got["x"]


def test_too_late_in_a_process_that_already_ran_ipopt(tmp_path):
    got, _ = child(str(tmp_path), when="before")
    assert not got["enabled"] and got["status"] == "Solve_Succeeded"
    assert not list(tmp_path.glob("blas-*.so"))


def test_without_a_compiler_the_solve_goes_on_with_a_warning(tmp_path):
    got, err = child(str(tmp_path), env={"CC": "no-such-compiler-motionx"})
    assert not got["enabled"] and got["status"] == "Solve_Succeeded"
    assert "optimized BLAS unavailable (no C compiler)" in err


def test_the_setting(monkeypatch):
    from service.config import Settings

    monkeypatch.setenv("MOTIONX_OPTIMIZED_BLAS", "0")
    assert Settings().optimized_blas is False
    monkeypatch.setenv("MOTIONX_OPTIMIZED_BLAS", "1")
    assert Settings().optimized_blas is True
