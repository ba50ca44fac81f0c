"""Generic functions of one frame, one pair of frames or one spline segment (built once per
character), with their exact derivatives: the building blocks of the spacetime NLP.

Wrenches are scaled (force / body weight W, moment / (W × leg length L)) and taken about a
per-frame reference point on the ground under each foot (x, y, ground height), so they are
O(1). The ground under each contact point is a per-frame parameter (terrain: stairs).

The trajectory is the C² cubic spline through the frames (``solver.trajectory``): with knot
velocities v, the segment [a, b] of duration h is the Hermite cubic of (q_a, v_a, q_b, v_b).
"""

from __future__ import annotations

import math
import time
import weakref
from typing import Any, ClassVar

import casadi as ca
import numpy as np

from solver import spatial as sp
from solver.character import Character
from solver.dynamics import casadi_functions
from solver.kinematics import forward_kinematics, marker_points, markers, point_world, standing_leg_length
from solver.motion import FEET
from solver.naturalness import trunk_axis
from solver.spacetime import compiled
from solver.spacetime.derivatives import jacobian, lagrangian_hessian
from solver.spacetime.types import STANDARD_GRAVITY, Naturalness, Realism

FOOT_ROWS = 16  # per foot: friction cone, 6 CoP half-spaces, 2 torsion, 2 free-moment cap, pitch under load (heel
#   up, toe up), push toward the centre of mass, fore-aft force cap (2)
SOLE_CORNERS = 4  # per foot: the drawn sole's corners (heel and toe ends, both edges)
CONE_EPS = 1e-4  # smoothing of the friction cone's norm (scaled force units)
#: the weight slots (``types.WEIGHT_SLOTS`` names) a frame's cost takes, in its ``wts`` input's order
FRAME_COST_WEIGHTS = ("direction", "singularity", "coordinates", "root_rotation", "joint_range", "com_track")
CROSS_ROWS = 4  # per frame: each foot's far side of the pelvis across the direction of travel, then across its heading


def rz(turn, v):
    """Rotate the 3-vector ``v`` about the vertical by ``turn`` (symbolic)."""
    c, s = ca.cos(turn), ca.sin(turn)
    return ca.vertcat(c * v[0] - s * v[1], s * v[0] + c * v[1], v[2])


class FrameFunctions:
    """Generic SX functions and their derivatives for one character."""

    #: name -> (number of variable inputs, number of them the Hessian involves)
    VARS: ClassVar[dict[str, tuple[int, int]]] = {
        "cost": (1, 1), "acc": (3, 3), "z": (1, 1), "sole": (1, 1), "slip": (2, 2), "feet": (2, 2), "seg": (6, 4),
        "c2": (5, 5), "jerk": (4, 4), "wrate": (2, 2), "frate": (2, 2), "smooth": (3, 3), "wcom": (1, 1),
        "cross": (1, 1), "lean": (1, 1), "clr": (1, 1), "ftrack": (1, 1), "jspeed": (2, 2), "width": (1, 1)}

    def __init__(self, character: Character, realism: Realism = Realism(),
                 naturalness: Naturalness = Naturalness()) -> None:
        t0 = time.perf_counter()
        ch = self.character = character
        self.realism = realism
        self.naturalness = naturalness
        n = self.n = ch.n
        model = ch.model
        self.n_markers = len(marker_points(ch))
        P = self.P = len(ch.contacts)
        self.weight_scale = ch.total_mass * STANDARD_GRAVITY
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

        # objective of a frame: its weights (``FRAME_COST_WEIGHTS``): markers, singularity, joint
        # coordinates prior, root rotations prior, joint-range prior beyond [lo, hi]
        gm = ca.SX.sym("gm", 3 * self.n_markers)
        wts = ca.SX.sym("wts", len(FRAME_COST_WEIGHTS))
        w = {name: wts[i] for i, name in enumerate(FRAME_COST_WEIGHTS)}
        gq = ca.SX.sym("gq", n)
        lo_, hi_ = ca.SX.sym("lo", n), ca.SX.sym("hi", n)
        gc = ca.SX.sym("gc", 3)  # the whole-body centre of mass to track (the capture's)
        com_expr = ca.SX.zeros(3)
        for sg in ch.segments:
            if sg.mass > 0:
                p_com: Any = ca.vertcat(*point_world(pose, *model.point_on_body(sg.name, sg.com)))
                com_expr += float(sg.mass) * p_com
        com_expr /= float(sum(sg.mass for sg in ch.segments))
        cost = (w["direction"] * ca.sumsqr(mk - gm) + w["coordinates"] * ca.sumsqr(q[6:] - gq[6:])
                + w["root_rotation"] * ca.sumsqr(q[3:6] - gq[3:6]) + w["com_track"] * ca.sumsqr(com_expr - gc))
        if n > 6:  # the joint-range prior (bounds per coordinate: ``Layout.joint_range``)
            cost += w["joint_range"] * sum(ca.fmax(0, q[i] - hi_[i]) ** 2 + ca.fmax(0, lo_[i] - q[i]) ** 2
                                           for i in range(6, n))
        sing = list(ch.singular_dofs)
        if sing:
            cost += w["singularity"] * sum((1 - ca.cos(2 * q[i])) / 2 for i in sing)
        self.n_sing = len(sing)
        self.cost = ca.Function("cost", [q, gm, gq, wts, lo_, hi_, gc], [cost])
        self.com = ca.Function("com", [q], [com_expr])
        self.marker_cost = ca.Function("marker_cost", [q, gm], [ca.sumsqr(mk - gm)])
        # kinematic fit: squared second difference of the rotations over three frames (rad)
        qm_, qp_, ws_ = ca.SX.sym("qm", n), ca.SX.sym("qp", n), ca.SX.sym("ws")
        self.acc = ca.Function("acc", [qm_, q, qp_, ws_], [ws_ * ca.sumsqr((qm_ - 2 * q + qp_)[3:])])
        # [naturalness] a joint coordinate turning faster than ``Naturalness.joint_speed_deg_s`` between two
        # frames pays quadratically (rad/s): the joints' fastest turns, not a flap between frames (the check
        # reads the same frame differences: 450°/s)
        hs_, wjs = ca.SX.sym("h"), ca.SX.sym("wjs")
        vmax = math.radians(naturalness.joint_speed_deg_s)
        dv = (qp_ - q) / hs_
        self.jspeed = ca.Function("jspeed", [q, qp_, hs_, wjs], [wjs * sum(ca.fmax(0, dv[i] - vmax) ** 2
                                                                          + ca.fmax(0, -dv[i] - vmax) ** 2
                                                                          for i in range(6, n))])

        self.has_contacts = P > 0 and len(ch.feet) == 2
        if self.has_contacts:
            self._contact_functions(q, pose, pts)
            self._segment_functions()
        self.compiled = False  # True once compiled.start has swapped in machine-code derivatives
        self.derivatives = {name: (self.seg_hessian if name == "seg" else lagrangian_hessian(fn, self.VARS[name][1]),
                                   jacobian(fn, self.VARS[name][0]))
                            for name, fn in self.functions().items()}
        self.build_time = time.perf_counter() - t0

    def functions(self) -> dict[str, ca.Function]:
        out = {"cost": self.cost, "acc": self.acc}
        if self.has_contacts:
            out.update({"z": self.z, "sole": self.sole, "slip": self.slip, "feet": self.feet, "seg": self.seg,
                        "c2": self.c2, "jerk": self.jerk, "wrate": self.wrate, "frate": self.frate,
                        "smooth": self.smooth, "wcom": self.wcom, "cross": self.cross, "lean": self.lean,
                        "clr": self.clr, "ftrack": self.ftrack, "jspeed": self.jspeed, "width": self.width})
        return out

    # --- contact rows ---------------------------------------------------------------------
    def _foot_indices(self) -> None:
        ch = self.character
        self.heel_of: dict[str, int] = {}
        self.toe_of: dict[str, int] = {}
        for side in FEET:
            self.heel_of[side], self.toe_of[side] = ch.sole_indices(side)

    def _contact_functions(self, q: ca.SX, pose, pts: list) -> None:
        ch = self.character
        model = ch.model
        rl = self.realism
        self._foot_indices()
        self._rest_points = np.asarray(self.kin(np.zeros(ch.n))[1]).reshape(-1, 3)  # contact points at q = 0
        gnd = ca.SX.sym("ground", self.P)
        self.z = ca.Function("z", [q, gnd], [ca.vertcat(*[p[2] for p in pts]) - gnd])  # height above the ground
        # the sole's corners (``Character.sole``, in ``solver.kinematics.sole_corners``' order: heel −w,
        # heel +w, toe −w, toe +w): heights above the ground under each foot (its heel point's),
        # SOLE_CORNERS rows per foot
        corners = []
        for side in FEET:
            sole = ch.sole(side)
            for corner in sole.corners()[[1, 0, 3, 2]]:
                b, pb = model.point_on_body(sole.segment, corner)
                corners.append(point_world(pose, b, pb)[2] - gnd[self.heel_of[side]])
        self.sole = ca.Function("sole", [q, gnd], [ca.vertcat(*corners)])
        # [naturalness] a swinging foot's sole clears the ground by the walker's own margin: each corner
        # below its foot's target height (a per-frame parameter: the mid-swing target where the foot moves,
        # none elsewhere) pays quadratically (scaled: per 1 cm)
        target, wclr = ca.SX.sym("target", 2), ca.SX.sym("wclr")
        deficit = [ca.fmax(0, target[k_] - corners[SOLE_CORNERS * k_ + r]) / 0.01
                   for k_ in range(2) for r in range(SOLE_CORNERS)]
        self.clr = ca.Function("clr", [q, gnd, target, wclr], [wclr * ca.sumsqr(ca.vertcat(*deficit))])
        # [naturalness] how far each foot (the mean of its contact points) stands on the far side of
        # the pelvis across the direction of travel (a per-frame parameter): right foot, left foot
        # (rows 0-1), then across the pelvis's own heading (its yaw: rows 2-3; a turn taken in the
        # pelvis puts the inner foot on the path line)
        th = ca.SX.sym("path")
        far = []
        for heading in (th, q[3]):
            left = ca.vertcat(-ca.sin(heading), ca.cos(heading))
            for sgn, side in ((1.0, "right"), (-1.0, "left")):
                c = (pts[self.heel_of[side]][:2] + pts[self.toe_of[side]][:2]) / 2
                far.append(sgn * ca.dot(c - q[:2], left))
        self.cross = ca.Function("cross", [q, th], [ca.vertcat(*far)])
        # [naturalness] each foot in contact where the walker puts it, per 1 cm against per-frame targets
        # (the guide's; masked where the foot is off the ground): its far-side distance across the
        # direction of travel toward the guide's (the step width is the walker's own), and across the
        # pelvis's heading no nearer the far side than the guide's (a turn is not taken by yawing the pelvis
        # over a planted inner foot: with the path rows alone, a 90° curve's inner foot stood on the
        # crossover bound's edge across the pelvis's heading; tracked both ways, the turn went into the hips'
        # limits instead)
        wtarget, wmask = ca.SX.sym("wtarget", CROSS_ROWS), ca.SX.sym("wmask", 2)
        wwd, wps = ca.SX.sym("wwd"), ca.SX.sym("wps")  # the path rows' weight, the pelvis rows'
        off = [far[r] - wtarget[r] if r < 2 else ca.fmax(0, far[r] - wtarget[r]) for r in range(CROSS_ROWS)]
        self.width = ca.Function("width", [q, th, wtarget, wmask, wwd, wps],
                                 [sum((wwd if r < 2 else wps) * wmask[r % 2] * (off[r] / 0.01) ** 2
                                      for r in range(CROSS_ROWS))])
        # [naturalness] the trunk's lean against gravity in the sagittal plane of the direction of
        # travel (sine; + forward), and its prior toward a target per frame (the guide's)
        seg, trunk_local = trunk_axis(ch)
        body = model.seg_body[seg]
        rot = sp.matmul(pose.rot[body], sp.const_mat(model.seg_rot[seg]))
        u = ca.vertcat(*[sum(rot[i][j] * float(trunk_local[j]) for j in range(3)) for i in range(3)])
        g = ca.SX.sym("g", 3)
        up = -g / ca.norm_2(g)
        fwd = ca.vertcat(ca.cos(th), ca.sin(th), 0)
        fp = fwd - up * ca.dot(up, fwd)
        sin_lean = ca.dot(u, fp / ca.norm_2(fp))
        self.lean_of = ca.Function("lean_of", [q, g, th], [sin_lean])
        target, wl = ca.SX.sym("target"), ca.SX.sym("wl")
        self.lean = ca.Function("lean", [q, g, th, target, wl], [wl * (sin_lean - target) ** 2])

        # no slip between consecutive frames (x, y of pinned points; the toe's sideways
        # component when the heel is pinned too), and no spin of each foot about the vertical
        qb = ca.SX.sym("qb", ch.n)
        pose_b = forward_kinematics(ch, qb)
        pts_b = self.kin(qb)[1]
        rows = [pts_b[3 * j : 3 * j + 2] - pts[j][:2] for j in range(self.P)]
        for side in FEET:
            h, t = self.heel_of[side], self.toe_of[side]
            axis = pts[t][:2] - pts[h][:2]
            perp = ca.vertcat(-axis[1], axis[0]) / ca.sqrt(ca.sumsqr(axis))
            rows.append(ca.dot(pts_b[3 * t : 3 * t + 2] - pts[t][:2], perp))
        for side in FEET:  # z of the rotation vector of R_b R_aᵀ (world): sin of the turn about the vertical
            body = model.seg_body[ch.foot(side).segment]
            Ra, Rb = pose.rot[body], pose_b.rot[body]
            m10 = sum(Rb[1][k] * Ra[0][k] for k in range(3))
            m01 = sum(Rb[0][k] * Ra[1][k] for k in range(3))
            rows.append((m10 - m01) / 2)
        self.slip = ca.Function("slip", [q, qb], [ca.vertcat(*rows)])  # 2P + 4 rows

        # feet: friction cone, CoP box, torsional friction, free-moment cap; support (last row)
        w = ca.SX.sym("w", 12)
        mu = ca.SX.sym("mu")
        ref = ca.SX.sym("ref", 6)  # per foot: the reference point (x, y, ground height)
        com = ca.SX.sym("com", 3)  # the frame's centre of mass
        path, fa_cap = ca.SX.sym("path"), ca.SX.sym("fa_cap")  # direction of travel; fore-aft force bound
        g_ratio = ca.SX.sym("g_ratio")  # the environment's gravity over the standard: its body weight
        L = self.length_scale
        rows = []
        for k, side in enumerate(FEET):
            foot = ch.foot(side)
            # the centre of pressure within the sole (``Character.sole``: heel to toe, as wide as the foot
            # box; the box's height, for a foot not flat), the foot MuJoCo simulates and the exports draw
            box_center, half = ch.sole_box(side)
            body = model.seg_body[foot.segment]
            rot_box = model.seg_rot[foot.segment]
            center = model.seg_pos[foot.segment] + rot_box @ box_center
            r_box = sp.matmul(pose.rot[body], sp.const_mat(rot_box))
            R = ca.vertcat(*[ca.horzcat(*r_box[i]) for i in range(3)])
            pc = ca.vertcat(*point_world(pose, body, center))
            wk = w[6 * k : 6 * k + 6]
            ns, fs = wk[:3], wk[3:]
            nmom = ns * self.moment_scale
            fz = fs[2] * self.weight_scale
            # friction cone, with the walker's margin to slipping (``Naturalness.friction_use`` of μ)
            rows.append(self.naturalness.friction_use * mu * fs[2] - ca.sqrt(fs[0] ** 2 + fs[1] ** 2 + CONE_EPS**2))
            # f_z × the CoP (on the ground plane at the reference point's height)
            fu = ca.vertcat(fz * ref[3 * k] - nmom[1], fz * ref[3 * k + 1] + nmom[0], fz * ref[3 * k + 2])
            local = ca.mtimes(R.T, fu - fz * pc) / self.weight_scale
            for kk in range(3):
                rows.append(half[kk] * fs[2] - local[kk])
                rows.append(half[kk] * fs[2] + local[kk])
            # free moment at the CoP times f_z: τ f_z = n·f (moment about a ground point), scaled by W·M
            nf = ca.dot(ns, fs)
            rho = rl.torsion_radius_fraction * 2 * float(np.max(foot.half[:2]))
            ktor = rl.torsion_margin * rho / L
            rows += [ktor * mu * fs[2] ** 2 - nf, ktor * mu * fs[2] ** 2 + nf]
            cap = rl.free_moment_cap / L
            rows += [cap * fs[2] - nf, cap * fs[2] + nf]
            # [naturalness] a loaded foot is not pitched far onto its toe: f_z (sin p − sin p_free) ≤ C
            # (C in the environment's body weights, as the check counts them)
            ph, pt = pts[self.heel_of[side]], pts[self.toe_of[side]]
            d0 = float(np.linalg.norm(self._rest_points[self.toe_of[side]] - self._rest_points[self.heel_of[side]]))
            sin_p = (ph[2] - pt[2]) / d0
            nt = self.naturalness
            rows.append(nt.pitch_coefficient * g_ratio - fs[2] * (sin_p - math.sin(math.radians(nt.pitch_free_deg))))
            rows.append(nt.pitch_coefficient * g_ratio - fs[2] * (-sin_p - math.sin(math.radians(nt.pitch_free_deg))))
            # [naturalness] the ground pushes the body: the foot's horizontal force does not point away
            # from the centre of mass (a parameter), beyond push_margin × f_z × leg (in double support
            # the feet would otherwise squeeze the ground between them)
            d = (com[:2] - ref[3 * k : 3 * k + 2]) / L
            rows.append(fs[0] * d[0] + fs[1] * d[1] + nt.push_margin * fs[2])
            # [naturalness] the fore-aft force along the direction of travel within ± fa_cap (BW; a
            # parameter: ``Naturalness.fore_aft`` on level ground, unbounded elsewhere)
            f_fwd = fs[0] * ca.cos(path) + fs[1] * ca.sin(path)
            rows += [fa_cap - f_fwd, fa_cap + f_fwd]
        rows.append(rl.support_max - w[5] - w[11])
        # 2 * FOOT_ROWS + 1 rows
        self.feet = ca.Function("feet", [q, w, mu, ref, com, path, fa_cap, g_ratio], [ca.vertcat(*rows)])

    # --- spline segments --------------------------------------------------------------------
    def _segment_functions(self) -> None:
        n = self.n
        h0fn = casadi_functions(self.character)["h0"]
        qa, va, qb, vb = (ca.SX.sym(s, n) for s in ("qa", "va", "qb", "vb"))
        wa, wb = ca.SX.sym("wa", 12), ca.SX.sym("wb", 12)
        g, h, turn = ca.SX.sym("g", 3), ca.SX.sym("h"), ca.SX.sym("turn")
        ra, rb = ca.SX.sym("ra", 6), ca.SX.sym("rb", 6)
        anc_a, anc_b = ca.SX.sym("anc_a", 3), ca.SX.sym("anc_b", 3)
        M, W = self.moment_scale, self.weight_scale

        def ground(wv, ref, tr):
            """Total ground wrench about the origin (moment, force) of both feet, turned by tr."""
            n_o, f_o = ca.SX.zeros(3), ca.SX.zeros(3)
            for k in range(2):
                wk = wv[6 * k : 6 * k + 6]
                nk, fk = rz(tr, wk[:3]) * M, rz(tr, wk[3:]) * W
                r = ref[3 * k : 3 * k + 3]
                n_o += nk + ca.cross(r, fk)
                f_o += fk
            return n_o, f_o

        def residual(h0, n_g, f_g, anchor):
            dn, df = h0[:3] - n_g, h0[3:] - f_g
            return ca.vertcat((dn - ca.cross(anchor, df)) / M, df / W)

        acc_a = 6 * (qb - qa) / h**2 - (4 * va + 2 * vb) / h
        qm = (qa + qb) / 2 + h * (va - vb) / 8
        vm = 1.5 * (qb - qa) / h - (va + vb) / 4
        am = (vb - va) / h
        na, fa = ground(wa, ra, 0)
        nb, fb = ground(wb, rb, turn)
        out = ca.vertcat(residual(h0fn(qa, va, acc_a, g), na, fa, anc_a),
                         residual(h0fn(qm, vm, am, g), (na + nb) / 2, (fa + fb) / 2, (anc_a + anc_b) / 2))
        seg_in = [qa, va, qb, vb, wa, wb, g, h, ra, rb, anc_a, anc_b, turn]
        self.seg = ca.Function("seg", seg_in, [out])

        # The Hessian of its Lagrangian over (qa, va, qb, vb), by structure: the residual is
        # linear in h0 (multipliers μ = (∂residual/∂h0)ᵀ λ), the ground wrenches do not depend
        # on the motion, and the points (q, v, a) where h0 is evaluated — the frame and the
        # midpoint — are linear in (qa, va, qb, vb). So H = Σ Lᵀ ∇²(μ·h0) L with the Hessian
        # of one RNEA over (q, v, a) (a enters linearly): half the instructions of the
        # Hessian of the composed expression, the same values.
        hq, hv, ha, hmu = ca.SX.sym("q", n), ca.SX.sym("v", n), ca.SX.sym("a", n), ca.SX.sym("mu", 6)
        hh0 = ca.Function("hess_h0", [hq, hv, ha, g, hmu],
                          [ca.hessian(ca.dot(hmu, h0fn(hq, hv, ha, g)), ca.vertcat(hq, hv, ha))[0]])
        lam = ca.SX.sym("lam", 12)
        z = ca.vertcat(qa, va, qb, vb)
        h0s = ca.SX.sym("h0s", 6)
        H = ca.SX(4 * n, 4 * n)
        for k, (pq, pv, pa, anc) in enumerate(((qa, va, acc_a, anc_a), (qm, vm, am, (anc_a + anc_b) / 2))):
            lk = lam[6 * k : 6 * k + 6]
            mu_k = ca.jtimes(residual(h0s, na, fa, anc), h0s, lk, True)  # linear in h0: exact
            Lk = ca.jacobian(ca.vertcat(pq, pv, pa), z)  # constant in the motion (depends on h)
            H += ca.mtimes([Lk.T, hh0(pq, pv, pa, g, mu_k), Lk])
        self.seg_hessian = ca.Function("hess_seg", [*seg_in, lam], [ca.triu(H)])

        # C² continuity at a knot: v_{k-1} + 4 v_k + v_{k+1} = 3 (q_{k+1} - q_{k-1}) / h
        qm_, qp_, vm_, v0_, vp_ = (ca.SX.sym(s, n) for s in ("qm", "qp", "vm", "v0", "vp"))
        self.c2 = ca.Function("c2", [qm_, qp_, vm_, v0_, vp_, h], [(vm_ + 4 * v0_ + vp_) * h - 3 * (qp_ - qm_)])

        # jerk of the rotations over a segment (constant on a cubic), × h³: rad
        wj = ca.SX.sym("wj")
        jerk = 12 * (qa - qb) + 6 * h * (va + vb)
        self.jerk = ca.Function("jerk", [qa, va, qb, vb, h, wj], [wj * ca.sumsqr(jerk[3:])])

        # change of each foot's (scaled) wrench between frames, and of the total ground force
        ww = ca.SX.sym("ww")
        dw = ca.vertcat(*[rz(turn, wb[3 * i : 3 * i + 3]) - wa[3 * i : 3 * i + 3] for i in range(4)])
        self.wrate = ca.Function("wrate", [wa, wb, turn, ww], [ww * ca.sumsqr(dw)])
        dF = rz(turn, wb[3:6] + wb[9:12]) - (wa[3:6] + wa[9:12])
        self.frate = ca.Function("frate", [wa, wb, turn], [ca.sumsqr(dF)])

        # [naturalness] each foot's ground reaction points at the centre of mass: the squared moment
        # of each foot's (scaled) wrench about the frame's centre of mass (a parameter). In single
        # support it is the rate of the whole body's angular momentum, which walking keeps small;
        # in double support it takes the split the optimum is otherwise free to choose (the feet
        # squeezing the ground between them costs nothing else) toward legs pushing along their
        # length: the leading foot braking, the trailing one propelling
        wcw, com_k = ca.SX.sym("wcw"), ca.SX.sym("com", 3)
        mc = ca.SX(0)
        for k in range(2):
            lever = (ra[3 * k : 3 * k + 3] - com_k) / self.length_scale
            mc += ca.sumsqr(wa[6 * k : 6 * k + 3] + ca.cross(lever, wa[6 * k + 3 : 6 * k + 6]))
        self.wcom = ca.Function("wcom", [wa, ra, com_k, wcw], [wcw * mc])

        # [fidelity] the total ground force toward a target (scaled: body weights): the capture's
        # whole-body centre of mass times its acceleration (the tutor), the guide's (an extrapolation)
        ftarget, wft = ca.SX.sym("ftarget", 3), ca.SX.sym("wft")
        self.ftrack = ca.Function("ftrack", [wa, ftarget, wft], [wft * ca.sumsqr(wa[3:6] + wa[9:12] - ftarget)])

        # second difference over three frames of the total ground force and of its moment about
        # the centre of mass (per-frame parameter): whole-body Newton–Euler from positions sees
        # m (a_{k-1} - 2 a_k + a_{k+1}) / 6 between the spline's accelerations and the positions'
        # second differences, so these must stay small for the motion to be realistic
        wc, rc = ca.SX.sym("wc", 12), ca.SX.sym("rc", 6)
        com_a, com_b, com_c = ca.SX.sym("com_a", 3), ca.SX.sym("com_b", 3), ca.SX.sym("com_c", 3)
        ta, tc = ca.SX.sym("ta"), ca.SX.sym("tc")
        tot = []
        for wv, ref, tr, com in ((wa, ra, ta, com_a), (wb, rb, 0, com_b), (wc, rc, tc, com_c)):
            n_o, f_o = ground(wv, ref, tr)
            tot.append((n_o - ca.cross(com, f_o), f_o))
        d2n = (tot[0][0] - 2 * tot[1][0] + tot[2][0]) / M
        d2f = (tot[0][1] - 2 * tot[1][1] + tot[2][1]) / W
        self.smooth = ca.Function("smooth", [wa, wb, wc, ra, rb, rc, com_a, com_b, com_c, ta, tc],
                                  [ca.vertcat(ca.sumsqr(d2f), ca.sumsqr(d2n))])


_FRAME_CACHE: weakref.WeakKeyDictionary[Character, FrameFunctions] = weakref.WeakKeyDictionary()


def frame_functions(character: Character) -> FrameFunctions:
    ff = _FRAME_CACHE.get(character)
    if ff is None:
        ff = FrameFunctions(character)
        _FRAME_CACHE[character] = ff
        compiled.start(ff)  # a background compile when enabled (solver.spacetime.compiled)
    return ff
