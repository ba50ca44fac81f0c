"""Guide transforms (docs/method.md (M7)): slope Ψ and curve Φ act on the root coordinates only.

Both take a motion Q (n, T) whose first six coordinates are the root (slides x, y, z then
hinges yaw z, pitch y, roll x) and return a new Q; joint coordinates are unchanged.
"""

from __future__ import annotations

import math

import numpy as np

from solver import spatial as sp


def _root_rotations(Q: np.ndarray) -> np.ndarray:
    return np.stack([sp.euler_zyx_to_matrix(Q[3, t], Q[4, t], Q[5, t]) for t in range(Q.shape[1])])


def _set_root_rotations(Q: np.ndarray, rots: np.ndarray, yaw_hint: np.ndarray) -> None:
    angles = np.array([sp.matrix_to_euler_zyx(r) for r in rots]).T  # (3, T)
    yaw = angles[0]
    # keep yaw continuous and close to the hint (the original yaw, possibly beyond ±π)
    yaw = yaw + 2 * math.pi * np.round((yaw_hint - yaw) / (2 * math.pi))
    Q[3], Q[4], Q[5] = yaw, angles[1], angles[2]


def slope(Q: np.ndarray, theta: float) -> np.ndarray:
    """Ψ(Q, θ): tilt every frame's root by θ about an axis parallel to world y through it,
    then move it along gravity so its distance to the ground along gravity is kept.

    With gravity rotated by R_y(θ) (the slope simulated by gravity), θ > 0 leans the body
    forward: an uphill walk is Ψ(Q, +slope) with gravity R_y(+slope)(0, 0, -g).
    """
    Q = np.array(Q, dtype=float, copy=True)
    if theta == 0.0:
        return Q
    r_y = sp.rotation_about([0.0, 1.0, 0.0], theta)
    rots = np.einsum("ij,tjk->tik", r_y, _root_rotations(Q))
    _set_root_rotations(Q, rots, Q[3].copy())
    # distance to the ground z = 0 along d = R_y(θ)(0, 0, -1): s = z / cos θ; keep s = z_original
    d = r_y @ np.array([0.0, 0.0, -1.0])
    z = Q[2].copy()
    alpha = z * (math.cos(theta) - 1.0) / math.cos(theta)  # p' = p - alpha d
    Q[0] -= alpha * d[0]
    Q[2] -= alpha * d[2]
    return Q


def curve(Q: np.ndarray, theta: float, *, cyclic: bool = True) -> np.ndarray:
    """Φ(Q, θ): bend the root path onto a circular arc turning by θ (left for θ > 0).

    d_T = straight distance from the root at frame 1 to the root at frame T-1 (the frame
    one cycle later; the last frame when ``cyclic`` is False); each frame's root is
    decomposed into arc length d_t along that segment plus a lateral deviation, mapped
    onto the arc of length d_T and radius d_T/θ, and yawed by θ·d_t/d_T.
    """
    Q = np.array(Q, dtype=float, copy=True)
    if theta == 0.0:
        return Q
    T = Q.shape[1]
    end = T - 2 if cyclic else T - 1
    o = Q[:2, 0].copy()
    chord = Q[:2, end] - o
    dT = float(np.linalg.norm(chord))
    if dT < 1e-6:
        raise ValueError("the motion does not travel: a curve needs a walk that moves forward")
    u = chord / dT
    v = np.array([-u[1], u[0]])
    rel = Q[:2] - o[:, None]
    d = u @ rel
    e = v @ rel
    alpha = theta * d / dT
    # R sin α and R (1 - cos α) with R = d_T / θ, written stably for small θ
    with np.errstate(invalid="ignore", divide="ignore"):
        s_over = np.where(np.abs(alpha) > 1e-9, np.sin(alpha) / np.where(alpha == 0, 1, alpha), 1.0)
        c_over = np.where(np.abs(alpha) > 1e-9, (1 - np.cos(alpha)) / np.where(alpha == 0, 1, alpha), alpha / 2)
    along = d * s_over
    across = d * c_over
    ca_, sa_ = np.cos(alpha), np.sin(alpha)
    Q[0] = o[0] + along * u[0] + across * v[0] + e * (-sa_ * u[0] + ca_ * v[0])
    Q[1] = o[1] + along * u[1] + across * v[1] + e * (-sa_ * u[1] + ca_ * v[1])
    # yaw each frame about world z (compose with the full root rotation)
    rots = _root_rotations(Q)
    rz = np.stack([sp.rotation_about([0.0, 0.0, 1.0], a) for a in alpha])
    _set_root_rotations(Q, np.einsum("tij,tjk->tik", rz, rots), Q[3] + alpha)
    return Q
