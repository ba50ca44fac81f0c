"""The fit's inverse kinematics (:func:`solver.io.fit.fit_track`): the first guess from the segment
frames (hinge chains decomposed, :mod:`solver.hinges`), a damped Gauss-Newton (Levenberg-Marquardt)
per frame on the landmarks and segment orientations, and the joint limits widened to what the
captured motion needs.
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from dataclasses import replace

import numpy as np

from solver import hinges
from solver import spatial as sp
from solver.character import Character, Dof
from solver.kinematics import forward_kinematics, points_world, segment_frames

log = logging.getLogger(__name__)

LIMIT_MARGIN = 5.0 * math.pi / 180.0
#: absolute damping (m² per rad²) of every IK step: coordinates the data cannot see
#: (e.g. the axial rotation of a straight limb without orientations) stay where they are.
PROXIMAL = 1e-6


def decompose_hinges(R: np.ndarray, axes: list[np.ndarray]) -> np.ndarray | None:
    """Angles (θ1, θ2, θ3) with R = Rot(a1, θ1) Rot(a2, θ2) Rot(a3, θ3) (:func:`solver.hinges.decompose_hinges`,
    in this module's (3, 3, T) layout, no polishing: the closed form).

    ``R`` may be (3, 3) or (3, 3, T). Returns (3,) / (3, T), or None when the chain is not three
    hinges that can be decomposed (the caller then starts from 0).
    """
    if len(axes) != 3:
        return None
    R = np.asarray(R, dtype=float)
    M = R[None] if R.ndim == 2 else np.moveaxis(R, -1, 0)
    try:
        theta, _ = hinges.decompose_hinges(M, [np.asarray(a, dtype=float) for a in axes], polish=0)
    except hinges.HingeError:
        return None
    return theta[0] if R.ndim == 2 else theta.T


def _initial_guess(ch: Character, F: Mapping[str, np.ndarray], origin: Mapping[str, np.ndarray], T: int) -> np.ndarray:
    """Analytic coordinates from the segment frames (relative rotations on the hinge axes)."""
    q0 = np.zeros((ch.n, T))
    k = 0
    for s in ch.segments:
        nd = len(s.dofs)
        if s.parent is None:
            p = origin[s.name]
            R = F[s.name]
            q0[k:k + 3] = p
            yaw = np.arctan2(R[1, 0], R[0, 0])
            pitch = np.arcsin(np.clip(-R[2, 0], -1, 1))
            roll = np.arctan2(R[2, 1], R[2, 2])
            q0[k + 3:k + 6] = np.stack([yaw, pitch, roll])
        elif s.name in F and s.parent in F and nd == 3 and all(d.kind == "hinge" for d in s.dofs):
            Rrel = np.einsum("jit,jkt->ikt", F[s.parent], F[s.name])
            Rrel = np.einsum("ji,jkt->ikt", s.orientation, Rrel)
            ang = decompose_hinges(Rrel, [d.axis for d in s.dofs])
            if ang is not None:
                q0[k:k + 3] = ang
        k += nd
    return q0


def _solve_ik(ch, times, lm, F, origin, ori, attach, w_ori):
    import casadi as ca  # lazy: keeps CasADi out of numpy-only paths and OpenSim's child process


    T = times.size
    att = [(name, seg, p) for name, (seg, p) in attach.items()]
    oris = [s.name for s in ch.segments if s.name in ori]  # merged segments' orientations are not fitted
    n = ch.n
    qs = ca.SX.sym("q", n)
    pts = points_world(ch, qs, [(seg, p) for _, seg, p in att])
    model = ch.model
    pose = forward_kinematics(ch, qs)
    rows = []
    for s in oris:
        b = model.seg_body[s]
        R = sp.matmul(pose.rot[b], sp.const_mat(model.seg_rot[s]))
        rows.extend(R[i][j] for i in range(3) for j in range(3))
    rot_expr = sp.stack(rows, like=qs) if rows else ca.SX(0, 1)
    L, O = len(att), len(oris)
    target = ca.SX.sym("target", 3 * L + 9 * O)
    weight = ca.SX.sym("w", 3 * L + 9 * O)
    model_expr = ca.vertcat(pts, rot_expr)
    r = weight * (model_expr - target)
    fun = _NormalEquations(qs, target, weight, r)

    # targets and weights (T, 3L + 9O); missing data weigh 0
    tgt = np.zeros((T, 3 * L + 9 * O))
    wts = np.zeros_like(tgt)
    for i, (name, _, _) in enumerate(att):
        p = lm[name].T
        ok = np.all(np.isfinite(p), axis=1)
        tgt[ok, 3 * i:3 * i + 3] = p[ok]
        wts[ok, 3 * i:3 * i + 3] = 1.0
    for j, s in enumerate(oris):
        R = np.moveaxis(ori[s], 2, 0).reshape(T, 9)
        ok = np.all(np.isfinite(R), axis=1)
        c = 3 * L + 9 * j
        tgt[ok, c:c + 9] = R[ok]
        wts[ok, c:c + 9] = w_ori

    t_solve = time.perf_counter()
    q0 = _initial_guess(ch, F, origin, T)
    hinge = np.array([k == "hinge" for k in ch.dof_kinds])
    Q = np.zeros((n, T))
    iters = np.zeros(T, dtype=int)
    prev = None
    for t in range(T):
        cands = []
        x0 = q0[:, t].copy()
        if np.all(np.isfinite(x0)):
            if prev is not None:  # the 2π branch nearest the previous frame
                x0[hinge] = prev[hinge] + np.angle(np.exp(1j * (x0[hinge] - prev[hinge])))
            cands.append(x0)
        if prev is not None:
            cands.append(prev)  # warm start
        if not cands:
            cands.append(np.nan_to_num(x0))
        if not np.any(wts[t]):
            Q[:, t] = cands[-1]
            prev = Q[:, t]
            continue
        if len(cands) > 1:
            fun.set_data(tgt[t], wts[t])
            costs = [fun.cost(c) for c in cands]
            x0 = cands[int(np.argmin(costs))]
        else:
            x0 = cands[0]
        fun.set_data(tgt[t], wts[t])
        Q[:, t], iters[t] = _levenberg_marquardt(fun, x0)
        prev = Q[:, t]

    solve_s = time.perf_counter() - t_solve
    for i in np.where(hinge)[0]:  # continuous angles (no 2π jumps), e.g. the yaw of a turning walk
        Q[i] = np.unwrap(Q[i])
    # errors
    pts_all = points_world(ch, Q, [(seg, p) for _, seg, p in att])  # (L, 3, T)
    per = {}
    all_err = []
    for i, (name, _, _) in enumerate(att):
        e = np.linalg.norm(pts_all[i] - lm[name], axis=0) * 1e3
        e = e[np.isfinite(e)]
        per[name] = {"mean": round(float(e.mean()), 2), "max": round(float(e.max()), 2),
                     "rms": round(float(np.sqrt(np.mean(e**2))), 2)}
        all_err.append(e)
    cat = np.concatenate(all_err)

    rots, _ = segment_frames(ch, Q)
    seg_idx = {s.name: i for i, s in enumerate(ch.segments)}
    ori_err = {}
    for s in oris:
        Rm, Rt = rots[seg_idx[s]], ori[s]
        c = (np.einsum("ijt,ijt->t", Rm, Rt) - 1.0) / 2.0
        ang = np.degrees(np.arccos(np.clip(c[np.isfinite(c)], -1, 1)))
        ori_err[s] = {"mean": round(float(ang.mean()), 2), "max": round(float(ang.max()), 2)}
    report = {
        "landmark_error_mm": {"mean": round(float(cat.mean()), 2), "max": round(float(cat.max()), 2),
                              "rms": round(float(np.sqrt(np.mean(cat**2))), 2)},
        "per_landmark_mm": per,
        "orientation_error_deg": ori_err,
        "orientation_weight_m": w_ori,
        "landmarks_used": [a[0] for a in att],
        "ik_iterations": {"mean": round(float(iters.mean()), 2), "max": int(iters.max())},
        "_solve_s": solve_s,
    }
    return Q, report


class _NormalEquations:
    """Cost ‖r‖², gradient Jᵀr and Gauss-Newton matrix JᵀJ of r(q; target, weight), compiled once.

    Evaluated through CasADi's zero-copy buffer interface: no numpy BLAS call on small
    matrices (a multithreaded BLAS costs ~100x more than the arithmetic there).
    """

    def __init__(self, qs, target, weight, r) -> None:
        import casadi as ca  # lazy: keeps CasADi out of numpy-only paths and OpenSim's child process

        n, m = qs.shape[0], r.shape[0]
        J = ca.jacobian(r, qs)
        full = ca.Function("ik_normal", [qs, target, weight],
                           [ca.dot(r, r), ca.densify(ca.mtimes(J.T, r)), ca.densify(ca.mtimes(J.T, J))])
        cost = ca.Function("ik_cost", [qs, target, weight], [ca.dot(r, r)])
        self._x, self._tgt, self._w = np.zeros(n), np.zeros(m), np.zeros(m)
        self._c, self._g, self._H = np.zeros(1), np.zeros(n), np.zeros((n, n))
        self._cc = np.zeros(1)
        self._full, self._full_run = full.buffer()
        self._cost, self._cost_run = cost.buffer()
        for buf in (self._full, self._cost):
            for i, a in enumerate((self._x, self._tgt, self._w)):
                buf.set_arg(i, memoryview(a))  # type: ignore[call-arg, arg-type]  # casadi's stubs: size is the view's
        for i, a in enumerate((self._c, self._g, self._H)):
            self._full.set_res(i, memoryview(a))  # type: ignore[call-arg, arg-type]
        self._cost.set_res(0, memoryview(self._cc))  # type: ignore[call-arg, arg-type]

    def set_data(self, tgt: np.ndarray, w: np.ndarray) -> None:
        self._tgt[:] = tgt
        self._w[:] = w

    def cost(self, x: np.ndarray) -> float:
        self._x[:] = x
        self._cost_run()
        return float(self._cc[0])

    def normal(self, x: np.ndarray) -> tuple[float, np.ndarray, np.ndarray]:
        self._x[:] = x
        self._full_run()
        return float(self._c[0]), self._g.copy(), self._H.copy()  # H is symmetric: layout-free


def _levenberg_marquardt(fun: _NormalEquations, x0: np.ndarray, max_iter: int = 100) -> tuple[np.ndarray, int]:
    """Minimise ‖r(x)‖² from x0; returns (x, iterations). Stops on a tiny step or decrease."""
    x = x0
    lam = 1e-4
    it = 0
    cost, g, H = fun.normal(x)
    for _it in range(1, max_iter + 1):
        d = lam * np.diag(H) + PROXIMAL
        accepted = False
        while lam < 1e12:
            dx = -np.linalg.solve(H + np.diag(d), g)
            cn = fun.cost(x + dx)
            if cn <= cost:
                accepted = True
                x = x + dx
                decrease = cost - cn
                lam = max(lam / 10.0, 1e-9)
                break
            lam *= 10.0
            d = lam * np.diag(H) + PROXIMAL
        if not accepted:
            break
        cost, g, H = fun.normal(x)
        if np.max(np.abs(dx)) < 1e-6 or decrease <= 1e-8 * cost + 1e-14:
            break
    return x, it


def _widen_limits(ch: Character, q: np.ndarray) -> tuple[Character, dict[str, list[float]]]:
    """Capture data are not clipped to anatomical limits: widen where the data exceed them."""
    widened: dict[str, list[float]] = {}
    segs = []
    k = 0
    for s in ch.segments:
        dofs = []
        for d in s.dofs:
            lo, hi = float(np.min(q[k])), float(np.max(q[k]))
            nl, nu = d.lower, d.upper
            if lo < d.lower:
                nl = lo - LIMIT_MARGIN
            if hi > d.upper:
                nu = hi + LIMIT_MARGIN
            if (nl, nu) != (d.lower, d.upper):
                widened[d.name] = ([round(math.degrees(nl), 1), round(math.degrees(nu), 1)] if d.kind == "hinge"
                                   else [nl, nu])
                d = Dof(d.name, d.kind, d.axis, nl, nu)
            dofs.append(d)
            k += 1
        segs.append(replace(s, dofs=tuple(dofs)))
    if widened:
        log.info("fit_track: joint limits widened to the data (deg): %s", widened)
    return replace(ch, segments=tuple(segs)), widened
