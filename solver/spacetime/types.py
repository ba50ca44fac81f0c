"""Values of the spacetime problem: environment, weights, realism bounds; what one solve takes (problem data,
warm start, solver options) and what it returns (solve result)."""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, fields
from typing import Any

import numpy as np

from solver.environment import STANDARD_GRAVITY, Environment  # noqa: F401  (re-exported)
from solver.naturalness import NaturalnessLimits
from solver.realism import RealismLimits

DEFAULT_IPOPT = {
    "ipopt.print_level": 0,
    "print_time": False,
    "ipopt.sb": "yes",
    "ipopt.mu_strategy": "adaptive",
    "ipopt.tol": 1e-7,
    "ipopt.constr_viol_tol": 1e-9,
    "ipopt.acceptable_iter": 0,  # never stop on the looser "acceptable" criterion
    "ipopt.linear_solver": "mumps",
    "ipopt.mumps_pivot_order": 5,  # METIS: the least fill-in on the spline transcription's KKT systems
    "error_on_fail": False,
}
SUCCESS_STATUSES = ("Solve_Succeeded",)
#: IPOPT options of a solve that starts from multipliers (``WarmStart.warm``): a small barrier
#: parameter and the starting point kept where it is (not pushed away from its bounds)
WARM_START_IPOPT = {
    "ipopt.warm_start_init_point": "yes",
    "ipopt.mu_init": 1e-4,
    "ipopt.warm_start_bound_push": 1e-6,
    "ipopt.warm_start_bound_frac": 1e-6,
    "ipopt.warm_start_slack_bound_push": 1e-6,
    "ipopt.warm_start_slack_bound_frac": 1e-6,
    "ipopt.warm_start_mult_bound_push": 1e-6,
}


@dataclass(frozen=True)
class Weights:
    direction: float = 1.0  # η_dir: marker distance to the guide, per (1 cm)²
    singularity: float = 1e-5  # η_sing
    #: [beyond] tiny weight on the squared contact wrenches (scaled by body weight and leg
    #: length): in double support only their sum is constrained, so without it the split
    #: is a flat direction of the NLP and IPOPT's tail convergence crawls.
    wrench: float = 1e-4
    #: [beyond] weak prior toward the guide's joint coordinates (not the root): one marker per
    #: segment leaves some rotations unobserved. 0.1 rad weighs like 1 mm of marker distance.
    coordinates: float = 1.0
    #: [realism] squared change of each foot's (scaled) wrench per 1/15 s (the change between
    #: frames × (1/15 s) / h, so the same at any frame rate), averaged over the cycle: the
    #: double-support split and the free moment may not flip from frame to frame, and a stance brakes
    #: then propels (at 1, HalfBoy's fore-aft force changed sign three times per stance)
    wrench_rate: float = 10.0
    #: [realism] squared jerk of the rotations (the spline's third derivative × (1/15 s)³, rad),
    #: averaged over the cycle: no frame-to-frame zig-zag of a coordinate that the markers hardly
    #: see. The time scale is fixed (``layout.RATE_TIME``), so the same motion costs the same at
    #: 15 and 30 frames/s
    jerk: float = 1.0
    #: [realism] prior of the root's three rotations toward the guide's (the kinematic fit: the
    #: capture's own pelvis orientation, measured by its markers; the correction and the
    #: continuation: the simplified or transformed guide's), 100× the joint coordinates' weight:
    #: 0.01 rad weighs like 1 mm of marker distance. One marker per segment leaves the pelvis's
    #: turn about the vertical to the fit, which used it to make up for segment lengths that
    #: differ from the capture's (Plug-in Gait: ±26° with 30° jumps between frames against the
    #: capture's smooth +3…−13°)
    root_rotation: float = 100.0
    #: [realism] kinematic fit (simplification) only: squared second difference of the rotations
    #: between frames per (1/15 s)² (the difference × ((1/15 s) / h)², so the same at any frame
    #: rate; with the frame as the scale, 30 frames/s made it 16 times weaker): a rotation the
    #: markers do not see (axial rotation of a straight arm) stays smooth instead of taking any
    #: value frame by frame
    smoothness: float = 0.01
    #: [naturalness] squared moment of each foot's ground reaction about the centre of mass
    #: (scaled by body weight × leg length), averaged over the cycle: ground reactions that
    #: point at the centre of mass, as a walker's legs push (in double support: the leading foot
    #: braking and the trailing one propelling, not the two feet squeezing the ground)
    com_moment: float = 3.0
    #: [naturalness] squared excursion of each joint coordinate into the last few degrees of its
    #: model range, and of each non-sagittal one (ab/adduction, axial rotation, bending) beyond the
    #: guide's own range (``Naturalness``, ``Layout.joint_range``): 0.1 rad beyond weighs like 3.2 cm
    #: of marker distance (1000× the coordinates prior). A turn is not taken in the hips at their
    #: limits when stance-foot pivot and foot placement can share it
    joint_range: float = 1000.0
    #: [naturalness] squared difference of the trunk's lean against gravity (sine, in the sagittal
    #: plane of the direction of travel) from the guide's, per frame, averaged over the cycle: 2°
    #: weighs like ~1 cm of marker distance. On a slope the guide is the tutor turned with gravity,
    #: so the walker keeps its posture against gravity instead of leaning with the ground
    trunk_lean: float = 1000.0
    #: [fidelity] squared distance of the whole-body centre of mass from the capture's, per (1 cm)² and
    #: frame (the tutor only: ``pipeline.TUTOR_WEIGHTS``). The ground reactions are the centre of mass's
    #: acceleration: a character whose mass is distributed otherwise than the subject's (HalfBoy's
    #: trunk, head and arms welded to the pelvis) keeps the subject's forces by keeping its centre of mass
    com_track: float = 0.0
    #: [fidelity] squared difference of the total ground force from the acceleration of the guide's centre
    #: of mass (scaled: body weights; the tutor: the capture's, whose kinematic forces match the plates
    #: within ~0.05 BW), averaged over the cycle: the force's shape — loading peak, valley, push-off, one
    #: braking → propulsion change per stance — is the walker's own, 0.05 BW off weighing like 1.6 cm of
    #: marker distance (at 100, HalfBoy's extrapolations to speed ×1.2 and a 90° curve still braked twice
    #: per stance)
    force_track: float = 1000.0
    #: [naturalness] squared excess of a joint coordinate's change between two frames over
    #: ``Naturalness.joint_speed_deg_s`` (rad/s), per coordinate and frame: 50°/s too fast at one joint
    #: and frame weighs like 16° off its angle there (a swing knee asked to clear the ground turned 468°/s
    #: between two frames where the capture's turned 363°/s; HalfBoy's ankle on a 10° downhill, 455°/s)
    joint_speed: float = 100.0
    #: [naturalness] squared difference of each foot's distance from the pelvis across the direction of
    #: travel from the guide's while it is on the ground (per 1 cm, averaged): a walker keeps its step width;
    #: a curve is not turned by bringing the inner foot onto the path line (the crossover bound's edge)
    step_width: float = 1.0
    #: [naturalness] squared clearance deficit of a moving swing foot's sole corners below the
    #: walker's mid-swing clearance (``Naturalness.clearance_target_m``), per (1 cm)² and corner-frame at
    #: 15 frames/s: 5 mm short at one corner of one frame weighs like 2.5 mm of marker distance over the
    #: whole cycle
    clearance: float = 1.0
    #: [naturalness] squared excess of each foot's distance from the pelvis toward its far side across the
    #: pelvis's own heading over the guide's foot's, while it is on the ground (per 1 cm, averaged): a curve
    #: is not turned by yawing the pelvis over a planted inner foot (with ``step_width`` alone, the overground
    #: walk's 90° curve and 20° uphill optima stood on the crossover bound's 2 cm edge across the pelvis's
    #: heading). One-sided: a wider stance is free (tracked both ways, HalfBoy's turns went into its hips'
    #: limits)
    pelvis_side: float = 1.0


#: the NLP's weight slots: the fields of :class:`Weights`, in the order of the parameter vector's
#: ``wts`` block (``Layout.parameters`` packs them, ``SpacetimeProblem`` reads them by name)
WEIGHT_SLOTS: tuple[str, ...] = tuple(f.name for f in fields(Weights))


def weight_slots(vector: Any) -> dict[str, Any]:
    """A packed weight vector (``WEIGHT_SLOTS`` order: numbers or CasADi symbols) by slot name."""
    size = int(vector.shape[0]) if hasattr(vector, "shape") else len(vector)
    if size != len(WEIGHT_SLOTS):
        raise ValueError(f"a weight vector has {len(WEIGHT_SLOTS)} slots ({', '.join(WEIGHT_SLOTS)}), got {size}")
    return {name: vector[i] for i, name in enumerate(WEIGHT_SLOTS)}


def inside(limit: float, margin: float) -> float:
    """A bound ``margin`` inside a check's ``limit`` (a maximum less a positive margin, a minimum
    less a negative one), to 1e-9 of the limit's unit: an optimum is never on the edge of the check."""
    return round(limit - margin, 9)


def _realism_bounds(lim: RealismLimits) -> dict[str, float]:
    """The realistic transcription's bounds inside the realism checks' limits (``solver.realism``)."""
    return {
        "torsion_radius_fraction": lim.torsion_radius,  # ρ = foot length / 10 (torsional friction radius)
        "free_moment_cap": inside(lim.torsion_abs, 0.005),  # |τ| ≤ 0.025 BW·m (validator: 0.03)
        "support_max": inside(lim.total_force, 0.05),  # total normal force ≤ 1.95 BW (validator: 2)
        "force_rate": inside(lim.force_rate, 1.5),  # |ΔF_total| ≤ 10.5 BW/s (validator: 12 BW/s, 0.8 BW at 15 fps)
        "spin_rate_deg_s": inside(lim.spin_rate, 15.0),  # a foot in contact turns ≤ 60°/s (validator: 75)
    }


def _naturalness_bounds(lim: NaturalnessLimits) -> dict[str, float]:
    """The bounds that keep an optimum's gait human, inside the naturalness checks' limits
    (``solver.naturalness``)."""
    return {
        "pitch_deg": lim.pitch_deg,
        "pitch_load": inside(lim.pitch_load, 0.05),  # 0.45 BW at 40° (check: 0.5 BW)
        "shared_load": inside(lim.shared_load, -0.02),  # 0.12 BW (check: 0.1 BW)
        "friction_use": inside(lim.friction_use, 0.05),  # 0.85 μ (check: 0.9 μ)
        "fore_aft": inside(lim.fore_aft, 0.03),  # 0.32 BW (check: 0.35 BW)
        "level_deg": lim.level_deg,
        "crossover_m": inside(lim.crossover_m, 0.01),  # 2 cm (check: 3 cm)
    }


_REALISM = _realism_bounds(RealismLimits())
_NATURALNESS = _naturalness_bounds(NaturalnessLimits())


@dataclass(frozen=True)
class Realism:
    """Bounds of the realistic transcription, each inside the validator's limit
    (``solver.realism.RealismLimits``) by a margin so that an optimum is never on the edge of a
    check: the defaults are :meth:`from_limits` of the validator's default limits."""

    torsion_radius_fraction: float = _REALISM["torsion_radius_fraction"]
    torsion_margin: float = 0.95  # |τ| ≤ 0.95 μ ρ f_z
    free_moment_cap: float = _REALISM["free_moment_cap"]
    support_max: float = _REALISM["support_max"]
    force_rate: float = _REALISM["force_rate"]
    #: second differences of the total ground wrench over three frames at 15 fps (scaled by
    #: (15 h)² at other rates): force (BW), moment about the centre of mass (BW × leg length);
    #: whole-body Newton–Euler from positions sees a sixth of them (validator: 0.08 / 0.04)
    force_curvature: float = 0.42
    moment_curvature: float = 0.16
    spin_rate_deg_s: float = _REALISM["spin_rate_deg_s"]

    @classmethod
    def from_limits(cls, lim: RealismLimits, **changes: float) -> Realism:
        """The bounds inside the realism checks' limits ``lim`` (the others: their defaults, or ``changes``)."""
        return cls(**{**_realism_bounds(lim), **changes})


@dataclass(frozen=True)
class Naturalness:
    """Bounds that keep an optimum's gait human (``solver.naturalness`` checks the result), each
    inside the check's limit (``NaturalnessLimits``) by a margin: the defaults are
    :meth:`from_limits` of the checks' default limits."""

    #: a swinging foot's sole (its four corners, the plane through its heel and toe contact
    #: points) stays this far above the ground: a safety net (the check: 9 mm in mid-swing; the
    #: cost ``Weights.clearance`` keeps a moving foot near ``clearance_target_m``)
    clearance_m: float = 0.003
    #: the mid-swing clearance a moving swing foot's sole is costed toward (people: 13 ± 4 mm, Winter
    #: 1992): full from ``clearance_speed[1]`` m/s of the foot in the start iterate, none below
    #: ``clearance_speed[0]``, linear between
    clearance_target_m: float = 0.015
    clearance_speed: tuple[float, float] = (0.5, 1.0)
    #: heel-up pitch of a loaded foot: below ``pitch_free_deg`` any load; above it the load is at
    #: most ``pitch_load`` × (sin p_max − sin p_free) / (sin p − sin p_free) BW, p_max = ``pitch_deg``
    #: — ``pitch_load`` at 40° (check: a foot over 0.5 BW pitched at most 40°), ~0.85 BW at 30°,
    #: ~0.26 BW at 60°
    pitch_free_deg: float = 20.0
    pitch_load: float = _NATURALNESS["pitch_load"]
    pitch_deg: float = _NATURALNESS["pitch_deg"]
    #: both feet carry at least this (BW) at the middle frame(s) of every double support
    #: (check: ≥ 0.1 BW at some frame of every change of support)
    shared_load: float = _NATURALNESS["shared_load"]
    #: the ground pushes the body: a foot's horizontal force along the line from the foot to the
    #: centre of mass is at least −push_margin × f_z × leg length (the force plates of the shared
    #: trials: ≥ −0.008; a double support whose feet squeeze the ground between them: −0.36; the
    #: check warns below −0.05)
    push_margin: float = 0.02
    #: a loaded foot uses at most this fraction of the friction μ (check: 0.9): a walk that needs all
    #: of it slips at the slightest disturbance
    friction_use: float = _NATURALNESS["friction_use"]
    #: on level ground a foot's fore-aft force stays within this (BW; check: 0.35; walking peaks
    #: ~0.2): the flat ground is walked on without braking and pushing twice as hard as people do
    fore_aft: float = _NATURALNESS["fore_aft"]
    level_deg: float = _NATURALNESS["level_deg"]
    #: a foot in contact stands at most this far on the far side of the pelvis, across the
    #: direction of travel (check: 3 cm for a loaded foot)
    crossover_m: float = _NATURALNESS["crossover_m"]
    #: the joint-range prior (``Weights.joint_range``) acts beyond the guide's own range of each
    #: non-sagittal joint coordinate (ab/adduction, axial rotation, bending) widened by this, and on
    #: every joint coordinate within ``limit_band_deg`` of its model limit where the guide does not go
    #: (check: a joint within 3° of its limit for more than one frame)
    joint_range_margin_deg: float = 10.0
    limit_band_deg: float = 8.0
    #: the NLP's joint bounds lie this far inside the model's limits: a safety net, the prior keeps
    #: joints out of the band
    limit_margin_deg: float = 0.0
    #: the change between frames beyond which a joint coordinate pays (``Weights.joint_speed``; Winter: the
    #: swing knee, the fastest joint of a walk, peaks near 400°/s; check: 450°/s between frames)
    joint_speed_deg_s: float = 400.0

    @classmethod
    def from_limits(cls, lim: NaturalnessLimits, **changes: Any) -> Naturalness:
        """The bounds inside the naturalness checks' limits ``lim`` (the others: their defaults, or ``changes``)."""
        return cls(**{**_naturalness_bounds(lim), **changes})

    @property
    def pitch_coefficient(self) -> float:
        """C of the pitch rows: f_z (sin p − sin p_free) ≤ C (f_z in BW)."""
        return self.pitch_load * (math.sin(math.radians(self.pitch_deg)) - math.sin(math.radians(self.pitch_free_deg)))


@dataclass(frozen=True, eq=False)
class SolveResult:
    """Outcome of one NLP solve. ``success`` False: ``q``/``wrenches`` are the last iterate,
    kept apart for diagnosis — never to be used as a solution."""

    success: bool
    status: str
    iterations: int
    wall_time: float
    q: np.ndarray
    wrenches: np.ndarray | None  # (2, 6, T) world frame about the origin
    objective: float
    marker_rms: float  # m, RMS marker distance to the guide
    lam_x: np.ndarray | None
    lam_g: np.ndarray | None
    max_violation: float  # largest constraint violation (scaled units)
    stats: Mapping[str, Any] = field(default_factory=dict)
    v: np.ndarray | None = None  # (n, T) knot velocities of the spline (dynamic problems)
    heading_change: float = math.nan  # rad, the cycle's yaw change Δψ imposed

    def solver_record(self, **extra: Any) -> dict[str, Any]:
        """What a motion's provenance keeps of this solve (``provenance.solver``), ``extra`` added or
        replacing: status, iterations, time, and the bounds the optimum rests on."""
        return {"name": "ipopt", "status": self.status, "iterations": self.iterations, "time_s": self.wall_time,
                "active_bounds": dict(self.stats.get("active_bounds") or {}), **extra}


@dataclass(frozen=True, eq=False)
class ProblemData:
    """What one solve of a built problem asks for: the values of its parameters.

    ``guide_q`` (n, T): the guide motion, whose markers the optimum tracks unless ``guide_markers``
    (3 × markers, T) are given (the kinematic fit: the capture's). ``heading_change`` Δψ (rad):
    yaw[T−2] − yaw[0] of the optimum (default: the start's). ``frame_interval``: the spline's frame
    interval h (s), default 1/fps (the speed axis changes it; the frame count is fixed). ``prior_q``:
    the coordinates the joint and root-rotation priors pull toward (default: the guide's; the tutor's
    correction: the capture's own joint angles). ``guide_com`` (3, T): the centre of mass
    ``Weights.com_track`` pulls toward (default: the guide's), whose acceleration is also the total
    ground force ``Weights.force_track`` pulls toward. ``locks``: coordinate index → value it is
    held at."""

    guide_q: np.ndarray | None = None
    guide_markers: np.ndarray | None = None
    env: Environment = field(default_factory=Environment)
    weights: Weights = field(default_factory=Weights)
    heading_change: float | None = None
    frame_interval: float | None = None
    prior_q: np.ndarray | None = None
    guide_com: np.ndarray | None = None
    locks: Mapping[int, float] | None = None


@dataclass(frozen=True, eq=False)
class WarmStart:
    """Where IPOPT starts: the coordinates ``q`` (n, T), the contact ``wrenches`` (2, 6, T; default:
    none) and, for a warm start proper, the multipliers of an earlier solve of the same problem
    (``lam_x``, ``lam_g``: both, or neither)."""

    q: np.ndarray
    wrenches: np.ndarray | None = None
    lam_x: np.ndarray | None = None
    lam_g: np.ndarray | None = None

    @property
    def warm(self) -> bool:
        """Starts from multipliers (IPOPT's ``WARM_START_IPOPT`` options)."""
        return self.lam_x is not None and self.lam_g is not None

    def with_multipliers(self, res: SolveResult) -> WarmStart:
        """This start with the multipliers of the solve ``res`` (none when it has none)."""
        if res.lam_x is None or res.lam_g is None:
            return self
        return WarmStart(self.q, self.wrenches, res.lam_x, res.lam_g)


@dataclass(frozen=True)
class SolverOptions:
    """How IPOPT runs one solve: at most ``max_iter`` iterations; ``ipopt``: options over the
    problem's own (``DEFAULT_IPOPT`` and its constructor's); ``should_stop()``: polled at every
    iteration (true: IPOPT stops with ``User_Requested_Stop``)."""

    max_iter: int = 500
    ipopt: Mapping[str, Any] = field(default_factory=dict)
    should_stop: Callable[[], bool] | None = None
