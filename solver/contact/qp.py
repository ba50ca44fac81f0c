"""The double-support QP (docs/method.md (M4.2)-(M4.6)): batched assembly, unconstrained optimum, quadprog,
relaxation."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import quadprog

from solver.character import Character
from solver.contact.common import FEASIBILITY_TOL, Status
from solver.contact.geometry import _foot_frames, _Pose, _screws, _side_sets, _skew
from solver.contact.nested import _nested
from solver.motion import FEET

log = logging.getLogger("solver.contact")

# --- the double-support QP -------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class _QPBatch:
    """min yᵀPy + 2 qᵀy  s.t.  G y ≤ h, for N frames; y = right-foot wrench about r."""

    P: np.ndarray  # (N, 6, 6)
    q: np.ndarray  # (N, 6)
    G: np.ndarray  # (N, m, 6)
    h: np.ndarray  # (N, m)
    row_weight: np.ndarray  # (N, m): scales rows to N·m for the relaxation stage
    row_foot: np.ndarray  # (m,) 0 right, 1 left
    row_is_cop: np.ndarray  # (m,) bool: polygon rows (N·m); else friction rows (N)
    r: np.ndarray  # (N, 3) reference point on the ground
    c: np.ndarray  # (N, 6) total wrench about r



def _qp_batch(
    character: Character,
    pose: _Pose,
    tau0: np.ndarray,
    c: np.ndarray,
    *,
    friction: float | None,
    penetration: float,
    regularization: float,
    effort: np.ndarray | None = None,
) -> _QPBatch:
    """QP data of N double-support frames at once: their pose, tau0 (n, N), c (6, N) about the origin."""
    N = pose.rot.shape[0]
    a_idx, b_idx = _side_sets(character, effort)
    boxes = [_foot_frames(character, pose, s) for s in FEET]
    # contact plane per foot: z = 0, or 1 cm above the lowest corner when the box floats
    centres, polys = [], []
    for rot, ctr, half in boxes:
        z_low = ctr[:, 2] - np.abs(rot[:, 2, :]) @ half
        z_plane = np.maximum(0.0, z_low + penetration)
        centres.append(ctr)
        polys.append(ctr - np.stack([np.zeros(N), np.zeros(N), z_plane], -1))  # box centre relative to its plane
    r = 0.5 * (centres[0] + centres[1])
    r[:, 2] = 0.0

    # screws about r: (ω, v + ω × r)
    S = _screws(character, pose)  # (N, n, 6)
    idx = np.concatenate([a_idx, b_idx])
    Sab = S[:, idx, :].copy()
    Sab[:, :, 3:] += np.cross(Sab[:, :, :3], r[:, None, :])
    # c about r: m_r = m_O − r × f
    cr = c.T.copy()
    cr[:, :3] -= np.cross(r, cr[:, 3:])
    t0 = tau0[idx].T  # (N, k)
    nA = len(a_idx)
    # A: τ = τ0 − S·y ; B: τ = (τ0 − S·c) + S·y
    base = t0.copy()
    base[:, nA:] -= np.einsum("nki,ni->nk", Sab[:, nA:], cr)
    sign = np.concatenate([-np.ones(nA), np.ones(len(b_idx))])
    H = np.einsum("nki,nkj->nij", Sab, Sab)
    g = np.einsum("nk,nki->ni", base * sign, Sab)

    # symmetric tie-breaker: ‖D_r y‖² + ‖D_l (c − y)‖²
    D = []
    for _rot, ctr, half in boxes:
        p = ctr.copy()
        p[:, 2] = 0.0
        d = p - r  # foot centre relative to r
        Dm = np.zeros((N, 6, 6))
        Dm[:, 0, 0] = Dm[:, 1, 1] = Dm[:, 2, 2] = 1.0
        # moment about p: m_r − d × f = m_r + [f]× d ... as a matrix on f: −[d]×
        Dm[:, :3, 3:] = -_skew(d)
        Dm[:, 3, 3] = Dm[:, 4, 4] = Dm[:, 5, 5] = half[0]
        D.append(Dm)
    M = np.einsum("nki,nkj->nij", D[0], D[0]) + np.einsum("nki,nkj->nij", D[1], D[1])
    tr_h = np.trace(H, axis1=1, axis2=2)
    # no joint between the feet and the root (tr H = 0): the tie-breaker alone decides
    eps = regularization * np.where(tr_h > 0, tr_h, 1.0) / np.trace(M, axis1=1, axis2=2)
    ML = np.einsum("nki,nkj->nij", D[1], D[1])
    P = H + eps[:, None, None] * M
    qv = g - eps[:, None] * np.einsum("nij,nj->ni", ML, cr)

    # polygon rows: for box axis e_k (row k of Rᵀ), centre b relative to the plane:
    # a_k·y = e_k1 m_rx − e_k0 m_ry + e_k·(r − b) f_z ;  |a_k·y| ≤ h_k f_z
    rows, rhs, weights, foot, is_cop = [], [], [], [], []
    for s, ((rot, _, half), bc) in enumerate(zip(boxes, polys)):
        E = np.swapaxes(rot, 1, 2)  # (N, 3, 3): rows = box axes in world
        a = np.zeros((N, 3, 6))
        a[:, :, 0] = E[:, :, 1]
        a[:, :, 1] = -E[:, :, 0]
        a[:, :, 5] = np.einsum("nkj,nj->nk", E, r - bc)
        hz = np.zeros((N, 3, 6))
        hz[:, :, 5] = half[None, :]
        Gs = np.concatenate([a - hz, -a - hz], axis=1)  # Gs w ≤ 0 for this foot's wrench w
        fr = None
        if friction is not None:
            fr = np.zeros((N, 4, 6))
            for j, (axis, sg) in enumerate(((3, 1.0), (3, -1.0), (4, 1.0), (4, -1.0))):
                fr[:, j, axis] = sg
                fr[:, j, 5] = -friction
            Gs = np.concatenate([Gs, fr], axis=1)
        m = Gs.shape[1]
        w = np.ones((N, m))
        if friction is not None:
            w[:, 6:] = half[0]
        if s == 0:
            rows.append(Gs)
            rhs.append(np.zeros((N, m)))
        else:  # Gs (c − y) ≤ 0  ->  −Gs y ≤ −Gs c
            rows.append(-Gs)
            rhs.append(-np.einsum("nmi,ni->nm", Gs, cr))
        weights.append(w)
        foot.append(np.full(m, s))
        is_cop.append(np.arange(m) < 6)
    return _QPBatch(
        P=P, q=qv, G=np.concatenate(rows, 1), h=np.concatenate(rhs, 1), row_weight=np.concatenate(weights, 1),
        row_foot=np.concatenate(foot), row_is_cop=np.concatenate(is_cop), r=r, c=cr,
    )


def _solve_qp(P: np.ndarray, qv: np.ndarray, G: np.ndarray, h: np.ndarray) -> np.ndarray | None:
    """min yᵀPy + 2qᵀy s.t. G y ≤ h with quadprog; None if infeasible."""

    try:
        return quadprog.solve_qp(2.0 * P, -2.0 * qv, -G.T, -h, 0)[0]
    except ValueError:
        return None


def _bounds(batch: _QPBatch, i: int) -> tuple[np.ndarray, np.ndarray]:
    """0 ≤ y_fz ≤ c_fz as rows (G, h) — kept hard when relaxing (nothing when c_fz ≤ 0: no split exists)."""
    if batch.c[i, 5] <= 0.0:
        return np.zeros((0, 6)), np.zeros(0)
    G = np.zeros((2, 6))
    G[0, 5], G[1, 5] = -1.0, 1.0
    return G, np.array([0.0, batch.c[i, 5]])


def _relaxation(batch: _QPBatch, i: int) -> np.ndarray | None:
    """Smallest least-squares relaxation s (rows weighted to N·m) of the polygon and friction rows
    making frame i feasible, the vertical-force bounds kept."""

    G, h, w = batch.G[i], batch.h[i], batch.row_weight[i]
    Gb, hb = _bounds(batch, i)
    m = G.shape[0]
    # variables (y, s): min ‖w∘s‖² + δ (yᵀPy + 2qᵀy)  s.t.  G y − s ≤ h,  Gb y ≤ hb
    P = batch.P[i]
    delta = 1e-8 / max(np.trace(P), 1e-300)
    big = np.zeros((6 + m, 6 + m))
    big[:6, :6] = delta * P
    big[6:, 6:] = np.diag(w**2)
    qq = np.concatenate([delta * batch.q[i], np.zeros(m)])
    A = np.vstack([np.hstack([G, -np.eye(m)]), np.hstack([Gb, np.zeros((len(hb), m))])])
    try:
        sol = quadprog.solve_qp(2.0 * big, -2.0 * qq, -A.T, -np.concatenate([h, hb]), 0)[0]
    except ValueError:
        return None
    return np.maximum(G @ sol[:6] - h, 0.0)



def _relax_frame(batch: _QPBatch, i: int, method: str) -> tuple[np.ndarray | None, tuple | None]:
    """Frame i with no feasible split: the least relaxation of its rows, then the split under them
    ((y, (G, h) relaxed rows), or (None, None) when that fails)."""
    scale = max(abs(batch.c[i, 5]), 1.0)
    s = _relaxation(batch, i)
    if s is None:
        log.warning("contact QP: relaxation failed at double-support frame %d", i)
        return None, None
    Gb, hb = _bounds(batch, i)
    G_rel = np.vstack([batch.G[i], Gb])
    h_rel = np.concatenate([batch.h[i] + s + 1e-7 * scale, hb])
    if method == "qp":
        sol = _solve_qp(batch.P[i], batch.q[i], G_rel, h_rel)
    else:
        sol = _nested(batch.P[i], batch.q[i], G_rel, h_rel, scale)
    if sol is None:
        log.warning("contact QP: relaxed problem failed at double-support frame %d", i)
        return None, None
    return sol, (G_rel, h_rel)


def _solve_batch(batch: _QPBatch, method: str, defer_relaxation: bool = False
                 ) -> tuple[np.ndarray, np.ndarray, list]:
    """Solve every frame: (y (N, 6) about r, status (N,), the constraint rows (G, h) each frame's
    solution satisfies — the relaxed rows for a relaxed frame, None for a failed one).
    ``defer_relaxation``: a frame with no feasible split is left ``RELAXED`` with y = NaN and its own rows,
    for the caller (which corrects its total, or calls :func:`_relax_frame`)."""
    N = batch.P.shape[0]
    y = np.full((N, 6), np.nan)
    status = np.full(N, Status.FAILED, dtype=np.int8)
    rows: list = [(batch.G[i], batch.h[i]) for i in range(N)]
    scale = np.maximum(np.abs(batch.c[:, 5]), 1.0)
    tol = FEASIBILITY_TOL * scale
    todo = np.arange(N)
    if method == "qp":
        # unconstrained optimum, batched; keep it where it is feasible
        yu = -np.linalg.solve(batch.P, batch.q[..., None])[..., 0]
        ok = np.all(np.einsum("nmi,ni->nm", batch.G, yu) <= batch.h + tol[:, None], axis=1)
        y[ok] = yu[ok]
        status[ok] = Status.OPTIMAL
        todo = np.flatnonzero(~ok)
    for i in todo:
        sol = None
        if method == "qp":
            sol = _solve_qp(batch.P[i], batch.q[i], batch.G[i], batch.h[i])
        else:
            sol = _nested(batch.P[i], batch.q[i], batch.G[i], batch.h[i], scale[i])
        if sol is not None and not np.any(batch.G[i] @ sol > batch.h[i] + 1e3 * tol[i]):
            y[i], status[i] = sol, Status.OPTIMAL
            continue
        if defer_relaxation:
            status[i] = Status.RELAXED
            continue
        sol, rows[i] = _relax_frame(batch, int(i), method)
        if sol is not None:
            y[i], status[i] = sol, Status.RELAXED
    for i in np.flatnonzero(status == Status.FAILED):
        rows[i] = None
    return y, status, rows
