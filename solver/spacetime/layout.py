"""Variable and parameter packing of the spacetime problem: how motions, wrenches, reference
points and weights map onto the NLP's x and p (a mixin of ``SpacetimeProblem``)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from solver.kinematics import centre_of_mass, contact_points, markers, sole_corners
from solver.motion import FEET, foot_schedule_of
from solver.naturalness import limited_coordinates
from solver.spacetime.frame import CROSS_ROWS
from solver.spacetime.types import STANDARD_GRAVITY, WEIGHT_SLOTS, Environment, Weights

MARKER_SCALE = 0.01  # m: the objective is in units of (1 cm)²
#: time scale of the rate costs (s): the jerk cost is the mean over the cycle of
#: (jerk × RATE_TIME³)², the wrench-change cost that of (wrench rate × RATE_TIME)² and the kinematic
#: fit's smoothness that of (second difference × (RATE_TIME / h)²)², so the same
#: motion costs the same at any frame rate (at 15 frames/s: the per-segment figures as before;
#: with the frame interval h as the scale, 30 frames/s made the jerk 2⁶ = 64, the smoothness
#: 2⁴ = 16 and the wrench change 2² = 4 times cheaper)
RATE_TIME = 1.0 / 15.0


class Layout:
    """Packing and unpacking; expects the attributes ``SpacetimeProblem.__init__`` sets."""

    character: Any
    contacts: Any
    ff: Any
    T: int
    n: int
    dt: float
    dynamics: bool
    nx: int
    nq_vars: int
    nv_vars: int
    n_markers: int
    eom_frames: list[int]
    weight_scale: float
    moment_scale: float
    _q_index: np.ndarray
    _v_index: np.ndarray
    _w_index: np.ndarray
    _lbg_raw: np.ndarray
    _ubg_raw: np.ndarray
    _h_bounds: list[tuple[np.ndarray, Any]]

    def foot_contact(self) -> np.ndarray:
        if self.contacts is None:
            return np.zeros((2, self.T), dtype=bool)
        return foot_schedule_of(self.character, self.contacts)

    def guide_markers(self, guide_q: np.ndarray) -> np.ndarray:
        mk = markers(self.character, np.asarray(guide_q, dtype=float))  # (nm, 3, T)
        return mk.reshape(self.n_markers * 3, self.T)

    @staticmethod
    def _pack(index: np.ndarray, a: np.ndarray, size: int, offset: int) -> np.ndarray:
        out = np.zeros(size)
        out[index - offset] = a  # overlap frames write the same entry; frames 0/1 win below
        out[index[:, :2] - offset] = a[:, :2]
        return out

    def pack_q(self, q: np.ndarray) -> np.ndarray:
        return self._pack(self._q_index, q, self.nq_vars, 0)

    def unpack_q(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(x)[self._q_index]

    def pack_v(self, v: np.ndarray) -> np.ndarray:
        return self._pack(self._v_index, v, self.nv_vars, self.nq_vars)

    def unpack_v(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(x)[self._v_index]

    def ref_points(self, q: np.ndarray, ground: np.ndarray | None = None) -> np.ndarray:
        """(6, T) per frame and foot: (x, y) the mean of its contact points, z the ground
        height under the foot (``ground`` (2, T); default the flat ground z = 0)."""
        cp = contact_points(self.character, q)  # (P, 3, T)
        ref = np.zeros((6, self.T))
        for k, side in enumerate(FEET):
            idx = [j for j, c in enumerate(self.character.contacts) if c.side == side]
            ref[3 * k : 3 * k + 2] = cp[idx, :2, :].mean(axis=0)
            if ground is not None:
                ref[3 * k + 2] = ground[k]
        return ref

    def contact_ground(self, ground: np.ndarray) -> np.ndarray:
        """(P, T) ground height under each contact point from the per-foot heights (2, T)."""
        side = {s: k for k, s in enumerate(FEET)}
        out = np.zeros((max(self.ff.P, 1), self.T))
        for j, c in enumerate(self.character.contacts):
            out[j] = ground[side[c.side]]
        return out

    def anchor_points(self, q: np.ndarray) -> np.ndarray:
        a = np.zeros((3, self.T))
        a[:2] = q[:2]
        return a

    def pack_wrenches(self, wrenches: np.ndarray | None, ref: np.ndarray) -> np.ndarray:
        x = np.zeros(12 * len(self.eom_frames))
        if wrenches is None:
            return x
        base = self.nq_vars + self.nv_vars
        for c, t in enumerate(self.eom_frames):
            for k in range(2):
                n0, f = wrenches[k, :3, t], wrenches[k, 3:, t]
                r = ref[3 * k : 3 * k + 3, t]
                x[self._w_index[6 * k : 6 * k + 6, c] - base] = np.r_[(n0 - np.cross(r, f)) / self.moment_scale,
                                                                      f / self.weight_scale]
        return x

    def unpack_wrenches(self, x: np.ndarray, ref: np.ndarray, dpsi: float) -> np.ndarray:
        """World wrenches about the origin (2, 6, T); frames 0 and T−1 are frames T−2 and 1
        under the cycle's turn, about their own reference points."""
        out = np.zeros((2, 6, self.T))
        x = np.asarray(x).ravel()
        Tn = self.T

        def put(t: int, c: int, turn: float) -> None:
            cz, sz = math.cos(turn), math.sin(turn)
            R = np.array([[cz, -sz, 0.0], [sz, cz, 0.0], [0.0, 0.0, 1.0]])
            for k in range(2):
                w = x[self._w_index[6 * k : 6 * k + 6, c]]
                n_r, f = R @ (w[:3] * self.moment_scale), R @ (w[3:] * self.weight_scale)
                r = ref[3 * k : 3 * k + 3, t]
                out[k, :3, t] = n_r + np.cross(r, f)
                out[k, 3:, t] = f

        for c, t in enumerate(self.eom_frames):
            put(t, c, 0.0)
        if self.eom_frames:
            put(0, Tn - 3, -dpsi)
            put(Tn - 1, 0, dpsi)
        return out

    def shared_load_frames(self) -> list[int]:
        """Frames (1..T−2) where both feet must carry a share of the load: the middle of every
        double support of the cycle (a run of one or two frames: all of it; longer: its inner
        frames)."""
        B = self.foot_contact()
        N = self.T - 2
        if N < 2 or not self.eom_frames:
            return []
        both = B[0, :N] & B[1, :N]
        out: list[int] = []
        if both.all():
            return []
        k0 = int(np.flatnonzero(~both)[0])
        t = k0
        while t < k0 + N:
            if both[t % N]:
                a = t
                while both[t % N] and t < k0 + N:
                    t += 1
                run = [u % N for u in range(a, t)]
                out += run if len(run) <= 2 else run[1:-1]
            else:
                t += 1
        return sorted(u if u >= 1 else N for u in out)

    def bounds(self, locks: Mapping[int, float] | None = None, shared_load: float = 0.0
               ) -> tuple[np.ndarray, np.ndarray]:
        """Variable bounds: joint limits (``Naturalness.limit_margin_deg`` inside the model's), locks,
        feet not in contact carry nothing, f_z ≥ 0 and,
        at ``shared_load_frames``, f_z ≥ ``shared_load`` (scaled: body weights of standard gravity)."""
        lbx = np.full(self.nx, -np.inf)
        ubx = np.full(self.nx, np.inf)
        lo, hi = self.character.lower, self.character.upper
        margin = np.radians(self.ff.naturalness.limit_margin_deg)  # a joint is not held at its limit
        limited = limited_coordinates(self.character)
        for i in range(self.n):
            idx = np.unique(self._q_index[i])
            m = margin if limited[i] else 0.0
            lbx[idx], ubx[idx] = lo[i] + m, hi[i] - m
        for i, v in (locks or {}).items():
            idx = np.unique(self._q_index[i])
            lbx[idx] = ubx[idx] = v
            if self.dynamics:
                vidx = np.unique(self._v_index[i])
                lbx[vidx] = ubx[vidx] = 0.0
        B = self.foot_contact()
        for c, t in enumerate(self.eom_frames):
            for k in range(2):
                idx = self._w_index[6 * k : 6 * k + 6, c]
                if not B[k, t]:
                    lbx[idx] = ubx[idx] = 0.0
                else:
                    lbx[idx[5]] = 0.0  # f_z >= 0
        if shared_load > 0:
            for t in self.shared_load_frames():
                c = self.eom_frames.index(t)
                for k in range(2):
                    lbx[self._w_index[6 * k + 5, c]] = shared_load
        return lbx, ubx

    def com_points(self, q: np.ndarray) -> np.ndarray:
        """(3, T) whole-body centre of mass of each frame."""
        return centre_of_mass(self.character, q)

    def parameters(self, guide_markers: np.ndarray, guide_q: np.ndarray, env: Environment, weights: Weights,
                   ref: np.ndarray, anchor: np.ndarray, dpsi: float, com: np.ndarray | None = None,
                   h: float | None = None, ground: np.ndarray | None = None, rise: float = 0.0,
                   joint_range: np.ndarray | None = None, path: np.ndarray | None = None,
                   lean: np.ndarray | None = None, fore_aft_cap: float = 1e3,
                   g_ratio: float = 1.0, guide_com: np.ndarray | None = None,
                   clearance: np.ndarray | None = None, guide_force: np.ndarray | None = None,
                   width: np.ndarray | None = None, stairs: np.ndarray | None = None) -> np.ndarray:
        """The parameter vector (``P_LAYOUT`` order); ``h``: frame interval (s), default 1/fps;
        ``joint_range`` (2, n) the joint-range prior's bounds (default: none); ``path`` (T,) the
        direction of travel per frame (rad); ``lean`` (T,) the trunk's target lean (sine);
        ``fore_aft_cap`` each foot's fore-aft force bound (scaled); ``g_ratio`` the environment's
        gravity over the standard (the loads the naturalness rows allow are in its body weights);
        ``guide_com`` (3, T) the centre of mass to track; ``clearance`` (2, T) each foot's sole
        clearance target (m); ``guide_force`` (3, T) the total ground force to track (scaled); ``width``
        (4, T) each foot's step width to keep and its mask; ``stairs`` (STAIRS_PARAMS, T) the stairs rows'
        parameters (``solver.spacetime.stairs.stairs_parameters``; default: none active)."""
        from solver.spacetime.stairs import stairs_parameters

        nT = self.T
        K = max(len(self.eom_frames), 1)
        hv = float(self.dt if h is None else h)
        rate = RATE_TIME / hv  # the rate costs' fixed time scale over the frame interval
        scaled = {
            "direction": weights.direction / (self.n_markers * nT * MARKER_SCALE**2),
            "singularity": weights.singularity / (max(self.ff.n_sing, 1) * nT * MARKER_SCALE**2),
            "wrench": weights.wrench / K,
            "coordinates": weights.coordinates / (max(self.n - 6, 1) * nT),  # (0.1 rad)² per coordinate = 0.01
            "wrench_rate": weights.wrench_rate * rate**2 / K,
            "jerk": weights.jerk * rate**6 / (max(self.n - 3, 1) * K),
            "smoothness": weights.smoothness * rate**4 / (max(self.n - 3, 1) * max(nT - 2, 1)),
            "root_rotation": weights.root_rotation / (max(self.n - 6, 1) * nT),  # (0.01 rad)² per root rotation
            "com_moment": weights.com_moment / K,
            "joint_range": weights.joint_range / (max(self.n - 6, 1) * nT),  # (0.1 rad)² beyond the range = 1
            "trunk_lean": weights.trunk_lean / nT,
            "com_track": weights.com_track / (nT * MARKER_SCALE**2),
            "clearance": weights.clearance * hv * 15.0,  # per corner-frame at 15 frames/s
            "force_track": weights.force_track / K,
            "joint_speed": weights.joint_speed / (max(self.n - 6, 1) * nT),
            "step_width": weights.step_width / (2 * nT),
            "pelvis_side": weights.pelvis_side / (2 * nT),
        }
        wts = [scaled[name] for name in WEIGHT_SLOTS]
        return np.concatenate([
            np.asarray(guide_markers, dtype=float).ravel(order="F"),
            np.asarray(guide_q, dtype=float).ravel(order="F"),
            np.asarray(env.gravity, dtype=float), [float(env.friction)], wts,
            ref.ravel(order="F"), anchor.ravel(order="F"), [float(dpsi)],
            (np.zeros((3, nT)) if com is None else com).ravel(order="F"),
            [hv],
            (np.zeros((max(self.ff.P, 1), nT)) if ground is None else ground).ravel(order="F"), [float(rise)],
            (np.array([[-1e3] * self.n, [1e3] * self.n]) if joint_range is None else joint_range).ravel(),
            np.zeros(nT) if path is None else np.asarray(path, dtype=float),
            np.zeros(nT) if lean is None else np.asarray(lean, dtype=float),
            [float(fore_aft_cap), float(g_ratio)],
            (np.zeros((3, nT)) if guide_com is None else np.asarray(guide_com, dtype=float)).ravel(order="F"),
            (np.zeros((2, nT)) if clearance is None else np.asarray(clearance, dtype=float)).ravel(order="F"),
            (np.zeros((3, nT)) if guide_force is None else np.asarray(guide_force, dtype=float)).ravel(order="F"),
            (np.zeros((CROSS_ROWS + 2, nT)) if width is None else np.asarray(width, dtype=float)).ravel(order="F"),
            (stairs_parameters(None, np.zeros((2, nT), dtype=bool)) if stairs is None
             else np.asarray(stairs, dtype=float)).ravel(order="F"),
        ])

    def width_targets(self, q: np.ndarray, path: np.ndarray) -> np.ndarray:
        """(6, T) each foot's far-side distance across the direction of travel ``path``, then across the
        pelvis's heading, in the motion ``q`` (the guide's: where the optimum keeps the feet), then 1 where
        the foot is on the ground."""
        f = self.ff.cross.map(self.T)
        far = np.asarray(f(np.asarray(q, dtype=float), np.asarray(path, dtype=float).reshape(1, -1)))
        return np.vstack([far, self.foot_contact().astype(float)])

    def force_targets(self, com: np.ndarray, h: float, gravity) -> np.ndarray:
        """(3, T) the total ground force (scaled: body weights of standard gravity) that moves the
        centre of mass ``com`` (3, T) in ``gravity``: m (a − g) with a by central second differences
        at frame interval ``h`` (frames 1 … T−2, the equations of motion's; 0 elsewhere)."""
        c = np.asarray(com, dtype=float)
        out = np.zeros((3, self.T))
        if self.T < 3:
            return out
        a = (c[:, :-2] - 2 * c[:, 1:-1] + c[:, 2:]) / (h * h)
        out[:, 1:-1] = (a - np.asarray(gravity, dtype=float).reshape(3, 1)) / STANDARD_GRAVITY
        return out

    def clearance_targets(self, q: np.ndarray, h: float, ground: np.ndarray) -> np.ndarray:
        """(2, T) each foot's sole clearance target (m) per frame (``Naturalness.clearance_target_m``):
        in swing, scaled by how fast the foot's sole moves in ``q`` (its fastest corner, central
        differences at frame interval ``h``) between ``Naturalness.clearance_speed``; none in contact
        (−1)."""
        nat = self.ff.naturalness
        out = np.full((2, self.T), -1.0)
        if not self.ff.has_contacts:
            return out
        corners = sole_corners(self.character, np.asarray(q, dtype=float))  # (2, 4, 3, T)
        xy = corners[:, :, :2, :]
        v = np.zeros((2, 4, self.T))
        v[..., 1:-1] = np.linalg.norm(xy[..., 2:] - xy[..., :-2], axis=2) / (2 * h)
        v[..., 0], v[..., -1] = v[..., -2] if self.T > 2 else 0.0, v[..., 1] if self.T > 2 else 0.0
        speed = v.max(axis=1)
        lo, hi = nat.clearance_speed
        ramp = np.clip((speed - lo) / max(hi - lo, 1e-9), 0.0, 1.0)
        B = self.foot_contact()
        out = np.where(B, -1.0, nat.clearance_target_m * ramp)
        return out

    def fore_aft_cap(self, env: Environment) -> float:
        """Each foot's fore-aft force bound (scaled by the standard body weight): on level ground
        (gravity along −z within ``Naturalness.level_deg``, no stairs) ``Naturalness.fore_aft`` body
        weights of the environment's gravity; elsewhere none (slopes and stairs need more)."""
        g = np.asarray(env.gravity, dtype=float)
        gn = float(np.linalg.norm(g))
        level = gn > 0 and -g[2] / gn >= np.cos(np.radians(self.ff.naturalness.level_deg)) and not env.step_height_m
        return self.ff.naturalness.fore_aft * gn / STANDARD_GRAVITY if level else 1e3

    def trunk_lean(self, guide_q: np.ndarray, gravity, path: np.ndarray) -> np.ndarray:
        """(T,) the guide's trunk lean against ``gravity`` per frame (sine, + forward): the trunk
        prior's target. The slope's guide is the tutor turned with gravity, so on a slope the
        target is the tutor's own posture against gravity."""
        f = self.ff.lean_of.map(self.T)
        g = np.repeat(np.asarray(gravity, dtype=float).reshape(3, 1), self.T, axis=1)
        return np.asarray(f(np.asarray(guide_q, dtype=float), g, np.asarray(path, dtype=float).reshape(1, -1))).ravel()

    def joint_range(self, guide_q: np.ndarray) -> np.ndarray:
        """(2, n) the joint-range prior's bounds per coordinate (``Weights.joint_range``): every
        joint coordinate stays out of the last ``Naturalness.limit_band_deg`` of its model range;
        a non-sagittal one (ab/adduction, axial rotation, bending: not a hinge about the segment's
        lateral axis) also within the guide's own range over its frames widened by
        ``Naturalness.joint_range_margin_deg``; the guide's own range is never penalized (a capture
        near a limit is tracked). Root coordinates: none."""
        nat = self.ff.naturalness
        m, b = np.radians(nat.joint_range_margin_deg), np.radians(nat.limit_band_deg)
        g = np.asarray(guide_q, dtype=float)
        lo = np.asarray(self.character.lower, dtype=float) + b
        hi = np.asarray(self.character.upper, dtype=float) - b
        dofs = [d for s in self.character.segments for d in s.dofs]
        for i, d in enumerate(dofs):
            axis = np.asarray(d.axis, dtype=float)
            if i >= 6 and d.kind == "hinge" and abs(axis[1]) < 0.9 * np.linalg.norm(axis):
                lo[i], hi[i] = max(lo[i], g[i].min() - m), min(hi[i], g[i].max() + m)
            if i >= 6:  # the band near a limit starts where the guide's own range ends
                lo[i], hi[i] = min(lo[i], g[i].min()), max(hi[i], g[i].max())
            if lo[i] > hi[i]:
                lo[i] = hi[i] = 0.5 * (lo[i] + hi[i])
        lo[:6], hi[:6] = -1e3, 1e3
        return np.stack([np.nan_to_num(lo, neginf=-1e3), np.nan_to_num(hi, posinf=1e3)])

    def constraint_bounds(self, h: float) -> tuple[np.ndarray, np.ndarray]:
        """(lbg, ubg) at the frame interval ``h``: the spin, force-rate and wrench-curvature
        bounds are rates per second, so their per-frame bounds follow h."""
        lo, hi = self._lbg_raw.copy(), self._ubg_raw.copy()
        for rows, fn in self._h_bounds:
            a, b = fn(float(h))
            lo[rows], hi[rows] = a, b
        return lo, hi
