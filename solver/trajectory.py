"""The continuous trajectory a motion stands for, and where its dynamics are sampled.

A motion stores frames. What happens *between* the frames is part of the motion's meaning:

* ``"cubic-spline"`` (motion file v2, the spacetime optimizer's transcription): the motion is
  the C² cubic spline through its frames. For a gait cycle (``cyclic``) the spline is
  periodic: frames T−2 and T−1 repeat frames 0 and 1 — joints, root height, pitch and roll
  exactly, the root's horizontal position, velocity and yaw under the cycle's rigid
  transform (a turn Δψ = yaw[T−2] − yaw[0] about the vertical and a translation).
  The equations of motion hold at the frames and at the midpoints between them; the
  ground wrench at a midpoint is the mean of its two frames' wrenches.
* ``"central-differences"`` (motion file v1, and any motion made without the optimizer):
  velocities and accelerations by central differences at the interior frames.

:func:`dynamics_samples` gives the instants where the equations must hold, with q, q̇, q̈ and
the ground wrenches there: the plausibility report and the MuJoCo replay both evaluate them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from solver.kinematics import finite_differences

#: root coordinates: x, y (horizontal translation), z, then the rotations; yaw is index 3
ROOT_XY = (0, 1)
ROOT_YAW = 3
INTERPOLATIONS = ("central-differences", "cubic-spline")


def cycle_turn(q: np.ndarray) -> float:
    """Heading change Δψ over a cycle whose frames T−2, T−1 repeat frames 0, 1."""
    return float(q[ROOT_YAW, -2] - q[ROOT_YAW, 0])


def _rot2(a: float) -> np.ndarray:
    c, s = np.cos(a), np.sin(a)
    return np.array([[c, -s], [s, c]])


def spline_velocities(q: np.ndarray, dt: float) -> np.ndarray:
    """Knot velocities (n, T) of the periodic C² cubic spline through a cycle's frames.

    Unknowns v_0..v_{T-1}; equations: C² continuity at the knots 1..T−2
    (v_{k−1} + 4 v_k + v_{k+1} = 3 (q_{k+1} − q_{k−1}) / h) and periodicity
    v_{T−2} = v_0, v_{T−1} = v_1 — under the cycle's turn for the horizontal root velocity.
    """
    q = np.asarray(q, dtype=float)
    n, T = q.shape
    if T < 5:
        raise ValueError(f"a cycle needs at least 5 frames, got {T}")
    h = float(dt)
    A = np.zeros((T, T))
    B = np.zeros((T, n))
    for r, k in enumerate(range(1, T - 1)):
        A[r, k - 1 : k + 2] = (1.0, 4.0, 1.0)
        B[r] = 3.0 * (q[:, k + 1] - q[:, k - 1]) / h
    A[T - 2, T - 2], A[T - 2, 0] = 1.0, -1.0
    A[T - 1, T - 1], A[T - 1, 1] = 1.0, -1.0
    v = np.linalg.solve(A, B).T  # periodic rows (every coordinate but x, y) are right as they are
    # x, y: the periodicity rows couple them through the turn
    R = _rot2(cycle_turn(q))
    A2 = np.zeros((2 * T, 2 * T))
    B2 = np.zeros(2 * T)
    for c in range(2):
        A2[c * T : (c + 1) * T - 2, c * T : (c + 1) * T] = A[: T - 2]
        B2[c * T : (c + 1) * T - 2] = B[: T - 2, ROOT_XY[c]]
    for r, (a, b) in enumerate(((T - 2, 0), (T - 1, 1))):
        for c in range(2):  # v_a[c] − Σ_j R[c, j] v_b[j] = 0
            row = c * T + T - 2 + r
            A2[row, c * T + a] = 1.0
            A2[row, b] -= R[c, 0]
            A2[row, T + b] -= R[c, 1]
    vxy = np.linalg.solve(A2, B2)
    v[ROOT_XY[0]], v[ROOT_XY[1]] = vxy[:T], vxy[T:]
    return v


def segment_accelerations(q: np.ndarray, v: np.ndarray, dt: float) -> np.ndarray:
    """Acceleration at the start of each segment [k, k+1] (n, T−1) of the Hermite cubic."""
    h = float(dt)
    return 6.0 * (q[:, 1:] - q[:, :-1]) / h**2 - (4.0 * v[:, :-1] + 2.0 * v[:, 1:]) / h


def midpoints(q: np.ndarray, v: np.ndarray, dt: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q, q̇, q̈ at the midpoint of every segment [k, k+1] (n, T−1) of the Hermite cubic."""
    h = float(dt)
    qa, qb, va, vb = q[:, :-1], q[:, 1:], v[:, :-1], v[:, 1:]
    qm = 0.5 * (qa + qb) + h * (va - vb) / 8.0
    vm = 1.5 * (qb - qa) / h - 0.25 * (va + vb)
    am = (vb - va) / h
    return qm, vm, am


@dataclass(frozen=True, eq=False)
class DynamicsSamples:
    """Instants where the equations of motion must hold, with the state and ground wrenches."""

    time: np.ndarray  # (S,) s from frame 0
    q: np.ndarray  # (n, S)
    qd: np.ndarray
    qdd: np.ndarray
    wrenches: np.ndarray | None  # (2, 6, S) world frame, moment about the origin
    kind: np.ndarray  # (S,) "frame" or "midpoint"


def dynamics_samples(motion) -> DynamicsSamples:
    """The motion's own dynamics samples (see the module docstring)."""
    q, dt, W = motion.q, motion.dt, motion.wrenches
    T = q.shape[1]
    if getattr(motion, "interpolation", "central-differences") == "cubic-spline" and getattr(motion, "cyclic", False):
        v = spline_velocities(q, dt)
        seg = np.arange(1, T - 1)  # segments [k, k+1], k = 1..T−2: one cycle of knots and midpoints
        acc = segment_accelerations(q, v, dt)
        qm, vm, am = midpoints(q, v, dt)
        S = 2 * len(seg)
        order = np.empty(S, dtype=int)  # interleave: frame k, midpoint k+½, frame k+1, ...
        order[0::2], order[1::2] = seg, seg
        is_mid = np.zeros(S, dtype=bool)
        is_mid[1::2] = True
        qs = np.where(is_mid, qm[:, order], q[:, order])
        qds = np.where(is_mid, vm[:, order], v[:, order])
        qdds = np.where(is_mid, am[:, order], acc[:, order])
        time = (order + 0.5 * is_mid) * dt
        ws = None
        if W is not None:
            wm = 0.5 * (W[:, :, :-1] + W[:, :, 1:])
            ws = np.where(is_mid, wm[:, :, order], W[:, :, order])
        kind = np.where(is_mid, "midpoint", "frame")
        return DynamicsSamples(time, qs, qds, qdds, ws, kind)
    qd, qdd = finite_differences(q, dt)
    ws = None if W is None else W[:, :, 1:-1]
    return DynamicsSamples(np.arange(1, T - 1) * dt, q[:, 1:-1], qd, qdd, ws, np.full(T - 2, "frame"))


def sample(q: np.ndarray, fps: float, times: np.ndarray, *, cyclic: bool = False,
           interpolation: str = "central-differences") -> np.ndarray:
    """The trajectory ``q`` (n, T) at ``fps`` evaluated at ``times`` (s from frame 0, clipped to the
    frames): the Hermite cubic through the frames with the knot velocities of the periodic C²
    spline (``cubic-spline``, cyclic) — the spline itself — or of central differences."""
    q = np.asarray(q, dtype=float)
    n, T = q.shape
    h = 1.0 / float(fps)
    if interpolation == "cubic-spline" and cyclic:
        v = spline_velocities(q, h)
    else:
        v = np.gradient(q, h, axis=1) if T >= 2 else np.zeros_like(q)
    s = np.clip(np.asarray(times, dtype=float) / h, 0.0, T - 1.0)
    k = np.minimum(np.floor(s).astype(int), T - 2)
    u = s - k
    h00, h10 = 2 * u**3 - 3 * u**2 + 1, u**3 - 2 * u**2 + u
    h01, h11 = -2 * u**3 + 3 * u**2, u**3 - u**2
    return q[:, k] * h00 + h * v[:, k] * h10 + q[:, k + 1] * h01 + h * v[:, k + 1] * h11
