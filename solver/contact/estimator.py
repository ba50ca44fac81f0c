"""The estimator: inverse dynamics, the support of every frame, the split in double support."""

from __future__ import annotations

import dataclasses
import logging
import math
from collections.abc import Sequence
from typing import Any

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
from solver.contact.correction import centre_of_mass, correct_double, correct_single, foot_rows
from solver.contact.geometry import _cop_violation, _dense_pose, _Pose, _project_cop
from solver.contact.lateral import MAX_TURN_DEG, lateral_correction
from solver.contact.qp import _qp_batch, _QPBatch, _relax_frame, _solve_batch
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
    project_cop: bool | str = False,
    lateral_hz: float | None = None,
) -> ContactEstimate:
    """Ground reaction wrench of each foot at every frame, from kinematics alone.

    ``q`` (n, T) the motion (our world frame: Z up, ground z = 0), ``fps`` its rate,
    ``foot_contact`` (2, T) bool (right, left) the contact schedule. See the module
    docstring for the method; ``method`` is ``"qp"`` (default) or ``"nested"`` (the
    thesis's reference form, slow). ``smoothing_hz`` (qp only): the temporal prior on the
    double-support split, as a cut-off frequency (None: one QP per frame, the thesis).
    ``project_cop``: what to do with a total wrench c the feet on the ground cannot take
    (its CoP outside the support): ``False`` the thesis (single support: the foot takes c;
    double support: the least relaxation of the rows, status ``RELAXED``); ``True`` or
    ``"com"`` c corrected by the least force at the centre of mass (:mod:`solver.contact.correction`,
    single support ``PROJECTED``, double support ``RELAXED`` with its CoPs in the feet);
    ``"cop"`` single-support CoPs moved to the nearest point of the foot (same force and free
    moment), double support as ``False``.
    ``lateral_hz``: the total's lateral force (across the mean progression) taken from the centre of
    mass low-passed at this cut-off, the difference applied at the centre of mass
    (:mod:`solver.contact.lateral`; None: the inverse dynamics' own, the thesis). A walk that turns by
    more than 30° keeps the inverse dynamics' (the estimate's ``lateral_hz`` is then None).
    """
    if method not in METHODS:
        raise ContactError(f"unknown method {method!r}; use one of {METHODS}")
    if project_cop not in (False, True, "com", "cop"):
        raise ContactError(f"project_cop must be False, True, 'com' or 'cop', got {project_cop!r}")
    mode = "com" if project_cop is True else (project_cop or None)
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
    if lateral_hz is not None and not (isinstance(lateral_hz, (int, float, np.floating))
                                       and math.isfinite(lateral_hz) and 0 < lateral_hz < fps / 2):
        raise ContactError(f"lateral_hz must be a frequency in (0, fps/2) (Hz) or None, got {lateral_hz!r}")
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
    full = mode == "com" or lateral_hz is not None
    com: np.ndarray | None
    if lateral_hz is not None:
        # every frame's pose (the filter needs the ends), the estimator's frames taken from it
        pose_all = _dense_pose(character, q, full=True)
        com_all = centre_of_mass(character, pose_all)
        sl = slice(int(frames[0]), int(frames[-1]) + 1)  # the frames are consecutive: views, no copies
        pose = _Pose(pose_all.rot[sl], pose_all.pos[sl])
        com = com_sl = com_all[:, sl]
        lat = lateral_correction(com_all, h0[3:], float(np.sum(character.model.mass)), float(fps),
                                 float(lateral_hz), cyclic)
        if lat is None:
            log.info("contact estimation: the walk turns (> %g°): no single lateral axis, the inverse dynamics' "
                     "lateral force kept", MAX_TURN_DEG)
            lateral_hz = None
        else:
            # a force df at the centre of mass: moment com × df about the origin (the wrench convention of h0)
            df = lat[0]
            h0 = h0.copy()
            h0[3:] += df
            h0[:3] += np.cross(com_sl.T, df.T).T
    else:
        pose = _dense_pose(character, qf, full=full)
        com = centre_of_mass(character, pose) if mode == "com" else None

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
    c = h0  # the total each split must sum to (corrected where no split exists, mode "com")
    if mode == "com":
        assert com is not None
        c = h0.copy()
        for s, mask in ((0, right), (1, left)):
            k = np.flatnonzero(mask)
            if len(k):
                G = foot_rows(character, pose.take(k), FEET[s], penetration, friction)
                bad = _outside(G, h0[:, k])
                if bad.any():
                    kb = k[bad]
                    w[s][:, kb], moved = correct_single(h0[:, kb], com[:, kb], G[bad])
                    c[:, kb] = w[s][:, kb]
                    st[kb[moved]] = Status.PROJECTED
    w_right_exact = w[0].copy()  # c or 0: the boundary values of the temporal prior (dynamics-consistent)
    if mode == "cop":
        for s, mask in ((0, right), (1, left)):
            k = np.flatnonzero(mask)
            if len(k):
                w[s][:, k], moved = _project_cop(w[s][:, k], character, pose.take(k), FEET[s], penetration)
                st[k[moved]] = Status.PROJECTED
    if len(ds):
        opts: dict[str, Any] = dict(friction=friction, penetration=penetration, regularization=regularization,
                                    effort=effort)
        pose_ds = pose.take(ds)
        batch = _qp_batch(character, pose_ds, tau0[:, ds], c[:, ds], **opts)
        y, st_ds, rows = _solve_batch(batch, method, defer_relaxation=mode == "com")
        if mode == "com" and np.any(st_ds == Status.RELAXED):
            # no split exists: the least force at the centre of mass that makes one exist, then the split
            j = np.flatnonzero(st_ds == Status.RELAXED)
            assert com is not None  # mode "com"
            pj = pose_ds.take(j)
            cj, moved, y_c = correct_double(c[:, ds[j]], com[:, ds[j]], batch.r[j],
                                            foot_rows(character, pj, FEET[0], penetration, friction),
                                            foot_rows(character, pj, FEET[1], penetration, friction))
            if moved.any():
                # c' sits on the edge of what the feet can take: its split is (all but) unique, the
                # correction's own; the frame's rows (for the temporal prior) are those of c'
                jm = j[moved]
                c[:, ds[jm]] = cj[:, moved]
                sub = _qp_batch(character, pose_ds.take(jm), tau0[:, ds[jm]], c[:, ds[jm]], **opts)
                batch = _splice(batch, sub, jm)
                y[jm] = y_c[moved]
                tol = 1e-7 * np.maximum(np.abs(sub.c[:, 5]), 1.0)
                for r, i in enumerate(jm):
                    rows[i] = (sub.G[r], sub.h[r] + np.maximum(sub.G[r] @ y_c[moved][r] - sub.h[r], 0.0) + tol[r])
            for i in j[~moved]:  # no correction found: the least relaxation of the frame's rows (the thesis's)
                sol, rows[i] = _relax_frame(batch, int(i), method)
                if sol is None:
                    st_ds[i] = Status.FAILED
                else:
                    y[i] = sol
        if smoothing_hz is not None:
            y = _smooth_split(batch, y, rows, ds, _timeline(character, pose, w_right_exact, cyclic),
                              float(fps) / (2.0 * math.pi * float(smoothing_hz)))
        # back to moments about the origin: m_O = m_r + r × f
        y_o = y.copy()
        y_o[:, :3] += np.cross(batch.r, y[:, 3:])
        w[0][:, ds] = y_o.T
        w[1][:, ds] = c[:, ds] - y_o.T
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
        log.info("contact estimation: %d of %d double-support frames infeasible, %s", n_rel, len(ds),
                 "total corrected at the centre of mass" if mode == "com" else "relaxed")
    return ContactEstimate(wrenches=wrenches, total=total, support=support, status=status,
                           cop_violation=viol, fps=float(fps), method=method, cyclic=bool(cyclic),
                           smoothing_hz=None if smoothing_hz is None else float(smoothing_hz),
                           lateral_hz=None if lateral_hz is None else float(lateral_hz))




def _outside(G: np.ndarray, c: np.ndarray) -> np.ndarray:
    """(N,) frames whose wrench c (6, N) breaks one of its rows G (N, m, 6) (G c ≤ 0 with a relative tolerance)."""
    tol = 1e-9 * np.maximum(np.abs(c[5]), 1.0)
    return np.any(np.einsum("nmi,in->nm", G, c) > tol[:, None], axis=1)


def _splice(batch: _QPBatch, sub: _QPBatch, j: np.ndarray) -> _QPBatch:
    """``batch`` with the frames ``j`` replaced by the frames of ``sub`` (same rows per frame)."""
    out = {}
    for f in dataclasses.fields(batch):
        a = getattr(batch, f.name)
        if f.name in ("row_foot", "row_is_cop"):
            out[f.name] = a
            continue
        a = np.array(a, copy=True)
        a[j] = getattr(sub, f.name)
        out[f.name] = a
    return _QPBatch(**out)
