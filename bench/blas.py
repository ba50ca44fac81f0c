"""MUMPS on CasADi's OpenBLAS (a CORE2 build) against scipy-openblas32's kernel for this CPU
(solver.spacetime.blas), the rest equal: the tutor corrections (HalfBoy 15 frames/s, full body
30 frames/s) with compiled derivatives, each mode in a fresh process (the BLAS MUMPS binds to is
fixed when a process first runs IPOPT). Iteration counts may differ (rounding); compare the
milliseconds per iteration.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile

CASES = [("c3d_pig", "halfboy", 15.0), ("deepmimic_walk", "halfboy", 15.0), ("c3d_pig", "fullbody", 30.0)]

CHILD = r"""
import json, sys
from pathlib import Path
from bench.compiled import tutor_correction
from bench.trials import trials
from solver.io import load_trial
from solver.pipeline import make_tutor
from solver.spacetime import blas, compiled, frame_functions
cache, optimized, cases = Path(sys.argv[1]), sys.argv[2] == "1", json.loads(sys.argv[3])
if optimized:
    assert blas.enable(cache), "the optimized BLAS did not load"
compiled.enable(cache)
out = {}
for trial, kind, fps in cases:
    res = make_tutor(load_trial(trials()[trial]), character=kind, fps=fps)
    compiled.start(frame_functions(res.motion.character), wait=True)
    row = min((tutor_correction(res) for _ in range(2)), key=lambda r: r["time_s"])
    row["ms_per_iteration"] = 1e3 * row["time_s"] / max(row["iterations"], 1)
    out[f"{trial}/{kind}_{fps:g}fps"] = row
print(json.dumps(out))
"""


def run() -> dict:
    out: dict = {}
    env = dict(os.environ, MOTIONX_OPTIMIZED_BLAS="0", OMP_NUM_THREADS="1")
    with tempfile.TemporaryDirectory() as tmp:
        for mode, flag in (("casadi_openblas", "0"), ("optimized", "1")):
            r = subprocess.run([sys.executable, "-c", CHILD, tmp, flag, json.dumps(CASES)], env=env,
                               capture_output=True, text=True, check=True)
            out[mode] = json.loads(r.stdout.strip().splitlines()[-1])
    for case, row in out["optimized"].items():
        base = out["casadi_openblas"][case]
        row["speedup_per_iteration"] = base["ms_per_iteration"] / row["ms_per_iteration"]
    return out
