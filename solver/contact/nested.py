"""The thesis's nested form (docs/method.md (M4.7)), kept as the reference: inner QP at fixed x_fz,
outer scalar search."""

from __future__ import annotations

import logging
import math

import numpy as np
import quadprog

log = logging.getLogger("solver.contact")


def _solve_qp(P: np.ndarray, qv: np.ndarray, G: np.ndarray, h: np.ndarray) -> np.ndarray | None:
    """min yᵀPy + 2qᵀy s.t. G y ≤ h with quadprog; None if infeasible."""

    try:
        return quadprog.solve_qp(2.0 * P, -2.0 * qv, -G.T, -h, 0)[0]
    except ValueError:
        return None



def _nested(P: np.ndarray, qv: np.ndarray, G: np.ndarray, h: np.ndarray, scale: float) -> np.ndarray | None:
    """Thesis form: inner QP with y_fz = z fixed, outer bounded search over z (docs/method.md (M4.7))."""
    from scipy.optimize import linprog, minimize_scalar  # lazy: scipy.optimize costs ~0.4 s to import

    # feasible interval of z = y_fz (an LP each way)
    e = np.zeros(6)
    e[5] = 1.0
    lo = linprog(e, A_ub=G, b_ub=h, bounds=[(None, None)] * 6, method="highs")
    hi = linprog(-e, A_ub=G, b_ub=h, bounds=[(None, None)] * 6, method="highs")
    if lo.status != 0 or hi.status != 0:
        return None
    z_lo, z_hi = float(lo.x[5]), float(hi.x[5])
    Puu, Puz = P[:5, :5], P[:5, 5]
    Gu, Gz = G[:, :5], G[:, 5]

    def inner(z: float) -> tuple[float, np.ndarray | None]:
        u = _solve_qp(Puu, qv[:5] + Puz * z, Gu, h - Gz * z + 1e-12 * scale)
        if u is None:
            return math.inf, None
        y = np.concatenate([u, [z]])
        return float(y @ P @ y + 2.0 * qv @ y), y

    if z_hi - z_lo <= 1e-12 * scale:
        return inner(0.5 * (z_lo + z_hi))[1]
    res = minimize_scalar(lambda z: inner(z)[0], bounds=(z_lo, z_hi), method="bounded",
                          options={"xatol": 1e-10 * scale, "maxiter": 500})
    # fminbound stops at a tolerance relative to |z| (√eps·|z| ≈ 1e-8·c_fz): polish around the
    # estimate in a shifted variable, where that relative tolerance vanishes
    z0 = float(res.x)
    w = 1e-5 * scale
    lo, hi = max(z_lo, z0 - w) - z0, min(z_hi, z0 + w) - z0
    if hi > lo:
        pol = minimize_scalar(lambda u: inner(z0 + u)[0], bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-12 * scale, "maxiter": 500})
        if pol.fun <= res.fun:
            z0 = z0 + float(pol.x)
    return inner(z0)[1]


