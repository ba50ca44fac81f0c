"""Values of the spacetime problem: environment, weights, realism bounds, solve result."""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from solver.environment import STANDARD_GRAVITY, Environment  # noqa: F401  (re-exported)

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
    #: double-support split and the free moment may not flip from frame to frame
    wrench_rate: float = 1.0
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


@dataclass(frozen=True)
class Realism:
    """Bounds of the realistic transcription, each inside the validator's limit
    (``solver.realism``) by a margin so that an optimum is never on the edge of a check."""

    torsion_radius_fraction: float = 0.1  # ρ = foot length / 10 (torsional friction radius)
    torsion_margin: float = 0.95  # |τ| ≤ 0.95 μ ρ f_z
    free_moment_cap: float = 0.025  # |τ| ≤ 0.025 BW·m (validator: 0.03)
    support_max: float = 1.95  # total normal force ≤ 1.95 BW (validator: 2)
    force_rate: float = 10.5  # |ΔF_total| ≤ 10.5 BW/s between frames (validator: 12 BW/s, 0.8 BW at 15 fps)
    #: second differences of the total ground wrench over three frames at 15 fps (scaled by
    #: (15 h)² at other rates): force (BW), moment about the centre of mass (BW × leg length);
    #: whole-body Newton–Euler from positions sees a sixth of them (validator: 0.08 / 0.04)
    force_curvature: float = 0.42
    moment_curvature: float = 0.16
    spin_rate_deg_s: float = 60.0  # a foot in contact turns ≤ 60°/s about the vertical (validator: 75)


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
