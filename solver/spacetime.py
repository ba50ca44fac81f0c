"""Spacetime optimization of a motion (SPEC §6, eq. 5.29) with CasADi + IPOPT.

The NLP is built once per *structure* — character, number of frames, frame rate, contact
schedule, cyclic flag, dynamics on/off — and re-solved with new *parameter values*:
guide motion (as marker positions), gravity vector, friction coefficient, weights, and
per-frame reference points of the contact wrenches. Continuation changes values, not code.

Decision variables: the coordinates of every frame and, at every frame where the
equations of motion are written, one contact wrench per foot. Constraints (SPEC 5.5–5.28)
with the conditioning fixes of SPEC §10:

* joint limits are variable bounds (locked coordinates: equal bounds);
* cyclic motion: coordinates that repeat (joints, root height, pitch, roll) are
  *eliminated* for the two overlap frames (q_{T-1} ≡ q_1, q_T ≡ q_2); the root's
  horizontal velocity and yaw rate are periodic *in the walker's heading frame* (so a
  curved walk can be cyclic); contact constraints of the overlap frames, which would
  duplicate those of frames 1–2, are not written;
* an independent set of contact equations: an active point is on the ground (z = 0); a
  point active in two consecutive frames does not slide (x, y) — except the toe of a foot
  whose heel is also pinned, which only keeps its sideways component (the heel–toe
  distance is rigid: its x, y would over-determine the foot);
* inactive points are above the ground (z ≥ 0); a foot with no active point has a zero
  wrench (bounds); friction cone μ²f_z² ≥ f_x² + f_y², f_z ≥ 0; CoP inside the foot box ∩
  ground, linear in the wrench once multiplied by f_z (SPEC 4.26–4.29);
* whole-body equations of motion at every interior frame: root wrench h0(q, q̇, q̈, g)
  (our RNEA on central differences) equals the sum of the contact wrenches.

**Derivatives.** The problem is a sum of a few kinds of per-frame terms. Each kind is a
small generic SX function (e.g. the EOM of one frame: 3n + 12 inputs); its exact Hessian
of the Lagrangian is generated once, evaluated for all frames with ``map``, and scattered
into the global sparse Hessian by one constant sparse matrix. This keeps the build time
linear in the number of frames (a global symbolic Hessian is superlinear: 22 s instead of
~1 s for the full body) with the same exact second derivatives.

Contact wrench variables are scaled (force / body weight, moment / (weight × leg length))
and expressed about a per-frame reference point on the ground under each foot, so they are
O(1); the public API speaks world wrenches about the origin (motion file v1).
"""

from __future__ import annotations

import logging
import math
import time
import weakref
from dataclasses import dataclass, field
from typing import Any, Mapping

import casadi as ca
import numpy as np
import scipy.sparse as sps

from solver import spatial as sp
from solver.character import Character
from solver.dynamics import casadi_functions
from solver.kinematics import contact_points, forward_kinematics, marker_points, markers, point_world, standing_leg_length
from solver.motion import FEET, foot_schedule_of

log = logging.getLogger(__name__)

#: root coordinates that repeat over a cycle (root_tz, pitch, roll); x, y, yaw: periodic rates
ROOT_PERIODIC = (2, 4, 5)
MARKER_SCALE = 0.01  # m: the objective is in units of (1 cm)²
MAP_THREADS = 2  # per-frame derivative evaluations run on this many threads
DEFAULT_IPOPT = {
    "ipopt.print_level": 0,
    "print_time": False,
    "ipopt.sb": "yes",
    "ipopt.mu_strategy": "adaptive",
    "ipopt.tol": 1e-7,
    "ipopt.constr_viol_tol": 1e-9,
    "ipopt.acceptable_iter": 0,  # never stop on the looser "acceptable" criterion
    "ipopt.linear_solver": "mumps",
    "ipopt.mumps_pivot_order": 2,  # AMF: the least fill-in on these banded KKT systems (measured)
    "error_on_fail": False,
}
SUCCESS_STATUSES = ("Solve_Succeeded",)


@dataclass(frozen=True)
class Environment:
    gravity: tuple[float, float, float] = (0.0, 0.0, -9.81)
    friction: float = 1.0

    def to_dict(self) -> dict:
        return {"gravity": [float(g) for g in self.gravity], "friction": float(self.friction)}

    @staticmethod
    def from_dict(d: Mapping[str, Any] | None) -> "Environment":
        if not d:
            return Environment()
        g = tuple(float(x) for x in d.get("gravity", (0.0, 0.0, -9.81)))
        return Environment(g, float(d.get("friction", 1.0)))  # type: ignore[arg-type]


@dataclass(frozen=True)
class Weights:
    direction: float = 1.0  # η_dir
    singularity: float = 1e-5  # η_sing
    #: [beyond] tiny weight on the squared contact wrenches (scaled by body weight and leg
    #: length): in double support only their sum is constrained, so without it the split
    #: is a flat direction of the NLP and IPOPT's tail convergence crawls.
    wrench: float = 1e-4
    #: [beyond] weak prior toward the guide's joint coordinates (not the root): one marker per
    #: segment leaves some rotations unobserved (a head turning about its own axis moves no
    #: marker; axial hip/shoulder rotation with a straight knee/elbow hardly does). Scaled so
    #: that 0.1 rad weighs like 1 mm of marker distance.
    coordinates: float = 1.0


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
    lam_x: np.ndarray
    lam_g: np.ndarray
    max_violation: float  # largest constraint violation (scaled units)
    stats: Mapping[str, Any] = field(default_factory=dict)


# --- generic per-frame functions (built once per character) ------------------------------


class FrameFunctions:
    """Generic SX functions of one frame and their Lagrangian Hessians."""

    def __init__(self, character: Character) -> None:
        t0 = time.perf_counter()
        ch = character
        self.character = ch
        n = ch.n
        self.n = n
        model = ch.model
        self.n_markers = len(marker_points(ch))
        P = len(ch.contacts)
        self.P = P
        self.weight_scale = ch.total_mass * 9.81
        self.length_scale = standing_leg_length(ch)
        self.moment_scale = self.weight_scale * self.length_scale

        q = ca.SX.sym("q", n)
        pose = forward_kinematics(ch, q)
        mk = markers(ch, q)
        pts = []
        for c in ch.contacts:
            b, pb = model.point_on_body(c.segment, c.position)
            pts.append(ca.vertcat(*point_world(pose, b, pb)))
        self.kin = ca.Function("kin", [q], [mk, ca.vertcat(*pts) if pts else ca.SX(0, 1)])

        # objective: wts = (weight of marker term, weight of singularity term)
        gm = ca.SX.sym("gm", 3 * self.n_markers)
        wts = ca.SX.sym("wts", 3)
        gq = ca.SX.sym("gq", n)
        cost = wts[0] * ca.sumsqr(mk - gm) + wts[2] * ca.sumsqr(q[6:] - gq[6:])
        sing = list(ch.singular_dofs)
        if sing:
            cost += wts[1] * sum((1 - ca.cos(2 * q[i])) / 2 for i in sing)
        self.cost = ca.Function("cost", [q, gm, gq, wts], [cost])
        self.n_sing = len(sing)

        self.has_contacts = P > 0 and len(ch.feet) == 2
        if self.has_contacts:
            self._contact_functions(q, pose, pts)
            self._eom_function()
        # the EOM are linear in the wrenches: their Hessian only involves the three frames' q
        hess_vars = dict(self.hess_args, eom=3)
        self.hessians = {name: _lagrangian_hessian(fn, hess_vars[name]) for name, fn in self.functions().items()}
        self.jacobians = {name: _jacobian(fn, self.hess_args[name]) for name, fn in self.functions().items()}
        self.build_time = time.perf_counter() - t0

    def functions(self) -> dict[str, ca.Function]:
        out = {"cost": self.cost}
        if self.has_contacts:
            out.update({"z": self.z, "slip": self.slip, "feet": self.feet, "eom": self.eom})
        return out

    @property
    def hess_args(self) -> dict[str, int]:
        """How many leading inputs of each function are decision variables."""
        return {"cost": 1, "z": 1, "slip": 2, "feet": 2, "eom": 4}

    def _contact_functions(self, q: ca.SX, pose, pts: list) -> None:
        ch = self.character
        model = ch.model
        z = ca.vertcat(*[p[2] for p in pts])
        self.z = ca.Function("z", [q], [z])
        # heel (rearmost point of each foot in its segment frame) and toe
        self.heel_of: dict[str, int] = {}
        self.toe_of: dict[str, int] = {}
        for side in FEET:
            idx = [j for j, c in enumerate(ch.contacts) if c.side == side]
            if len(idx) != 2:
                raise ValueError(f"the {side} foot needs exactly two contact points (heel, toe)")
            xs = [ch.contacts[j].position[0] for j in idx]
            self.heel_of[side] = idx[int(np.argmin(xs))]
            self.toe_of[side] = idx[int(np.argmax(xs))]
        qb = ca.SX.sym("qb", ch.n)
        pts_b = self.kin(qb)[1]
        rows = []
        for j in range(self.P):
            rows.append(pts_b[3 * j : 3 * j + 2] - pts[j][:2])
        for side in FEET:
            h, t = self.heel_of[side], self.toe_of[side]
            axis = pts[t][:2] - pts[h][:2]
            perp = ca.vertcat(-axis[1], axis[0]) / ca.sqrt(ca.sumsqr(axis))
            rows.append(ca.dot(pts_b[3 * t : 3 * t + 2] - pts[t][:2], perp))
        self.slip = ca.Function("slip", [q, qb], [ca.vertcat(*rows)])  # 2P + 2 rows

        # feet: friction cone + 6 CoP half-spaces per foot, for the wrench of each foot
        w = ca.SX.sym("w", 12)
        mu = ca.SX.sym("mu")
        ref = ca.SX.sym("ref", 4)
        rows = []
        for k, side in enumerate(FEET):
            foot = ch.foot(side)
            body = model.seg_body[foot.segment]
            rot_box = model.seg_rot[foot.segment]
            center = model.seg_pos[foot.segment] + rot_box @ foot.center
            r_box = sp.matmul(pose.rot[body], sp.const_mat(rot_box))
            R = ca.vertcat(*[ca.horzcat(*r_box[i]) for i in range(3)])
            pc = ca.vertcat(*point_world(pose, body, center))
            wk = w[6 * k : 6 * k + 6]
            nmom = wk[:3] * self.moment_scale
            fs = wk[3:]
            fz = fs[2] * self.weight_scale
            rows.append(mu**2 * fs[2] ** 2 - fs[0] ** 2 - fs[1] ** 2)
            fu = ca.vertcat(fz * ref[2 * k] - nmom[1], fz * ref[2 * k + 1] + nmom[0], 0)
            local = ca.mtimes(R.T, fu - fz * pc) / self.weight_scale
            fzs = fs[2]
            for kk in range(3):
                rows.append(foot.half[kk] * fzs - local[kk])
                rows.append(foot.half[kk] * fzs + local[kk])
        self.feet = ca.Function("feet", [q, w, mu, ref], [ca.vertcat(*rows)])  # 14 rows

    def _eom_function(self) -> None:
        ch = self.character
        n = ch.n
        h0fn = casadi_functions(ch)["h0"]
        qm, q0, qp = ca.SX.sym("qm", n), ca.SX.sym("q0", n), ca.SX.sym("qp", n)
        w = ca.SX.sym("w", 12)
        g = ca.SX.sym("g", 3)
        dt = ca.SX.sym("dt")
        ref = ca.SX.sym("ref", 4)
        anchor = ca.SX.sym("anchor", 3)
        qd = (qp - qm) / (2 * dt)
        qdd = (qp - 2 * q0 + qm) / (dt * dt)
        h0 = h0fn(q0, qd, qdd, g)
        n_res = h0[:3] - ca.cross(anchor, h0[3:])
        f_res = h0[3:]
        for k in range(2):
            wk = w[6 * k : 6 * k + 6]
            n_r = wk[:3] * self.moment_scale
            f = wk[3:] * self.weight_scale
            r = ca.vertcat(ref[2 * k], ref[2 * k + 1], 0)
            n_res = n_res - (n_r + ca.cross(r - anchor, f))
            f_res = f_res - f
        out = ca.vertcat(n_res / self.moment_scale, f_res / self.weight_scale)
        self.eom = ca.Function("eom", [qm, q0, qp, w, g, dt, ref, anchor], [out])


def _lagrangian_hessian(fn: ca.Function, n_var_inputs: int) -> ca.Function:
    """H(vars..., params..., lam) = triu(∇²_vars (lam · fn)) for a generic frame function."""
    ins = [ca.SX.sym(fn.name_in(i), fn.sparsity_in(i)) for i in range(fn.n_in())]
    out = fn(*ins)
    lam = ca.SX.sym("lam", out.shape[0])
    z = ca.vertcat(*ins[:n_var_inputs])
    H = ca.triu(ca.hessian(ca.dot(lam, out), z)[0])
    return ca.Function(f"hess_{fn.name()}", ins + [lam], [H])


def _jacobian(fn: ca.Function, n_var_inputs: int) -> ca.Function:
    """J(vars..., params...) = ∂fn/∂(vars) for a generic frame function."""
    ins = [ca.SX.sym(fn.name_in(i), fn.sparsity_in(i)) for i in range(fn.n_in())]
    out = fn(*ins)
    return ca.Function(f"jac_{fn.name()}", ins, [ca.jacobian(out, ca.vertcat(*ins[:n_var_inputs]))])


_FRAME_CACHE: "weakref.WeakKeyDictionary[Character, FrameFunctions]" = weakref.WeakKeyDictionary()


def frame_functions(character: Character) -> FrameFunctions:
    ff = _FRAME_CACHE.get(character)
    if ff is None:
        ff = FrameFunctions(character)
        _FRAME_CACHE[character] = ff
    return ff


# --- the NLP ------------------------------------------------------------------------------


class _Terms:
    """A generic function mapped over calls, its variable indices and selected rows."""

    def __init__(self, name: str, nvar: int, zidx: np.ndarray, rows_out: int) -> None:
        self.name = name
        self.nvar = nvar  # number of variable inputs (z = their vertcat)
        self.zidx = zidx  # (nz, N): global x index of each z entry, per call
        self.rows_out = rows_out
        self.selected: list[tuple[int, int]] = []  # (call, row) in constraint order

    @property
    def ncalls(self) -> int:
        return int(self.zidx.shape[1])


class SpacetimeProblem:
    """The NLP of SPEC 5.29 for one structure; solve it many times with new parameters."""

    def __init__(
        self,
        character: Character,
        T: int,
        fps: float,
        contacts: np.ndarray | None,
        *,
        cyclic: bool = True,
        dynamics: bool = True,
        ipopt_options: Mapping[str, Any] | None = None,
    ) -> None:
        t0 = time.perf_counter()
        self.character = character
        self.T = Tn = int(T)
        self.fps = float(fps)
        self.dt = 1.0 / self.fps
        self.cyclic = bool(cyclic)
        self.dynamics = bool(dynamics)
        n = self.n = character.n
        if Tn < (5 if cyclic else 3):
            raise ValueError(f"too few frames for a spacetime problem: {T}")
        ff = self.ff = frame_functions(character)
        if dynamics:
            if not ff.has_contacts:
                raise ValueError("the character needs heel/toe contact points and a foot box on both feet")
            if contacts is None:
                raise ValueError("a dynamic spacetime problem needs a contact schedule")
            contacts = np.asarray(contacts, dtype=bool)
            if contacts.shape != (ff.P, Tn):
                raise ValueError(f"contact schedule must be ({ff.P}, {Tn}), got {contacts.shape}")
            if cyclic and not (np.array_equal(contacts[:, Tn - 2], contacts[:, 0])
                               and np.array_equal(contacts[:, Tn - 1], contacts[:, 1])):
                raise ValueError("a cyclic contact schedule must repeat frames 1-2 in its last two frames")
        self.contacts = None if contacts is None else contacts.copy()
        self.weight_scale, self.moment_scale = ff.weight_scale, ff.moment_scale
        self.n_markers = ff.n_markers

        # --- variable layout ---------------------------------------------------------------
        periodic = np.zeros(n, dtype=bool)
        if cyclic:
            periodic[6:] = True
            periodic[list(ROOT_PERIODIC)] = True
        self.periodic = periodic
        q_index = np.zeros((n, Tn), dtype=int)
        k = 0
        for i in range(n):
            nfree = Tn - 2 if periodic[i] else Tn
            for t in range(Tn):
                q_index[i, t] = k + (t if t < nfree else t - (Tn - 2))
            k += nfree
        self._q_index = q_index
        self.nq_vars = k
        self.eom_frames = list(range(1, Tn - 1)) if dynamics else []
        self.distinct_frames = list(range(Tn - 2)) if cyclic else list(range(Tn))
        w_index = np.zeros((12, len(self.eom_frames)), dtype=int)
        for c in range(len(self.eom_frames)):
            w_index[:, c] = k + np.arange(12)
            k += 12
        self._w_index = w_index
        self.nx = k

        x = ca.MX.sym("x", self.nx)
        # parameters: guide markers (3nm x T), g (3), mu, wts (2), ref (4 x T), anchor (3 x T)
        nm3 = 3 * ff.n_markers
        self._p_layout = {}
        off = 0
        for name, size in (("gm", nm3 * Tn), ("gq", n * Tn), ("g", 3), ("mu", 1), ("wts", 4), ("ref", 4 * Tn),
                           ("anchor", 3 * Tn)):
            self._p_layout[name] = (off, size)
            off += size
        p = ca.MX.sym("p", off)

        def par(name: str, shape: tuple[int, int] | None = None) -> ca.MX:
            o, s = self._p_layout[name]
            v = p[o : o + s]
            return ca.reshape(v, *shape) if shape else v

        GM = par("gm", (nm3, Tn))
        GQ = par("gq", (n, Tn))
        grav, mu, wts = par("g"), par("mu"), par("wts")
        REF, ANCHOR = par("ref", (4, Tn)), par("anchor", (3, Tn))
        Q = ca.reshape(x[q_index.ravel(order="F").tolist()], n, Tn)

        terms: list[_Terms] = []
        # objective
        cost_terms = _Terms("cost", 1, q_index, 1)
        cw = ca.vertcat(wts[0], wts[1], wts[3])
        fcost = ff.cost.map(Tn)(Q, GM, GQ, ca.repmat(cw, 1, Tn))
        objective = ca.sum2(fcost)
        self._cost_map = (cost_terms, [GM, GQ, ca.repmat(cw, 1, Tn)])
        xw = x[self.nq_vars:]
        if self.nx > self.nq_vars:
            objective = objective + wts[2] * ca.sumsqr(xw)
        self._wts_sym = wts

        g_parts: list[ca.MX] = []
        lbg: list[np.ndarray] = []
        ubg: list[np.ndarray] = []
        self._groups: dict[str, list[int]] = {}
        self._hess_inputs: list[tuple[_Terms, list[ca.MX], ca.MX]] = []  # (terms, param inputs, outputs)

        def add_rows(name: str, expr: ca.MX, lo: np.ndarray, hi: np.ndarray) -> None:
            start = sum(int(e.shape[0]) for e in g_parts)
            g_parts.append(expr)
            lbg.append(np.asarray(lo, dtype=float))
            ubg.append(np.asarray(hi, dtype=float))
            self._groups.setdefault(name, []).extend(range(start, start + int(expr.shape[0])))

        if cyclic:
            self._add_cyclic_root(x, add_rows, terms)

        if dynamics:
            A = self.contacts
            frames = self.distinct_frames
            # contact heights
            zt = _Terms("z", 1, q_index[:, frames], ff.P)
            zout = ff.z.map(len(frames))(Q[:, frames])
            sel, lo, hi = [], [], []
            for c, t in enumerate(frames):
                for j in range(ff.P):
                    sel.append((c, j))
                    lo.append(0.0)
                    hi.append(0.0 if A[j, t] else math.inf)
            self._select(zt, zout, sel, "contact", lo, hi, add_rows, [])
            terms.append(zt)
            # no slip between consecutive frames
            pairs = [t for t in frames if t + 1 < Tn]
            st = _Terms("slip", 2, np.vstack([q_index[:, pairs], q_index[:, [t + 1 for t in pairs]]]), 2 * ff.P + 2)
            sout = ff.slip.map(len(pairs))(Q[:, pairs], Q[:, [t + 1 for t in pairs]])
            sel = []
            for c, t in enumerate(pairs):
                for s_i, side in enumerate(FEET):
                    h, toe = ff.heel_of[side], ff.toe_of[side]
                    heel_pinned = A[h, t] and A[h, t + 1]
                    toe_pinned = A[toe, t] and A[toe, t + 1]
                    if heel_pinned:
                        sel += [(c, 2 * h), (c, 2 * h + 1)]
                    if toe_pinned and heel_pinned:
                        sel.append((c, 2 * ff.P + s_i))
                    elif toe_pinned:
                        sel += [(c, 2 * toe), (c, 2 * toe + 1)]
            self._select(st, sout, sel, "no_slip", [0.0] * len(sel), [0.0] * len(sel), add_rows, [])
            terms.append(st)
            # feet: friction cone and CoP (only feet in contact)
            E = self.eom_frames
            B = self.foot_contact()
            W = ca.reshape(x[w_index.ravel(order="F").tolist()], 12, len(E))
            ft = _Terms("feet", 2, np.vstack([q_index[:, E], w_index]), 14)
            fin = [ca.repmat(mu, 1, len(E)), REF[:, E]]
            fout = ff.feet.map(len(E))(Q[:, E], W, *fin)
            sel = []
            for c, t in enumerate(E):
                for k_, side in enumerate(FEET):
                    if B[k_, t]:
                        sel += [(c, 7 * k_ + r) for r in range(7)]
            self._select(ft, fout, sel, "feet", [0.0] * len(sel), [math.inf] * len(sel), add_rows, fin)
            terms.append(ft)
            # equations of motion
            et = _Terms("eom", 4, np.vstack([q_index[:, [t - 1 for t in E]], q_index[:, E],
                                             q_index[:, [t + 1 for t in E]], w_index]), 6)
            ein = [ca.repmat(grav, 1, len(E)), ca.DM.ones(1, len(E)) * self.dt, REF[:, E], ANCHOR[:, E]]
            eout = ff.eom.map(len(E))(Q[:, [t - 1 for t in E]], Q[:, E], Q[:, [t + 1 for t in E]], W, *ein)
            sel = [(c, r) for c in range(len(E)) for r in range(6)]
            self._select(et, eout, sel, "eom", [0.0] * len(sel), [0.0] * len(sel), add_rows, ein)
            terms.append(et)

        g = ca.vertcat(*g_parts) if g_parts else ca.MX(0, 1)
        self.ng = int(g.shape[0])
        self._lbg = np.concatenate(lbg) if lbg else np.zeros(0)
        self._ubg = np.concatenate(ubg) if ubg else np.zeros(0)
        self._terms = terms
        self._jac, self._hess = self._build_derivatives(x, p, Q, g)
        self._nlp = {"x": x, "p": p, "f": objective, "g": g}
        self._fg = ca.Function("fg", [x, p], [objective, g, ca.sum2(ff.cost.map(Tn)(Q, GM, GQ, ca.repmat(
            ca.vertcat(1.0, 0.0, 0.0), 1, Tn)))])
        self._base_options = dict(DEFAULT_IPOPT)
        if ipopt_options:
            self._base_options.update(ipopt_options)
        self._solver_cache: dict[tuple, ca.Function] = {}
        self.build_time = time.perf_counter() - t0
        log.info("spacetime NLP: %d variables, %d constraints, built in %.2f s", self.nx, self.ng, self.build_time)

    # --- construction helpers ---------------------------------------------------------------
    def _select(self, terms: _Terms, out: ca.MX, sel: list[tuple[int, int]], name: str, lo, hi, add_rows,
                params: list[ca.MX]) -> None:
        terms.selected = sel
        terms.params = params  # type: ignore[attr-defined]
        if not sel:
            return
        flat = [c * terms.rows_out + r for c, r in sel]
        add_rows(name, ca.vec(out)[flat], np.asarray(lo), np.asarray(hi))
        terms.g_offset = self._groups[name][-len(sel)]  # type: ignore[attr-defined]

    def _add_cyclic_root(self, x: ca.MX, add_rows, terms: list[_Terms]) -> None:
        Tn = self.T
        qi = self._q_index
        # z = (x_0, x_1, x_{T-2}, x_{T-1}, y_0, y_1, y_{T-2}, y_{T-1}, yaw_0), plus yaw at 1, T-2, T-1
        z = ca.SX.sym("z", 12)
        xa, ya, yaw = z[0:4], z[4:8], z[8:12]

        def heading(vx, vy, psi):
            c, s = ca.cos(psi), ca.sin(psi)
            return ca.vertcat(c * vx + s * vy, -s * vx + c * vy)

        rows = ca.vertcat(
            heading(xa[3] - xa[2], ya[3] - ya[2], yaw[2]) - heading(xa[1] - xa[0], ya[1] - ya[0], yaw[0]),
            (yaw[3] - yaw[2]) - (yaw[1] - yaw[0]),
        )
        fn = ca.Function("cyc", [z], [rows])
        frames = [0, 1, Tn - 2, Tn - 1]
        zidx = np.concatenate([qi[0, frames], qi[1, frames], qi[3, frames]])[:, None]
        t_ = _Terms("cyc", 1, zidx, 3)
        out = fn(x[zidx[:, 0].tolist()])
        self._cyc_fn = fn
        self._select(t_, out, [(0, 0), (0, 1), (0, 2)], "cyclic_root", [0.0] * 3, [0.0] * 3, add_rows, [])
        terms.append(t_)

    def _term_function(self, t_: _Terms) -> ca.Function:
        return self._cyc_fn if t_.name == "cyc" else self.ff.functions()[t_.name]

    def _term_vars(self, x: ca.MX, t_: _Terms, fn: ca.Function) -> list[ca.MX]:
        out, o = [], 0
        for i in range(t_.nvar):
            s = fn.size1_in(i)
            out.append(ca.reshape(x[t_.zidx[o : o + s].ravel(order="F").tolist()], s, t_.ncalls))
            o += s
        return out

    def _mapped(self, fn: ca.Function, ncalls: int) -> ca.Function:
        # threads pay off only for the heavy per-frame functions (EOM derivatives)
        if ncalls > 1 and fn.n_instructions() > 20000 * MAP_THREADS:
            return fn.map(ncalls, "thread", MAP_THREADS)
        return fn.map(ncalls) if ncalls > 1 else fn

    def _build_derivatives(self, x: ca.MX, p: ca.MX, Q: ca.MX, g: ca.MX) -> tuple[ca.Function, ca.Function]:
        """jac_g(x, p) = (g, ∂g/∂x) and hess_lag(x, p, lam_f, lam_g) = triu ∇²(lam_f f + lam_g·g),
        both assembled from per-frame derivatives of the generic frame functions."""
        ff = self.ff
        lam_f = ca.MX.sym("lam_f")
        lam_g = ca.MX.sym("lam_g", self.ng)
        lam_ext = ca.vertcat(lam_g, 0)  # index ng -> a zero multiplier (rows not in the NLP)
        hblocks: list[tuple[ca.MX, np.ndarray, ca.Sparsity, np.ndarray | None]] = []
        jblocks: list[tuple[ca.MX, np.ndarray, ca.Sparsity, np.ndarray]] = []

        cost_terms, cost_params = self._cost_map
        hc = self._mapped(ff.hessians["cost"], self.T)(Q, *cost_params, ca.repmat(lam_f, 1, self.T))
        hblocks.append((hc, cost_terms.zidx, ff.hessians["cost"].sparsity_out(0), None))
        for t_ in self._terms:
            if not t_.selected:
                continue
            fn = self._term_function(t_)
            rowmap = np.full((t_.rows_out, t_.ncalls), -1, dtype=int)
            for k, (c, r) in enumerate(t_.selected):
                rowmap[r, c] = t_.g_offset + k  # type: ignore[attr-defined]
            zvars = self._term_vars(x, t_, fn)
            params = t_.params  # type: ignore[attr-defined]
            lam_idx = np.where(rowmap >= 0, rowmap, self.ng)
            LAM = ca.reshape(lam_ext[lam_idx.ravel(order="F").tolist()], t_.rows_out, t_.ncalls)
            hf = _lagrangian_hessian(fn, t_.nvar) if t_.name == "cyc" else ff.hessians[t_.name]
            h = self._mapped(hf, t_.ncalls)(*zvars, *params, LAM)
            hblocks.append((h, t_.zidx, hf.sparsity_out(0), None))
            jf = _jacobian(fn, t_.nvar) if t_.name == "cyc" else ff.jacobians[t_.name]
            jv = self._mapped(jf, t_.ncalls)(*zvars, *params)
            jblocks.append((jv, t_.zidx, jf.sparsity_out(0), rowmap))

        if self.nx > self.nq_vars:  # wrench regularization: 2 lam_f wts[2] on the wrench diagonal
            nw = self.nx - self.nq_vars
            idx = np.arange(self.nq_vars, self.nx)
            diag = ca.repmat(2 * lam_f * p[self._p_layout["wts"][0] + 2], 1, nw)
            hblocks.append((diag, idx[None, :], ca.Sparsity.dense(1, 1), None))
        H = self._scatter(hblocks, self.nx, self.nx, symmetric=True)
        J = self._scatter(jblocks, self.ng, self.nx, symmetric=False)
        self.hessian_nnz = int(H.nnz())
        self.jacobian_nnz = int(J.nnz())
        hess = ca.Function("nlp_hess_l", [x, p, lam_f, lam_g], [H], ["x", "p", "lam_f", "lam_g"], ["hess"])
        jac = ca.Function("nlp_jac_g", [x, p], [g, J], ["x", "p"], ["g", "jac_g_x"])
        return jac, hess

    @staticmethod
    def _scatter(blocks, nrows: int, ncols: int, *, symmetric: bool) -> ca.MX:
        """Sum mapped per-call derivative blocks into one global sparse matrix.

        Each block: (values (m x nz*N, repeated sparsity), zidx (nz, N) global column of each
        local column, local sparsity, rowmap (m, N) global row or -1, None = symmetric).
        """
        rows_all, cols_all, src_all, fac_all, parts = [], [], [], [], []
        offset = 0
        for vals, zidx, spz, rowmap in blocks:
            r, c = (np.asarray(v, dtype=int) for v in spz.get_triplet())
            nnz, ncall = len(r), zidx.shape[1]
            if nnz == 0:
                continue
            src = offset + np.arange(nnz * ncall).reshape(ncall, nnz).T  # (nnz, ncall)
            b = zidx[c]
            if symmetric:
                a = zidx[r]
                gr, gc = np.minimum(a, b), np.maximum(a, b)
                fac = np.where((r != c)[:, None] & (a == b), 2.0, 1.0)
                keep = np.ones_like(gr, dtype=bool)
            else:
                gr = rowmap[r]  # (nnz, ncall)
                gc = b
                fac = np.ones(gr.shape)
                keep = gr >= 0
            rows_all.append(gr[keep])
            cols_all.append(gc[keep])
            src_all.append(src[keep])
            fac_all.append(fac[keep])
            parts.append(ca.vec(vals.nz[:]))
            offset += nnz * ncall
        rows_g = np.concatenate(rows_all)
        cols_g = np.concatenate(cols_all)
        keys = cols_g.astype(np.int64) * nrows + rows_g
        uniq, inv = np.unique(keys, return_inverse=True)
        ucols, urows = np.divmod(uniq, nrows)  # sorted keys = CasADi's column-major order
        S = sps.csc_matrix((np.concatenate(fac_all), (inv, np.concatenate(src_all))), shape=(len(uniq), offset))
        S.sort_indices()
        Sd = ca.DM(ca.Sparsity(S.shape[0], S.shape[1], S.indptr.tolist(), S.indices.tolist()), S.data)
        pattern = ca.Sparsity.triplet(nrows, ncols, urows.tolist(), ucols.tolist())
        return ca.MX(pattern, ca.mtimes(Sd, ca.vertcat(*parts)))

    # --- public API ------------------------------------------------------------------------------
    def foot_contact(self) -> np.ndarray:
        if self.contacts is None:
            return np.zeros((2, self.T), dtype=bool)
        return foot_schedule_of(self.character, self.contacts)

    def guide_markers(self, guide_q: np.ndarray) -> np.ndarray:
        mk = markers(self.character, np.asarray(guide_q, dtype=float))  # (nm, 3, T)
        return mk.reshape(self.n_markers * 3, self.T)

    def pack_q(self, q: np.ndarray) -> np.ndarray:
        x = np.zeros(self.nq_vars)
        x[self._q_index] = q  # overlap frames write the same entry; frames 0/1 win below
        x[self._q_index[:, :2]] = q[:, :2]
        return x

    def unpack_q(self, x: np.ndarray) -> np.ndarray:
        return np.asarray(x)[self._q_index]

    def ref_points(self, q: np.ndarray) -> np.ndarray:
        """Per-frame (x, y) under each foot: the mean of its contact points, on the ground."""
        cp = contact_points(self.character, q)  # (P, 3, T)
        ref = np.zeros((4, self.T))
        for k, side in enumerate(FEET):
            idx = [j for j, c in enumerate(self.character.contacts) if c.side == side]
            ref[2 * k : 2 * k + 2] = cp[idx, :2, :].mean(axis=0)
        return ref

    def anchor_points(self, q: np.ndarray) -> np.ndarray:
        a = np.zeros((3, self.T))
        a[:2] = q[:2]
        return a

    def pack_wrenches(self, wrenches: np.ndarray | None, ref: np.ndarray) -> np.ndarray:
        x = np.zeros(self.nx - self.nq_vars)
        if wrenches is None:
            return x
        for c, t in enumerate(self.eom_frames):
            for k in range(2):
                n0, f = wrenches[k, :3, t], wrenches[k, 3:, t]
                r = np.array([ref[2 * k, t], ref[2 * k + 1, t], 0.0])
                n_r = n0 - np.cross(r, f)
                idx = self._w_index[6 * k : 6 * k + 6, c] - self.nq_vars
                x[idx] = np.r_[n_r / self.moment_scale, f / self.weight_scale]
        return x

    def unpack_wrenches(self, x: np.ndarray, ref: np.ndarray) -> np.ndarray:
        out = np.zeros((2, 6, self.T))
        x = np.asarray(x).ravel()
        for c, t in enumerate(self.eom_frames):
            for k in range(2):
                w = x[self._w_index[6 * k : 6 * k + 6, c]]
                n_r, f = w[:3] * self.moment_scale, w[3:] * self.weight_scale
                r = np.array([ref[2 * k, t], ref[2 * k + 1, t], 0.0])
                out[k, :3, t] = n_r + np.cross(r, f)
                out[k, 3:, t] = f
        if self.cyclic and self.eom_frames:
            out[:, :, 0] = out[:, :, self.T - 2]
            out[:, :, self.T - 1] = out[:, :, 1]
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
        B = self.foot_contact()
        for c, t in enumerate(self.eom_frames):
            for k in range(2):
                idx = self._w_index[6 * k : 6 * k + 6, c]
                if not B[k, t]:
                    lbx[idx] = ubx[idx] = 0.0
                else:
                    lbx[idx[5]] = 0.0  # f_z >= 0
        return lbx, ubx

    def parameters(self, guide_markers: np.ndarray, guide_q: np.ndarray, env: Environment, weights: Weights,
                   ref: np.ndarray, anchor: np.ndarray) -> np.ndarray:
        wdir = weights.direction / (self.n_markers * self.T * MARKER_SCALE**2)
        wsing = weights.singularity / (max(self.ff.n_sing, 1) * self.T * MARKER_SCALE**2)
        wwr = weights.wrench / max(len(self.eom_frames), 1)
        # per marker and frame, (1 mm / 1 cm)² = 0.01 units for 1 mm; per coordinate, w (0.1 rad)² = 0.01
        wq = weights.coordinates / (max(self.n - 6, 1) * self.T)
        return np.concatenate([
            np.asarray(guide_markers, dtype=float).ravel(order="F"),
            np.asarray(guide_q, dtype=float).ravel(order="F"),
            np.asarray(env.gravity, dtype=float),
            [float(env.friction)],
            [wdir, wsing, wwr, wq],
            ref.ravel(order="F"),
            anchor.ravel(order="F"),
        ])

    def solve(
        self,
        guide_q: np.ndarray | None,
        *,
        guide_markers: np.ndarray | None = None,
        env: Environment = Environment(),
        weights: Weights = Weights(),
        init_q: np.ndarray | None = None,
        init_wrenches: np.ndarray | None = None,
        lam_x0: np.ndarray | None = None,
        lam_g0: np.ndarray | None = None,
        max_iter: int = 500,
        locks: Mapping[int, float] | None = None,
        warm: bool = False,
        ipopt_options: Mapping[str, Any] | None = None,
    ) -> SolveResult:
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
        if init_q is None:
            if guide_q is None:
                raise ValueError("give an initial motion")
            init_q = guide_q
        q0 = np.asarray(init_q, dtype=float)
        if q0.shape != (self.n, self.T) or not np.all(np.isfinite(q0)):
            raise ValueError(f"initial motion must be finite with shape ({self.n}, {self.T})")
        gq = q0 if guide_q is None else guide_q  # coordinates prior: the guide's, else the start's
        ref = self.ref_points(q0) if self.dynamics else np.zeros((4, self.T))
        anchor = self.anchor_points(q0)
        p = self.parameters(guide_markers, gq, env, weights, ref, anchor)
        x0 = np.concatenate([self.pack_q(q0), self.pack_wrenches(init_wrenches, ref)])
        lbx, ubx = self.bounds(locks)
        x0 = np.clip(x0, lbx, ubx)
        args: dict[str, Any] = dict(x0=x0, p=p, lbx=lbx, ubx=ubx, lbg=self._lbg, ubg=self._ubg)
        opts: dict[str, Any] = {"ipopt.max_iter": int(max_iter)}
        if warm and lam_x0 is not None and lam_g0 is not None:
            args["lam_x0"] = lam_x0
            args["lam_g0"] = lam_g0
            opts.update({
                "ipopt.warm_start_init_point": "yes",
                "ipopt.mu_init": 1e-4,
                "ipopt.warm_start_bound_push": 1e-6,
                "ipopt.warm_start_bound_frac": 1e-6,
                "ipopt.warm_start_slack_bound_push": 1e-6,
                "ipopt.warm_start_slack_bound_frac": 1e-6,
                "ipopt.warm_start_mult_bound_push": 1e-6,
            })
        if ipopt_options:
            opts.update(ipopt_options)
        solver = self._solver_for(opts)
        t0 = time.perf_counter()
        sol = solver(**args)
        wall = time.perf_counter() - t0
        stats = solver.stats()
        status = str(stats.get("return_status", "unknown"))
        x = np.asarray(sol["x"]).ravel()
        q = self.unpack_q(x)
        wr = self.unpack_wrenches(x, ref) if self.dynamics else None
        obj, gval, fdir_sum = (np.asarray(v).ravel() for v in self._fg(x, p))
        viol = 0.0
        if self.ng:
            viol = float(np.max(np.maximum(self._lbg - gval, 0) + np.maximum(gval - self._ubg, 0)))
        marker_rms = math.sqrt(max(float(fdir_sum[0]), 0.0) / (self.n_markers * self.T))
        return SolveResult(
            success=bool(stats.get("success", False)) and status in SUCCESS_STATUSES,
            status=status,
            iterations=int(stats.get("iter_count", -1)),
            wall_time=wall,
            q=q,
            wrenches=wr,
            objective=float(obj[0]),
            marker_rms=marker_rms,
            lam_x=np.asarray(sol["lam_x"]).ravel(),
            lam_g=np.asarray(sol["lam_g"]).ravel(),
            max_violation=viol,
            stats={"n_variables": self.nx, "n_constraints": self.ng, "build_time": self.build_time},
        )

    def _solver_for(self, opts: Mapping[str, Any]) -> ca.Function:
        """IPOPT options are fixed per solver instance: one instance per option set, all
        sharing the same pre-built Hessian function (cheap to create)."""
        key = tuple(sorted((k, str(v)) for k, v in opts.items()))
        solver = self._solver_cache.get(key)
        if solver is None:
            full = dict(self._base_options)
            full.update(opts)
            full["hess_lag"] = self._hess
            if self.ng:
                full["jac_g"] = self._jac
            solver = ca.nlpsol("spacetime", "ipopt", self._nlp, full)
            self._solver_cache[key] = solver
        return solver

    def solver_instance_options(self) -> list[tuple]:
        return list(self._solver_cache)
