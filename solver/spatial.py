"""Spatial algebra written once, generic over the scalar type.

Every quantity is stored *component-wise*: a 3-vector is a tuple of three scalars,
a 3x3 matrix a tuple of three row tuples. A "scalar" may be

* a Python float (a model constant, folded at build time: multiplying by an exact 0
  or 1 emits no operation),
* a numpy array of shape ``(T,)`` (a batch of frames: every operation is one
  vectorised numpy call over all frames), or
* a CasADi ``SX``/``MX`` scalar (symbolic: the same code builds the expression graph).

This is what lets one RNEA implementation serve numeric batches and the CasADi NLP
(pinocchio.casadi's habit, without templates). Spatial vectors follow Featherstone:
motion vectors (angular; linear), force vectors (moment; force).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

Scalar = Any
#: a 3-vector / 3x3 matrix given as numbers: a sequence or an array
Vec = Sequence[float] | np.ndarray
Mat = Sequence[Sequence[float]] | np.ndarray
Vec3 = tuple[Scalar, Scalar, Scalar]
Mat3 = tuple[Vec3, Vec3, Vec3]

ZERO3: Vec3 = (0.0, 0.0, 0.0)
IDENTITY3: Mat3 = ((1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0))


_ARRAY = np.ndarray


def _is_const(x: Scalar) -> bool:
    t = type(x)
    if t is float or t is int:
        return True
    if t is _ARRAY:
        return False
    return isinstance(x, (int, float)) and not isinstance(x, bool)


def _is_zero(x: Scalar) -> bool:
    return _is_const(x) and x == 0.0


def add(a: Scalar, b: Scalar) -> Scalar:
    ta, tb = type(a), type(b)
    if ta is _ARRAY:  # the numeric batch: nothing to fold but a constant 0
        if tb is _ARRAY:
            return a + b
        if tb is float:
            return a if b == 0.0 else a + b
    elif tb is _ARRAY and ta is float:
        return b if a == 0.0 else a + b
    if _is_zero(a):
        return b
    if _is_zero(b):
        return a
    return a + b


def sub(a: Scalar, b: Scalar) -> Scalar:
    if type(a) is _ARRAY and type(b) is _ARRAY:
        return a - b
    if _is_zero(b):
        return a
    if _is_zero(a):
        return -b
    return a - b


def neg(a: Scalar) -> Scalar:
    if _is_zero(a):
        return 0.0
    return -a


def mul(a: Scalar, b: Scalar) -> Scalar:
    ta, tb = type(a), type(b)
    if ta is _ARRAY:
        if tb is _ARRAY:
            return a * b
        if tb is float:  # the numeric batch times a model constant: the same folding, fewer checks
            return 0.0 if b == 0.0 else (a if b == 1.0 else (-a if b == -1.0 else a * b))
    elif tb is _ARRAY and ta is float:
        return 0.0 if a == 0.0 else (b if a == 1.0 else (-b if a == -1.0 else a * b))
    if _is_zero(a) or _is_zero(b):
        return 0.0
    if _is_const(a):
        if a == 1.0:
            return b
        if a == -1.0:
            return -b
    if _is_const(b):
        if b == 1.0:
            return a
        if b == -1.0:
            return -a
    return a * b


def dot3(a: Sequence[Scalar], b: Sequence[Scalar]) -> Scalar:
    return add(add(mul(a[0], b[0]), mul(a[1], b[1])), mul(a[2], b[2]))


def vadd(a: Vec3, b: Vec3) -> Vec3:
    return (add(a[0], b[0]), add(a[1], b[1]), add(a[2], b[2]))


def vsub(a: Vec3, b: Vec3) -> Vec3:
    return (sub(a[0], b[0]), sub(a[1], b[1]), sub(a[2], b[2]))


def vscale(s: Scalar, a: Vec3) -> Vec3:
    return (mul(s, a[0]), mul(s, a[1]), mul(s, a[2]))


def cross(a: Vec3, b: Vec3) -> Vec3:
    return (
        sub(mul(a[1], b[2]), mul(a[2], b[1])),
        sub(mul(a[2], b[0]), mul(a[0], b[2])),
        sub(mul(a[0], b[1]), mul(a[1], b[0])),
    )


def matvec(m: Mat3, v: Vec3) -> Vec3:
    """m @ v."""
    return (dot3(m[0], v), dot3(m[1], v), dot3(m[2], v))


def matTvec(m: Mat3, v: Vec3) -> Vec3:
    """m.T @ v."""
    return (
        add(add(mul(m[0][0], v[0]), mul(m[1][0], v[1])), mul(m[2][0], v[2])),
        add(add(mul(m[0][1], v[0]), mul(m[1][1], v[1])), mul(m[2][1], v[2])),
        add(add(mul(m[0][2], v[0]), mul(m[1][2], v[1])), mul(m[2][2], v[2])),
    )


def matmul(a: Mat3, b: Mat3) -> Mat3:
    cols = tuple(zip(*b))
    return tuple(tuple(dot3(a[i], cols[j]) for j in range(3)) for i in range(3))  # type: ignore[return-value]


def rotz_apply(c: Scalar, s: Scalar, v: Vec3) -> Vec3:
    """Rz(q) @ v with c = cos q, s = sin q."""
    return (sub(mul(c, v[0]), mul(s, v[1])), add(mul(s, v[0]), mul(c, v[1])), v[2])


def rotzT_apply(c: Scalar, s: Scalar, v: Vec3) -> Vec3:
    """Rz(q).T @ v."""
    return (add(mul(c, v[0]), mul(s, v[1])), sub(mul(c, v[1]), mul(s, v[0])), v[2])


def mat_rotz(m: Mat3, c: Scalar, s: Scalar) -> Mat3:
    """m @ Rz(q): columns x' = c x + s y, y' = -s x + c y, z' = z."""
    rows = []
    for r in m:
        rows.append((add(mul(r[0], c), mul(r[1], s)), sub(mul(r[1], c), mul(r[0], s)), r[2]))
    return tuple(rows)  # type: ignore[return-value]


# --- spatial (6D) operations, Featherstone conventions ---------------------------


def motion_cross_force(v: tuple[Vec3, Vec3], f: tuple[Vec3, Vec3]) -> tuple[Vec3, Vec3]:
    """v x* f for motion v = (w, vl) and force f = (n, fl)."""
    w, vl = v
    n, fl = f
    return vadd(cross(w, n), cross(vl, fl)), cross(w, fl)


def inertia_apply(mass: float, com: Vec3, inertia_com: Mat3, v: tuple[Vec3, Vec3]) -> tuple[Vec3, Vec3]:
    """Spatial inertia (mass, com c, rotational inertia about the com) times motion v.

    I v = (Ic w + c x h, h) with h = m (vl + w x c).
    """
    w, vl = v
    h = vscale(mass, vadd(vl, cross(w, com)))
    n = vadd(matvec(inertia_com, w), cross(com, h))
    return n, h


def force_to_parent(rot: Mat3, pos: Vec3, f: tuple[Vec3, Vec3]) -> tuple[Vec3, Vec3]:
    """Express a force given in a child frame in the parent frame.

    ``rot`` is the child orientation in the parent (parent <- child), ``pos`` the child
    origin in parent coordinates: f_p = R f, n_p = R n + pos x f_p.
    """
    n, fl = f
    fp = matvec(rot, fl)
    return vadd(matvec(rot, n), cross(pos, fp)), fp


def force_to_child(rot: Mat3, pos: Vec3, f: tuple[Vec3, Vec3]) -> tuple[Vec3, Vec3]:
    """Inverse of :func:`force_to_parent`."""
    n, fl = f
    return matTvec(rot, vsub(n, cross(pos, fl))), matTvec(rot, fl)


def motion_to_child(rot: Mat3, pos: Vec3, v: tuple[Vec3, Vec3]) -> tuple[Vec3, Vec3]:
    """Motion vector in parent coordinates -> child coordinates (X = [E 0; -E rx E], E = rot.T)."""
    w, vl = v
    return matTvec(rot, w), matTvec(rot, vsub(vl, cross(pos, w)))


# --- backend helpers -----------------------------------------------------------------


def is_symbolic(x: Any) -> bool:
    try:
        import casadi as ca  # lazy: keeps CasADi out of numpy-only paths and OpenSim's child process
    except ImportError:  # pragma: no cover - casadi is a hard dependency
        return False
    return isinstance(x, (ca.SX, ca.MX))


def cos(x: Scalar) -> Scalar:
    if is_symbolic(x):
        import casadi as ca  # lazy: keeps CasADi out of numpy-only paths and OpenSim's child process

        return ca.cos(x)
    if _is_const(x):
        return math.cos(x)
    return np.cos(x)


def sin(x: Scalar) -> Scalar:
    if is_symbolic(x):
        import casadi as ca  # lazy: keeps CasADi out of numpy-only paths and OpenSim's child process

        return ca.sin(x)
    if _is_const(x):
        return math.sin(x)
    return np.sin(x)


def components(x: Any, n: int) -> list[Scalar]:
    """Split an n-vector (numpy (n,) / (n, T), or casadi (n, 1)) into n scalars."""
    if is_symbolic(x):
        if x.shape[0] != n:
            raise ValueError(f"expected {n} rows, got shape {x.shape}")
        return [x[i] for i in range(n)]
    arr = np.asarray(x, dtype=float)
    if arr.shape[0] != n:
        raise ValueError(f"expected {n} rows, got shape {arr.shape}")
    return [arr[i] for i in range(n)]


def stack(items: Sequence[Scalar], like: Any = None) -> Any:
    """Inverse of :func:`components`: stack scalars into a column (casadi) or array (numpy).

    Python-constant entries are broadcast to the batch shape of the others.
    """
    if any(is_symbolic(x) for x in items) or is_symbolic(like):
        import casadi as ca  # lazy: keeps CasADi out of numpy-only paths and OpenSim's child process

        return ca.vertcat(*[x if is_symbolic(x) else ca.DM(float(x)) for x in items])
    shape: tuple[int, ...] = ()
    for x in items:
        if isinstance(x, np.ndarray):
            shape = x.shape
            break
    if shape == () and like is not None:
        shape = np.asarray(like).shape[1:]
    out = np.empty((len(items),) + shape)
    for i, x in enumerate(items):
        out[i] = x
    return out


def snap(x: float, tol: float = 1e-14) -> float:
    """Round model constants that are 0 or +-1 up to floating noise, so folding applies."""
    x = float(x)
    if abs(x) < tol:
        return 0.0
    if abs(x - 1.0) < tol:
        return 1.0
    if abs(x + 1.0) < tol:
        return -1.0
    return x


def const_vec(v: Vec) -> Vec3:
    return (snap(v[0]), snap(v[1]), snap(v[2]))


def const_mat(m: Any) -> Mat3:
    m = np.asarray(m, dtype=float)
    return tuple(tuple(snap(m[i, j]) for j in range(3)) for i in range(3))  # type: ignore[return-value]


# --- plain numpy helpers for model construction ---------------------------------------


def rotation_about(axis: Vec, angle: float | np.ndarray) -> np.ndarray:
    """Rotation about ``axis`` (normalised here) by ``angle`` radians (Rodrigues): (3, 3) for a
    number, (..., 3, 3) for an array of angles. The one rotation-about-an-axis helper (joint
    DOF, exporters, reimport, transforms); :func:`elementary_rotation` is its exact form about
    a coordinate axis."""
    a = np.asarray(axis, dtype=float)
    a = a / np.linalg.norm(a)
    k = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    th = np.asarray(angle, dtype=float)
    if th.ndim == 0:
        t = float(th)
        return np.eye(3) + math.sin(t) * k + (1 - math.cos(t)) * (k @ k)
    s = np.sin(th)[..., None, None]
    c = np.cos(th)[..., None, None]
    return np.eye(3) + s * k + (1.0 - c) * (k @ k)


def elementary_rotation(axis: int, angle: np.ndarray) -> np.ndarray:
    """Rotations (..., 3, 3) about coordinate axis ``axis`` (0 x, 1 y, 2 z) by ``angle`` radians,
    written out (cos and sin in place, no rounding of Rodrigues' 1 - (1 - cos)): BVH channels,
    DeepMimic's heading."""
    a = np.asarray(angle, dtype=float)
    c, s = np.cos(a), np.sin(a)
    o, z = np.ones_like(a), np.zeros_like(a)
    if axis == 0:
        rows = [[o, z, z], [z, c, -s], [z, s, c]]
    elif axis == 1:
        rows = [[c, z, s], [z, o, z], [-s, z, c]]
    else:
        rows = [[c, -s, z], [s, c, z], [z, z, o]]
    return np.stack([np.stack(r, axis=-1) for r in rows], axis=-2)


def quaternion_to_matrix(quat: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) of quaternions (..., 4) in (x, y, z, w) order, normalised
    first. Callers check for zero or non-finite quaternions (with their own error type)."""
    qv = np.asarray(quat, dtype=float)
    x, y, z, w = np.moveaxis(qv / np.linalg.norm(qv, axis=-1, keepdims=True), -1, 0)
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], -2)


def align_z(axis: Vec) -> np.ndarray:
    """A rotation A with A @ e_z = axis (unit); deterministic choice of the other columns.

    Exact for the coordinate axes (a permutation with signs), so constant folding applies.
    """
    a = np.asarray(axis, dtype=float)
    n = np.linalg.norm(a)
    if not np.isfinite(n) or n < 1e-12:
        raise ValueError(f"joint axis must be a non-zero finite vector, got {axis!r}")
    a = a / n
    for i in range(3):
        if abs(abs(a[i]) - 1.0) < 1e-12:
            s = 1.0 if a[i] > 0 else -1.0
            if i == 2:
                return np.diag([s, 1.0, s])  # z -> s z (rotation by pi about y when s < 0)
            if i == 0:  # z -> s x : columns (x', y', z') = (-s z, y, s x)
                return np.array([[0.0, 0.0, s], [0.0, 1.0, 0.0], [-s, 0.0, 0.0]])
            # z -> s y : columns (x, -s z ... ) : x' = x, y' = -s z, z' = s y
            return np.array([[1.0, 0.0, 0.0], [0.0, 0.0, s], [0.0, -s, 0.0]])
    ref = np.array([1.0, 0.0, 0.0]) if abs(a[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    x = ref - a * (ref @ a)
    x /= np.linalg.norm(x)
    y = np.cross(a, x)
    return np.column_stack([x, y, a])


def skew(v: Vec) -> np.ndarray:
    return np.array([[0.0, -v[2], v[1]], [v[2], 0.0, -v[0]], [-v[1], v[0], 0.0]])


def spatial_force_transform(rot: np.ndarray, pos: np.ndarray) -> np.ndarray:
    """6x6 matrix of :func:`force_to_parent` (numeric), for tests and QP assembly."""
    out = np.zeros((6, 6))
    out[:3, :3] = rot
    out[3:, 3:] = rot
    out[:3, 3:] = skew(pos) @ rot
    return out


def euler_zyx_to_matrix(yaw: float, pitch: float, roll: float) -> np.ndarray:
    """R = Rz(yaw) Ry(pitch) Rx(roll): the root's intrinsic z-y-x rotation sequence."""
    return rotation_about([0, 0, 1], yaw) @ rotation_about([0, 1, 0], pitch) @ rotation_about([1, 0, 0], roll)


def matrix_to_euler_zyx(r: np.ndarray) -> tuple[float, float, float]:
    """Inverse of :func:`euler_zyx_to_matrix` (pitch in [-pi/2, pi/2])."""
    pitch = math.asin(max(-1.0, min(1.0, -r[2, 0])))
    yaw = math.atan2(r[1, 0], r[0, 0])
    roll = math.atan2(r[2, 1], r[2, 2])
    return yaw, pitch, roll
