"""The estimator: inverse dynamics, the support of every frame, the split in double support."""

from __future__ import annotations

import logging
import math
from typing import Any, Sequence

import numpy as np

from solver.character import Character
from solver.contact.common import (
    DEFAULT_FRICTION,
    DEFAULT_PENETRATION,
    DEFAULT_REGULARIZATION,
    METHODS,
    ContactError,
    ContactEstimate,
    Status,
    Support,
    _check_inputs,
    _check_schedule,
    _derivatives,
)
from solver.contact.geometry import _cop_violation, _dense_pose, _project_cop
from solver.contact.qp import _qp_batch, _solve_batch
from solver.contact.smoothing import _smooth_split, _timeline
from solver.dynamics import DEFAULT_GRAVITY, rnea
from solver.motion import FEET

log = logging.getLogger("solver.contact")

# --- the estimator -------------------------------------------------------------------------


def estimate_contact_wrenches(
    character: Character,
    q: Any,
    fps: float,
    foot_contact: Any,
    *,
    gravity: Sequence[float] = DEFAULT_GRAVITY,
    method: str = "qp",
    cyclic: bool = False,
    friction: float | None = DEFAULT_FRICTION,
    penetration: float = DEFAULT_PENETRATION,
    regularization: float = DEFAULT_REGULARIZATION,
    effort_coordinates: Sequence[str] | None = None,
    smoothing_hz: float | None = None,
    project_cop: bool = False,
) -> ContactEstimate:
    """Ground reaction wrench of each foot at every frame, from kinematics alone.

    ``q`` (n, T) the motion (our world frame: Z up, ground z = 0), ``fps`` its rate,
    ``foot_contact`` (2, T) bool (right, left) the contact schedule. See the module
    docstring for the method; ``method`` is ``"qp"`` (default) or ``"nested"`` (the
    thesis's reference form, slow). ``smoothing_hz`` (qp only): the temporal prior on the
    double-support split, as a cut-off frequency (None: one QP per frame, the thesis).
    ``project_cop``: single-support CoPs outside the foot's polygon moved into it.
    """
    if method not in METHODS:
        raise ContactError(f"unknown method {method!r}; use one of {METHODS}")
    if friction is not None and not (math.isfinite(friction) and friction > 0):
        raise ContactError(f"friction must be a positive number or None, got {friction!r}")
    if not (math.isfinite(penetration) and penetration >= 0):
        raise ContactError(f"penetration must be >= 0, got {penetration!r}")
    if not (math.isfinite(regularization) and regularization > 0):
        raise ContactError(f"regularization must be > 0 (it makes the QP strictly convex), got {regularization!r}")
    if smoothing_hz is not None:
        if not (isinstance(smoothing_hz, (int, float, np.floating)) and math.isfinite(smoothing_hz)
                and smoothing_hz > 0):
            raise ContactError(f"smoothing_hz must be a positive frequency (Hz) or None, got {smoothing_hz!r}")
        if method != "qp":
            raise ContactError("smoothing_hz goes with method='qp' (the nested form is the thesis's per-frame "
                               "reference)")
    q, fc, g = _check_inputs(character, q, fps, foot_contact, gravity)
    T = q.shape[1]
    effort = None
    if effort_coordinates is not None:
        unknown = [c for c in effort_coordinates if c not in character.coordinate_names]
        if unknown:
            raise ContactError(f"effort_coordinates: unknown coordinates {unknown} for character {character.name!r}")
        effort = np.isin(np.array(character.coordinate_names), list(effort_coordinates))
    frames, qd, qdd = _derivatives(q, 1.0 / float(fps), cyclic)
    defined = np.zeros(T, dtype=bool)
    defined[frames] = True
    _check_schedule(fc, defined)

    support = np.where(fc[0] & fc[1], Support.DOUBLE,
                       np.where(fc[0], Support.RIGHT, np.where(fc[1], Support.LEFT, Support.FLIGHT))).astype(np.int8)
    qf = q[:, frames]
    res = rnea(character, qf, qd, qdd, g)
    tau0, h0 = np.asarray(res.tau), np.asarray(res.h0)

    wrenches = np.full((2, 6, T), np.nan)
    total = np.full((6, T), np.nan)
    status = np.full(T, Status.UNDEFINED, dtype=np.int8)
    total[:, frames] = h0
    sup = support[frames]
    w = np.zeros((2, 6, len(frames)))
    st = np.full(len(frames), Status.FLIGHT, dtype=np.int8)
    right, left = sup == Support.RIGHT, sup == Support.LEFT
    w[0][:, right] = h0[:, right]
    w[1][:, left] = h0[:, left]
    st[right | left] = Status.SINGLE
    ds = np.flatnonzero(sup == Support.DOUBLE)
    pose = _dense_pose(character, qf)
    w_right_exact = w[0].copy()  # c or 0: the boundary values of the temporal prior (dynamics-consistent)
    if project_cop:
        for s, mask in ((0, right), (1, left)):
            k = np.flatnonzero(mask)
            if len(k):
                w[s][:, k], moved = _project_cop(w[s][:, k], character, pose.take(k), FEET[s], penetration)
                st[k[moved]] = Status.PROJECTED
    if len(ds):
        batch = _qp_batch(character, pose.take(ds), tau0[:, ds], h0[:, ds], friction=friction,
                          penetration=penetration, regularization=regularization, effort=effort)
        y, st_ds, rows = _solve_batch(batch, method)
        if smoothing_hz is not None:
            y = _smooth_split(batch, y, rows, ds, _timeline(character, pose, w_right_exact, cyclic),
                              float(fps) / (2.0 * math.pi * float(smoothing_hz)))
        # back to moments about the origin: m_O = m_r + r × f
        y_o = y.copy()
        y_o[:, :3] += np.cross(batch.r, y[:, 3:])
        w[0][:, ds] = y_o.T
        w[1][:, ds] = h0[:, ds] - y_o.T
        st[ds] = st_ds
        failed = st_ds == Status.FAILED
        if failed.any():
            w[:, :, ds[failed]] = np.nan
    wrenches[:, :, frames] = w
    status[frames] = st
    viol = np.full((2, T), np.nan)
    viol[:, frames] = np.where((sup != Support.FLIGHT)[None, :], _cop_violation(w, character, pose, penetration), 0.0)
    n_rel = int(np.sum(st == Status.RELAXED))
    if n_rel:
        log.info("contact estimation: %d of %d double-support frames infeasible, relaxed", n_rel, len(ds))
    return ContactEstimate(wrenches=wrenches, total=total, support=support, status=status,
                           cop_violation=viol, fps=float(fps), method=method, cyclic=bool(cyclic),
                           smoothing_hz=None if smoothing_hz is None else float(smoothing_hz))


