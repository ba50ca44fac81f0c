"""Total wrenches no foot can take, corrected by the least force at the centre of mass.

Inverse dynamics of filtered capture gives, at some frames, a total wrench c that the feet
on the ground cannot produce: its centre of pressure lies outside the support (outside the
stance foot in single support, outside what any split between the two feet reaches in
double support), or it breaks friction. The error behind it is mostly an error of the
centre of mass acceleration — a zero-phase low-pass spreads the other foot's heel-strike
impact into the frames before it touches down, and noise in the trunk markers shakes the
whole body — and an error of the centre of mass acceleration is a force through the
centre of mass: it changes the force *and*, through the moment arm of the centre of mass
height, the centre of pressure (F_x / F_z = (x_com − x_cop) / z_com). So the correction is

    c' = c + (r_com × δ; δ),   δ = argmin ‖δ‖²  s.t.  c' is a wrench the support can take

(one 3-variable QP per single-support frame, a 9-variable QP — δ and a feasible right-foot
wrench — per double-support frame), rather than moving the CoP at a fixed force, which
would attribute the whole error to the angular momentum.
"""

from __future__ import annotations

import numpy as np
import quadprog

from solver.character import Character
from solver.contact.geometry import _foot_frames, _Pose


def centre_of_mass(character: Character, pose: _Pose) -> np.ndarray:
    """Whole-body centre of mass (3, N) from a pose of every body (``_dense_pose(..., full=True)``)."""
    model = character.model
    m = np.asarray(model.mass, dtype=float)
    b = np.flatnonzero(m > 0)  # the bodies with mass (a joint's intermediate bodies have none)
    c = np.array([np.asarray(model.com[k], dtype=float) for k in b])  # (k, 3) body coordinates
    pts = pose.pos[:, b] + np.einsum("nbij,bj->nbi", pose.rot[:, b], c)  # (N, k, 3)
    return (np.einsum("b,nbi->in", m[b], pts)) / m.sum()


def foot_rows(character: Character, pose: _Pose, side: str, penetration: float,
              friction: float | None) -> np.ndarray:
    """(N, m, 6) rows G with G w ≤ 0 ⇔ the foot can take the wrench w (about the world origin:
    moment; force): its CoP in the foot's contact polygon (box ∩ contact plane, as the QP) and,
    with ``friction``, inside the friction pyramid. Every row is ≤ 0 only if f_z ≥ 0."""
    rot, ctr, half = _foot_frames(character, pose, side)
    N = rot.shape[0]
    z_low = ctr[:, 2] - np.abs(rot[:, 2, :]) @ half
    zp = np.maximum(0.0, z_low + penetration)
    E = np.swapaxes(rot, 1, 2)  # rows: box axes in world
    # e_k·(p − ctr) with p = (−M_y/F_z, M_x/F_z, z_plane), times F_z
    a = np.zeros((N, 3, 6))
    a[:, :, 0] = E[:, :, 1]
    a[:, :, 1] = -E[:, :, 0]
    a[:, :, 5] = E[:, :, 2] * zp[:, None] - np.einsum("nkj,nj->nk", E, ctr)
    hz = np.zeros((N, 3, 6))
    hz[:, :, 5] = half[None, :]
    rows = [a - hz, -a - hz]
    if friction is not None:
        fr = np.zeros((N, 4, 6))
        for j, (axis, sg) in enumerate(((3, 1.0), (3, -1.0), (4, 1.0), (4, -1.0))):
            fr[:, j, axis] = sg
            fr[:, j, 5] = -friction
        rows.append(fr)
    return np.concatenate(rows, axis=1)


def com_force_matrix(com: np.ndarray) -> np.ndarray:
    """(N, 6, 3): the wrench about the origin of a force δ applied at the centre of mass (3, N)."""
    N = com.shape[1]
    A = np.zeros((N, 6, 3))
    x, y, z = com
    A[:, 0, 1], A[:, 0, 2] = -z, y
    A[:, 1, 0], A[:, 1, 2] = z, -x
    A[:, 2, 0], A[:, 2, 1] = -y, x
    A[:, 3, 0] = A[:, 4, 1] = A[:, 5, 2] = 1.0
    return A


def least_norm(B: np.ndarray, b: np.ndarray, tol: np.ndarray) -> np.ndarray:
    """argmin ‖δ‖² s.t. B δ ≤ b for a batch (B (N, m, 3), b (N, m), tol (N,)); NaN rows where no δ is
    feasible. δ = 0 where it is feasible. Otherwise the optimum's active set holds a row that 0 breaks
    (b_i < 0; KKT: if every active b_i ≥ 0, ‖δ‖² = −Σ λ_i b_i ≤ 0), and when the least-norm point of
    one such row's boundary, b_i B_i / ‖B_i‖², satisfies every row it is the optimum (every feasible
    point satisfies row i, so lies at least that far from 0): one batched step settles most frames;
    the others (corners: 2 or 3 active rows) are one small QP each (quadprog)."""

    N, m, k = B.shape
    out = np.full((N, k), np.nan)
    ok0 = np.all(b >= -tol[:, None], axis=1)
    out[ok0] = 0.0
    todo = np.flatnonzero(~ok0)
    if not len(todo):
        return out
    Bt, bt, tt = B[todo], b[todo], tol[todo]
    g2 = np.einsum("nmi,nmi->nm", Bt, Bt)
    d = Bt * (bt / np.where(g2 > 0, g2, np.inf))[..., None]  # (n, m, 3): each row's boundary point
    feas = (bt < -tt[:, None]) & (g2 > 0)
    feas &= np.all(np.einsum("nmi,nki->nkm", Bt, d) <= bt[:, None, :] + tt[:, None, None], axis=2)
    nrm = np.where(feas, np.sum(d * d, axis=2), np.inf)
    j = np.argmin(nrm, axis=1)
    found = np.isfinite(nrm[np.arange(len(todo)), j])
    out[todo[found]] = d[np.arange(len(todo)), j][found]
    for i in todo[~found]:
        try:
            out[i] = quadprog.solve_qp(2.0 * np.eye(k), np.zeros(k), -B[i].T, -b[i], 0)[0]
        except ValueError:  # infeasible: stays NaN
            pass
    return out


def correct_single(c: np.ndarray, com: np.ndarray, G: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Single-support wrenches (6, N) about the origin the stance foot (rows G (N, m, 6)) cannot take,
    corrected by the least force at the centre of mass (3, N) (:func:`least_norm`). Returns
    (wrenches, corrected (N,)); a frame no force at the centre of mass can fix (its c_fz far below 0)
    is left as it is."""
    out = np.array(c, dtype=float, copy=True)
    A = com_force_matrix(com)
    B = G @ A  # (N, m, 3)
    b = -np.einsum("nmi,in->nm", G, out)
    tol = 1e-9 * np.maximum(np.abs(out[5]), 1.0)
    d = least_norm(B, b, tol)
    moved = np.all(np.isfinite(d), axis=1) & (np.linalg.norm(np.nan_to_num(d), axis=1) > 0)
    out[:, moved] += np.einsum("nij,nj->in", A[moved], d[moved])
    return out, moved


def correct_double(c: np.ndarray, com: np.ndarray, r: np.ndarray, G_r: np.ndarray, G_l: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Double-support totals (6, N) about the origin that no split between the feet (rows G_r, G_l
    (N, m, 6)) can take, corrected by the least force at the centre of mass: the QP in (δ, y), y the
    right foot's wrench about the frame's reference point r (N, 3) (conditioning), minimises ‖δ‖²
    (plus 1e-8 ‖y‖² for strict convexity: 1e-8 N² per N² of load) under both feet's rows. Returns
    (totals, corrected (N,), a feasible right-foot wrench about r (N, 6), NaN where not corrected)."""

    out = np.array(c, dtype=float, copy=True)
    N = out.shape[1]
    moved = np.zeros(N, dtype=bool)
    y_r = np.full((N, 6), np.nan)
    A = com_force_matrix(com)
    for i in range(N):
        T = np.eye(6)  # wrench about r -> about the origin: m_O = m_r + r × f
        x, y, z = r[i]
        T[0, 4], T[0, 5], T[1, 3], T[1, 5], T[2, 3], T[2, 4] = -z, y, z, -x, -y, x
        Gr, Gl = G_r[i] @ T, G_l[i]
        # right: Gr y ≤ 0 ; left: Gl (c + A δ − T y) ≤ 0
        C = np.vstack([np.hstack([np.zeros((len(Gr), 3)), Gr]), np.hstack([Gl @ A[i], -Gl @ T])])
        b = np.concatenate([np.zeros(len(Gr)), -Gl @ out[:, i]])
        scale = max(abs(float(out[5, i])), 1.0)
        Pm = np.diag([2.0] * 3 + [2e-8] * 6)
        try:
            sol = quadprog.solve_qp(Pm, np.zeros(9), -C.T, -b, 0)[0]
        except ValueError:
            continue
        d = sol[:3]
        if np.linalg.norm(d) <= 1e-9 * scale:
            continue
        out[:, i] += A[i] @ d
        moved[i] = True
        y_r[i] = sol[3:]
    return out, moved, y_r


__all__ = ["centre_of_mass", "com_force_matrix", "correct_double", "correct_single", "foot_rows", "least_norm"]
