"""Ground reactions in the model's frame: the motion's wrenches carried to OpenSim's ground
(:func:`wrenches_to_input`) and written per foot as force, centre of pressure on the floor and
free moment (:func:`grf_columns`, :data:`GRF_LABELS`); the residual reduction's wrench added to
the loaded feet (:func:`reduce_residuals_on_feet`) and how far it moved them (footprints,
centre-of-pressure shifts, force and free-moment changes)."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from solver.capture import GroundFrame

#: a foot loaded less than this fraction of the body weight keeps its last centre of pressure
MIN_LOAD_FRACTION = 0.01


def wrenches_to_input(w: np.ndarray, t_abs: np.ndarray, frame: GroundFrame) -> np.ndarray:
    """Wrenches (2, 6, S) (moment about our origin; force) -> the input's ground frame, the moment
    about its origin (the frame's translation, belt motion included, carried along)."""
    M = np.moveaxis(w[:, :3], 1, -1)
    F = np.moveaxis(w[:, 3:], 1, -1)  # (2, S, 3)
    Fi = frame.vector_to_input(F)
    o = frame.point_to_input(np.zeros((t_abs.size, 3)), t_abs)  # our origin in the input frame
    Mi = frame.vector_to_input(M) + np.cross(o[None], Fi)
    return np.moveaxis(np.concatenate([Mi, Fi], axis=-1), -1, 1)


def grf_columns(w_in: np.ndarray, normal: np.ndarray, origin: np.ndarray, min_load: float) -> np.ndarray:
    """Per foot (2, S, 9): force, point on the ground plane, torque — OpenSim's ground-reaction
    columns — for wrenches ``w_in`` (2, 6, S) about OpenSim's ground origin; the ground is the
    plane through ``origin`` (S, 3) with unit ``normal`` (3,) (the level floor: y up).

    Loaded (force along the normal above ``min_load``): the point is the centre of pressure
    ``o + n × M_o / (n · F)`` (``M_o`` the moment about ``o``), the torque the free moment
    along the normal. Otherwise the foot's nearest loaded centre of pressure is kept and the
    torque is whatever keeps the wrench (zero for an unloaded foot)."""
    n = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    o = np.broadcast_to(np.asarray(origin, dtype=float), (w_in.shape[2], 3))
    out = np.zeros((2, w_in.shape[2], 9))
    for f in range(2):
        M, F = w_in[f, :3].T, w_in[f, 3:].T  # (S, 3)
        fn = F @ n
        loaded = fn > min_load
        Mo = M - np.cross(o, F)
        p = o + np.cross(n, Mo) / np.where(loaded, fn, 1.0)[:, None]
        p[~loaded] = np.nan
        if loaded.any():
            idx = np.where(loaded)[0]
            near = idx[np.abs(np.arange(F.shape[0])[:, None] - idx[None]).argmin(axis=1)]
            p[~loaded] = p[near[~loaded]]
        else:
            p[:] = o
        tq = M - np.cross(p, F)
        tq[loaded] = np.outer(tq[loaded] @ n, n)  # along the normal at the centre of pressure (rounding only)
        out[f] = np.concatenate([F, p, tq], axis=1)
    return out


GRF_LABELS = tuple(f"ground_{kind}_{s}_{c}" for s in "rl" for kind, cs in (
    ("force", ("vx", "vy", "vz", "px", "py", "pz")), ("torque", ("x", "y", "z"))) for c in cs)


def _grf_table(cols: np.ndarray) -> np.ndarray:
    """(2, S, 9) -> (S, 18) in GRF_LABELS order."""
    return np.concatenate([cols[0], cols[1]], axis=1)


def reduce_residuals_on_feet(w_in: np.ndarray, ans: Mapping[str, Any], t: np.ndarray, min_load: float
                             ) -> tuple[np.ndarray, np.ndarray]:
    """The feet's wrenches (2, 6, S) (OpenSim ground, moment about its origin) with the external
    wrench an inverse-dynamics run (:func:`~solver.export.opensim.residuals.run_inverse_dynamics`)
    still needed added, shared by the loaded feet in proportion to their vertical forces (see
    :mod:`solver.export.opensim`). Returns the new wrenches and the wrench added per row (S, 6)
    (zero where no row was analysed)."""
    labels = list(ans["labels"])
    roots = list(ans["root_coordinates"])
    cols = [labels.index(f"{c}_moment") if f"{c}_moment" in labels else labels.index(f"{c}_force") for c in roots]
    r = np.asarray(ans["data"], dtype=float)[:, cols]  # (rows, 6)
    t_id = np.asarray(ans["times"], dtype=float)
    tw_t = np.asarray(ans["twist_times"], dtype=float)
    G = np.asarray(ans["twists"], dtype=float)  # (rows, 6 coords, 6)
    out = np.array(w_in, copy=True)
    added = np.zeros((t.size, 6))
    for k, tk in enumerate(t_id):
        j = int(np.argmin(np.abs(t - tk)))
        g = int(np.argmin(np.abs(tw_t - tk)))
        if abs(t[j] - tk) > 1e-6 or abs(tw_t[g] - tk) > 1e-6:
            continue
        dW = np.linalg.solve(G[g], r[k])  # r = G W: the wrench (M about the origin, F) still missing
        fy = np.maximum(out[:, 4, j], 0.0)
        on = fy > min_load
        if not on.any():
            continue
        share = np.where(on, fy, 0.0) / fy[on].sum()
        out[:, :, j] += share[:, None] * dW[None, :]
        added[j] = dW
    return out, added


#: an adjustment moving a foot's centre of pressure further than this (mm) is flagged as large
LARGE_COP_SHIFT_MM = 50.0
#: half-width (m) of a foot's footprint around its heel-to-toe line
FOOT_HALF_WIDTH_M = 0.05


def footprints(bodies: Sequence[str], body_com: np.ndarray, W: np.ndarray, P: np.ndarray,
               feet: Mapping[str, str]) -> np.ndarray:
    """Per foot (right, left) and row, its heel-to-toe line on the floor (2, S, 2, 2): (x, z) of
    the foot body's origin (the heel of a gait model's calcn) and of the toe tip (the toes
    body's origin moved forward by twice its centre of mass, as the importer places it)."""
    out = np.empty((2, W.shape[0], 2, 2))
    for f, (side, s) in enumerate((("right", "r"), ("left", "l"))):
        heel = P[:, list(bodies).index(feet[side])]
        ti = list(bodies).index(f"toes_{s}") if f"toes_{s}" in bodies else list(bodies).index(feet[side])
        tip = P[:, ti] + 2.0 * np.einsum("tij,j->ti", W[:, ti], np.array([body_com[ti][0], 0.0, 0.0]))
        out[f, :, 0], out[f, :, 1] = heel[:, [0, 2]], tip[:, [0, 2]]
    return out


def cop_outside_feet(cols: np.ndarray, prints: np.ndarray, rows: np.ndarray, min_load: float) -> list[float]:
    """Per foot, how far (m) its centre of pressure leaves its footprint (the heel-to-toe line
    widened by ``FOOT_HALF_WIDTH_M``) at worst over ``rows`` where it is loaded."""
    out = []
    for f in range(2):
        loaded = rows & (cols[f, :, 1] > min_load)
        if not loaded.any():
            out.append(0.0)
            continue
        c = cols[f, loaded][:, [3, 5]]
        a, b = prints[f, loaded, 0], prints[f, loaded, 1]
        ab = b - a
        u = np.clip(np.einsum("ti,ti->t", c - a, ab) / np.maximum(np.einsum("ti,ti->t", ab, ab), 1e-9), 0.0, 1.0)
        d = np.linalg.norm(c - (a + u[:, None] * ab), axis=1)
        out.append(float(np.maximum(d - FOOT_HALF_WIDTH_M, 0.0).max()))
    return out


def _adjustment_figures(before: np.ndarray, after: np.ndarray, t: np.ndarray, window: tuple[float, float],
                        min_load: float) -> dict[str, Any]:
    """How much the ground reactions moved (per foot, over the analysed window): force change,
    centre-of-pressure shift on the floor while loaded, free-moment change."""
    keep = (t >= window[0] - 1e-9) & (t <= window[1] + 1e-9)
    out: dict[str, Any] = {}
    for f, side in enumerate(("right", "left")):
        b, a = before[f, keep], after[f, keep]
        dF = np.linalg.norm(a[:, :3] - b[:, :3], axis=1)
        loaded = (b[:, 1] > min_load) & (a[:, 1] > min_load)
        dp = np.linalg.norm(a[loaded, 3:6] - b[loaded, 3:6], axis=1)
        dm = np.abs(a[:, 7] - b[:, 7])
        out[side] = {"force_change_N": {"max": float(dF.max(initial=0.0)), "rms": float(np.sqrt(np.mean(dF**2)))},
                     "cop_shift_mm": {"max": 1e3 * float(dp.max(initial=0.0)),
                                      "rms": 1e3 * float(np.sqrt(np.mean(dp**2))) if dp.size else 0.0},
                     "free_moment_change_Nm": {"max": float(dm.max(initial=0.0))},
                     "free_moment_Nm": {"max_before": float(np.abs(b[:, 7]).max(initial=0.0)),
                                        "max_after": float(np.abs(a[:, 7]).max(initial=0.0))}}
    return out
