"""The figures of a walk's naturalness checks (``gait_figures``): heights, speeds and angles
from the frames' forward kinematics, loads from the ground reactions.

Each figure is measured over the distinct frames of a cycle: the swing feet's clearance, the
feet's pitch under load, the joints at their limits and their speeds, where the feet stand
against the pelvis, the pelvis's ranges and the trunk's lean, the ground reactions' extremes,
shape and friction, and on stairs the clearance over the nosings, the stance soles on their
treads and the swings' peak flexions. ``solver.naturalness`` turns them into checks.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from solver.environment import STANDARD_GRAVITY_VECTOR, Flight
from solver.kinematics import centre_of_mass, contact_points, segment_frames, sole_corners, standing_leg_length
from solver.motion import FEET, foot_schedule_of
from solver.naturalness_limits import NaturalnessLimits

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

