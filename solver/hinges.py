"""Hinge chains: the angles of consecutive hinges (rotations about fixed axes) that compose a
given rotation — the one decomposition of the project (the importers' first guess,
solver.io.fit; reading motions back, solver.export.reimport).

    decompose_hinges(M (T, 3, 3), axes, lower=None, upper=None, *, polish=2) -> (θ (T, k), residual (T,))
    product(axes, θ (T, k)) -> (R (T, 3, 3), prefix products)
    rotation_angle(E (..., 3, 3)) -> angle (...)
"""

from __future__ import annotations

import itertools

import numpy as np

from solver import spatial as sp


class HingeError(ValueError):
    """The chain cannot be decomposed (more than 3 hinges, consecutive parallel axes)."""


def rotation_angle(E: np.ndarray) -> np.ndarray:
    """Rotation angle (rad) of each (..., 3, 3) rotation matrix, accurate near 0 and π."""
    v = np.stack([E[..., 2, 1] - E[..., 1, 2], E[..., 0, 2] - E[..., 2, 0], E[..., 1, 0] - E[..., 0, 1]], -1)
    return np.arctan2(0.5 * np.linalg.norm(v, axis=-1), 0.5 * (np.trace(E, axis1=-2, axis2=-1) - 1.0))


def _about(axis: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """Paden-Kahan subproblem 1: the angle θ that best rotates ``p`` onto ``q`` about ``axis``
    (R(axis, θ) p ∥ q in the plane normal to the axis). ``p``, ``q``: (T, 3) or (3,)."""
    p = np.broadcast_to(p, np.shape(q)) if np.ndim(p) < np.ndim(q) else p
    pp = p - np.multiply.outer(p @ axis, axis)
    qq = q - np.multiply.outer(q @ axis, axis)
    return np.arctan2(np.einsum("...i,...i->...", np.cross(pp, qq), np.broadcast_to(axis, pp.shape)),
                      np.einsum("...i,...i->...", pp, qq))


def _single(axis: np.ndarray, M: np.ndarray) -> np.ndarray:
    """The angle θ maximising tr(R(axis, θ)ᵀ M), i.e. the rotation about ``axis`` nearest M (T, 3, 3)."""
    K = sp.skew(axis)
    b = np.einsum("ij,tij->t", K, M)
    c = np.einsum("i,tij,j->t", axis, M, axis) - np.trace(M, axis1=1, axis2=2)
    return np.arctan2(b, -c)


def _wrap(x: np.ndarray) -> np.ndarray:
    return (np.asarray(x) + np.pi) % (2.0 * np.pi) - np.pi


def _limit_violation(theta: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
    """Distance of each angle (..., k) to its joint interval, the angle taken modulo 2π."""
    out = np.full(theta.shape, np.inf)
    for shift in (-2.0 * np.pi, 0.0, 2.0 * np.pi):
        t = _wrap(theta) + shift
        out = np.minimum(out, np.maximum(lower - t, 0.0) + np.maximum(t - upper, 0.0))
    return out


def product(axes: list[np.ndarray], theta: np.ndarray) -> tuple[np.ndarray, list[np.ndarray]]:
    """R(a₁, θ₁) R(a₂, θ₂) … (T, 3, 3) and the prefix products before each factor."""
    T = theta.shape[0]
    R = np.broadcast_to(np.eye(3), (T, 3, 3)).copy()
    prefixes = []
    for i, a in enumerate(axes):
        prefixes.append(R)
        R = R @ sp.rotation_about(a, theta[:, i])
    return R, prefixes


def decompose_hinges(M: np.ndarray, axes: list[np.ndarray], lower: np.ndarray | None = None,
                     upper: np.ndarray | None = None, *, polish: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Angles θ (T, k) with R(a₁, θ₁) … R(a_k, θ_k) ≈ M (T, 3, 3) and the residual angle (T,) per frame.

    Closed form for k ≤ 3 hinges (any axes, consecutive axes not parallel), then ``polish``
    Gauss-Newton steps on the rotation error. Of the two solutions of a 3-hinge chain, frame
    0 takes the one in the limits (``lower``/``upper``, default unbounded; then the smaller
    angles) and every later frame the one nearest the previous frame's.
    """
    M = np.asarray(M, dtype=float)
    T, k = M.shape[0], len(axes)
    axes = [np.asarray(a, dtype=float) / np.linalg.norm(a) for a in axes]
    lower = np.full(k, -np.inf) if lower is None else np.asarray(lower, dtype=float)
    upper = np.full(k, np.inf) if upper is None else np.asarray(upper, dtype=float)
    if k > 3:
        raise HingeError(f"cannot decompose a chain of {k} hinges (at most 3)")
    for a, b in itertools.pairwise(axes):
        if np.linalg.norm(np.cross(a, b)) < 1e-6:
            raise HingeError("cannot decompose a hinge chain with two consecutive parallel axes")
    if k == 0:
        return np.zeros((T, 0)), rotation_angle(M)
    if k == 1:
        theta = _single(axes[0], M)[:, None]
    elif k == 2:
        a1, a2 = axes
        t1 = _about(a1, a2, M @ a2)
        rest = np.swapaxes(sp.rotation_about(a1, t1), 1, 2) @ M
        theta = np.stack([t1, _single(a2, rest)], axis=1)
    else:
        a1, a2, a3 = axes
        q = M @ a3  # = R1 R2 a3: find c = R2 a3 = R1ᵀ q (subproblem 2), then θ3
        u = float(a1 @ a2)
        w = np.cross(a1, a2)
        d1, d2 = q @ a1, float(a2 @ a3)
        alpha = (d1 - u * d2) / (1.0 - u * u)
        beta = (d2 - u * d1) / (1.0 - u * u)
        g2 = (1.0 - alpha**2 - beta**2 - 2.0 * alpha * beta * u) / float(w @ w)
        gamma = np.sqrt(np.maximum(g2, 0.0))
        cands = []
        for sign in (1.0, -1.0):
            c = np.outer(alpha, a1) + np.outer(beta, a2) + np.outer(sign * gamma, w)
            t2 = _about(a2, a3, c)
            t1 = _about(a1, c, q)
            R12 = sp.rotation_about(a1, t1) @ sp.rotation_about(a2, t2)
            t3 = _single(a3, np.swapaxes(R12, 1, 2) @ M)
            cands.append(np.stack([t1, t2, t3], axis=1))
        cand = np.stack(cands)  # (2, T, 3)
        pick = np.empty(T, dtype=int)
        cost0 = _limit_violation(cand[:, 0], lower, upper).sum(axis=1) + 1e-6 * np.sum(_wrap(cand[:, 0]) ** 2, axis=1)
        pick[0] = int(np.argmin(cost0))
        prev = cand[pick[0], 0]
        for t in range(1, T):
            d = np.sum(_wrap(cand[:, t] - prev) ** 2, axis=1)
            pick[t] = int(np.argmin(d))
            prev = cand[pick[t], t]
        theta = cand[pick, np.arange(T)]
    for _ in range(polish):  # Gauss-Newton on the left rotation error M Rᵀ ≈ I + [e]×
        R, prefixes = product(axes, theta)
        E = M @ np.swapaxes(R, 1, 2)
        e = 0.5 * np.stack([E[:, 2, 1] - E[:, 1, 2], E[:, 0, 2] - E[:, 2, 0], E[:, 1, 0] - E[:, 0, 1]], -1)
        J = np.stack([P @ a for P, a in zip(prefixes, axes)], axis=-1)  # (T, 3, k)
        JtJ = np.swapaxes(J, 1, 2) @ J + 1e-12 * np.eye(k)
        theta = theta + np.linalg.solve(JtJ, np.einsum("tik,ti->tk", J, e)[..., None])[..., 0]
    R, _ = product(axes, theta)
    return theta, rotation_angle(M @ np.swapaxes(R, 1, 2))
