"""How fast this machine is, on a fixed workload that does not change with our code.

The figures of ``make bench`` are seconds on whatever machine ran them, and the machines differ
(sessions have measured the same correction at 0.89 s on one and 1.6–2.2 s on another, and one
machine slowing by 25 % within a session). Every section therefore records this probe when it
runs: the same kind of work as a spacetime solve — CasADi SX functions with dense blocks,
IPOPT with MUMPS on the BLAS it is bound to (recorded) — on a problem that is fixed here
(seeded, no project code). Its iteration count is fixed by the libraries; its seconds per iteration are the
machine's speed for our workload. Divide a section's seconds by its probe's to compare runs
made on different machines or at different times.

The seconds per iteration are not the whole story: IPOPT's *iteration counts* on our problems
depend on the CPU too, through the floating-point rounding of the BLAS kernel OpenBLAS picks for
it (measured: the DeepMimic HalfBoy correction takes 109 iterations with the SkylakeX
kernel of NumPy's OpenBLAS, 104 on the same machine with ``OPENBLAS_CORETYPE=Haswell``, 103 on an
AMD machine; CasADi's own OpenBLAS is a CORE2 build, the same kernel everywhere), and
a continuation magnifies that (the PiG full-body curve 90°: 230 iterations there, 665 here). So
the probe also records the CPU (OpenBLAS's name for it) and MUMPS' BLAS kernel: compare
iteration counts only between runs that agree on both.
"""

from __future__ import annotations

import platform
import time
from pathlib import Path

import casadi as ca
import numpy as np

STAGES, WIDTH = 60, 44  # a banded KKT with dense 2·WIDTH blocks, like a spline segment's


def _nlp() -> tuple[dict, dict]:
    rng = np.random.default_rng(21)
    A = rng.normal(scale=0.6 / np.sqrt(WIDTH), size=(WIDTH, WIDTH))
    B = rng.normal(scale=1.0 / np.sqrt(WIDTH), size=(WIDTH, WIDTH))
    C = rng.normal(scale=0.3, size=(WIDTH, WIDTH // 2))
    target = rng.normal(size=(WIDTH, STAGES + 1))
    X = ca.SX.sym("x", WIDTH, STAGES + 1)
    U = ca.SX.sym("u", WIDTH // 2, STAGES)  # inputs, as the contact wrenches
    f, g = 0, []
    for k in range(STAGES + 1):
        f += ca.sumsqr(X[:, k] - target[:, k]) + 0.1 * ca.sum1(ca.cos(ca.mtimes(B, X[:, k])))
    for k in range(STAGES):  # a nonlinear dense coupling of consecutive stages
        f += 0.1 * ca.sumsqr(U[:, k])
        g.append(X[:, k + 1] - X[:, k] - 0.2 * ca.tanh(ca.mtimes(A, X[:, k])) - 0.05 * ca.sin(X[:, k + 1])
                 - ca.mtimes(C, U[:, k]))
    g.append(X[:WIDTH // 2, STAGES] - X[:WIDTH // 2, 0])  # a cyclic link, as in a gait cycle
    nlp = {"x": ca.vertcat(ca.vec(X), ca.vec(U)), "f": f, "g": ca.vertcat(*g)}
    nx = WIDTH * (STAGES + 1) + WIDTH // 2 * STAGES
    args = {"x0": np.zeros(nx), "lbg": 0.0, "ubg": 0.0, "lbx": -3.0, "ubx": 3.0}
    return nlp, args


def cpu() -> dict:
    """The CPU as OpenBLAS detects it (the kernel family its rounding depends on) and the BLAS
    MUMPS runs on: CasADi's OpenBLAS (built for CORE2) or scipy-openblas32 (solver.spacetime.blas)."""
    from solver.spacetime import blas

    kernel = blas.corename()
    info = {"cpu": f"{platform.machine()} {kernel or ''}".strip()}
    if blas.loaded() is not None:
        return {**info, "mumps_blas": f"scipy-openblas32 {kernel}"}
    core = blas.corename(Path(ca.__file__).with_name(blas.SONAME))
    return {**info, "mumps_blas": f"casadi openblas {core}"}


def probe(repeats: int = 3) -> dict:
    """Median wall time and iterations of the fixed NLP (IPOPT + MUMPS, as the solver runs it)."""
    nlp, args = _nlp()
    solver = ca.nlpsol("probe", "ipopt", nlp, {
        "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes", "ipopt.tol": 1e-9,
        "ipopt.linear_solver": "mumps", "ipopt.mumps_pivot_order": 5, "error_on_fail": False})
    times, its, status = [], 0, ""
    for _ in range(repeats):
        t = time.perf_counter()
        solver(**args)
        times.append(time.perf_counter() - t)
        st = solver.stats()
        its, status = int(st["iter_count"]), str(st["return_status"])
    med = float(np.median(times))
    return {"probe_s": round(med, 4), "probe_iterations": its, "probe_status": status,
            "probe_ms_per_iteration": round(1e3 * med / max(its, 1), 3), **cpu()}


def run() -> dict:
    return probe()


if __name__ == "__main__":
    print(probe())
