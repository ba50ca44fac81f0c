"""Naturalness checks: the features of a human walk that physics alone does not impose.

A motion can satisfy every equation of motion and still not look like a walk: a swing foot
skimming the floor, a foot standing on its toe tip under the body's weight, a turn taken in
the hips at their limits, the load jumping from one foot to the other. Each check here is a
figure with its limit and the published source of the limit (``SOURCES``); every check runs
on the captured walk too (``gait_figures`` of the capture, with its force plates where it has
them), so a result is judged against its own capture and against the published ranges for
its environment.

Nothing here shares the optimizer's transcription: heights, speeds and angles are read from
the frames' forward kinematics (speeds by central differences between the frames), loads
from the stored ground reactions (or the plates).

Failures (a λ optimum breaking one is rejected by the continuation, like an unrealistic one)
are what an observer sees at once and what people do not do: a foot dragging (trip), a toe
tip carrying the weight, a joint jammed at its limit, a loaded foot across the body's
midline, the load jumping between the feet, a level walk braking and pushing twice as hard
as people do, the trunk leaning back going uphill, a walk using all the friction there is.
Warnings are figures where gait varies between people and environments (force shape, lateral
force, push toward the centre of mass, pelvis ranges, foot heading). Step widths are reported
as figures (``step_width_m``), not judged: crossover is the failure they lead to.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np

from solver.checks import Check, Context, SectionResult, register_check
from solver.environment import STANDARD_GRAVITY_VECTOR, Flight, body_weight, ground_of
from solver.jsonable import jsonable
from solver.kinematics import centre_of_mass, contact_points, segment_frames, sole_corners, standing_leg_length
from solver.motion import FEET, Motion, foot_schedule_of
from solver.stairs import flight_of


@dataclass(frozen=True)
class NaturalnessLimits:
    """Limits of the naturalness checks (BW = body weight). Sources: ``SOURCES``.

    Each limit lies outside what people do by a margin an optimum has no reason to reach: the
    optimizer costs each feature toward the capture's own figure (``solver.spacetime``), and its
    hard bounds, safety nets only, lie beyond these limits or at the model's."""

    clearance_m: float = 0.009  # mid-swing: heel, toe and sole at least this above the ground (people: 13 ± 4 mm)
    moving_speed: float = 1.0  # m/s: a swing point faster than this is in mid-swing (not lifting off or landing)
    #: the frames of a swing next to its lift-off and its touchdown are not mid-swing: there the foot
    #: leaves or meets the ground (its height goes to zero by definition), whatever its speed; Winter's
    #: minimum toe clearance is the trough of mid-swing
    swing_edge_frames: int = 1
    pitch_load: float = 0.5  # BW: a foot carrying more than this ...
    pitch_deg: float = 40.0  # ... is pitched (heel up or toe up) at most this
    limit_band_deg: float = 3.0  # a coordinate within this of its model limit is "at" it
    limit_frames: int = 1  # frames a coordinate may spend at a limit in a cycle
    joint_speed_deg_s: float = 450.0  # a joint coordinate's change between two frames, per second
    crossover_m: float = 0.03  # a loaded foot at most this far on the far side of the pelvis
    crossover_load: float = 0.1  # BW: "loaded"
    shared_load: float = 0.1  # BW: both feet carry at least this at some frame of a change of support
    fore_aft: float = 0.35  # BW per foot on level ground
    #: BW: a fore-aft force changes sign when it crosses ±this (mid-stance, where the force crosses zero
    #: slowly, a walk at 15 frames/s wiggles by a few hundredths: the issue is braking again after
    #: propelling, 0.1-0.2 BW each way)
    fore_aft_band: float = 0.05
    fore_aft_changes: int = 1  # braking → propulsion: sign changes per stance, level ground
    fore_aft_load: float = 0.1  # BW: a foot carrying less neither brakes nor propels (heel strike, toe-off)
    lateral: float = 0.15  # BW per foot on level ground (warning)
    lean_tol_deg: float = 2.0  # slopes: trunk lean against gravity vs the tutor's
    level_deg: float = 1.0  # ground within this of level (gravity direction), and no stairs, is "level ground"
    pelvis_pitch_range_deg: float = 12.0  # warnings: ranges over the cycle (yaw: about the heading's trend)
    pelvis_roll_range_deg: float = 20.0
    pelvis_yaw_range_deg: float = 25.0
    foot_heading_deg: float = 35.0  # warning: a loaded foot's heading off the pelvis's
    friction_use: float = 0.9  # required friction at most this fraction of μ (loaded feet)
    friction_load: float = 0.2  # BW: "loaded" for the friction margin
    peak_vertical: float = 1.5  # BW per foot on level ground (warning)
    push: float = -0.05  # warning: a loaded foot's horizontal force along foot → centre of mass ≥ this × f_z × leg
    hump: float = 0.03  # BW: a loading peak / push-off peak stands this above the mid-stance valley
    #: the capture's plates show a mid-stance valley when its peaks stand this far above it (BW): the
    #: motion's valley (``hump``) is then a failure, not a warning
    plates_hump: float = 0.1
    fit_marker_rms_mm: float = 20.0  # the capture's fit: marker RMS at most this (a broken fit is no reference)
    #: stairs: a swinging sole corner clears every nosing it passes by this (m, along the spline)
    nosing_clearance_m: float = 0.02
    #: stairs: a stance sole's corner stands at most this far over its tread's nosing ...
    tread_overhang_m: float = 0.02
    #: ... and at most this far into the riser of the tread above (a foot inside the step)
    tread_riser_m: float = 0.005
    #: stairs: spline samples per frame interval the nosing clearance is measured on
    stairs_swing_samples: int = 20


#: stairs: the published peak swing flexion (deg) of the knee and the hip, going up and down
#: (``SOURCES["stairs_swing"]``): the stairs_swing warnings compare a walk's peaks with the lower ends
STAIRS_SWING = {"up": {"knee": (90.0, 100.0), "hip": (55.0, 65.0)},
                "down": {"knee": (85.0, 100.0), "hip": (25.0, 40.0)}}


#: where each limit comes from. "This project's" marks a limit the literature does not give as a
#: number; docs/naturalness.md lists what each source reports and what the shared trials' own
#: captures and force plates show.
SOURCES = {
    "swing_clearance": "Winter 1992, Phys Ther 72:45 (minimum toe clearance in swing 1.29 cm, variability ~4 mm); "
                       "Begg et al. 2007, Gait Posture 25:191 (minimum foot clearance of young and elderly walkers); "
                       "9 mm is 13 mm less one standard deviation",
    "foot_pitch_under_load": "Perry & Burnfield, Gait Analysis (the heel rises in terminal stance, after mid-stance "
                             "has carried the weight on a flat foot; at heel strike the foot is ~20° toe-up and "
                             "lowers within 0.1 s as the load comes on); 40° either way at 0.5 BW is this "
                             "project's limit",
    "joint_limits": "the model's own joint limits (walking does not hold a joint at the end of its range)",
    "joint_speed": "Winter, Biomechanics and Motor Control of Human Movement (the fastest joint in walking, the knee "
                   "at toe-off and the ankle at push-off, turns at ~300-400°/s); a joint flapping between frames "
                   "is faster",
    "crossover": "Donelan, Kram & Kuo 2001, Proc R Soc B 268:1985 (preferred step width 0.13 leg lengths); "
                 "Taylor, Dabnichki & Strike 2005, Hum Mov Sci 24:558 (step turns keep a wide base of support)",
    "shared_load": "Perry & Burnfield; Kirtley, Clinical Gait Analysis (double support ~10-12 % of the cycle at "
                   "each change of support, both feet loaded)",
    "fore_aft_force": "Winter, Biomechanics and Motor Control of Human Movement (fore-aft peaks ~±0.2 BW at "
                      "natural speed); the shared trials' force plates: -0.22 to +0.28 BW",
    "fore_aft_pattern": "Winter; Kirtley (level walking: each stance brakes, then propels, the force crossing zero "
                        "once near mid-stance)",
    "fit_quality": "AddBiomechanics (Werling et al. 2023: marker RMS under 2 cm); OpenSim's best practice (marker "
                   "errors 1-2 cm): a capture fitted worse is no reference for a walk",
    "lateral_force": "Winter; Kirtley (mediolateral force ≲ 0.1 BW); the shared trials' force plates: ≤ 0.12 BW",
    "vertical_force_shape": "Kirtley (a loading peak ~20 % above body weight, a mid-stance valley below it); Keller "
                            "et al. 1996, Clin Biomech 11:253 (~1.2 BW peaks in walking)",
    "trunk_lean": "Prentice et al. 2004, Gait Posture 20:255 (the trunk pitches forward onto an uphill ramp); "
                  "Leroux, Fung & Barbeau 2002, Gait Posture 15:64 (postural adaptation to inclines)",
    "pelvis_ranges": "Perry & Burnfield; Kirtley (pelvic tilt, obliquity and rotation of a few degrees to ~10° in "
                     "level walking); the limit is also the capture's own range + 5°",
    "foot_heading": "Taylor, Dabnichki & Strike 2005; Glaister et al. 2007, Gait Posture 25:289 (turns by "
                    "stance-foot pivot and foot placement); 35° is this project's warning threshold",
    "friction_margin": "a slope needs at least tan(slope) of friction on average, and a walk that needs all of μ "
                       "slips at the slightest disturbance; the 10 % margin is this project's",
    "nosing_clearance": "Hamel, Okita, Higginson & Cavanagh 2005, Gait Posture 21:135 (foot clearance over stair "
                        "edges in descent); McFadyen & Winter 1988, J Biomech 21:733 (in ascent the swing leg "
                        "lifts the foot over the next step's edge); a toe or heel catching a nosing is the usual "
                        "stair trip; 2 cm is this project's margin",
    "stance_on_tread": "building codes' going (0.25-0.30 m: a foot fits on a tread); Riener, Rabuffetti & Frigo "
                       "2002, Gait Posture 15:32 (the forefoot lands first on the tread, up and down); a sole "
                       "corner 2 cm over the nosing or into the riser above is this project's limit",
    "stairs_swing": "McFadyen & Winter 1988, J Biomech 21:733 and Riener, Rabuffetti & Frigo 2002, Gait Posture "
                    "15:32 (step-over-step stairs of ~0.17 m rise, ~0.28 m going): peak swing knee flexion "
                    "~90-100° going up, ~85-100° going down; peak hip flexion ~55-65° going up, ~25-40° going down "
                    "(the ranges over the inclinations and subjects, read from their figures)",
    "push": "a walking leg pushes the body: its ground reaction points from the foot toward the centre of mass "
            "(the shared trials' force plates: ≥ -0.01 f_z × leg at every loaded frame)",
}


# --- geometry of a walk -------------------------------------------------------------------------


#: the corners of a drawn sole, in order (``sole_corners``)
CORNERS = ("heel-right", "heel-left", "toe-right", "toe-left")


def trunk_axis(character) -> tuple[str, np.ndarray]:
    """(segment, unit axis in its frame) whose lean against gravity is the trunk's: the thorax's
    bone; without a trunk segment (HalfBoy, whose pelvis carries the head, arms and trunk), the
    line from the pelvis's origin to its centre of mass."""
    names = [s.name for s in character.segments]
    trunk = next((s for s in ("thorax", "abdomen") if s in names), names[0])
    seg = character.segments[names.index(trunk)]
    local = np.asarray(seg.direction if trunk != names[0] or np.linalg.norm(seg.com) < 1e-6 else seg.com,
                       dtype=float)
    return trunk, local / np.linalg.norm(local)


def path_heading(q: np.ndarray, N: int) -> np.ndarray:
    """(T,) the direction of travel at each frame of a cycle of N distinct frames: the chord of the
    pelvis path over the cycle (frame 0 to frame N), turned uniformly by the cycle's heading
    change (a walk along a circular arc turns its direction of travel at a constant rate). Unlike
    the pelvis's own yaw it does not swing with the pelvis's rotation within a step."""
    q = np.asarray(q, dtype=float)
    T = q.shape[1]
    chord = q[:2, N] - q[:2, 0]
    dpsi = float(q[3, N] - q[3, 0])
    mid = math.atan2(chord[1], chord[0]) if np.linalg.norm(chord) > 1e-6 else float(np.mean(q[3, :N]))
    return mid + dpsi * (np.arange(T) - 0.5 * N) / N


def _central_differences(x: np.ndarray, dt: float) -> np.ndarray:
    """Central differences along the last axis (ends: one-sided)."""
    out = np.empty_like(x)
    out[..., 1:-1] = (x[..., 2:] - x[..., :-2]) / (2 * dt)
    out[..., 0] = (x[..., 1] - x[..., 0]) / dt
    out[..., -1] = (x[..., -1] - x[..., -2]) / dt
    return out


def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[(start, end)] of the runs of True in a cyclic mask (end exclusive, may exceed len)."""
    n = len(mask)
    if mask.all():
        return [(0, n)]
    if not mask.any():
        return []
    k0 = int(np.flatnonzero(~mask)[0])
    out, t = [], k0
    while t < k0 + n:
        if mask[t % n]:
            a = t
            while t < k0 + n and mask[t % n]:
                t += 1
            out.append((a, t))
        else:
            t += 1
    return out


@dataclass(frozen=True, eq=False)
class _Walk:
    """The quantities of a walk every figure reads (frames, feet, directions, loads)."""

    character: Any
    q: np.ndarray  # (n, T)
    T: int
    N: int  # distinct frames of the cycle
    dt: float
    up: np.ndarray  # (3,) against gravity
    weight: float
    B: np.ndarray  # (2, T) feet in contact
    ground: np.ndarray  # (2, T) ground height under each foot
    contacts_xyz: np.ndarray  # (P, 3, T)
    soles: np.ndarray  # (2, 4, 3, T)
    fwd: np.ndarray  # (3, T) the direction of travel
    left: np.ndarray  # (3, T)
    forces: np.ndarray | None  # (2, 3, T) N, NaN where unknown
    fz: np.ndarray | None  # (2, T) BW

    @property
    def distinct(self) -> np.ndarray:
        return np.arange(self.N)

    def foot_points(self, side: str) -> list[int]:
        return [j for j, c in enumerate(self.character.contacts) if c.side == side]

    def loaded(self, threshold: float) -> np.ndarray:
        """(2, T) feet carrying more than ``threshold`` BW (in contact, without forces)."""
        return self.B.copy() if self.fz is None else np.nan_to_num(self.fz, nan=0.0) > threshold


def _clearance(w: _Walk, lim: NaturalnessLimits) -> dict[str, Any]:
    """Lowest heel, toe or sole corner of a foot in mid-swing — a swing frame more than
    ``swing_edge_frames`` from the foot's lift-off and touchdown — moving faster than
    ``moving_speed`` (speeds by central differences), at the interior frames."""
    worst: dict[str, Any] | None = None
    below = 0
    for k, side in enumerate(FEET):
        idx = w.foot_points(side)
        pts = np.concatenate([w.contacts_xyz[idx], w.soles[k]], axis=0)  # (6, 3, T)
        labels = [w.character.contacts[j].name for j in idx] + [f"sole {c}" for c in CORNERS]
        h = pts[:, 2] - w.ground[k]
        v = np.linalg.norm(_central_differences(pts[:, :2], w.dt), axis=1)  # (6, T)
        e = lim.swing_edge_frames
        for t in range(1, w.T - 1):
            moving = v[:, t] > lim.moving_speed
            if w.B[k, max(t - e, 0):t + e + 1].any() or not moving.any():
                continue
            hm = np.where(moving, h[:, t], np.inf)
            i = int(np.argmin(hm))
            below += int(hm[i] < lim.clearance_m)
            if worst is None or hm[i] < worst["value"]:
                worst = {"value": float(hm[i]), "foot": side, "point": labels[i], "frame": int(t),
                         "speed_m_s": float(v[i, t])}
    return {"min_m": None if worst is None else worst["value"], "worst": worst, "frames_below_limit": below}


def _foot_pitch(w: _Walk, lim: NaturalnessLimits) -> tuple[np.ndarray, dict[str, Any] | None]:
    """(2, T) each foot's heel-up pitch (deg: the heel–toe line's elevation against the ground;
    negative: toe up), and the largest pitch either way of a foot carrying more than
    ``pitch_load`` BW (None without forces)."""
    pitch = np.zeros((2, w.T))
    for k, side in enumerate(FEET):
        heel, toe = w.character.sole_indices(side)
        d = w.contacts_xyz[toe] - w.contacts_xyz[heel]
        pitch[k] = np.degrees(np.arctan2(-d[2], np.linalg.norm(d[:2], axis=0)))
    if w.fz is None:
        return pitch, None
    sel = w.loaded(lim.pitch_load)[:, w.distinct]
    if not sel.any():
        return pitch, {"max_deg": None, "at": None}
    pv = np.abs(pitch[:, w.distinct])
    k, t = np.argwhere(sel)[np.argmax(pv[sel])]
    return pitch, {"max_deg": float(pv[k, t]), "at": {"foot": FEET[k], "frame": int(t), "load_bw": float(w.fz[k, t]),
                                                      "pitch_deg": float(pitch[k, t]),
                                                      "way": "heel up" if pitch[k, t] >= 0 else "toe up"}}


#: a hinge whose model range is at most this is not judged (nor kept off) at its limits: its whole
#: range is a few degrees, so it is as good as locked
MIN_LIMITED_RANGE_DEG = 8.0


def limited_coordinates(character) -> np.ndarray:
    """(n,) the joint coordinates whose limits a natural walk keeps off: hinges (the root's six
    and slides excluded) with finite limits more than ``MIN_LIMITED_RANGE_DEG`` apart. The
    optimizer bounds these inside their limits; ``joint_limits`` checks them."""
    lo, hi = np.asarray(character.lower, dtype=float), np.asarray(character.upper, dtype=float)
    kinds = np.array(character.dof_kinds)
    with np.errstate(invalid="ignore"):
        ok = (kinds == "hinge") & np.isfinite(lo) & np.isfinite(hi) & (hi - lo > math.radians(MIN_LIMITED_RANGE_DEG))
    ok[:6] = False
    return ok


def _joint_limits(w: _Walk, lim: NaturalnessLimits) -> dict[str, Any]:
    """Frames each limited joint coordinate (``limited_coordinates``) spends within
    ``limit_band_deg`` of its model limit."""
    band = math.radians(lim.limit_band_deg)
    lo, hi = w.character.lower, w.character.upper
    frames: dict[str, int] = {}
    limited = limited_coordinates(w.character)
    for i, name in enumerate(w.character.coordinate_names):
        if not limited[i]:
            continue
        x = w.q[i, : w.N]
        n_at = int(np.sum((x <= lo[i] + band) | (x >= hi[i] - band)))
        if n_at:
            frames[name] = n_at
    worst = max(frames, key=lambda k: frames[k]) if frames else None
    return {"frames": frames, "max_frames": frames[worst] if worst else 0, "worst": worst}


def _joint_speed(w: _Walk) -> dict[str, Any]:
    """The fastest change of a joint coordinate (hinges, the root's six excluded) between two
    consecutive frames of the cycle, in degrees per second: a joint flapping between frames."""
    kinds = np.array(w.character.dof_kinds)
    hinge = kinds == "hinge"
    hinge[:6] = False
    if not hinge.any():
        return {"max_deg_s": None, "worst": None}
    dq = np.degrees(np.abs(np.diff(w.q[:, : w.N + 1], axis=1))) / w.dt  # (n, N): frame k -> k+1
    dq[~hinge] = 0.0
    i, t = np.unravel_index(int(np.argmax(dq)), dq.shape)
    return {"max_deg_s": float(dq[i, t]), "worst": {"coordinate": w.character.coordinate_names[i], "frame": int(t)}}


def _placement(w: _Walk, lim: NaturalnessLimits) -> dict[str, Any]:
    """Where the feet stand against the pelvis and the direction of travel: how far a loaded
    foot stands on the far side of the pelvis — across the direction of travel and across the
    pelvis's own heading (a turn taken in the pelvis puts the inner foot on the path line) —, the
    step width at each touch-down, and a loaded foot's heading against the pelvis's."""
    centre = np.stack([w.contacts_xyz[w.foot_points(s)].mean(axis=0) for s in FEET])  # (2, 3, T)
    sel = w.loaded(lim.crossover_load)[:, w.distinct]
    rots, _ = segment_frames(w.character, w.q)
    yaw = np.arctan2(rots[0, 1, 0], rots[0, 0, 0])  # the pelvis's heading
    pelvis_left = np.stack([-np.sin(yaw), np.cos(yaw), np.zeros(w.T)])

    def far_side(left: np.ndarray) -> float | None:
        lateral = np.einsum("kit,it->kt", centre - w.q[None, :3], left)  # + to the left of the pelvis
        far = np.stack([lateral[0], -lateral[1]])[:, w.distinct]  # the right foot's far side is its left
        return float(far[sel].max()) if sel.any() else None

    widths = [float(abs(np.dot(centre[k, :, a % w.N] - centre[1 - k, :, a % w.N], w.left[:, a % w.N])))
              for k in range(2) for a, _ in _runs(w.B[k, : w.N]) if w.B[1 - k, a % w.N]]
    heading = np.zeros((2, w.T))
    for k, side in enumerate(FEET):
        heel, toe = w.character.sole_indices(side)
        d = w.contacts_xyz[toe, :2] - w.contacts_xyz[heel, :2]
        heading[k] = np.degrees(np.angle(np.exp(1j * (np.arctan2(d[1], d[0]) - yaw))))
    path, pelvis = far_side(w.left), far_side(pelvis_left)
    both = [v for v in (path, pelvis) if v is not None]
    return {
        "crossover": {"max_far_side_m": max(both) if both else None, "across_path_m": path,
                      "across_pelvis_m": pelvis},
        "step_width_m": widths,
        "foot_heading_deg": {"max_abs_loaded": float(np.abs(heading[:, w.distinct][sel]).max()) if sel.any()
                             else None},
    }


def _posture(w: _Walk, cyclic: bool) -> dict[str, Any]:
    """The pelvis's ranges over the cycle (yaw about the trend of the cycle's heading change) and
    the trunk's lean against gravity in the sagittal plane of the direction of travel; the
    ground's slope along the cycle's travel (+ uphill) and tilt, from gravity."""
    ch, q, N = w.character, w.q, w.N
    rots, _ = segment_frames(ch, q)
    names = [s.name for s in ch.segments]
    R = rots[0]  # the root segment (pelvis)
    yaw = np.unwrap(np.arctan2(R[1, 0], R[0, 0]))
    pitch = np.degrees(np.arcsin(np.clip(-R[2, 0], -1, 1)))
    roll = np.degrees(np.arctan2(R[2, 1], R[2, 2]))
    ys = np.degrees(yaw[:N])
    trend = (ys[0] + np.degrees(yaw[N] - yaw[0]) * np.arange(N) / N if cyclic
             else np.polyval(np.polyfit(np.arange(N), ys, 1), np.arange(N)))
    trunk, local = trunk_axis(ch)
    axis = np.einsum("ijt,j->it", rots[names.index(trunk)], local)
    f_perp = w.fwd - np.outer(w.up, w.up @ w.fwd)
    f_perp /= np.linalg.norm(f_perp, axis=0, keepdims=True)
    lean = np.degrees(np.arctan2(np.einsum("it,it->t", axis, f_perp), w.up @ axis))[:N]
    travel = q[:2, N] - q[:2, 0] if cyclic else q[:2, -1] - q[:2, 0]
    dirn = np.r_[travel / max(float(np.linalg.norm(travel)), 1e-9), 0.0]
    return {
        "pelvis_range_deg": {"pitch": float(np.ptp(pitch[:N])), "roll": float(np.ptp(roll[:N])),
                             "yaw": float(np.ptp(ys - trend))},
        "trunk_lean_deg": {"segment": trunk, "mean": float(lean.mean()), "range": float(np.ptp(lean))},
        "slope_along_deg": float(np.degrees(np.arcsin(np.clip(w.up @ dirn, -1.0, 1.0)))),
        "tilt_deg": float(np.degrees(np.arccos(np.clip(w.up[2], -1.0, 1.0)))),
        "stairs": bool(np.ptp(w.ground) > 1e-9),  # the ground under the feet is not one plane
    }


def _loads(w: _Walk, lim: NaturalnessLimits, mu: float) -> dict[str, Any]:
    """Figures of the ground reactions: per-foot extremes (BW; fore-aft along the direction of
    travel), the load both feet share at each change of support, the vertical force's shape over
    each stance, the friction the loaded feet need, and how the horizontal force points against
    the centre of mass."""
    assert w.forces is not None and w.fz is not None  # the caller checks
    F, fz, N = w.forces, w.fz, w.N
    fa = np.einsum("kit,it->kt", F, w.fwd)[:, :N] / w.weight
    ml = np.einsum("kit,it->kt", F, w.left)[:, :N] / w.weight
    known = np.all(np.isfinite(F), axis=1)[:, :N]

    def extreme(x: np.ndarray, fn: Any) -> float | None:
        xv = x[known]
        return float(fn(xv)) if xv.size else None

    shares: list[dict[str, Any]] = []
    for k in range(2):
        for a, _ in _runs(w.B[k, :N]):
            ds = [t % N for t in range(a, a + N) if w.B[k, t % N] and w.B[1 - k, t % N]]
            ds = ds[: next((i for i in range(1, len(ds)) if ds[i] != (ds[i - 1] + 1) % N), len(ds))]
            both = np.minimum(fz[0, ds], fz[1, ds]) if ds and ds[0] == a % N else np.zeros(1)
            if np.all(np.isnan(both)):
                continue
            shares.append({"touch_down": FEET[k], "frame": int(a % N), "double_support_frames": len(ds),
                           "shared_bw": float(np.nanmax(both))})
    shapes = []
    for k in range(2):
        for a, b in _runs(w.B[k, :N]):
            x = fz[k, [t % N for t in range(a, b)]]
            n = len(x)
            if n < 6 or np.any(np.isnan(x)):
                continue
            mid = x[int(0.25 * n): max(int(0.25 * n) + 1, math.ceil(0.75 * n))]
            shapes.append({"foot": FEET[k], "frames": n, "loading_peak_bw": float(np.max(x[: max(2, int(0.45 * n))])),
                           "valley_bw": float(np.min(mid)), "push_off_peak_bw": float(np.max(x[int(0.55 * n):]))})
    patterns: list[dict[str, Any]] = []
    for k in range(2):
        for a, b in _runs(w.B[k, :N]):
            frames = [t % N for t in range(a, b)]
            x = fa[k, frames]
            if np.any(np.isnan(x)):
                continue
            x = np.where(fz[k, frames] > lim.fore_aft_load, x, 0.0)  # a foot barely touching neither brakes nor propels
            state, changes = 0, 0  # −1 braking, +1 propelling: a change crosses the whole ±band
            for v in x:
                now = 1 if v > lim.fore_aft_band else -1 if v < -lim.fore_aft_band else 0
                if now and state and now != state:
                    changes += 1
                state = now or state
            patterns.append({"foot": FEET[k], "frames": int(b - a), "sign_changes": changes,
                             "braking_bw": float(min(x.min(), 0.0)), "propulsion_bw": float(max(x.max(), 0.0))})
    loaded = w.loaded(lim.friction_load)[:, :N]
    with np.errstate(invalid="ignore", divide="ignore"):
        rcof = np.linalg.norm(F[:, :2], axis=1)[:, :N] / F[:, 2, :N]
        com = centre_of_mass(w.character, w.q)
        leg = standing_leg_length(w.character)
        centre = np.stack([w.contacts_xyz[w.foot_points(s)].mean(axis=0) for s in FEET])
        push = np.einsum("kit,kit->kt", F[:, :2], (com[None] - centre)[:, :2])[:, :N] / (F[:, 2, :N] * leg)
    return {
        "forces_bw": {"fore_aft_max_abs": extreme(np.abs(fa), np.max), "fore_aft_min": extreme(fa, np.min),
                      "fore_aft_max": extreme(fa, np.max), "lateral_max_abs": extreme(np.abs(ml), np.max),
                      "vertical_max": extreme(fz[:, :N], np.max)},
        "shared_load": {"changes": shares, "min_bw": min((float(c["shared_bw"]) for c in shares), default=None)},
        "vertical_force_shape": shapes,
        "fore_aft_pattern": {"stances": patterns,
                             "max_sign_changes": max((int(p["sign_changes"]) for p in patterns), default=None)},
        "required_friction": {"max": float(np.nanmax(np.where(loaded, rcof, 0.0))), "mu": float(mu)},
        "push": {"min": float(np.nanmin(np.where(loaded, push, np.inf))) if loaded.any() else None},
    }


def _stairs(w: _Walk, flight: Flight, fps: float, lim: NaturalnessLimits) -> dict[str, Any]:
    """Stairs figures: the least clearance of a swinging sole corner over the nosings it passes
    (along the spline between the frames: the height above a nosing where the corner crosses its
    riser's plane; negative: the corner went through the riser), how far a stance sole stands over
    its nosing or into the riser above, and the peak knee and hip flexion of each swing."""
    from solver.trajectory import sample

    ch, q, N = w.character, w.q, w.N
    sgn = 1.0 if flight.rise > 0 else -1.0
    g = flight.going
    # stance: each corner against its tread's edges (nosing side: the lower tread's; riser: the higher's)
    over, into, worst_tread = -math.inf, -math.inf, None
    for k, side in enumerate(FEET):
        for t in range(N):
            if not w.B[k, t]:
                continue
            j = int(flight.left[k, t])
            s_c = flight.along(w.soles[k, :, :2, t].T)  # (4,)
            back, front = j * g - s_c.min(), s_c.max() - (j + 1) * g  # > 0: beyond the edge
            o_, i_ = (back, front) if sgn > 0 else (front, back)
            if o_ > over or i_ > into:
                worst_tread = {"foot": side, "frame": t, "tread": j, "over_nosing_m": float(o_),
                               "into_riser_m": float(i_)}
            over, into = max(over, o_), max(into, i_)
    # swing: corners along the spline, against the nosings between the tread left and the tread reached
    n_sub = max(int(lim.stairs_swing_samples), 2)
    turn = float(q[3, N] - q[3, 0])
    R = np.array([[math.cos(turn), -math.sin(turn)], [math.sin(turn), math.cos(turn)]])
    shift = q[:2, N] - R @ q[:2, 0]
    rise = float(q[2, N] - q[2, 0])
    clear, worst = math.inf, None
    knee = {side: f"knee_angle_{side[0]}" for side in FEET}
    hip = {side: f"hip_flexion_{side[0]}" for side in FEET}
    names = list(ch.coordinate_names)
    peaks: list[dict[str, Any]] = []
    for k, side in enumerate(FEET):
        for a, b in _runs(~w.B[k, :N]):
            times = np.linspace(a - 1, b, (b + 1 - a) * n_sub + 1) * w.dt  # lift-off to touch-down
            times = np.where(times < 0, times + N * w.dt, times)  # frame −1 is frame N−1
            c_, u = np.divmod(times, N * w.dt)  # a swing past the cycle's end: the next cycle's frames
            qs = sample(q, fps, u, cyclic=True, interpolation="cubic-spline")
            for j_ in np.flatnonzero(c_ > 0):
                qs[:2, j_] = R @ qs[:2, j_] + shift
                qs[3, j_] += turn
                qs[2, j_] += rise
            corners = sole_corners(ch, qs)[k]  # (4, 3, S)
            s_c = flight.along(np.moveaxis(corners[:, :2], 1, 0))  # (4, S)
            z = corners[:, 2]
            lo, hi = int(flight.left[k, a % N]), int(flight.reached[k, a % N])
            for kk in range(min(lo, hi), max(lo, hi) + 2):  # the risers behind, crossed and ahead
                s_i, h_i = (float(x) for x in flight.nosing(kk))
                past = sgn * (s_c - s_i)  # > 0: on the higher tread's side of the riser plane
                for ci in range(4):
                    vals = []
                    for i in range(len(times) - 1):
                        if (past[ci, i] <= 0) != (past[ci, i + 1] <= 0):
                            f = past[ci, i] / (past[ci, i] - past[ci, i + 1])
                            vals.append(float(z[ci, i] + f * (z[ci, i + 1] - z[ci, i]) - h_i))
                    if vals and min(vals) < clear:
                        clear = min(vals)
                        worst = {"foot": side, "corner": CORNERS[ci], "nosing": kk, "swing_frames": [a, b - 1]}
            pk: dict[str, Any] = {"foot": side, "frames": [int(a), int(b - 1)]}
            for label, coord in (("knee_deg", knee[side]), ("hip_deg", hip[side])):
                if coord in names:
                    pk[label] = float(np.degrees(qs[names.index(coord)].max()))
            peaks.append(pk)
    knees = [p_["knee_deg"] for p_ in peaks if "knee_deg" in p_]
    hips = [p_["hip_deg"] for p_ in peaks if "hip_deg" in p_]
    return {
        "rise_m": float(flight.rise), "going_m": float(g), "direction": "up" if sgn > 0 else "down",
        "nosing_clearance": {"min_m": None if worst is None else float(clear), "worst": worst},
        "tread": {"max_over_nosing_m": None if worst_tread is None else float(over),
                  "max_into_riser_m": None if worst_tread is None else float(into), "worst": worst_tread},
        "swing_peaks": {"swings": peaks, "knee_min_deg": min(knees) if knees else None,
                        "hip_min_deg": min(hips) if hips else None},
    }


def gait_figures(character, q: np.ndarray, fps: float, contacts: np.ndarray, *, forces: np.ndarray | None = None,
                 gravity=STANDARD_GRAVITY_VECTOR, mu: float = 1.0, weight: float | None = None,
                 ground: np.ndarray | None = None, cyclic: bool = True,
                 lim: NaturalnessLimits = NaturalnessLimits(), flight: Flight | None = None) -> dict[str, Any]:
    """The figures of a walk's naturalness checks.

    ``q`` (n, T) frames of one gait cycle (with the two overlap frames when ``cyclic``),
    ``contacts`` (P, T), ``forces`` (2, 3, T) each foot's ground reaction force in the world
    frame (NaN where unknown: incomplete plates) or None (kinematic figures only), ``ground``
    (2, T) the ground height under each foot (stairs), ``flight`` the stairs' geometry
    (``solver.stairs.flight_of``: nosings and treads). Figures are taken over the cycle's
    distinct frames (0 .. T−3 for a cycle)."""
    q = np.asarray(q, dtype=float)
    T = q.shape[1]
    N = T - 2 if cyclic else T
    g = np.asarray(gravity, dtype=float)
    W = float(weight if weight is not None else character.total_mass * np.linalg.norm(g))
    path = path_heading(q, N) if cyclic else np.full(T, math.atan2(q[1, -1] - q[1, 0], q[0, -1] - q[0, 0]))
    F = None if forces is None else np.asarray(forces, dtype=float)
    w = _Walk(character=character, q=q, T=T, N=N, dt=1.0 / fps, up=-g / max(float(np.linalg.norm(g)), 1e-12),
              weight=W, B=foot_schedule_of(character, np.asarray(contacts, dtype=bool)),
              ground=np.zeros((2, T)) if ground is None else np.asarray(ground, dtype=float),
              contacts_xyz=np.asarray(contact_points(character, q)), soles=sole_corners(character, q),
              fwd=np.stack([np.cos(path), np.sin(path), np.zeros(T)]),
              left=np.stack([-np.sin(path), np.cos(path), np.zeros(T)]),
              forces=F, fz=None if F is None else F[:, 2] / W)
    pitch, under_load = _foot_pitch(w, lim)
    out: dict[str, Any] = {"frames": int(N), "fps": float(fps), "weight_N": W,
                           "swing_clearance": _clearance(w, lim), "foot_pitch_deg": pitch[:, :N].round(2).tolist(),
                           "joints_at_limits": _joint_limits(w, lim), "joint_speed": _joint_speed(w),
                           **_placement(w, lim), **_posture(w, cyclic)}
    if under_load is not None:
        out["foot_pitch_under_load"] = under_load
        out.update(_loads(w, lim, mu))
    if flight is not None and cyclic:
        out["stairs_geometry"] = _stairs(w, flight, fps, lim)
    return out


# --- the checks -------------------------------------------------------------------------------------


def _get(d: Mapping | None, *keys: str) -> Any:
    for k in keys:
        if not isinstance(d, Mapping):
            return None
        d = d.get(k)
    return d


def checks_of(fig: Mapping[str, Any], *, reference: Mapping[str, Any] | None = None,
              lim: NaturalnessLimits = NaturalnessLimits()) -> dict[str, Check]:
    """The checks (figure, limit, source, the capture's figure) from ``gait_figures``, by name;
    ``reference``: {"capture": figures of the captured walk, "tutor": figures of the tutor}."""
    cap = (reference or {}).get("capture")
    tut = (reference or {}).get("tutor")
    level = fig["tilt_deg"] <= lim.level_deg and not fig.get("stairs")
    checks: list[Check] = []
    fit = (reference or {}).get("fit")
    if isinstance(fit, Mapping) and fit.get("marker_rms_mm") is not None:
        checks.append(Check.measure(
            "fit_quality", fit["marker_rms_mm"], lim.fit_marker_rms_mm, "mm",
            "RMS distance between the capture's markers and the fitted skeleton's (the capture this walk keeps)",
            source=SOURCES["fit_quality"]))
    checks.append(Check.measure(
        "swing_clearance", _get(fig, "swing_clearance", "min_m"), lim.clearance_m, "m",
        f"lowest heel, toe or sole corner of a swing foot moving faster than {lim.moving_speed:g} m/s in mid-swing "
        f"(more than {lim.swing_edge_frames} frame from lift-off and touchdown)",
        source=SOURCES["swing_clearance"], at_least=True, capture=_get(cap, "swing_clearance", "min_m")))
    if "foot_pitch_under_load" in fig:
        checks.append(Check.measure(
            "foot_pitch_under_load", _get(fig, "foot_pitch_under_load", "max_deg"), lim.pitch_deg, "deg",
            f"largest pitch, heel up or toe up, of a foot carrying more than {lim.pitch_load:g} BW",
            source=SOURCES["foot_pitch_under_load"], capture=_get(cap, "foot_pitch_under_load", "max_deg")))
    checks.append(Check.measure(
        "joint_limits", fig["joints_at_limits"]["max_frames"], lim.limit_frames, "frames",
        f"frames a coordinate spends within {lim.limit_band_deg:g}° of its model limit"
        + (f" (worst: {fig['joints_at_limits']['worst']})" if fig["joints_at_limits"]["worst"] else ""),
        source=SOURCES["joint_limits"], capture=_get(cap, "joints_at_limits", "max_frames")))
    js = fig.get("joint_speed") or {}
    checks.append(Check.measure(
        "joint_speed", js.get("max_deg_s"), lim.joint_speed_deg_s, "deg/s",
        "fastest change of a joint coordinate between two frames"
        + (f" (worst: {js['worst']['coordinate']})" if js.get("worst") else ""),
        source=SOURCES["joint_speed"], capture=_get(cap, "joint_speed", "max_deg_s")))
    checks.append(Check.measure(
        "crossover", _get(fig, "crossover", "max_far_side_m"), lim.crossover_m, "m",
        "furthest a loaded foot stands on the far side of the pelvis, across the direction of travel and "
        "across the pelvis's heading", source=SOURCES["crossover"], capture=_get(cap, "crossover", "max_far_side_m")))
    if "shared_load" in fig:
        checks.append(Check.measure(
            "shared_load", _get(fig, "shared_load", "min_bw"), lim.shared_load, "BW",
            "least, over the changes of support, of the load both feet carry at once", source=SOURCES["shared_load"],
            at_least=True, capture=_get(cap, "shared_load", "min_bw")))
    if "forces_bw" in fig:
        checks.append(Check.measure(
            "fore_aft_force", fig["forces_bw"]["fore_aft_max_abs"], lim.fore_aft, "BW",
            "largest fore-aft force of a foot, level ground", source=SOURCES["fore_aft_force"],
            capture=_get(cap, "forces_bw", "fore_aft_max_abs"), applies=level))
        checks.append(Check.measure(
            "lateral_force", fig["forces_bw"]["lateral_max_abs"], lim.lateral, "BW",
            "largest mediolateral force of a foot, level ground", source=SOURCES["lateral_force"], warning=True,
            capture=_get(cap, "forces_bw", "lateral_max_abs"), applies=level))
        checks.append(Check.measure(
            "vertical_force_peak", fig["forces_bw"]["vertical_max"], lim.peak_vertical, "BW",
            "largest vertical force of a foot, level ground",
            source=SOURCES["vertical_force_shape"], warning=True, capture=_get(cap, "forces_bw", "vertical_max"),
            applies=level))
        humps = [min(s["loading_peak_bw"], s["push_off_peak_bw"]) - s["valley_bw"]
                 for s in fig.get("vertical_force_shape") or []]
        cap_humps = [min(s["loading_peak_bw"], s["push_off_peak_bw"]) - s["valley_bw"]
                     for s in (_get(cap, "vertical_force_shape") or [])]
        plates_valley = bool(_get(cap, "plates")) and bool(cap_humps) and min(cap_humps) >= lim.plates_hump
        checks.append(Check.measure(
            "vertical_force_shape", min(humps) if humps else None, lim.hump, "BW",
            "smallest height of a stance's loading or push-off peak above its mid-stance valley, level ground"
            + (" (the capture's plates show the valley)" if plates_valley else ""),
            source=SOURCES["vertical_force_shape"], warning=not plates_valley, at_least=True,
            capture=min(cap_humps) if cap_humps else None, applies=level))
        checks.append(Check.measure(
            "fore_aft_pattern", _get(fig, "fore_aft_pattern", "max_sign_changes"), lim.fore_aft_changes, "changes",
            f"most sign changes of a foot's fore-aft force within one stance (crossing ±{lim.fore_aft_band:g} BW "
            f"while the foot carries over {lim.fore_aft_load:g} BW), level ground", source=SOURCES["fore_aft_pattern"],
            capture=_get(cap, "fore_aft_pattern", "max_sign_changes"), applies=level))
        rf = fig["required_friction"]
        cap_rf = _get(cap, "required_friction", "max")
        checks.append(Check.measure(
            "friction_margin", rf["max"] / rf["mu"], lim.friction_use, "μ",
            f"largest friction a foot loaded over {lim.friction_load:g} BW needs, as a fraction of μ",
            source=SOURCES["friction_margin"], capture=None if cap_rf is None else cap_rf / rf["mu"]))
        checks.append(Check.measure(
            "push", _get(fig, "push", "min"), lim.push, "f_z·leg",
            "least horizontal force of a loaded foot along the line from the foot to the centre of mass",
            source=SOURCES["push"], warning=True, at_least=True, capture=_get(cap, "push", "min")))
    st = fig.get("stairs_geometry")
    if st:
        checks.append(Check.measure(
            "nosing_clearance", _get(st, "nosing_clearance", "min_m"), lim.nosing_clearance_m, "m",
            "least height of a swinging sole corner above a nosing it passes, where it crosses the riser's plane "
            "(along the spline between the frames; negative: through the riser)", source=SOURCES["nosing_clearance"],
            at_least=True))
        checks.append(Check.measure(
            "stance_over_nosing", _get(st, "tread", "max_over_nosing_m"), lim.tread_overhang_m, "m",
            "furthest a stance sole's corner stands beyond its tread's nosing (over the step below)",
            source=SOURCES["stance_on_tread"]))
        checks.append(Check.measure(
            "stance_into_riser", _get(st, "tread", "max_into_riser_m"), lim.tread_riser_m, "m",
            "furthest a stance sole's corner reaches into the riser of the step above its tread",
            source=SOURCES["stance_on_tread"]))
        ref = STAIRS_SWING[st["direction"]]
        for joint in ("knee", "hip"):
            lo_, hi_ = ref[joint]
            checks.append(Check.measure(
                f"stairs_swing_{joint}", _get(st, "swing_peaks", f"{joint}_min_deg"), lo_, "deg",
                f"least, over the swings, of the peak swing {joint} flexion (people going {st['direction']}: "
                f"{lo_:g}-{hi_:g}°)", source=SOURCES["stairs_swing"], warning=True, at_least=True))
    slope = fig["slope_along_deg"]
    lean, tut_lean = fig["trunk_lean_deg"]["mean"], _get(tut, "trunk_lean_deg", "mean")
    if tut_lean is not None and abs(slope) > lim.level_deg:
        back = (tut_lean - lean) if slope > 0 else (lean - tut_lean)  # leaning back uphill, forward downhill
        checks.append(Check.measure(
            "trunk_lean", back, lim.lean_tol_deg, "deg",
            (f"trunk ({fig['trunk_lean_deg']['segment']}) lean against gravity {lean:+.1f}° vs the tutor's "
             f"{tut_lean:+.1f}° on a {slope:+.1f}° slope: degrees further "
             + ("back" if slope > 0 else "forward")), source=SOURCES["trunk_lean"]))
    pr = fig["pelvis_range_deg"]
    cpr = _get(cap, "pelvis_range_deg") or {}
    for ax, limv in (("pitch", lim.pelvis_pitch_range_deg), ("roll", lim.pelvis_roll_range_deg),
                     ("yaw", lim.pelvis_yaw_range_deg)):
        checks.append(Check.measure(f"pelvis_{ax}_range", pr[ax], max(limv, cpr.get(ax, 0.0) + 5.0), "deg",
                                    f"pelvis {ax} range over the cycle"
                                    + (" (about the heading's trend)" if ax == "yaw" else "")
                                    + " (limit: the published range, or the capture's + 5°)",
                                    source=SOURCES["pelvis_ranges"], warning=True, capture=cpr.get(ax)))
    checks.append(Check.measure(
        "foot_heading", _get(fig, "foot_heading_deg", "max_abs_loaded"), lim.foot_heading_deg, "deg",
        "largest heading difference between a loaded foot and the pelvis", source=SOURCES["foot_heading"], warning=True,
        capture=_get(cap, "foot_heading_deg", "max_abs_loaded")))
    return {c.name: c for c in checks}


def motion_figures(motion: Motion, lim: NaturalnessLimits = NaturalnessLimits()) -> dict[str, Any]:
    """``gait_figures`` of a motion (its stored ground reactions, its environment)."""
    env = motion.environment
    if motion.contacts is None:
        raise ValueError("naturalness needs a contact schedule")
    forces = None if motion.wrenches is None else np.asarray(motion.wrenches)[:, 3:6]
    return gait_figures(motion.character, motion.q, motion.fps, motion.contacts, forces=forces, gravity=env.gravity,
                        mu=env.friction, weight=body_weight(motion), ground=ground_of(motion),
                        cyclic=motion.cyclic, lim=lim, flight=flight_of(motion))


def naturalness_report(motion: Motion, reference: Mapping[str, Any] | None = None,
                       lim: NaturalnessLimits = NaturalnessLimits()) -> dict[str, Any]:
    """The naturalness section of the validation report: every check as a figure with its limit,
    its source and the capture's own figure; ``reference`` defaults to the motion's context
    ``gait_reference`` ({"capture": …, "tutor": …} figures). ``passed`` is None when the motion
    cannot be checked (no contact schedule, or feet without a heel and a toe point)."""
    return naturalness_checks(motion, reference, lim).to_dict()


@register_check(section="naturalness", verdict="natural", order=20)
def _naturalness_section(ctx: Context) -> SectionResult:
    return naturalness_checks(ctx.motion)


def naturalness_checks(motion: Motion, reference: Mapping[str, Any] | None = None,
                       lim: NaturalnessLimits = NaturalnessLimits()) -> SectionResult:
    """The naturalness checks of a motion (and the section's limits, notes and figures)."""
    t0 = time.perf_counter()
    out: dict[str, Any] = {"limits": asdict(lim), "notes": []}
    if motion.contacts is None or not motion.character.has_soles:
        out["notes"].append("no contact schedule, or feet without a heel and a toe contact point: "
                            "naturalness not checked")
        out["time_s"] = time.perf_counter() - t0
        return SectionResult((), out, checked=False, unchecked=None)
    if reference is None:
        ref = motion.context.gait_reference
        reference = None if ref is None else ref.to_dict()
    fig = motion_figures(motion, lim)
    checks = checks_of(fig, reference=reference, lim=lim)
    if reference is None or reference.get("capture") is None:
        out["notes"].append("no figures of the captured walk recorded: checked against the published limits only")
    out["figures"] = jsonable(fig)
    out["time_s"] = time.perf_counter() - t0
    return SectionResult(tuple(checks.values()), out)


# --- the captured walk ------------------------------------------------------------------------------


def plate_forces(measured, T: int) -> np.ndarray | None:
    """(2, 3, T) the force plates' per-foot forces on a cycle's frames, NaN where the plates are
    incomplete (``MeasuredGRF.valid`` False); None without plates."""
    if measured is None:
        return None
    F = np.array(measured.force, dtype=float)
    if F.shape != (2, 3, T):
        return None
    F[:, :, ~np.asarray(measured.valid, dtype=bool)] = np.nan
    return F


def capture_figures(character, q: np.ndarray, fps: float, contacts: np.ndarray, measured=None,
                    lim: NaturalnessLimits = NaturalnessLimits()) -> dict[str, Any]:
    """``gait_figures`` of a captured cycle (the capture skeleton, its plates where complete): the
    capture column of every check."""
    fig = gait_figures(character, q, fps, contacts, forces=plate_forces(measured, q.shape[1]), lim=lim)
    fig["plates"] = measured is not None
    return jsonable(fig)


def against_plates(forces: np.ndarray, measured, q: np.ndarray, weight: float) -> dict[str, Any] | None:
    """A motion's per-foot vertical and fore-aft forces against the force plates on the same frames
    (complete plates only): RMS error and peaks, in body weights (fore-aft along the direction of
    travel)."""
    P = plate_forces(measured, q.shape[1])
    if P is None:
        return None
    N = q.shape[1] - 2
    path = path_heading(q, N)
    fwd = np.stack([np.cos(path), np.sin(path), np.zeros(q.shape[1])])
    out: dict[str, Any] = {}
    for k, side in enumerate(FEET):
        ok = np.all(np.isfinite(P[k]), axis=0)
        ok[N:] = False
        if ok.sum() < 3:
            continue
        row: dict[str, Any] = {"frames": int(ok.sum())}
        for name, comp in (("vertical", lambda F: F[2]), ("fore_aft", lambda F: fwd[0] * F[0] + fwd[1] * F[1])):
            a, b = comp(forces[k])[ok] / weight, comp(P[k])[ok] / weight
            row[name] = {"rms_bw": float(np.sqrt(np.mean((a - b) ** 2))), "max_bw": float(a.max()),
                         "min_bw": float(a.min()), "plates_max_bw": float(b.max()), "plates_min_bw": float(b.min())}
        out[side] = row
    return out or None


def joint_rms_deg(character, q: np.ndarray, capture_character, q_capture: np.ndarray,
                  exclude: tuple[str, ...] = ()) -> dict[str, Any]:
    """RMS difference (deg) over the cycle between a motion's joint angles and the capture's own,
    per coordinate the two share (hinges, root excluded) and overall; the pelvis's three rotations
    apart; ``exclude``: coordinates the capture did not measure (still arms given a swing)."""
    N = q.shape[1] - 2
    per: dict[str, float] = {}
    for i, name in enumerate(character.coordinate_names):
        if i < 3 or name not in capture_character.coordinate_names or name in exclude:
            continue
        d = q[i, :N] - q_capture[capture_character.coordinate_names.index(name), :N]
        per[name] = float(np.degrees(np.sqrt(np.mean(d ** 2))))
    joints = [v for k, v in per.items() if not k.startswith("root_")]
    pelvis = [v for k, v in per.items() if k.startswith("root_")]
    return {"overall": float(np.sqrt(np.mean(np.square(joints)))) if joints else None,
            "pelvis": float(np.sqrt(np.mean(np.square(pelvis)))) if pelvis else None, "per_coordinate": per}
