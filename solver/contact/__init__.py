"""Contact-force estimation from kinematics (docs/method.md (M4), thesis ch. 4 and appendix A).

Inverse dynamics of the motion with no external force gives, at every frame, the total
ground wrench the motion needs, ``c = h0`` (docs/method.md (M3.5)). Single support: the foot on the
ground takes ``c``. Double support: the right-foot wrench ``x`` (the left one is ``c − x``)
minimises the internal effort, the sum of squared joint forces (docs/method.md (M4.1)-(M4.3))

    τ_i(x) = τ0_i − S_i·x          i ∈ A (ancestors of the right foot only)
    τ_i(x) = τ0_i − S_i·(c − x)    i ∈ B (ancestors of the left foot only)
    τ_i    = τ0_i − S_i·c          i ∈ C (common ancestors: constant, 0 at the root)
    τ_i    = τ0_i                  i ∈ D (the others)

where τ0 are the joint forces of the motion without external force and S_i the world
screw of joint i (:func:`solver.kinematics.joint_screws`), subject to

* each centre of pressure inside its foot's contact polygon (foot box ∩ ground),
  written linearly by multiplying by the vertical force (docs/method.md (M4.6)),
* ``0 ≤ x_fz ≤ c_fz`` (implied by the polygon rows) and a friction pyramid
  ``|f_x|, |f_y| ≤ μ f_z`` on each foot (μ = 1 as in the correction problem,
  docs/method.md (M5.7); pass ``friction=None`` to drop it).

``method="qp"`` solves this as one strictly convex 6-variable QP per double-support
frame (**[beyond]** the thesis): the QP data of every double-support frame are assembled
at once with numpy; frames whose unconstrained optimum is feasible are done with one
batched linear solve, the others go to quadprog (Goldfarb-Idnani). ``method="nested"`` is
the thesis's form kept as a reference: inner QP with ``x_fz`` fixed, outer bounded scalar
search (docs/method.md (M4.7)). Both minimise the same function under the same constraints.

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

Contact polygon. The ground is the plane z = 0 (docs/method.md (M2)). A foot the schedule declares
on the ground but whose box does not reach z = 0 (a rigid box and a fitted skeleton
approximate a real foot: it may float a few mm) would get no polygon at all; for such a
foot the contact plane is moved up to ``penetration`` (1 cm, docs/method.md (M1)) above the box's
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

Lateral force from the centre of mass (``lateral_hz``, **[beyond]**; off by default here, 4 Hz in
:func:`estimate_capture`). Across the walking direction the body's acceleration is a step-frequency
sway, but the inverse dynamics of 6 Hz joint angles give it 4-8 Hz pelvis and trunk ringing the
plates do not have. The total's lateral force is replaced by M ÿ of the centre of mass's lateral
coordinate low-passed at ``lateral_hz``, the difference a force through the centre of mass (the
moment about the centre of mass unchanged); a walk turning by more than 30° keeps the inverse
dynamics' (``solver.contact.lateral``, docs/grf.md).

Accelerations are central differences (docs/method.md (M2.2)), undefined at the first and last
frames of a non-cyclic motion (status ``UNDEFINED``, NaN). With ``cyclic=True`` the last
frame must close the cycle (the first pose one period later, root advanced): differences
wrap around with that offset and every frame is defined.

Package layout: ``common`` (status codes, the estimate, input checks, derivatives),
``geometry`` (pose, screws, foot boxes, CoP projection), ``qp`` (the per-frame QP core),
``nested`` (the thesis's reference form), ``smoothing`` (the temporal prior), ``estimator``
(:func:`estimate_contact_wrenches`), ``lateral`` (the total's lateral force from the centre of mass
low-passed across the walk), ``trial`` (filter, schedule, :func:`estimate_capture`).
"""

from solver.contact.common import (
    COP_MIN_FZ,
    DEFAULT_FRICTION,
    DEFAULT_PENETRATION,
    DEFAULT_REGULARIZATION,
    METHODS,
    ContactError,
    ContactEstimate,
    Status,
    Support,
    cop_and_free_moment,
)
from solver.contact.estimator import estimate_contact_wrenches
from solver.contact.trial import (
    CONTACT_SOURCES,
    DEFAULT_CUTOFF_HZ,
    DEFAULT_LATERAL_HZ,
    TrialEstimate,
    estimate_capture,
    foot_schedule,
    lowpass_kinematics,
)

__all__ = [
    "CONTACT_SOURCES",
    "COP_MIN_FZ",
    "DEFAULT_CUTOFF_HZ",
    "DEFAULT_FRICTION",
    "DEFAULT_LATERAL_HZ",
    "DEFAULT_PENETRATION",
    "DEFAULT_REGULARIZATION",
    "METHODS",
    "ContactError",
    "ContactEstimate",
    "Status",
    "Support",
    "TrialEstimate",
    "cop_and_free_moment",
    "estimate_capture",
    "estimate_contact_wrenches",
    "foot_schedule",
    "lowpass_kinematics",
]
