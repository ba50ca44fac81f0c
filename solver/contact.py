"""Contact-force estimation from kinematics (SPEC §5, thesis ch. 4 and appendix A).

Inverse dynamics of the motion with no external force gives, at every frame, the total
ground wrench the motion needs, ``c = h0`` (SPEC 4.7). Single support: the foot on the
ground takes ``c``. Double support: the right-foot wrench ``x`` (the left one is ``c − x``)
minimises the internal effort, the sum of squared joint forces (SPEC 4.8-4.18)

    τ_i(x) = τ0_i − S_i·x          i ∈ A (ancestors of the right foot only)
    τ_i(x) = τ0_i − S_i·(c − x)    i ∈ B (ancestors of the left foot only)
    τ_i    = τ0_i − S_i·c          i ∈ C (common ancestors: constant, 0 at the root)
    τ_i    = τ0_i                  i ∈ D (the others)

where τ0 are the joint forces of the motion without external force and S_i the world
screw of joint i (:func:`solver.kinematics.joint_screws`), subject to

* each centre of pressure inside its foot's contact polygon (foot box ∩ ground),
  written linearly by multiplying by the vertical force (SPEC 4.26-4.29),
* ``0 ≤ x_fz ≤ c_fz`` (implied by the polygon rows) and a friction pyramid
  ``|f_x|, |f_y| ≤ μ f_z`` on each foot (μ = 1 as in the correction problem, SPEC
  Table 5.1; pass ``friction=None`` to drop it).

``method="qp"`` solves this as one strictly convex 6-variable QP per double-support
frame (**[beyond]** the thesis): the QP data of every double-support frame are assembled
at once with numpy; frames whose unconstrained optimum is feasible are done with one
batched linear solve, the others go to quadprog (Goldfarb-Idnani). ``method="nested"`` is
the thesis's form kept as a reference: inner QP with ``x_fz`` fixed, outer bounded scalar
search (SPEC 4.30-4.31). Both minimise the same function under the same constraints.

Strict convexity. ``H = Σ_{A∪B} S_i S_iᵀ`` is singular whenever the legs' joints do not
span every wrench direction (e.g. a character with locked coordinates has no joint that
feels a free moment or some force direction), and the split is then not unique. We add
a tie-breaker that is symmetric between the feet and expressed where the loads act:

    ε · ( ‖D_r x‖² + ‖D_l (c − x)‖² ),   D_s w = (moment about foot s's centre ; ℓ_s·force)

with ℓ_s the foot box half-length (so a force at the toe weighs like its moment about the
foot centre). Alone, it shares the load evenly with each CoP under the foot's centre.
ε = ``regularization`` × tr(H)/tr(Dᵀ_rD_r + Dᵀ_lD_l) per frame: scale-free (a ratio of
matrices of the same units) and small (1e-6), so it only decides directions in which the
effort is flat and moves the solution by ~1e-6 relative elsewhere.

Contact polygon. The ground is the plane z = 0 (SPEC §6). A foot the schedule declares
on the ground but whose box does not reach z = 0 (a rigid box and a fitted skeleton
approximate a real foot: it may float a few mm) would get no polygon at all; for such a
foot the contact plane is moved up to ``penetration`` (1 cm, SPEC §2) above the box's
lowest corner, i.e. its lowest 1 cm is the contact surface. Where the box reaches the
ground, the polygon is exactly box ∩ {z = 0} as in the thesis.

Infeasible frames. If no split satisfies every constraint (c's CoP outside both polygons
— noisy accelerations, model errors — or c_fz ≤ 0), the frame is solved in two stages
(status ``RELAXED``): first the smallest (least-squares, N·m) relaxation of the polygon
and friction rows that makes the problem feasible, then the least-effort split under the
relaxed rows. ``cop_violation`` reports how far (m) each CoP ends up outside its
polygon. Nothing is silently clipped and no frame raises.

Temporal prior (``smoothing_hz``, **[beyond]**; off by default here, on in
:func:`estimate_capture`). The per-frame criterion knows nothing of time: a foot's load may
jump between frames and the trailing foot keeps load up to the frame it leaves the ground. With
``smoothing_hz = f_s`` every run of consecutive double-support frames is solved as one convex
QP, the frames' effort plus

    κ² Σ_k Δ_kᵀ W_k Δ_k,   κ = fps / (2π f_s),

Δ_k the change of the right-foot wrench between consecutive frames (both about their
mid-point) and W_k the effort's own metric (the per-frame Hessians there), the wrenches of the
neighbouring single-support frames (c under the stance foot, 0 under the swing foot) as
boundary values, each frame's constraint rows unchanged. Without constraints this is exactly a
zero-phase first-order low-pass at f_s of the per-frame optimum (Euler-Lagrange: x − τ² ẍ =
x*, τ = 1/2πf_s), so f_s = the kinematics' cut-off adds no frequency the filtered motion does
not have; the boundary values make each foot's load continuous at touch-down and lift-off
(ground reactions have no jump there). Runs are block tridiagonal: their unconstrained optima
come from one banded solve, runs with active rows (and cyclic runs wrapping the clip's end)
are one dense QP each (quadprog). Single-support frames are untouched; the per-frame QP and
the nested form remain the reference (they agree to 1e-3 N / N·m).

CoP projection (``project_cop``, **[beyond]**; off by default here, on in
:func:`estimate_capture`). In single support the thesis lets the foot take c, wherever c's
centre of pressure falls; inverse dynamics of noisy kinematics puts it outside the foot at
some frames (centimetres ahead of the toes at the end of a stance, before the other heel's
impact reaches the filtered accelerations). The ground can only push inside the contact
polygon: such a frame gets the nearest CoP in the polygon, with c's force and c's free moment
(status ``PROJECTED``); the moment it cannot explain stays in ``total − Σ wrenches``.

Accelerations are central differences (SPEC 3.7-3.8), undefined at the first and last
frames of a non-cyclic motion (status ``UNDEFINED``, NaN). With ``cyclic=True`` the last
frame must close the cycle (the first pose one period later, root advanced): differences
wrap around with that offset and every frame is defined.
"""

from __future__ import annotations

import logging
import math
import weakref
from dataclasses import dataclass, field
from enum import IntEnum
from typing import Any, Sequence

import numpy as np

from solver.character import Character, CharacterError, merge_segments
from solver.dynamics import DEFAULT_GRAVITY, rnea
from solver.kinematics import forward_kinematics
from solver.motion import FEET, foot_schedule_of

log = logging.getLogger(__name__)

METHODS = ("qp", "nested")
DEFAULT_PENETRATION = 0.01  # m, SPEC §2
DEFAULT_FRICTION = 1.0  # SPEC Table 5.1
DEFAULT_REGULARIZATION = 1e-6
FEASIBILITY_TOL = 1e-9  # relative, on the constraint rows (N·m per N of load)


class ContactError(ValueError):
    """Bad input to contact-force estimation; the message names the problem."""


class Support(IntEnum):
    FLIGHT = 0
    RIGHT = 1
    LEFT = 2
    DOUBLE = 3


class Status(IntEnum):
    UNDEFINED = 0  # accelerations undefined (ends of a non-cyclic motion): NaN
    SINGLE = 1  # single support: the foot on the ground takes c exactly
    OPTIMAL = 2  # double support: least-effort split, every constraint satisfied
    RELAXED = 3  # double support, infeasible: least relaxation, then least effort
    FLIGHT = 4  # no foot on the ground: zero wrenches (c unexplained)
    FAILED = 5  # the QP solver failed: NaN
    PROJECTED = 6  # single support, c's CoP outside the foot: CoP moved into the polygon (project_cop)


def _frozen(a: Any, dtype: Any = float) -> np.ndarray:
    a = np.array(a, dtype=dtype, copy=True)
    a.setflags(write=False)
    return a


def cop_and_free_moment(wrenches: np.ndarray, min_fz: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """CoP on the ground z = 0 and free moment about the vertical at the CoP.

    ``wrenches`` (..., 6, T): world frame about the origin (moment; force). Returns CoP
    (..., 3, T) (NaN where f_z ≤ ``min_fz``) and the free moment (..., T) (0 there).
    """
    w = np.asarray(wrenches, dtype=float)
    mx, my, mz, fx, fy, fz = (w[..., k, :] for k in range(6))
    loaded = fz > min_fz
    with np.errstate(divide="ignore", invalid="ignore"):
        px = np.where(loaded, -my / fz, np.nan)
        py = np.where(loaded, mx / fz, np.nan)
    cop = np.stack([px, py, np.where(loaded, 0.0, np.nan)], axis=-2)
    tz = np.where(loaded, mz - (px * fy - py * fx), 0.0)
    return cop, tz


@dataclass(frozen=True, eq=False)
class ContactEstimate:
    """Estimated ground reaction of each foot at every frame (our world frame, SI).

    ``wrenches`` (2, 6, T): feet (right, left), world frame, (moment about the world
    origin; force) — the :class:`~solver.motion.Motion` convention. ``total`` (6, T) is
    c = h0. ``support`` and ``status`` hold :class:`Support` / :class:`Status` codes per
    frame. ``cop`` (2, 3, T) on the ground (NaN for an unloaded foot), ``free_moment``
    (2, T) about the vertical at the CoP, ``cop_violation`` (2, T) metres outside the
    contact polygon (0 inside; NaN where undefined).
    """

    wrenches: np.ndarray
    total: np.ndarray
    support: np.ndarray
    status: np.ndarray
    cop_violation: np.ndarray
    fps: float
    method: str
    cyclic: bool = False
    smoothing_hz: float | None = None
    cop: np.ndarray = field(init=False)
    free_moment: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        for name in ("wrenches", "total", "cop_violation"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        object.__setattr__(self, "support", _frozen(self.support, np.int8))
        object.__setattr__(self, "status", _frozen(self.status, np.int8))
        cop, tz = cop_and_free_moment(self.wrenches)
        object.__setattr__(self, "cop", _frozen(cop))
        object.__setattr__(self, "free_moment", _frozen(tz))

    @property
    def T(self) -> int:
        return int(self.wrenches.shape[-1])

    @property
    def force(self) -> np.ndarray:
        return self.wrenches[:, 3:, :]

    @property
    def defined(self) -> np.ndarray:
        return np.isin(self.status, (Status.SINGLE, Status.PROJECTED, Status.OPTIMAL, Status.RELAXED, Status.FLIGHT))

    @property
    def double_support(self) -> np.ndarray:
        return (self.support == Support.DOUBLE) & self.defined

    def summary(self) -> dict:
        return {
            "frames": self.T,
            "method": self.method,
            "smoothing_hz": self.smoothing_hz,
            **{f"support_{s.name.lower()}": int(np.sum(self.support == s)) for s in Support},
            **{f"status_{s.name.lower()}": int(np.sum(self.status == s)) for s in Status},
            "max_cop_violation_m": float(np.nanmax(self.cop_violation)) if np.any(self.defined) else None,
        }


# --- input checks ------------------------------------------------------------------------


def _check_inputs(character: Character, q: Any, fps: float, foot_contact: Any, gravity: Any) -> tuple:
    q = np.asarray(q, dtype=float)
    n = character.n
    if q.ndim != 2:
        raise ContactError(f"the motion must be a (coordinates, frames) array, got shape {q.shape}")
    if q.shape[0] != n:
        raise ContactError(
            f"model/motion mismatch: character {character.name!r} has {n} coordinates, "
            f"the motion has {q.shape[0]} rows"
        )
    T = q.shape[1]
    if T < 3:
        raise ContactError(f"accelerations need at least 3 frames, got {T}")
    bad = ~np.isfinite(q)
    if bad.any():
        i, t = np.argwhere(bad)[0]
        raise ContactError(
            f"coordinate {character.coordinate_names[i]!r} is not finite (NaN/inf) at frame {t} "
            f"({int(bad.sum())} bad values)"
        )
    if not (isinstance(fps, (int, float, np.floating)) and math.isfinite(fps) and fps > 0):
        raise ContactError(f"fps must be a positive finite number, got {fps!r}")
    fc = np.asarray(foot_contact)
    if fc.shape != (2, T):
        raise ContactError(f"foot_contact must have shape (2 feet (right, left), T={T}), got {fc.shape}")
    if fc.dtype != bool:
        if not np.all(np.isin(fc, (0, 1))):
            raise ContactError("foot_contact must be boolean (or 0/1)")
        fc = fc.astype(bool)
    g = np.asarray(gravity, dtype=float).reshape(-1)
    if g.shape != (3,) or not np.all(np.isfinite(g)):
        raise ContactError(f"gravity must be a finite 3-vector, got {gravity!r}")
    for side in FEET:
        try:
            character.foot(side)
        except CharacterError as e:
            raise ContactError(str(e)) from None
    return q, fc, g


def _check_schedule(fc: np.ndarray, defined: np.ndarray) -> None:
    for i, side in enumerate(FEET):
        if not fc[i].any():
            raise ContactError(f"the {side} foot is never on the ground in the contact schedule")
    ds = fc[0] & fc[1]
    if not ds.any():
        raise ContactError("the contact schedule has no double support (no frame with both feet on the ground)")
    if not (ds & defined).any():
        raise ContactError(
            "double support only at frames where accelerations are undefined (first/last frame); "
            "give more frames or cyclic=True"
        )


# --- derivatives ---------------------------------------------------------------------------


def _derivatives(q: np.ndarray, dt: float, cyclic: bool) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Central differences (SPEC 3.7-3.8): (frames where defined, q̇, q̈) at those frames."""
    T = q.shape[1]
    if not cyclic:
        qd = (q[:, 2:] - q[:, :-2]) / (2.0 * dt)
        qdd = (q[:, 2:] - 2.0 * q[:, 1:-1] + q[:, :-2]) / (dt * dt)
        return np.arange(1, T - 1), qd, qdd
    # the last frame closes the cycle: q[T-1] = q[0] + offset (offset: root advance)
    offset = q[:, -1] - q[:, 0]
    P = T - 1
    ext = np.concatenate([q[:, P - 1 : P] - offset[:, None], q[:, :P], q[:, :1] + offset[:, None]], axis=1)
    qd = (ext[:, 2:] - ext[:, :-2]) / (2.0 * dt)
    qdd = (ext[:, 2:] - 2.0 * ext[:, 1:-1] + ext[:, :-2]) / (dt * dt)
    # frame T-1 is frame 0 one period later: same velocity and acceleration
    return np.arange(T), np.concatenate([qd, qd[:, :1]], axis=1), np.concatenate([qdd, qdd[:, :1]], axis=1)


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


def _side_sets(character: Character, effort: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Joints of A (ancestors of the right foot only) and B (left only) whose force counts in the effort."""
    model = character.model
    anc = [set(model.ancestors(model.seg_body[character.foot(s).segment])) for s in FEET]
    keep = set(range(character.n)) if effort is None else set(np.flatnonzero(effort))
    a = sorted((anc[0] - anc[1]) & keep)
    b = sorted((anc[1] - anc[0]) & keep)
    return np.array(a, dtype=int), np.array(b, dtype=int)


@dataclass(frozen=True, eq=False)
class _Pose:
    """World pose of every body as dense arrays over N frames: rot (N, n, 3, 3) world <- body, pos (N, n, 3)."""

    rot: np.ndarray
    pos: np.ndarray

    def take(self, idx: np.ndarray) -> "_Pose":
        return _Pose(self.rot[idx], self.pos[idx])


_LEGS: "weakref.WeakKeyDictionary[Character, tuple[Character, np.ndarray]]" = weakref.WeakKeyDictionary()


def _legs(character: Character) -> tuple[Character, np.ndarray]:
    """The character reduced to the feet and the segments they hang from (what the estimator
    needs the pose of: joint screws of the feet's ancestors, foot boxes, root), and the indices of
    its coordinates (= bodies) in the full character. Cached per character."""
    hit = _LEGS.get(character)
    if hit is not None:
        return hit
    by_name = {s.name: s for s in character.segments}
    keep: set[str] = set()
    for side in FEET:
        name: str | None = character.foot(side).segment
        while name is not None and name not in keep:
            keep.add(name)
            name = by_name[name].parent
    drop = [s.name for s in character.segments if s.name not in keep and s.parent in keep]
    legs = merge_segments(character, drop, name=f"{character.name}-feet") if drop else character
    kept = np.array([character.index(c) for c in legs.coordinate_names], dtype=int)
    _LEGS[character] = (legs, kept)
    return legs, kept


def _dense_pose(character: Character, q: np.ndarray) -> _Pose:
    """Pose of the bodies the estimator uses (the feet and their ancestors; NaN for the others):
    forward kinematics of the character reduced to them (the rest of the body does not move them)."""
    legs, kept = _legs(character)
    pose = forward_kinematics(legs, q[kept])
    N, n = q.shape[1], character.n
    rot = np.full((N, n, 3, 3), np.nan)
    pos = np.full((N, n, 3), np.nan)
    for j, k in enumerate(kept):
        for i in range(3):
            pos[:, k, i] = pose.pos[j][i]
            for c in range(3):
                rot[:, k, i, c] = pose.rot[j][i][c]
    return _Pose(rot, pos)


def _screws(character: Character, pose: _Pose) -> np.ndarray:
    """World joint screws (N, n, 6) from a pose: the same as :func:`solver.kinematics.joint_screws`."""
    z = pose.rot[:, :, :, 2]
    rev = np.asarray(character.model.revolute)
    ang = np.where(rev[None, :, None], z, 0.0)
    lin = np.where(rev[None, :, None], np.cross(pose.pos, z), z)
    return np.concatenate([ang, lin], axis=-1)


def _foot_frames(character: Character, pose: _Pose, side: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """World rotation (N, 3, 3) world <- box, centre (N, 3) and half extents (3,) of a foot box."""
    box = character.foot(side)
    model = character.model
    b = model.seg_body[box.segment]
    r_sb = model.seg_rot[box.segment]
    c_b = model.seg_pos[box.segment] + r_sb @ box.center
    rot, pos = pose.rot[:, b], pose.pos[:, b]
    return rot @ r_sb, pos + rot @ c_b, np.asarray(box.half, dtype=float)


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
    for rot, ctr, half in boxes:
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


def _skew(v: np.ndarray) -> np.ndarray:
    z = np.zeros(v.shape[:-1])
    x, y, w = v[..., 0], v[..., 1], v[..., 2]
    return np.stack([np.stack([z, -w, y], -1), np.stack([w, z, -x], -1), np.stack([-y, x, z], -1)], -2)


def _row_scale(batch: _QPBatch, i: int) -> float:
    """Tolerance scale for frame i's rows: |c_fz| × a length (rows are N·m)."""
    return max(abs(batch.c[i, 5]), 1.0)


def _solve_qp(P: np.ndarray, qv: np.ndarray, G: np.ndarray, h: np.ndarray) -> np.ndarray | None:
    """min yᵀPy + 2qᵀy s.t. G y ≤ h with quadprog; None if infeasible."""
    import quadprog

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
    import quadprog

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


def _nested(P: np.ndarray, qv: np.ndarray, G: np.ndarray, h: np.ndarray, scale: float) -> np.ndarray | None:
    """Thesis form: inner QP with y_fz = z fixed, outer bounded search over z (SPEC 4.30-4.31)."""
    from scipy.optimize import linprog, minimize_scalar

    # feasible interval of z = y_fz (an LP each way)
    e = np.zeros(6)
    e[5] = 1.0
    lo = linprog(e, A_ub=G, b_ub=h, bounds=[(None, None)] * 6, method="highs")
    hi = linprog(-e, A_ub=G, b_ub=h, bounds=[(None, None)] * 6, method="highs")
    if lo.status != 0 or hi.status != 0:
        return None
    z_lo, z_hi = float(lo.x[5]), float(hi.x[5])
    Puu, Puz = P[:5, :5], P[:5, 5]
    Gu, Gz = G[:, :5], G[:, 5]

    def inner(z: float) -> tuple[float, np.ndarray | None]:
        u = _solve_qp(Puu, qv[:5] + Puz * z, Gu, h - Gz * z + 1e-12 * scale)
        if u is None:
            return math.inf, None
        y = np.concatenate([u, [z]])
        return float(y @ P @ y + 2.0 * qv @ y), y

    if z_hi - z_lo <= 1e-12 * scale:
        return inner(0.5 * (z_lo + z_hi))[1]
    res = minimize_scalar(lambda z: inner(z)[0], bounds=(z_lo, z_hi), method="bounded",
                          options={"xatol": 1e-10 * scale, "maxiter": 500})
    # fminbound stops at a tolerance relative to |z| (√eps·|z| ≈ 1e-8·c_fz): polish around the
    # estimate in a shifted variable, where that relative tolerance vanishes
    z0 = float(res.x)
    w = 1e-5 * scale
    lo, hi = max(z_lo, z0 - w) - z0, min(z_hi, z0 + w) - z0
    if hi > lo:
        pol = minimize_scalar(lambda u: inner(z0 + u)[0], bounds=(lo, hi), method="bounded",
                              options={"xatol": 1e-12 * scale, "maxiter": 500})
        if pol.fun <= res.fun:
            z0 = z0 + float(pol.x)
    return inner(z0)[1]


def _solve_batch(batch: _QPBatch, method: str) -> tuple[np.ndarray, np.ndarray, list]:
    """Solve every frame: (y (N, 6) about r, status (N,), the constraint rows (G, h) each frame's
    solution satisfies — the relaxed rows for a relaxed frame, None for a failed one)."""
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
        st = Status.OPTIMAL
        if sol is None or np.any(batch.G[i] @ sol > batch.h[i] + 1e3 * tol[i]):
            s = _relaxation(batch, i)
            if s is None:
                log.warning("contact QP: relaxation failed at double-support frame %d", i)
                rows[i] = None
                continue
            Gb, hb = _bounds(batch, i)
            G_rel = np.vstack([batch.G[i], Gb])
            h_rel = np.concatenate([batch.h[i] + s + 1e-7 * scale[i], hb])
            if method == "qp":
                sol = _solve_qp(batch.P[i], batch.q[i], G_rel, h_rel)
            else:
                sol = _nested(batch.P[i], batch.q[i], G_rel, h_rel, scale[i])
            st = Status.RELAXED
            rows[i] = (G_rel, h_rel)
            if sol is None:
                log.warning("contact QP: relaxed problem failed at double-support frame %d", i)
                rows[i] = None
                continue
        y[i] = sol
        status[i] = st
    for i in np.flatnonzero(status == Status.FAILED):
        rows[i] = None
    return y, status, rows


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
    import quadprog

    out = y.copy()
    P = line.period
    n_pos = P if P is not None else line.r.shape[0]
    where = np.full(line.r.shape[0], -1)
    where[ds] = np.arange(len(ds))  # position -> row of the batch (-1: not double support)
    runs = [run for run in _runs(where >= 0, P) if all(rows[where[pos]] is not None for pos in run)]
    if not runs:
        return out
    # every pair (a -> b) of consecutive frames touching a run; "wrapped": b is frame 0 seen as frame P
    pa, pb, wr, rid, la, lb = [], [], [], [], [], []
    for r_i, run in enumerate(runs):
        loc = {pos: j for j, pos in enumerate(run)}
        prv = run[0] - 1 if run[0] > 0 else (n_pos - 1 if P is not None else None)
        if prv is not None and prv not in loc:
            pa.append(prv), pb.append(run[0]), wr.append(P is not None and run[0] == 0), rid.append(r_i)
            la.append(-1), lb.append(0)
        for j, pos in enumerate(run):
            nxt = pos + 1 if pos + 1 < n_pos else (0 if P is not None else None)
            if nxt is None:
                continue
            pa.append(pos), pb.append(nxt), wr.append(P is not None and nxt == 0), rid.append(r_i)
            la.append(j), lb.append(loc.get(nxt, -1))
    pa, pb, wr, rid, la, lb = (np.array(v) for v in (pa, pb, wr, rid, la, lb))
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
    if P is not None and where[P] >= 0 and where[0] >= 0:  # frame P is frame 0 one period later
        out[where[P]] = line.wrap @ out[where[0]]
    return out


def _solve_block_tridiagonal(D: np.ndarray, O: np.ndarray, rhs: np.ndarray) -> np.ndarray:
    """x with the symmetric block-tridiagonal system (diagonal blocks D (N, 6, 6), blocks O (N−1, 6, 6)
    above the diagonal) times x = rhs (N, 6): one banded solve."""
    from scipy.linalg import solve_banded

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


def _project_points(p: np.ndarray, G: np.ndarray, h: np.ndarray) -> np.ndarray:
    """Nearest points of the convex polygons {x : G x <= h} (N, m, 2), (N, m) to the points p (N, 2).

    Exact: the nearest point is p itself, its projection onto one edge line, or a vertex (two
    edge lines meeting); every candidate is tried and the nearest feasible one kept."""
    N, m, _ = G.shape
    g2 = np.einsum("nmi,nmi->nm", G, G)
    ok = g2 > 1e-18
    cands = [p[:, None, :]]
    step = np.where(ok, (np.einsum("nmi,ni->nm", G, p) - h) / np.where(ok, g2, 1.0), np.nan)
    cands.append(p[:, None, :] - step[..., None] * G)  # onto each edge line
    i, j = np.triu_indices(m, 1)
    M = np.stack([G[:, i], G[:, j]], axis=-2)  # (N, pairs, 2, 2)
    det = M[..., 0, 0] * M[..., 1, 1] - M[..., 0, 1] * M[..., 1, 0]
    good = np.abs(det) > 1e-12 * np.sqrt(g2[:, i] * g2[:, j] + 1e-300)
    d = np.where(good, det, 1.0)
    hi, hj = h[:, i], h[:, j]
    vx = (hi * M[..., 1, 1] - hj * M[..., 0, 1]) / d
    vy = (M[..., 0, 0] * hj - M[..., 1, 0] * hi) / d
    cands.append(np.where(good[..., None], np.stack([vx, vy], -1), np.nan))  # vertices
    C = np.concatenate(cands, axis=1)  # (N, K, 2)
    slack = np.einsum("nmi,nki->nkm", G, C) - h[:, None, :]
    tol = 1e-9 * (1.0 + np.abs(h)).max(axis=1)
    feasible = np.all(slack <= tol[:, None, None], axis=2) & np.all(np.isfinite(C), axis=2)
    dist = np.where(feasible, np.sum((C - p[:, None, :]) ** 2, axis=2), np.inf)
    best = np.argmin(dist, axis=1)
    out = C[np.arange(N), best]
    return np.where(np.isfinite(dist[np.arange(N), best])[:, None], out, p)


def _project_cop(w: np.ndarray, character: Character, pose: _Pose, side: str,
                 penetration: float) -> tuple[np.ndarray, np.ndarray]:
    """Single-support wrenches (6, N) about the origin whose CoP lies outside the foot's contact
    polygon: the CoP moved to the nearest point of the polygon (same force, same free moment).
    Returns the wrenches and which frames moved."""
    out = np.array(w, dtype=float, copy=True)
    N = out.shape[1]
    moved = np.zeros(N, dtype=bool)
    cop, tz = cop_and_free_moment(out)
    rot, ctr, half = _foot_frames(character, pose, side)
    z_low = ctr[:, 2] - np.abs(rot[:, 2, :]) @ half
    z_plane = np.maximum(0.0, z_low + penetration)
    E = np.swapaxes(rot, 1, 2)  # (N, 3, 3) rows: box axes in world
    A = E[:, :, :2]  # the polygon: |A p + b| <= half, p the CoP on the foot's plane
    b = np.einsum("nkj,nj->nk", E, np.stack([np.zeros(N), np.zeros(N), z_plane], -1) - ctr)
    p = np.nan_to_num(cop[:2].T)
    excess = np.abs(np.einsum("nkj,nj->nk", A, p) + b) - half
    todo = np.flatnonzero(np.isfinite(cop[0]) & np.any(excess > 1e-12, axis=1))
    if len(todo):
        G = np.concatenate([A[todo], -A[todo]], axis=1)
        h = np.concatenate([half - b[todo], half + b[todo]], axis=1)
        pt = _project_points(p[todo], G, h)
        f = out[3:, todo]
        pt3 = np.stack([pt[:, 0], pt[:, 1], np.zeros(len(todo))])
        out[:3, todo] = np.cross(pt3, f, axis=0)
        out[2, todo] += tz[todo]
        moved[todo] = True
    return out, moved


def _cop_violation(wrenches: np.ndarray, character: Character, pose: _Pose, penetration: float) -> np.ndarray:
    """Metres by which each foot's CoP lies outside its contact polygon (0 inside), (2, N)."""
    N = pose.rot.shape[0]
    out = np.zeros((2, N))
    cop, _ = cop_and_free_moment(wrenches)
    for s, side in enumerate(FEET):
        rot, ctr, half = _foot_frames(character, pose, side)
        z_low = ctr[:, 2] - np.abs(rot[:, 2, :]) @ half
        z_plane = np.maximum(0.0, z_low + penetration)
        p = cop[s].T + np.stack([np.zeros(N), np.zeros(N), z_plane], -1)  # the CoP on the foot's plane
        local = np.einsum("nji,nj->ni", rot, p - ctr)
        excess = np.max(np.abs(local) - half[None, :], axis=1)
        out[s] = np.where(np.isfinite(excess), np.maximum(excess, 0.0), 0.0)
    return out


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
    project_cop: bool = False,
) -> ContactEstimate:
    """Ground reaction wrench of each foot at every frame, from kinematics alone.

    ``q`` (n, T) the motion (our world frame: Z up, ground z = 0), ``fps`` its rate,
    ``foot_contact`` (2, T) bool (right, left) the contact schedule. See the module
    docstring for the method; ``method`` is ``"qp"`` (default) or ``"nested"`` (the
    thesis's reference form, slow). ``smoothing_hz`` (qp only): the temporal prior on the
    double-support split, as a cut-off frequency (None: one QP per frame, the thesis).
    ``project_cop``: single-support CoPs outside the foot's polygon moved into it.
    """
    if method not in METHODS:
        raise ContactError(f"unknown method {method!r}; use one of {METHODS}")
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
    pose = _dense_pose(character, qf)
    w_right_exact = w[0].copy()  # c or 0: the boundary values of the temporal prior (dynamics-consistent)
    if project_cop:
        for s, mask in ((0, right), (1, left)):
            k = np.flatnonzero(mask)
            if len(k):
                w[s][:, k], moved = _project_cop(w[s][:, k], character, pose.take(k), FEET[s], penetration)
                st[k[moved]] = Status.PROJECTED
    if len(ds):
        batch = _qp_batch(character, pose.take(ds), tau0[:, ds], h0[:, ds], friction=friction,
                          penetration=penetration, regularization=regularization, effort=effort)
        y, st_ds, rows = _solve_batch(batch, method)
        if smoothing_hz is not None:
            y = _smooth_split(batch, y, rows, ds, _timeline(character, pose, w_right_exact, cyclic),
                              float(fps) / (2.0 * math.pi * float(smoothing_hz)))
        # back to moments about the origin: m_O = m_r + r × f
        y_o = y.copy()
        y_o[:, :3] += np.cross(batch.r, y[:, 3:])
        w[0][:, ds] = y_o.T
        w[1][:, ds] = h0[:, ds] - y_o.T
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
        log.info("contact estimation: %d of %d double-support frames infeasible, relaxed", n_rel, len(ds))
    return ContactEstimate(wrenches=wrenches, total=total, support=support, status=status,
                           cop_violation=viol, fps=float(fps), method=method, cyclic=bool(cyclic),
                           smoothing_hz=None if smoothing_hz is None else float(smoothing_hz))


# --- trials: filter, schedule, estimate -----------------------------------------------------

DEFAULT_CUTOFF_HZ = 6.0  # Winter, Biomechanics and Motor Control of Human Movement: gait kinematics
CONTACT_SOURCES = ("auto", "kinematics", "plates")


def lowpass_kinematics(character: Character, q: np.ndarray, fps: float, cutoff_hz: float = DEFAULT_CUTOFF_HZ,
                       *, cyclic: bool = False, order: int = 2) -> np.ndarray:
    """Zero-phase Butterworth low-pass of every coordinate before differentiation.

    Hinge angles are unwrapped first. ``order`` 2 run forwards and backwards gives the
    classic 4th-order zero-lag filter of gait biomechanics. End effects: the signal is
    extended by odd reflection over 3 periods of the cut-off (``3·fps/cutoff`` samples,
    the filter's transient has died out by then; scipy's default of a few samples leaves
    a transient that corrupts accelerations near the ends). A cyclic motion (last frame =
    first frame one period later) is filtered as the periodic signal it is.
    """
    from scipy.signal import butter, sosfiltfilt

    q = np.array(q, dtype=float, copy=True)
    if not (math.isfinite(cutoff_hz) and 0 < cutoff_hz < fps / 2):
        raise ContactError(f"low-pass cut-off {cutoff_hz} Hz must lie in (0, fps/2 = {fps / 2:g} Hz)")
    for i, kind in enumerate(character.dof_kinds):
        if kind == "hinge":
            q[i] = np.unwrap(q[i])
    sos = butter(order, cutoff_hz, btype="low", fs=fps, output="sos")
    T = q.shape[1]
    if cyclic:
        P = T - 1
        offset = (q[:, -1] - q[:, 0])[:, None]
        reps = max(3, 2 * int(math.ceil(3 * fps / cutoff_hz / P)) + 1)
        k0 = reps // 2
        ext = np.concatenate([q[:, :P] + (k - k0) * offset for k in range(reps)], axis=1)
        out = sosfiltfilt(sos, ext, axis=1, padtype=None)
        return np.concatenate([out[:, k0 * P:(k0 + 1) * P], out[:, k0 * P:k0 * P + 1] + offset], axis=1)
    padlen = min(T - 1, int(math.ceil(3 * fps / cutoff_hz)))
    return sosfiltfilt(sos, q, axis=1, padtype="odd", padlen=padlen)


def foot_schedule(contacts: np.ndarray, character: Character) -> np.ndarray:
    """(P, T) contact-point schedule -> (2, T) foot schedule (right, left): any point of the foot."""
    c = np.asarray(contacts, dtype=bool)
    if c.ndim != 2 or c.shape[0] != len(character.contacts):
        raise ContactError(f"contact schedule must have one row per contact point "
                           f"({len(character.contacts)}), got shape {c.shape}")
    return foot_schedule_of(character, c)


@dataclass(frozen=True, eq=False)
class TrialEstimate:
    """A capture's estimated ground reactions with what produced them."""

    estimate: ContactEstimate
    times: np.ndarray  # (T,) the capture's times (s)
    q: np.ndarray  # (n, T) the filtered coordinates that were differentiated
    contacts: np.ndarray  # (P, T) contact-point schedule used
    contacts_from: str  # "plates", "importer", "kinematics", "given"
    cutoff_hz: float | None


def estimate_capture(
    capture: Any,
    *,
    cutoff_hz: float | None = DEFAULT_CUTOFF_HZ,
    contacts: str | np.ndarray = "auto",
    cyclic: bool | None = None,
    smoothing_hz: float | str | None = "cutoff",
    project_cop: bool = True,
    **options: Any,
) -> TrialEstimate:
    """Filter a capture's kinematics, get its contact schedule, estimate its ground reactions.

    ``cutoff_hz``: low-pass cut-off (6 Hz, the same for every trial; ``None`` = no filter).
    ``smoothing_hz``: the temporal prior on the double-support split
    (:func:`estimate_contact_wrenches`); ``"cutoff"`` (default) = the kinematics' own
    cut-off — the split gets no frequency the filtered kinematics do not have — with
    ``method="qp"``, none with the nested reference form or without a filter; ``None`` = one
    QP per frame (the thesis). ``project_cop``: single-support CoPs outside the foot's
    contact polygon moved into it (default; ``False``: the foot takes c exactly, the thesis).
    ``contacts``: ``"kinematics"`` (:func:`solver.io.preprocess.detect_contacts` on the
    filtered motion), ``"plates"`` (force-plate loading, kinematics where the plates are
    incomplete; needs ``capture.measured``), ``"auto"`` (the importer's schedule when it has
    one — from plates —, else the plates, else kinematics) or a (P, T) array.
    ``cyclic``: ``None`` = the capture's ``source["loop"] == "wrap"``. Other options go to
    :func:`estimate_contact_wrenches`.
    """
    from solver.io.preprocess import contacts_from_plates, detect_contacts

    ch = capture.character
    q, fps = np.asarray(capture.q, dtype=float), float(capture.fps)
    if q.shape[0] != ch.n:
        raise ContactError(f"model/motion mismatch: character {ch.name!r} has {ch.n} coordinates, "
                           f"the motion has {q.shape[0]} rows")
    bad = ~np.isfinite(q)
    if bad.any():
        i, t = np.argwhere(bad)[0]
        raise ContactError(f"coordinate {ch.coordinate_names[i]!r} is not finite (NaN/inf) at frame {t}")
    if cyclic is None:
        cyclic = capture.source.get("loop") == "wrap"
    dt = np.diff(capture.times)
    if capture.T > 2 and np.max(np.abs(dt - np.median(dt))) > 0.01 * np.median(dt):
        raise ContactError("the capture is not uniformly sampled; resample it first (solver.io.preprocess.resample)")
    qf = q if cutoff_hz is None else lowpass_kinematics(ch, q, fps, cutoff_hz, cyclic=cyclic)
    if isinstance(contacts, str):
        if contacts not in CONTACT_SOURCES:
            raise ContactError(f"contacts must be one of {CONTACT_SOURCES} or an array, got {contacts!r}")
        how = contacts
        if how == "auto":
            how = "importer" if capture.contacts is not None else ("plates" if capture.measured is not None
                                                                     else "kinematics")
        if how == "importer":
            sched = np.asarray(capture.contacts, dtype=bool)
        elif how == "plates":
            if capture.measured is None:
                raise ContactError("contacts='plates' but the capture has no measured ground reactions")
            sched = contacts_from_plates(capture.measured, character=ch, q=qf, fps=fps)
        else:
            sched = detect_contacts(ch, qf, fps)
    else:
        how, sched = "given", np.asarray(contacts, dtype=bool)
    if sched.shape != (len(ch.contacts), capture.T):
        raise ContactError(f"contact schedule must have shape ({len(ch.contacts)}, T={capture.T}), got {sched.shape}")
    if isinstance(smoothing_hz, str):
        if smoothing_hz != "cutoff":
            raise ContactError(f"smoothing_hz must be a frequency (Hz), 'cutoff' or None, got {smoothing_hz!r}")
        smoothing_hz = cutoff_hz if options.get("method", "qp") == "qp" else None
    est = estimate_contact_wrenches(ch, qf, fps, foot_schedule(sched, ch), cyclic=cyclic, smoothing_hz=smoothing_hz,
                                    project_cop=project_cop, **options)
    return TrialEstimate(estimate=est, times=np.asarray(capture.times, dtype=float), q=qf, contacts=sched,
                         contacts_from=how, cutoff_hz=cutoff_hz)
