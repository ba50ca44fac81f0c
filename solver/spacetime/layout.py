"""Variable and parameter packing of the spacetime problem: how motions, wrenches, reference
points and weights map onto the NLP's x and p (a mixin of ``SpacetimeProblem``)."""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import numpy as np

from solver.kinematics import centre_of_mass, contact_points, markers
from solver.motion import FEET, foot_schedule_of
from solver.spacetime.types import Environment, Weights

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

    def bounds(self, locks: Mapping[int, float] | None = None) -> tuple[np.ndarray, np.ndarray]:
        lbx = np.full(self.nx, -np.inf)
        ubx = np.full(self.nx, np.inf)
        lo, hi = self.character.lower, self.character.upper
        for i in range(self.n):
            idx = np.unique(self._q_index[i])
            lbx[idx], ubx[idx] = lo[i], hi[i]
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
        return lbx, ubx

    def com_points(self, q: np.ndarray) -> np.ndarray:
        """(3, T) whole-body centre of mass of each frame."""
        return centre_of_mass(self.character, q)

    def parameters(self, guide_markers: np.ndarray, guide_q: np.ndarray, env: Environment, weights: Weights,
                   ref: np.ndarray, anchor: np.ndarray, dpsi: float, com: np.ndarray | None = None,
                   h: float | None = None, ground: np.ndarray | None = None, rise: float = 0.0) -> np.ndarray:
        """The parameter vector (``P_LAYOUT`` order); ``h``: frame interval (s), default 1/fps."""
        nT = self.T
        K = max(len(self.eom_frames), 1)
        hv = float(self.dt if h is None else h)
        rate = RATE_TIME / hv  # the rate costs' fixed time scale over the frame interval
        wts = [weights.direction / (self.n_markers * nT * MARKER_SCALE**2),
               weights.singularity / (max(self.ff.n_sing, 1) * nT * MARKER_SCALE**2),
               weights.wrench / K,
               weights.coordinates / (max(self.n - 6, 1) * nT),  # (0.1 rad)² per coordinate = 0.01
               weights.wrench_rate * rate**2 / K,
               weights.jerk * rate**6 / (max(self.n - 3, 1) * K),
               weights.smoothness * rate**4 / (max(self.n - 3, 1) * max(nT - 2, 1)),
               weights.root_rotation / (max(self.n - 6, 1) * nT)]  # (0.01 rad)² per root rotation = 0.01
        return np.concatenate([
            np.asarray(guide_markers, dtype=float).ravel(order="F"),
            np.asarray(guide_q, dtype=float).ravel(order="F"),
            np.asarray(env.gravity, dtype=float), [float(env.friction)], wts,
            ref.ravel(order="F"), anchor.ravel(order="F"), [float(dpsi)],
            (np.zeros((3, nT)) if com is None else com).ravel(order="F"),
            [hv],
            (np.zeros((max(self.ff.P, 1), nT)) if ground is None else ground).ravel(order="F"), [float(rise)],
        ])

    def constraint_bounds(self, h: float) -> tuple[np.ndarray, np.ndarray]:
        """(lbg, ubg) at the frame interval ``h``: the spin, force-rate and wrench-curvature
        bounds are rates per second, so their per-frame bounds follow h."""
        lo, hi = self._lbg_raw.copy(), self._ubg_raw.copy()
        for rows, fn in self._h_bounds:
            a, b = fn(float(h))
            lo[rows], hi[rows] = a, b
        return lo, hi
