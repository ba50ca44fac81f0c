"""Temporal prior on the double-support split: each run of double-support frames as one convex QP."""

from __future__ import annotations

import logging
from dataclasses import dataclass

import numpy as np
import quadprog

from solver.character import Character
from solver.contact.common import FEASIBILITY_TOL
from solver.contact.geometry import _foot_frames, _Pose, _skew
from solver.contact.qp import _QPBatch
from solver.motion import FEET

log = logging.getLogger("solver.contact")

# --- temporal prior on the double-support split ---------------------------------------------


@dataclass(frozen=True, eq=False)
class _Timeline:
    """What the temporal prior needs about every defined frame (positions in ``frames``)."""

    r: np.ndarray  # (N, 3) reference point of every frame (between the feet, on the ground)
    y_known: np.ndarray  # (N, 6) right-foot wrench about r where it is known (single support, flight)
    period: int | None  # cyclic: P (frame P is frame 0 one period later), else None
    wrap: np.ndarray  # (6, 6) wrench about r at frame 0 -> the same wrench seen at frame P


def _timeline(character: Character, pose: _Pose, w_right: np.ndarray, cyclic: bool) -> _Timeline:
    """Reference points of every frame, the known right-foot wrenches about them, the cyclic link."""
    centres = [_foot_frames(character, pose, side)[1] for side in FEET]
    r = 0.5 * (centres[0] + centres[1])
    r[:, 2] = 0.0
    yk = np.asarray(w_right, dtype=float).T.copy()  # (N, 6) about the origin
    yk[:, :3] -= np.cross(r, yk[:, 3:])
    N = r.shape[0]
    wrap = np.eye(6)
    period = None
    if cyclic:
        period = N - 1
        b = character.model.seg_body[character.segments[0].name]
        rel = pose.rot[period, b] @ pose.rot[0, b].T  # rotation of the whole body over one period
        wrap[:3, :3] = wrap[3:, 3:] = rel
    return _Timeline(r=r, y_known=yk, period=period, wrap=wrap)


def _runs(is_ds: np.ndarray, period: int | None) -> list[list[int]]:
    """Maximal runs of consecutive double-support positions; cyclic runs may wrap P−1 -> 0."""
    n = period if period is not None else len(is_ds)
    ds = [k for k in range(n) if is_ds[k]]
    if not ds:
        return []
    if period is not None and len(ds) == n:
        return [list(range(n))]  # a ring: double support throughout
    in_ds = set(ds)

    def pred(k: int) -> int | None:
        return k - 1 if k > 0 else (n - 1 if period is not None else None)

    out = []
    for k in ds:
        if pred(k) in in_ds:
            continue
        run = [k]
        while True:
            nxt = run[-1] + 1 if run[-1] + 1 < n else (0 if period is not None else None)
            if nxt is None or nxt not in in_ds or nxt == k:
                break
            run.append(nxt)
        out.append(run)
    return out


def _shift_T(d: np.ndarray) -> np.ndarray:
    """(K, 6, 6) transposes of the matrices taking wrenches about a point a to about a − d."""
    S = np.zeros(d.shape[:-1] + (6, 6))
    S[..., 0, 0] = S[..., 1, 1] = S[..., 2, 2] = S[..., 3, 3] = S[..., 4, 4] = S[..., 5, 5] = 1.0
    S[..., 3:, :3] = -_skew(d)  # (m' = m + d × f)ᵀ: the skew block transposed
    return S


def _smooth_split(batch: _QPBatch, y: np.ndarray, rows: list, ds: np.ndarray, line: _Timeline,
                  kappa: float) -> np.ndarray:
    """Every run of consecutive double-support frames as one convex QP (see the module doc):

        Σ_k [y_kᵀ P_k y_k + 2 q_kᵀ y_k] + κ² Σ_k Δ_kᵀ W_k Δ_k,   Δ_k = change of the right-foot
        wrench from frame k to k+1 (both about their mid-point), W_k = the effort metric P there,

    with the neighbouring single-support frames' known wrenches (c or 0) as boundary values,
    under every frame's own constraint rows. κ = fps / (2π f_s): a zero-phase first-order
    low-pass at f_s of the per-frame optimum, in the effort metric, that respects the
    constraints and the boundaries. Returns y (N_ds, 6) about each frame's r."""

    out = y.copy()
    P = line.period
    n_pos = P if P is not None else line.r.shape[0]
    where = np.full(line.r.shape[0], -1)
    where[ds] = np.arange(len(ds))  # position -> row of the batch (-1: not double support)
    runs = [run for run in _runs(where >= 0, P) if all(rows[where[pos]] is not None for pos in run)]
    if not runs:
        return out
    # every pair (a -> b) of consecutive frames touching a run; "wrapped": b is frame 0 seen as frame P
    # per pair: a, b, wrapped, run, a's and b's place in the run (-1: outside it)
    pairs: tuple[list, list, list, list, list, list] = ([], [], [], [], [], [])
    for r_i, run in enumerate(runs):
        loc = {pos: j for j, pos in enumerate(run)}
        prv = run[0] - 1 if run[0] > 0 else (n_pos - 1 if P is not None else None)
        if prv is not None and prv not in loc:
            for lst, v in zip(pairs, (prv, run[0], P is not None and run[0] == 0, r_i, -1, 0)):
                lst.append(v)
        for j, pos in enumerate(run):
            nxt = pos + 1 if pos + 1 < n_pos else (0 if P is not None else None)
            if nxt is None:
                continue
            for lst, v in zip(pairs, (pos, nxt, P is not None and nxt == 0, r_i, j, loc.get(nxt, -1))):
                lst.append(v)
    pa, pb, wr, rid, la, lb = (np.array(v) for v in pairs)
    b_phys = np.where(wr, P if P is not None else 0, pb)
    d = 0.5 * (line.r[pa] - line.r[b_phys])  # r_a − R with R the pair's mid-point; r_b − R = −d
    K = len(pa)
    # metric: mean of the double-support sides' effort Hessians, moved to R (A⁻ᵀ P A⁻¹, A⁻¹ shifts by −offset)
    W = np.zeros((K, 6, 6))
    cnt = np.zeros(K)
    for side, off in ((pa, d), (b_phys, -d)):
        has = where[side] >= 0
        X = _shift_T(-off[has])
        W[has] += np.einsum("kij,kjl,kml->kim", X, batch.P[where[side[has]]], X)
        cnt[has] += 1
    W *= (kappa * kappa) / cnt[:, None, None]
    Ca = -np.swapaxes(_shift_T(d), 1, 2)  # Δ = C_a y_a + C_b y_b, both sides moved to R
    Ab = np.swapaxes(_shift_T(-d), 1, 2)
    Cb = Ab.copy()
    Cb[wr] = Ab[wr] @ line.wrap  # the variable is frame 0's wrench, seen one period later
    # known sides (single support, flight) enter Δ as constants
    dk = np.where((la < 0)[:, None], np.einsum("kij,kj->ki", Ca, np.nan_to_num(line.y_known[pa])), 0.0)
    dk += np.where((lb < 0)[:, None], np.einsum("kij,kj->ki", Ab, np.nan_to_num(line.y_known[b_phys])), 0.0)
    CaW = np.einsum("kji,kjl->kil", Ca, W)
    CbW = np.einsum("kji,kjl->kil", Cb, W)
    Kaa, Kab, Kbb = CaW @ Ca, CaW @ Cb, CbW @ Cb
    # the objective is block tridiagonal in the batch's row order (runs do not interact) except where
    # a cyclic run wraps P−1 -> 0: diagonal blocks D, blocks O above, linear term g
    Nds = len(ds)
    ga, gb = np.where(la >= 0, where[pa], -1), np.where(lb >= 0, where[pb], -1)  # variables (frame 0, not P)
    va, vb = ga >= 0, gb >= 0
    D = batch.P.copy()
    g = batch.q.copy()
    O = np.zeros((max(Nds - 1, 0), 6, 6))
    np.add.at(D, ga[va], Kaa[va])
    np.add.at(D, gb[vb], Kbb[vb])
    np.add.at(g, ga[va], np.einsum("kij,kj->ki", CaW[va], dk[va]))
    np.add.at(g, gb[vb], np.einsum("kij,kj->ki", CbW[vb], dk[vb]))
    link = va & vb & ~wr  # consecutive rows: gb = ga + 1
    np.add.at(O, ga[link], Kab[link])
    tol = FEASIBILITY_TOL * np.maximum(np.abs(batch.c[:, 5]), 1.0)
    dense = []
    # unconstrained optimum of every run at once (block tridiagonal: one banded solve); a run whose
    # optimum breaks one of its frames' rows, or that wraps a cycle, is solved as one dense QP
    wrapped = {int(rid[k]) for k in np.flatnonzero(va & vb & wr)}
    flat = [r_i for r_i in range(len(runs)) if r_i not in wrapped]
    if flat:
        sub = np.sort(np.concatenate([where[np.array(runs[r_i])] for r_i in flat]))
        Osub = np.where((np.diff(sub) == 1)[:, None, None], O[sub[:-1]], 0.0) if len(sub) > 1 else O[:0]
        x = np.full_like(out, np.nan)
        x[sub] = _solve_block_tridiagonal(D[sub], Osub, -g[sub])
        dense = sorted(wrapped)
        for r_i in flat:
            rows_i = where[np.array(runs[r_i])]
            if any(np.any(rows[i][0] @ x[i] > rows[i][1] + tol[i]) for i in rows_i):
                dense.append(r_i)
            else:
                out[rows_i] = x[rows_i]
    for r_i in dense:
        # this run's QP as one dense problem (quadprog): active rows, or a cyclic run wrapping P−1 -> 0
        run = runs[r_i]
        rows_i = where[np.array(run)]
        sel = np.flatnonzero((rid == r_i) & va & vb & wr)
        m = len(run)
        B = np.zeros((m, m, 6, 6))
        ar = np.arange(m)
        B[ar, ar] = D[rows_i]
        nb = np.flatnonzero(np.diff(rows_i) == 1)
        B[nb, nb + 1] = O[rows_i[nb]]
        B[nb + 1, nb] = np.swapaxes(O[rows_i[nb]], 1, 2)
        for k in sel:
            B[la[k], lb[k]] += Kab[k]
            B[lb[k], la[k]] += Kab[k].T
        big = B.transpose(0, 2, 1, 3).reshape(6 * m, 6 * m)
        big = 0.5 * (big + big.T)
        rhs = g[rows_i].reshape(-1)
        Gs = [rows[i] for i in rows_i]
        G = np.zeros((sum(len(h_) for _, h_ in Gs), 6 * m))
        h = np.concatenate([h_ for _, h_ in Gs])
        r0 = 0
        for j, (G_, h_) in enumerate(Gs):
            G[r0:r0 + len(h_), 6 * j:6 * j + 6] = G_
            r0 += len(h_)
        tol_r = np.repeat(tol[rows_i], [len(h_) for _, h_ in Gs])
        x = -np.linalg.solve(big, rhs)
        if np.any(G @ x > h + tol_r):
            try:
                x = quadprog.solve_qp(2.0 * big, -2.0 * rhs, -G.T, -h, 0)[0]
            except ValueError:
                log.warning("contact QP: the temporal prior failed on %d double-support frames; per-frame "
                            "solutions kept", m)
                continue
        out[rows_i] = x.reshape(m, 6)
    if P is not None and where[P] >= 0 and where[0] >= 0:  # frame P is frame 0 one period later ...
        cand = line.wrap @ out[where[0]]
        k = where[P]
        G, h = rows[k] if rows[k] is not None else (batch.G[k], batch.h[k])
        if np.all(G @ cand <= h + 1e3 * tol[k]):  # ... unless the loop does not close (its own total differs)
            out[k] = cand
    return out


def _solve_block_tridiagonal(D: np.ndarray, O: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """x with the symmetric block-tridiagonal system (diagonal blocks D (N, 6, 6), blocks O (N−1, 6, 6)
    above the diagonal) times x = rhs (N, 6): one banded solve."""
    from scipy.linalg import solve_banded  # lazy: scipy.linalg costs ~0.2 s to import

    N, b = D.shape[0], D.shape[1]
    n = N * b
    u = 2 * b - 1
    ab = np.zeros((2 * u + 1, n))
    blk = np.arange(N)[:, None, None] * b
    i = np.arange(b)[None, :, None]
    j = np.arange(b)[None, None, :]
    rows, cols = (blk + i).repeat(b, 2), (blk + j).repeat(b, 1)
    ab[u + rows - cols, cols] = D
    if N > 1:
        r_up, c_up = rows[:-1], cols[:-1] + b
        ab[u + r_up - c_up, c_up] = O
        ab[u + c_up - r_up, r_up] = O  # the transposed blocks below the diagonal: (c, r) <- O[r, c]
    return solve_banded((u, u), ab, rhs.reshape(-1), check_finite=False).reshape(N, b)


