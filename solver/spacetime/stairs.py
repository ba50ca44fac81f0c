"""[stairs] Rows of the spacetime NLP that make stairs stairs (``SpacetimeProblem(rising=True)``):
each stance foot on its tread, each swinging foot clear of the nosings it passes, the cycle's
travel one going per step. The geometry is ``solver.environment.stair_flight`` (the same the
checks, the simulation and the plots read), passed per frame as the ``stairs`` parameter block:

``[ox, oy, cx, cy, σ, d]`` the flight (origin of s, its direction, the sign of the rise, the cycle's
travel along it), then per foot
(right, left) ``[lo, hi, s₁, h₁, m₁, w₁, …]``: in contact, the tread's extent along s less the
margins (``StairsBounds``); swinging, the nosings it passes (s, height, the margin over it, the
lead-in of its approach slope; an unused slot lies far below). Rows, for the sole's corners (heel
and toe ends of the sole through the foot's heel and toe contact points, as wide as its foot box):

* **tread** (a foot in contact): heel corners' s ≥ lo, toe corners' s ≤ hi;
* **step** (a swinging foot, at the frames and on the spline between them): no corner inside a
  step — beyond the riser plane of a nosing it crosses (less ``riser_gap_m``, on the side of the
  higher tread) a corner is above the nosing's height — and none beyond the riser past the tread
  it lands on (less ``riser_gap_m``);
* **nosing** (same frames): a corner over the nosing (from ``riser_gap_m`` before the riser plane
  to ``over_m`` past it onto the higher tread) is ``nosing_margin_m`` above it, and before it
  above a slope falling from there by ``approach_slope`` (not at the swing's first and last
  frames: lift-off and landing);
* **travel** (once): the root's travel over the cycle along the flight = (steps per cycle) × going.

"Either behind the riser or above the nosing" is a disjunction: a smooth maximum (a hyperbola
rounding the corner by ``SMOOTH_M``) makes it one differentiable row.
"""

from __future__ import annotations

import math
import weakref
from dataclasses import dataclass
from typing import Any

import casadi as ca
import numpy as np

from solver.character import Character
from solver.environment import Flight
from solver.kinematics import forward_kinematics, point_world
from solver.motion import FEET
from solver.spacetime.derivatives import jacobian, lagrangian_hessian

#: per frame: the flight (6), then per foot the tread extent (2) and the nosing slots (4 each)
FLIGHT_PARAMS = 6
#: nosings per swinging foot: the two it crosses (step-over-step), then the riser past the tread it
#: reaches (the foot does not reach over it: a swing foot overshooting its tread and pulled back
#: would hover over the next step's nosing); the riser behind the tread it left needs no row (the
#: ground under a swinging foot, ``stair_heights``, already keeps it above that tread going up;
#: going down the first crossed nosing does)
NOSING_SLOTS = 3
CROSSED = 2
SLOT_PARAMS = 4  # a nosing slot: s, height, the margin over it, the lead-in (m) of the approach slope
FOOT_PARAMS = 2 + SLOT_PARAMS * NOSING_SLOTS
STAIRS_PARAMS = FLIGHT_PARAMS + 2 * FOOT_PARAMS
CORNERS = 4  # heel-right, heel-left, toe-right, toe-left (``solver.kinematics.sole_corners``)
TREAD_ROWS = 2 * CORNERS  # per frame: each foot's four corners against its tread's extent
#: per frame: each foot's corners out of the step of each nosing slot, and over the crossed nosings
STEP_ROWS = 2 * CORNERS * (NOSING_SLOTS + CROSSED)
SMOOTH_M = 0.004  # m: the smooth maximum's rounding
#: where between two frames the step and nosing rows also hold (fractions of the frame interval)
SPLINE_POINTS = (0.25, 0.5, 0.75)
UNUSED = -1e3  # the height of an unused nosing slot


@dataclass(frozen=True)
class StairsBounds:
    """The stairs rows' margins, inside the stairs checks' limits (``solver.naturalness``: a nosing
    cleared by 2 cm, a stance sole at most 2 cm over its nosing and not into its riser)."""

    #: a swinging sole corner over a nosing clears it by this (check: 0.02 m)
    nosing_margin_m: float = 0.03
    #: a swinging corner this close to a riser's plane (on the lower side) is as if over it ...
    riser_gap_m: float = 0.03
    #: ... and "over the nosing" reaches this far past it onto the higher tread (a foot does not skim
    #: onto a tread at its height: between the frames the spline would cut the nosing)
    over_m: float = 0.12
    #: ... and a corner before it (on the lower side, beyond ``riser_gap_m``) is above a slope falling
    #: from the margin by this (m per m): between the samples the spline cannot dip under the nosing
    #: from a corner far below it (not at the swing's first and last frames)
    approach_slope: float = 1.5
    #: a stance sole's corners stay this far inside its tread's edges (check: 2 cm over the nosing,
    #: none into the riser; ≥ ``riser_gap_m``, so that a foot lifting off is clear of the riser ahead)
    tread_margin_m: float = 0.03
    #: on stairs the joints turn faster: each joint's change between frames stays this far inside the
    #: naturalness check's speed (°/s)
    joint_speed_margin_deg_s: float = 30.0
    #: on stairs a joint's bounds lie this far inside its model limits (the naturalness check: at most
    #: one frame within 3°): the knee, hip and ankle work near their ranges' ends climbing
    joint_limit_margin_deg: float = 4.0


def _smax(a, b):
    return 0.5 * (a + b + ca.sqrt((a - b) ** 2 + SMOOTH_M**2))


class StairsFunctions:
    """The stairs rows of one character, with their derivatives (built once per character)."""

    def __init__(self, character: Character, bounds: StairsBounds = StairsBounds()) -> None:
        ch = self.character = character
        self.bounds = bounds
        n = ch.n
        q = ca.SX.sym("q", n)
        pose = forward_kinematics(ch, q)
        model = ch.model
        corners: list[Any] = []  # per foot: 4 corners (world x, y, z)
        for side in FEET:
            half_w = float(ch.foot(side).half[1])
            sole = ch.sole(side)
            for c in (sole.heel, sole.toe):
                for sgn in (-1.0, 1.0):
                    b, pb = model.point_on_body(c.segment, np.asarray(c.position) + np.array([0.0, sgn * half_w, 0.0]))
                    corners.append(ca.vertcat(*point_world(pose, b, pb)))
        par = ca.SX.sym("par", STAIRS_PARAMS)
        ox, oy, cx, cy, sgn_ = (par[i] for i in range(5))

        def along(p):
            return cx * (p[0] - ox) + cy * (p[1] - oy)

        tread, step = [], []
        gap, over = self.bounds.riser_gap_m, self.bounds.over_m
        for k in range(2):
            fp = par[FLIGHT_PARAMS + FOOT_PARAMS * k : FLIGHT_PARAMS + FOOT_PARAMS * (k + 1)]
            cs = corners[CORNERS * k : CORNERS * (k + 1)]
            tread += [along(cs[0]) - fp[0], along(cs[1]) - fp[0], fp[1] - along(cs[2]), fp[1] - along(cs[3])]
            for i in range(NOSING_SLOTS):
                s_i, h_i, m_i, w_i = (fp[2 + SLOT_PARAMS * i + r] for r in range(SLOT_PARAMS))
                for c in cs:
                    behind = sgn_ * (s_i - along(c))  # > 0: on the lower tread's side of the riser plane
                    if i == CROSSED:  # the riser past the tread it lands on: the foot does not reach over it
                        step.append(s_i - along(c) - gap)
                        continue
                    step.append(_smax(behind - gap, c[2] - h_i))  # not inside the step
                    if i < CROSSED:  # over the nosing, approached from above a slope on the riser's side
                        lead = self.bounds.approach_slope * _smax(behind - gap, 0.0)
                        step.append(_smax(_smax(behind - gap - w_i, -behind - over), c[2] - h_i - m_i + lead))
        self.tread = ca.Function("stairs_tread", [q, par], [ca.vertcat(*tread)])
        self.step = ca.Function("stairs_step", [q, par], [ca.vertcat(*step)])
        qa, va, qb, vb = (ca.SX.sym(name, n) for name in ("qa", "va", "qb", "vb"))
        h, u = ca.SX.sym("h"), ca.SX.sym("u")
        # the spline between two frames at the fraction u (the Hermite cubic, solver.trajectory.sample)
        qu = ((2 * u**3 - 3 * u**2 + 1) * qa + (u**3 - 2 * u**2 + u) * h * va + (-2 * u**3 + 3 * u**2) * qb
              + (u**3 - u**2) * h * vb)
        self.step_mid = ca.Function("stairs_step_mid", [qa, va, qb, vb, h, u, par], [self.step(qu, par)])
        # [naturalness] a joint's change between frames (the check: 450°/s; bounded inside it, per h)
        self.rate = ca.Function("stairs_rate", [qa, qb], [(qb - qa)[6:]])
        z = ca.SX.sym("z", 4)  # x0, y0, x_{T−2}, y_{T−2}
        tp = ca.SX.sym("tp", 3)  # cx, cy, the cycle's travel
        self.travel = ca.Function("stairs_travel", [z, tp], [tp[0] * (z[2] - z[0]) + tp[1] * (z[3] - z[1]) - tp[2]])
        self.derivatives = {
            "tread": (lagrangian_hessian(self.tread, 1), jacobian(self.tread, 1)),
            "step": (lagrangian_hessian(self.step, 1), jacobian(self.step, 1)),
            "step_mid": (lagrangian_hessian(self.step_mid, 4), jacobian(self.step_mid, 4)),
            "travel": (lagrangian_hessian(self.travel, 1), jacobian(self.travel, 1)),
            "rate": (lagrangian_hessian(self.rate, 2), jacobian(self.rate, 2)),
        }



_CACHE: weakref.WeakKeyDictionary[Character, StairsFunctions] = weakref.WeakKeyDictionary()


def stairs_functions(character: Character) -> StairsFunctions:
    fns = _CACHE.get(character)
    if fns is None:
        fns = _CACHE[character] = StairsFunctions(character)
    return fns


def stairs_parameters(flight: Flight | None, foot_contact: np.ndarray, bounds: StairsBounds = StairsBounds()
                      ) -> np.ndarray:
    """(STAIRS_PARAMS, T) the ``stairs`` parameter block of a problem for ``flight`` (None: every
    row inactive — flat ground, λ = 0 of a stairs continuation)."""
    B = np.asarray(foot_contact, dtype=bool)
    T = B.shape[1]
    out = np.zeros((STAIRS_PARAMS, T))
    for k in range(2):
        o = FLIGHT_PARAMS + FOOT_PARAMS * k
        out[o], out[o + 1] = -1e3, 1e3
        out[o + 3 : o + FOOT_PARAMS : SLOT_PARAMS] = UNUSED
        out[o + 2 + SLOT_PARAMS * CROSSED] = -UNUSED  # no riser ahead: far away
    if flight is None:
        return out
    g, sgn = flight.going, float(np.sign(flight.rise))
    out[0], out[1] = flight.origin
    out[2], out[3] = flight.direction
    out[4], out[5] = sgn, flight.n * g
    m = bounds.tread_margin_m
    for k in range(2):
        o = FLIGHT_PARAMS + FOOT_PARAMS * k
        swing = [t for t in range(T) if not B[k, t]]
        first_last = {t for t in swing if B[k, (t - 1) % (T - 2)] or B[k, (t + 1) % (T - 2)]}
        for t in range(T):
            a, c = int(flight.left[k, t]), int(flight.reached[k, t])
            if B[k, t]:
                out[o, t], out[o + 1, t] = a * g + m, (a + 1) * g - m
                continue
            lo_, hi_ = min(a, c), max(a, c)
            crossed = list(range(lo_ + 1, hi_ + 1))[-CROSSED:]
            for i, kk in enumerate([*crossed, hi_ + 1]):  # the risers crossed, then the one ahead
                j = i if kk <= hi_ else CROSSED
                s_i, h_i = flight.nosing(kk)
                o_ = o + 2 + SLOT_PARAMS * j
                out[o_, t], out[o_ + 1, t] = float(s_i), float(h_i)
                if kk <= hi_ and t not in first_last:  # the margin, and the approach slope up to 1 m before
                    out[o_ + 2, t], out[o_ + 3, t] = bounds.nosing_margin_m, 1.0
    return out


def add_stairs_terms(prob, STAIRS, bounds: StairsBounds = StairsBounds()) -> None:
    """The stairs rows of a ``rising`` problem (``STAIRS``: the (STAIRS_PARAMS, T) parameter block):
    tread rows for the feet in contact, step and nosing rows for the swinging feet at the distinct
    frames and at the midpoints of the segments they swing through, the cycle's travel."""
    from solver.spacetime.derivatives import Term

    fns = stairs_functions(prob.character)
    D = fns.derivatives
    B = prob.foot_contact()
    qi, vi, Tn = prob._q_index, prob._v_index, prob.T
    frames = prob.distinct_frames
    sel = [(c, CORNERS * k + r) for c, t in enumerate(frames) for k in range(2) if B[k, t] for r in range(CORNERS)]
    prob._rows(Term("stairs_tread", fns.tread, 1, qi[:, frames], [STAIRS[:, frames]], derivatives=D["tread"]), sel,
               0.0, np.inf, "stairs_tread")
    per_foot = STEP_ROWS // 2
    sel = [(c, per_foot * k + r) for c, t in enumerate(frames) for k in range(2) if not B[k, t]
           for r in range(per_foot)]
    prob._rows(Term("stairs_step", fns.step, 1, qi[:, frames], [STAIRS[:, frames]], derivatives=D["step"]), sel,
               0.0, np.inf, "stairs_step")
    # the spline's midpoints of the segments a foot swings through, lifts off or touches down in: the
    # foot's rows take the parameters of its swinging frame
    segs = [t for t in frames if not (B[0, t] and B[0, t + 1]) or not (B[1, t] and B[1, t + 1])]
    if segs:
        nxt = [t + 1 for t in segs]
        sel = [(c, per_foot * k + r) for c, t in enumerate(segs) for k in range(2) if not (B[k, t] and B[k, t + 1])
               for r in range(per_foot)]
        cols = []
        for t in segs:
            parts = [STAIRS[:FLIGHT_PARAMS, t]]
            for k in range(2):
                u = t if not B[k, t] else t + 1
                parts.append(STAIRS[FLIGHT_PARAMS + FOOT_PARAMS * k : FLIGHT_PARAMS + FOOT_PARAMS * (k + 1), u])
            cols.append(ca.vertcat(*parts))
        z = np.vstack([qi[:, segs], vi[:, segs], qi[:, nxt], vi[:, nxt]])
        m = len(segs)
        us = ca.DM(np.repeat(SPLINE_POINTS, m)).T
        sel = [(c + m * j, r) for j in range(len(SPLINE_POINTS)) for c, r in sel]
        prob._rows(Term("stairs_step_spline", fns.step_mid, 4, np.tile(z, len(SPLINE_POINTS)),
                        [ca.repmat(prob._par["h"], 1, m * len(SPLINE_POINTS)), us,
                         ca.repmat(ca.horzcat(*cols), 1, len(SPLINE_POINTS))],
                        derivatives=D["step_mid"]), sel, 0.0, np.inf, "stairs_step")
    # joints change between frames inside the naturalness check's speed (hinges; the root's six excluded)
    from solver.naturalness import NaturalnessLimits

    kinds = np.array(prob.character.dof_kinds)[6:]
    rows = [i for i in range(prob.n - 6) if kinds[i] == "hinge"]
    pairs = list(frames)
    g0 = prob._ng
    limit = math.radians(NaturalnessLimits().joint_speed_deg_s - bounds.joint_speed_margin_deg_s)
    prob._h_bounds.append((g0 + np.arange(len(pairs) * len(rows)),
                           lambda hv: (-limit * hv, limit * hv)))
    prob._rows(Term("stairs_rate", fns.rate, 2, np.vstack([qi[:, pairs], qi[:, [t + 1 for t in pairs]]]), [],
                    derivatives=D["rate"]), [(c, r) for c in range(len(pairs)) for r in rows], -np.inf, np.inf,
               "joint_rate")
    z = np.array([qi[0, 0], qi[1, 0], qi[0, Tn - 2], qi[1, Tn - 2]])[:, None]
    prob._rows(Term("stairs_travel", fns.travel, 1, z, [STAIRS[[2, 3, 5], 0]], derivatives=D["travel"]),
               [(0, 0)], 0.0, 0.0, "stairs_travel")


def stairs_joint_bounds(prob, lbx: np.ndarray, ubx: np.ndarray, bounds: StairsBounds = StairsBounds()
                        ) -> tuple[np.ndarray, np.ndarray]:
    """The variable bounds of a ``rising`` problem with each limited joint coordinate
    (``solver.naturalness.limited_coordinates``) ``joint_limit_margin_deg`` inside its model limits."""
    from solver.naturalness import limited_coordinates

    lbx, ubx = lbx.copy(), ubx.copy()
    m = math.radians(bounds.joint_limit_margin_deg)
    lo, hi = prob.character.lower, prob.character.upper
    for i in np.flatnonzero(limited_coordinates(prob.character)):
        idx = np.unique(prob._q_index[i])
        lbx[idx] = np.maximum(lbx[idx], lo[i] + m)
        ubx[idx] = np.minimum(ubx[idx], hi[i] - m)
    return lbx, ubx
