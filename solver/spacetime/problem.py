"""The spacetime NLP of one structure (docs/method.md (M5.14)), transcribed so that the physics
holds along the motion, not only at the frames; re-solved with new parameter values.

Structure: character, number of frames T, frame rate, contact schedule, dynamics on/off.
Parameters: guide markers and coordinates, gravity, friction, weights, the cycle's heading
change Δψ, per-frame reference points of the contact wrenches.

**Transcription** (docs/spacetime.md). The motion is the C² cubic spline through its frames
(periodic over the gait cycle): the knot velocities v are variables, tied to the coordinates by
the spline's banded continuity equations. The whole-body equations of motion hold at every
frame and at every midpoint between frames (ground wrench at a midpoint: the mean of its
frames'). A frame-to-frame zig-zag is thus seen by the dynamics between the frames, and cannot
be balanced by zig-zagging forces: the ground wrenches change by bounded amounts per frame,
with a cost on their change, and the coordinates' jerk has a small cost.

Variables: q (n × T, with the two overlap frames of the cycle eliminated for joints, root
height, pitch and roll), v (same, yaw rate included), and one scaled wrench per foot at the
frames 1..T−2. Constraints:

* joint limits (bounds); the cycle: yaw[T−2] = yaw[0] + Δψ exactly (the curve is a constraint),
  horizontal displacement and velocity periodic in the walker's heading frame;
* contacts: active points on the ground, inactive above; pinned points do not slide; a foot in
  contact does not spin about the vertical faster than ``Realism.spin_rate_deg_s``;
* feet in contact: friction cone, CoP in the foot box, torsional friction |τ| ≤ 0.95 μ ρ f_z
  and |τ| ≤ 0.025 BW·m; total normal force ≤ 1.95 BW; total ground force change per frame
  bounded; a foot not in contact carries nothing (bounds);
* equations of motion at the frames 1..T−2 and the midpoints after them (one cycle of each).
"""

from __future__ import annotations

import logging
import math
import time
from collections.abc import Mapping
from typing import Any

import casadi as ca
import numpy as np

from solver.character import Character
from solver.environment import stair_heights, stair_rise
from solver.motion import FEET
from solver.naturalness import path_heading
from solver.spacetime.callback import STOP, STOP_CALLBACK
from solver.spacetime.derivatives import Term, assemble
from solver.spacetime.frame import CROSS_ROWS, FOOT_ROWS, FRAME_COST_WEIGHTS, SOLE_CORNERS, frame_functions
from solver.spacetime.layout import Layout
from solver.spacetime.stairs import STAIRS_PARAMS, add_stairs_terms, stairs_joint_bounds, stairs_parameters
from solver.spacetime.types import (
    DEFAULT_IPOPT,
    STANDARD_GRAVITY,
    SUCCESS_STATUSES,
    WARM_START_IPOPT,
    WEIGHT_SLOTS,
    ProblemData,
    SolveResult,
    SolverOptions,
    WarmStart,
    weight_slots,
)
from solver.stairs import flight_for
from solver.trajectory import spline_velocities

log = logging.getLogger(__name__)

#: root coordinates that repeat over a cycle (root_tz, pitch, roll); x, y, yaw: under the cycle's transform
ROOT_PERIODIC = (2, 4, 5)
ROOT_Z = 2  # on stairs (``rising``): root z[T−2] = z[0] + the cycle's rise, not periodic
YAW = 3
#: parameter blocks in order; "h" is the frame interval (s) of the spline: the speed axis changes it
#: "ground": per contact point and frame, the ground height (terrain); "rise": the cycle's
#: height gain (root z of frames T−2, T−1 over frames 0, 1; stairs)
#: "range": per coordinate, the joint-range prior's lower then upper bound; "path": per frame, the
#: direction of travel (rad) the feet's crossover is measured across
#: "lean": per frame, the trunk's target lean against gravity (sine); "loads": a foot's fore-aft force
#: bound (scaled: body weights of standard gravity) and the environment's gravity over the standard;
#: "gcom": per frame, the centre of mass to track; "clear": per foot and frame, the sole's clearance target;
#: "gforce": per frame, the total ground force to track (body weights of standard gravity); "width": per frame,
#: each foot's far-side distance across the direction of travel, then across the pelvis's heading, to keep,
#: then a mask (1: the foot is down);
#: "stairs": per frame, the flight of stairs and each foot's tread or nosings (``solver.spacetime.stairs``)
P_LAYOUT = ("gm", "gq", "g", "mu", "wts", "ref", "anchor", "dpsi", "com", "h", "ground", "rise", "range", "path",
            "lean", "loads", "gcom", "clear", "gforce", "width", "stairs")


def _heading(vx, vy, psi):
    c, s = ca.cos(psi), ca.sin(psi)
    return ca.vertcat(c * vx + s * vy, -s * vx + c * vy)


def _cyclic_root_function(dynamics: bool, rising: bool = False) -> ca.Function:
    """Rows tying frames T−2, T−1 to frames 0, 1 for x, y, yaw (and their velocities); with
    ``rising``, root z too: raised by the cycle's rise."""
    z = ca.SX.sym("z", (20 if dynamics else 12) + (4 if rising else 0))
    dpsi = ca.SX.sym("dpsi")
    rise = ca.SX.sym("rise")
    xa, ya, yaw = z[0:4], z[4:8], z[8:12]  # frames (0, 1, T−2, T−1)
    rows = [_heading(xa[3] - xa[2], ya[3] - ya[2], yaw[2]) - _heading(xa[1] - xa[0], ya[1] - ya[0], yaw[0])]
    if dynamics:  # the heading change over the cycle is exact
        vx, vy = z[12:16], z[16:20]
        rows += [yaw[2] - yaw[0] - dpsi, yaw[3] - yaw[1] - dpsi,
                 _heading(vx[2], vy[2], yaw[2]) - _heading(vx[0], vy[0], yaw[0]),
                 _heading(vx[3], vy[3], yaw[3]) - _heading(vx[1], vy[1], yaw[1])]
    else:  # kinematic fit: the yaw rate repeats, the turn follows the capture's markers
        rows.append((yaw[3] - yaw[2]) - (yaw[1] - yaw[0]))
    if rising:
        rz_ = z[z.shape[0] - 4:]
        rows += [rz_[2] - rz_[0] - rise, rz_[3] - rz_[1] - rise]
    return ca.Function("cyc", [z, dpsi, rise], [ca.vertcat(*rows)])


class SpacetimeProblem(Layout):
    """The NLP of docs/method.md (M5.14) for one structure; solve it many times with new parameters."""

    def __init__(self, character: Character, T: int, fps: float, contacts: np.ndarray | None, *,
                 cyclic: bool = True, dynamics: bool = True, ipopt_options: Mapping[str, Any] | None = None,
                 rising: bool = False) -> None:
        t0 = time.perf_counter()
        self.character = character
        self.T = Tn = int(T)
        self.fps = float(fps)
        self.dt = 1.0 / self.fps
        self.cyclic, self.dynamics = bool(cyclic), bool(dynamics)
        #: root z may gain a rise over the cycle (stairs): its overlap frames are variables
        self.rising = bool(rising)
        n = self.n = character.n
        if Tn < 5:
            raise ValueError(f"too few frames for a spacetime problem: {T}")
        if not self.cyclic:
            raise ValueError("the spacetime problem transcribes a gait cycle: cyclic=True")
        ff = self.ff = frame_functions(character)
        self.derivatives_used = ff.derivatives  # compiled later? (stale, solver.spacetime.compiled)
        if dynamics:
            if not ff.has_contacts:
                raise ValueError("the character needs heel/toe contact points and a foot box on both feet")
            if contacts is None:
                raise ValueError("a dynamic spacetime problem needs a contact schedule")
            contacts = np.asarray(contacts, dtype=bool)
            if contacts.shape != (ff.P, Tn):
                raise ValueError(f"contact schedule must be ({ff.P}, {Tn}), got {contacts.shape}")
            if not (np.array_equal(contacts[:, Tn - 2], contacts[:, 0])
                    and np.array_equal(contacts[:, Tn - 1], contacts[:, 1])):
                raise ValueError("a cyclic contact schedule must repeat frames 1-2 in its last two frames")
        self.contacts = None if contacts is None else contacts.copy()
        self.weight_scale, self.moment_scale = ff.weight_scale, ff.moment_scale
        self.n_markers = ff.n_markers

        # --- variable layout: q, then v, then wrenches --------------------------------------
        periodic = np.zeros(n, dtype=bool)
        periodic[6:] = True
        periodic[list(ROOT_PERIODIC)] = True
        if self.rising:
            periodic[ROOT_Z] = False
        self.periodic = periodic
        k = 0
        self._q_index, k = self._index(periodic, k)
        self.nq_vars = k
        v_periodic = periodic.copy()
        v_periodic[YAW] = True
        v_periodic[ROOT_Z] = True  # the vertical velocity repeats, also on stairs
        self._v_index, k = self._index(v_periodic, k) if dynamics else (np.zeros((n, 0), dtype=int), k)
        self.nv_vars = k - self.nq_vars
        self.eom_frames = list(range(1, Tn - 1)) if dynamics else []
        self._w_index = (k + np.arange(12 * len(self.eom_frames))).reshape(len(self.eom_frames), 12).T
        k += 12 * len(self.eom_frames)
        self.nx = k
        self.distinct_frames = list(range(Tn - 2))

        x = self._x = ca.MX.sym("x", self.nx)
        nm3 = 3 * ff.n_markers
        #: each parameter block's shape: (rows, frames) for a per-frame block, else a vector's length
        shapes: dict[str, int | tuple[int, int]] = {
            "gm": (nm3, Tn), "gq": (n, Tn), "g": 3, "mu": 1, "wts": len(WEIGHT_SLOTS), "ref": (6, Tn),
            "anchor": (3, Tn), "dpsi": 1, "com": (3, Tn), "h": 1, "ground": (max(ff.P, 1), Tn), "rise": 1,
            "range": 2 * n, "path": Tn, "lean": Tn, "loads": 2, "gcom": (3, Tn), "clear": (2, Tn), "gforce": (3, Tn),
            "width": (CROSS_ROWS + 2, Tn), "stairs": (STAIRS_PARAMS, Tn)}
        self._p_layout, off = {}, 0
        for name in P_LAYOUT:
            shape = shapes[name]
            size = shape[0] * shape[1] if isinstance(shape, tuple) else shape
            self._p_layout[name] = (off, size)
            off += size
        p = ca.MX.sym("p", off)
        #: the parameter blocks by name (``P_LAYOUT``), slices of p in their shapes
        self._par: dict[str, ca.MX] = {}
        for name, (o, size) in self._p_layout.items():
            shape = shapes[name]
            self._par[name] = ca.reshape(p[o : o + size], *shape) if isinstance(shape, tuple) else p[o : o + size]
        P = self._par
        wts = weight_slots(P["wts"])
        #: constraint rows whose bounds scale with the frame interval: (rows, fn(h) -> (lo, hi))
        self._h_bounds: list[tuple[np.ndarray, Any]] = []
        qi = self._q_index
        self._terms: list[Term] = []
        self._g_parts: list[ca.MX] = []
        self._lbg: list[np.ndarray] = []
        self._ubg: list[np.ndarray] = []
        self._groups: dict[str, list[int]] = {}
        self._ng = 0

        # --- objective ---------------------------------------------------------------------
        cw = ca.repmat(ca.vertcat(*(wts[name] for name in FRAME_COST_WEIGHTS)), 1, Tn)
        rng = P["range"]
        self._cost(Term("cost", ff.cost, 1, qi, [P["gm"], P["gq"], cw, ca.repmat(rng[:n], 1, Tn),
                                                 ca.repmat(rng[n:], 1, Tn), P["gcom"]],
                        derivatives=ff.derivatives["cost"], cost=True))
        self._cyclic_root()
        if dynamics:
            self._dynamic_terms(wts)
            if self.rising:  # [stairs] treads, risers and nosings (solver.spacetime.stairs)
                add_stairs_terms(self, P["stairs"])
        else:
            K = list(range(1, Tn - 1))
            zacc = np.vstack([qi[:, [t - 1 for t in K]], qi[:, K], qi[:, [t + 1 for t in K]]])
            self._cost(Term("acc", ff.acc, 3, zacc,
                            [ca.repmat(wts["smoothness"], 1, len(K))], derivatives=ff.derivatives["acc"], cost=True))
        objective = sum(ca.sum2(t_.outputs(x)) for t_ in self._terms if t_.cost)
        extra = []
        if self.nx > self.nq_vars + self.nv_vars:  # wrench regularization
            xw = x[self.nq_vars + self.nv_vars:]
            objective = objective + wts["wrench"] * ca.sumsqr(xw)
            nw = xw.shape[0]
            extra.append((lambda lam_f, nw=nw: ca.repmat(2 * lam_f * wts["wrench"], 1, nw),
                          np.arange(self.nq_vars + self.nv_vars, self.nx)))
        g = ca.vertcat(*self._g_parts) if self._g_parts else ca.MX(0, 1)
        self.ng = int(g.shape[0])
        self._lbg_raw = np.concatenate(self._lbg) if self._lbg else np.zeros(0)
        self._ubg_raw = np.concatenate(self._ubg) if self._ubg else np.zeros(0)
        self._lbg_a, self._ubg_a = self.constraint_bounds(self.dt)
        self._jac, self._hess, self.hessian_nnz, self.jacobian_nnz = assemble(self._terms, x, p, g, self.nx,
                                                                                self.ng, extra)
        self._nlp = {"x": x, "p": p, "f": objective, "g": g}
        Q = ca.reshape(x[qi.ravel(order="F").tolist()], n, Tn)
        self._fg = ca.Function("fg", [x, p], [objective, g, ca.sum2(ff.marker_cost.map(Tn)(Q, P["gm"]))])
        self._base_options = dict(DEFAULT_IPOPT)
        if ipopt_options:
            self._base_options.update(ipopt_options)
        self._solver_cache: dict[tuple, ca.Function] = {}
        self.build_time = time.perf_counter() - t0
        log.info("spacetime NLP: %d variables, %d constraints, built in %.2f s", self.nx, self.ng, self.build_time)

    # --- construction helpers ---------------------------------------------------------------
    def _index(self, periodic: np.ndarray, k: int) -> tuple[np.ndarray, int]:
        """(n, T) variable index; periodic rows share frames T−2, T−1 with frames 0, 1."""
        Tn = self.T
        idx = np.zeros((self.n, Tn), dtype=int)
        for i in range(self.n):
            nfree = Tn - 2 if periodic[i] else Tn
            idx[i] = k + np.array([t if t < nfree else t - (Tn - 2) for t in range(Tn)])
            k += nfree
        return idx, k

    def _cost(self, term: Term) -> None:
        self._terms.append(term)

    def _rows(self, term: Term, sel: list[tuple[int, int]], lo, hi, group: str | None = None) -> None:
        """Constraint rows ``sel`` (call, row) of ``term`` with bounds ``lo``, ``hi``."""
        term.selected = sel
        self._terms.append(term)
        if not sel:
            return
        out = term.outputs(self._x)
        rows_out = term.fn.size1_out(0)
        expr = ca.vec(out)[[c * rows_out + r for c, r in sel]]
        term.g_offset = self._ng
        self._g_parts.append(expr)
        self._lbg.append(np.broadcast_to(np.asarray(lo, dtype=float), (len(sel),)).copy())
        self._ubg.append(np.broadcast_to(np.asarray(hi, dtype=float), (len(sel),)).copy())
        self._groups.setdefault(group or term.name, []).extend(range(self._ng, self._ng + len(sel)))
        self._ng += len(sel)

    def _cyclic_root(self) -> None:
        Tn, qi, vi = self.T, self._q_index, self._v_index
        fr = [0, 1, Tn - 2, Tn - 1]
        parts = [qi[0, fr], qi[1, fr], qi[YAW, fr]]
        if self.dynamics:
            parts += [vi[0, fr], vi[1, fr]]
        if self.rising:
            parts += [qi[ROOT_Z, fr]]
        fn = _cyclic_root_function(self.dynamics, self.rising)
        rows = fn.size1_out(0)
        self._rows(Term("cyc", fn, 1, np.concatenate(parts)[:, None], [self._par["dpsi"], self._par["rise"]]),
                   [(0, r) for r in range(rows)], 0.0, 0.0, "cyclic_root")

    def _wrench_columns(self, frames: list[int]) -> np.ndarray:
        """(12, len(frames)) wrench variable indices; frame T−1 is frame 1 (turned by Δψ)."""
        cols = [self._w_index[:, (1 if t == self.T - 1 else t) - 1] for t in frames]
        return np.stack(cols, axis=1)

    def _dynamic_terms(self, wts: dict[str, ca.MX]) -> None:
        ff, Tn, qi, vi = self.ff, self.T, self._q_index, self._v_index
        P = self._par
        grav, mu, dpsi, REF, ANCHOR = P["g"], P["mu"], P["dpsi"], P["ref"], P["anchor"]
        A = self.contacts
        B = self.foot_contact()
        h = P["h"]  # the frame interval: an NLP parameter
        frames = self.distinct_frames
        D = ff.derivatives
        # contact heights
        sel, hi = [], []
        for c, t in enumerate(frames):
            for j in range(ff.P):
                sel.append((c, j))
                hi.append(0.0 if A[j, t] else math.inf)
        self._rows(Term("z", ff.z, 1, qi[:, frames], [P["ground"][:, frames]], derivatives=D["z"]), sel, 0.0,
                   np.array(hi), "contact")
        # [naturalness] a swinging foot's sole (its four corners) clears the ground
        sel = [(c, SOLE_CORNERS * k_ + r) for c, t in enumerate(frames) for k_ in range(2) if not B[k_, t]
               for r in range(SOLE_CORNERS)]
        self._rows(Term("sole", ff.sole, 1, qi[:, frames], [P["ground"][:, frames]], derivatives=D["sole"]), sel,
                   ff.naturalness.clearance_m, math.inf, "clearance")
        self._cost(Term("clr", ff.clr, 1, qi[:, frames], [P["ground"][:, frames], P["clear"][:, frames],
                                                          ca.repmat(wts["clearance"], 1, len(frames))],
                        derivatives=D["clr"], cost=True))
        # [naturalness] a foot in contact does not cross to the far side of the pelvis
        sel = [(c, r) for c, t in enumerate(frames) for r in range(CROSS_ROWS) if B[r % 2, t]]
        self._rows(Term("cross", ff.cross, 1, qi[:, frames], [P["path"][frames].T], derivatives=D["cross"]), sel,
                   -math.inf, ff.naturalness.crossover_m, "crossover")
        self._cost(Term("width", ff.width, 1, qi[:, frames], [P["path"][frames].T, P["width"][:CROSS_ROWS, frames],
                                                              P["width"][CROSS_ROWS:, frames],
                                                              ca.repmat(wts["step_width"], 1, len(frames)),
                                                              ca.repmat(wts["pelvis_side"], 1, len(frames))],
                        derivatives=D["width"], cost=True))
        # no slip, no spin between consecutive frames
        pairs = frames
        sel, lo, hi = [], [], []
        spin_rows = []
        for c, t in enumerate(pairs):
            for s_i, side in enumerate(FEET):
                hh, toe = ff.heel_of[side], ff.toe_of[side]
                heel_pinned, toe_pinned = A[hh, t] and A[hh, t + 1], A[toe, t] and A[toe, t + 1]
                rows = []
                if heel_pinned:
                    rows += [2 * hh, 2 * hh + 1]
                if toe_pinned and heel_pinned:
                    rows.append(2 * ff.P + s_i)
                elif toe_pinned:
                    rows += [2 * toe, 2 * toe + 1]
                sel += [(c, r) for r in rows]
                lo += [0.0] * len(rows)
                hi += [0.0] * len(rows)
                if B[s_i, t] and B[s_i, t + 1] and not (heel_pinned and toe_pinned):
                    spin_rows.append(len(sel))
                    sel.append((c, 2 * ff.P + 2 + s_i))
                    lo.append(-math.inf)
                    hi.append(math.inf)
        nxt = [t + 1 for t in pairs]
        g0 = self._ng
        spin_rate = math.radians(ff.realism.spin_rate_deg_s)
        self._h_bounds.append((g0 + np.array(spin_rows, dtype=int),
                               lambda hv: (-math.sin(spin_rate * hv), math.sin(spin_rate * hv))))
        self._rows(Term("slip", ff.slip, 2, np.vstack([qi[:, pairs], qi[:, nxt]]), [], derivatives=D["slip"]),
                   sel, np.array(lo), np.array(hi), "no_slip")
        # feet in contact: cone, CoP, torsion, free-moment cap; support
        E = self.eom_frames
        W = self._wrench_columns(E)
        sel = []
        for c, t in enumerate(E):
            for k_ in range(2):
                if B[k_, t]:
                    sel += [(c, FOOT_ROWS * k_ + r) for r in range(FOOT_ROWS)]
            if B[:, t].any():
                sel.append((c, 2 * FOOT_ROWS))
        self._rows(Term("feet", ff.feet, 2, np.vstack([qi[:, E], W]), [ca.repmat(mu, 1, len(E)), REF[:, E],
                                                                        P["com"][:, E], P["path"][E].T,
                                                                        ca.repmat(P["loads"][0], 1, len(E)),
                                                                        ca.repmat(P["loads"][1], 1, len(E))],
                        derivatives=D["feet"]), sel, 0.0, math.inf)
        # spline continuity at the knots 1..T−2
        K = list(range(1, Tn - 1))
        km, kp = [t - 1 for t in K], [t + 1 for t in K]
        self._rows(Term("c2", ff.c2, 5, np.vstack([qi[:, km], qi[:, kp], vi[:, km], vi[:, K], vi[:, kp]]),
                        [ca.repmat(h, 1, len(K))], derivatives=D["c2"]),
                   [(c, r) for c in range(len(K)) for r in range(self.n)], 0.0, 0.0, "spline")
        # equations of motion on the segments [k, k+1], k = 1..T−2: at frame k and the midpoint
        Wb = self._wrench_columns(kp)
        turn = ca.horzcat(ca.DM.zeros(1, len(K) - 1), dpsi)
        zseg = np.vstack([qi[:, K], vi[:, K], qi[:, kp], vi[:, kp], W, Wb])
        seg_params = [ca.repmat(grav, 1, len(K)), ca.repmat(h, 1, len(K)), REF[:, K], REF[:, kp],
                      ANCHOR[:, K], ANCHOR[:, kp], turn]
        self._rows(Term("seg", ff.seg, 6, zseg, seg_params, derivatives=D["seg"]),
                   [(c, r) for c in range(len(K)) for r in range(12)], 0.0, 0.0, "eom")
        # realism: bounded change of the total ground force per frame; costs on wrench change and jerk
        rl = ff.realism
        self._h_bounds.append((self._ng + np.arange(len(K)), lambda hv: (-math.inf, (rl.force_rate * hv) ** 2)))
        self._rows(Term("frate", ff.frate, 2, np.vstack([W, Wb]), [turn], derivatives=D["frate"]),
                   [(c, 0) for c in range(len(K))], -math.inf, math.inf, "force_rate")
        # realism: small second differences of the total ground wrench (frames k−1, k, k+1)
        Wm = self._wrench_columns([T_ if T_ > 0 else Tn - 2 for T_ in km])  # frame 0 is frame T−2 turned back
        ta = ca.horzcat(-dpsi, ca.DM.zeros(1, len(K) - 1))
        sm_params = [REF[:, km], REF[:, K], REF[:, kp], P["com"][:, km], P["com"][:, K], P["com"][:, kp], ta, turn]
        self._h_bounds.append((self._ng + np.arange(2 * len(K)), lambda hv: (-math.inf, np.tile(
            [(rl.force_curvature * (15.0 * hv) ** 2) ** 2, (rl.moment_curvature * (15.0 * hv) ** 2) ** 2], len(K)))))
        self._rows(Term("smooth", ff.smooth, 3, np.vstack([Wm, W, Wb]), sm_params, derivatives=D["smooth"]),
                   [(c, r) for c in range(len(K)) for r in range(2)], -math.inf, math.inf, "smooth_ground_wrench")
        self._cost(Term("wrate", ff.wrate, 2, np.vstack([W, Wb]), [turn, ca.repmat(wts["wrench_rate"], 1, len(K))],
                        derivatives=D["wrate"], cost=True))
        self._cost(Term("lean", ff.lean, 1, qi[:, frames],
                        [ca.repmat(grav, 1, len(frames)), P["path"][frames].T, P["lean"][frames].T,
                         ca.repmat(wts["trunk_lean"], 1, len(frames))],
                        derivatives=D["lean"], cost=True))
        self._cost(Term("wcom", ff.wcom, 1, W, [REF[:, E], P["com"][:, E], ca.repmat(wts["com_moment"], 1, len(E))],
                        derivatives=D["wcom"], cost=True))
        GF = P["gforce"]
        self._cost(Term("ftrack", ff.ftrack, 1, W, [GF[:, E], ca.repmat(wts["force_track"], 1, len(E))],
                        derivatives=D["ftrack"], cost=True))
        self._cost(Term("jspeed", ff.jspeed, 2, np.vstack([qi[:, frames], qi[:, [t + 1 for t in frames]]]),
                        [ca.repmat(h, 1, len(frames)), ca.repmat(wts["joint_speed"], 1, len(frames))],
                        derivatives=D["jspeed"], cost=True))
        self._cost(Term("jerk", ff.jerk, 4, np.vstack([qi[:, K], vi[:, K], qi[:, kp], vi[:, kp]]),
                        [ca.repmat(h, 1, len(K)), ca.repmat(wts["jerk"], 1, len(K))], derivatives=D["jerk"], cost=True))

    @property
    def stale(self) -> bool:
        """Built before its character's compiled derivative functions were ready."""
        return self.derivatives_used is not self.ff.derivatives

    # --- solve -----------------------------------------------------------------------------
    def solve(self, data: ProblemData, start: WarmStart | None = None,
              options: SolverOptions = SolverOptions()) -> SolveResult:
        """Solve at the parameter values ``data`` from ``start`` (default: the guide, no wrenches,
        no multipliers) as ``options`` say."""
        guide_q, guide_markers, env, frame_interval = data.guide_q, data.guide_markers, data.env, data.frame_interval
        h = self.dt if frame_interval is None else float(frame_interval)
        if not (math.isfinite(h) and h > 0):
            raise ValueError(f"the frame interval must be a positive number of seconds, got {frame_interval!r}")
        if guide_markers is None:
            if guide_q is None:
                raise ValueError("give a guide motion or guide markers")
            guide_q = np.asarray(guide_q, dtype=float)
            if guide_q.shape != (self.n, self.T):
                raise ValueError(f"guide must be ({self.n}, {self.T}), got {guide_q.shape}")
            guide_markers = self.guide_markers(guide_q)
        guide_markers = np.asarray(guide_markers, dtype=float)
        if guide_markers.shape != (3 * self.n_markers, self.T):
            raise ValueError(f"guide markers must be ({3 * self.n_markers}, {self.T}), got {guide_markers.shape}")
        if start is None:
            if guide_q is None:
                raise ValueError("give an initial motion")
            start = WarmStart(guide_q)
        q0 = np.asarray(start.q, dtype=float)
        if q0.shape != (self.n, self.T) or not np.all(np.isfinite(q0)):
            raise ValueError(f"initial motion must be finite with shape ({self.n}, {self.T})")
        dpsi = float(q0[YAW, -2] - q0[YAW, 0]) if data.heading_change is None else float(data.heading_change)
        if not math.isfinite(dpsi):
            raise ValueError("the heading change must be finite")
        gq = q0 if guide_q is None else guide_q  # coordinates prior: the guide's, else the start's
        feet_ground = np.zeros((2, self.T))
        rise = 0.0
        flight = None
        if env.step_height_m:
            if not (self.rising and self.dynamics):
                raise ValueError("stairs (step_height_m) need a dynamic problem built with rising=True")
            feet_ground = stair_heights(self.foot_contact(), env.step_height_m)
            rise = stair_rise(self.foot_contact(), env.step_height_m)
            flight = flight_for(self.character, q0, self.foot_contact(), env)
        ref = self.ref_points(q0, feet_ground) if self.dynamics else np.zeros((6, self.T))
        # the direction of travel the crossover rows are measured across: the start iterate's (at a
        # λ step the previous optimum, which the optimum stays closer to than to the guide)
        path = path_heading(q0, self.T - 2)
        anchor = self.anchor_points(q0)
        prior = gq if data.prior_q is None else np.asarray(data.prior_q, dtype=float)
        com_target = self.com_points(gq) if data.guide_com is None else np.asarray(data.guide_com, dtype=float)
        if prior.shape != (self.n, self.T) or not np.all(np.isfinite(prior)):
            raise ValueError(f"prior_q must be finite with shape ({self.n}, {self.T})")
        p = self.parameters(guide_markers, prior, env, data.weights, ref, anchor, dpsi,
                            self.com_points(q0) if self.dynamics else None, h=h,
                            ground=self.contact_ground(feet_ground), rise=rise, joint_range=self.joint_range(gq),
                            path=path, lean=self.trunk_lean(gq, env.gravity, path) if self.ff.has_contacts else None,
                            fore_aft_cap=self.fore_aft_cap(env),
                            g_ratio=float(np.linalg.norm(env.gravity)) / STANDARD_GRAVITY,
                            guide_com=com_target,
                            clearance=self.clearance_targets(q0, h, feet_ground) if self.dynamics else None,
                            guide_force=self.force_targets(com_target, h, env.gravity),
                            width=(self.width_targets(gq, path_heading(gq, self.T - 2))
                                   if self.dynamics and self.ff.has_contacts else None),
                            stairs=stairs_parameters(flight, self.foot_contact()))
        lbg, ubg = self.constraint_bounds(h)
        parts = [self.pack_q(q0)]
        if self.dynamics:
            parts += [self.pack_v(spline_velocities(q0, h)), self.pack_wrenches(start.wrenches, ref)]
        x0 = np.concatenate(parts)
        g_ratio = float(np.linalg.norm(env.gravity)) / STANDARD_GRAVITY  # loads in the environment's body weights
        lbx, ubx = self.bounds(data.locks, shared_load=self.ff.naturalness.shared_load * g_ratio)
        if self.rising:  # [stairs] joints off their limits (solver.spacetime.stairs)
            lbx, ubx = stairs_joint_bounds(self, lbx, ubx)
        x0 = np.clip(x0, lbx, ubx)
        args: dict[str, Any] = dict(x0=x0, p=p, lbx=lbx, ubx=ubx, lbg=lbg, ubg=ubg)
        opts: dict[str, Any] = {"ipopt.max_iter": int(options.max_iter)}
        if start.warm:
            args["lam_x0"], args["lam_g0"] = start.lam_x, start.lam_g
            opts.update(WARM_START_IPOPT)
        opts.update(options.ipopt)
        solver = self._solver_for(opts, options.should_stop is not None)
        STOP.check = options.should_stop
        t0 = time.perf_counter()
        try:
            sol = solver(**args)
        finally:
            STOP.check = None
        wall = time.perf_counter() - t0
        stats = solver.stats()
        status = str(stats.get("return_status", "unknown"))
        x = np.asarray(sol["x"]).ravel()
        q = self.unpack_q(x)
        wr = self.unpack_wrenches(x, ref, dpsi) if self.dynamics else None
        obj, gval, mk_sum = (np.asarray(v).ravel() for v in self._fg(x, p))
        viol = 0.0
        if self.ng:
            viol = float(np.max(np.maximum(lbg - gval, 0) + np.maximum(gval - ubg, 0)))
        return SolveResult(
            success=bool(stats.get("success", False)) and status in SUCCESS_STATUSES,
            status=status, iterations=int(stats.get("iter_count", -1)), wall_time=wall, q=q, wrenches=wr,
            objective=float(obj[0]), marker_rms=math.sqrt(max(float(mk_sum[0]), 0.0) / (self.n_markers * self.T)),
            lam_x=np.asarray(sol["lam_x"]).ravel(), lam_g=np.asarray(sol["lam_g"]).ravel(), max_violation=viol,
            stats={"n_variables": self.nx, "n_constraints": self.ng, "build_time": self.build_time,
                   "active_bounds": self.active_bounds(x, gval, lbg, ubg, lbx, ubx)},
            v=self.unpack_v(x) if self.dynamics else None, heading_change=dpsi,
        )

    def active_bounds(self, x: np.ndarray, g: np.ndarray, lbg: np.ndarray, ubg: np.ndarray, lbx: np.ndarray,
                      ubx: np.ndarray, tol: float = 1e-6) -> dict[str, int]:
        """Where a solution ``x`` (constraint values ``g``) rests on an inequality: per constraint group
        ("clearance", "crossover", "feet", "joint_rate", …) the rows within ``tol`` (their scaled units) of
        a bound they do not share with the other side (equalities are not counted), and per coordinate
        ("bound:knee_angle_r") the knots at its variable bounds (joint limits, the stairs' margins). An
        optimum whose figure equals a safety bound shows here, before any check looks at it."""
        def count(v: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> int:
            return int(((lo < hi) & (((v - lo) < tol) | ((hi - v) < tol))).sum())

        rows = {name: np.asarray(r, dtype=int) for name, r in self._groups.items()}
        counts = {name: count(g[r], lbg[r], ubg[r]) for name, r in rows.items()}
        names = self.character.coordinate_names
        knots = {f"bound:{names[i]}": np.unique(self._q_index[i]) for i in range(6, self.n)}  # joints: not the root
        counts.update({name: count(x[k], lbx[k], ubx[k]) for name, k in knots.items()})
        return {name: c for name, c in counts.items() if c}

    def _solver_for(self, opts: Mapping[str, Any], stoppable: bool) -> ca.Function:
        """IPOPT options are fixed per solver instance: one instance per option set, all
        sharing the same pre-built derivative functions (cheap to create)."""
        key = tuple(sorted((k, str(v)) for k, v in opts.items())) + (("stoppable", stoppable),)
        solver = self._solver_cache.get(key)
        if solver is None:
            full = dict(self._base_options)
            full.update(opts)
            full["hess_lag"] = self._hess
            if self.ng:
                full["jac_g"] = self._jac
            if stoppable:
                full["iteration_callback"] = STOP_CALLBACK.get(self.nx, self.ng)
            solver = ca.nlpsol("spacetime", "ipopt", self._nlp, full)  # type: ignore[arg-type]
            self._solver_cache[key] = solver
        return solver
