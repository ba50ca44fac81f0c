"""The motion as the OpenSim export samples it: repeated over gait cycles at the written rate
(:func:`cycle_samples`, at the times :func:`cycle_times`), and the map from its world to the trial's ground for OpenSim
(:func:`export_frame`)."""

from __future__ import annotations

import math

import numpy as np
from scipy.spatial.transform import Rotation

from solver.capture import GroundFrame
from solver.motion import Motion
from solver.trajectory import ROOT_XY, ROOT_YAW, cycle_turn, sample


def _rotz(a: float) -> np.ndarray:
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0.0], [s, c, 0.0], [0.0, 0.0, 1.0]])


def cycle_times(motion: Motion, cycles: int, rate: float) -> tuple[np.ndarray, float]:
    """The times (S,) from 0 at which :func:`cycle_samples` samples ``cycles`` gait cycles at ``rate``,
    and the cycle duration D (s)."""
    D = (motion.T - 2) / motion.fps  # frames T-2, T-1 repeat 0, 1
    S = int(math.floor(cycles * D * rate + 1e-9)) + 1
    return np.arange(S) / rate, D


def cycle_samples(motion: Motion, cycles: int, rate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """The motion repeated ``cycles`` times and sampled at ``rate``: times (S,) from 0, q (n, S)
    (the periodic spline; each repetition moved by the cycle's own turn and displacement),
    wrenches (2, 6, S) (linear between the frames and midpoints where the optimizer's
    equations hold, moved alike) and the cycle duration D (s)."""
    N = motion.T - 2  # frames T-2, T-1 repeat 0, 1
    t, D = cycle_times(motion, cycles, rate)
    S = t.size
    c = np.minimum(np.floor(t / D + 1e-12).astype(int), cycles - 1)
    tau = t - c * D
    q1 = sample(motion.q, motion.fps, tau, cyclic=True, interpolation=motion.interpolation)
    dpsi = cycle_turn(motion.q)
    R2 = _rotz(dpsi)[:2, :2]
    x0, xN = motion.q[list(ROOT_XY), 0], motion.q[list(ROOT_XY), N]
    b = xN - R2 @ x0  # xy_{k+N} = R xy_k + b
    # the wrenches where the optimizer's equations hold — frames 1..N and the midpoints between
    # them, frame N and the midpoint after it standing for frame 0 and the midpoint of [0, 1]
    # (carried back by the cycle's transform: frame 0's own wrench is not constrained) — and
    # linear between those samples
    W = np.asarray(motion.wrenches, dtype=float)
    R3, b3 = np.eye(3), np.array([b[0], b[1], 0.0])
    R3[:2, :2] = R2

    def back(w: np.ndarray) -> np.ndarray:  # a wrench of cycle 1 expressed in cycle 0
        F = R3.T @ w[:, 3:].T
        M = R3.T @ (w[:, :3].T - np.cross(b3, w[:, 3:]).T)
        return np.concatenate([M, F]).T

    half = np.empty((2, 6, 2 * N + 1))
    half[:, :, 2::2] = W[:, :, 1:N + 1]
    half[:, :, 3::2] = 0.5 * (W[:, :, 1:N] + W[:, :, 2:N + 1])
    half[:, :, 0] = back(W[:, :, N])
    half[:, :, 1] = back(0.5 * (W[:, :, N] + W[:, :, N + 1]))
    s2 = np.clip(2 * tau * motion.fps, 0.0, 2 * N)
    k = np.minimum(np.floor(s2).astype(int), 2 * N - 1)
    u = s2 - k
    w1 = half[:, :, k] * (1 - u) + half[:, :, k + 1] * u  # (2, 6, S)
    q = q1.copy()
    w = w1.copy()
    for j in range(S):
        Rk = np.eye(2)
        bk = np.zeros(2)
        for _ in range(int(c[j])):
            Rk, bk = R2 @ Rk, R2 @ bk + b
        if c[j]:
            q[list(ROOT_XY), j] = Rk @ q1[list(ROOT_XY), j] + bk
            q[ROOT_YAW, j] = q1[ROOT_YAW, j] + c[j] * dpsi
            R3 = np.eye(3)
            R3[:2, :2] = Rk
            b3 = np.array([bk[0], bk[1], 0.0])
            for f in range(2):
                F = R3 @ w1[f, 3:, j]
                w[f, 3:, j] = F
                w[f, :3, j] = R3 @ w1[f, :3, j] + np.cross(b3, F)
    return t, q, w, D


def export_frame(motion: Motion) -> tuple[GroundFrame, np.ndarray]:
    """The map from the motion's world to the trial's ground for OpenSim, and the gravity there.

    The optimizer models a slope by tilting gravity over a level ground; OpenSim's gravity
    points down its y axis. The motion is first turned (about the origin, its ground and a
    treadmill's belt velocity with it) so that its gravity points down, then mapped by its
    ``GroundFrame``: the written ground is the inclined plane. Returns that frame and the
    gravity vector in OpenSim ground (the motion's own magnitude)."""

    frame = motion.frame
    g = np.asarray(motion.environment.gravity, dtype=float)
    gn = float(np.linalg.norm(g))
    down = np.array([0.0, 0.0, -1.0])
    u = g / gn if gn > 0 else down
    axis = np.cross(u, down)
    angle = math.atan2(float(np.linalg.norm(axis)), float(u @ down))
    Rg = Rotation.from_rotvec(axis / np.linalg.norm(axis) * angle).as_matrix() if angle > 1e-12 else np.eye(3)
    out = GroundFrame(R=frame.R @ Rg, offset=frame.offset, unit_m=frame.unit_m, velocity=frame.velocity,
                      axes=frame.axes)
    return out, out.R @ g
