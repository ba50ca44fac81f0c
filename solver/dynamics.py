"""Inverse dynamics: recursive Newton-Euler (docs/method.md (M3.4), the thesis's Algorithm 1), one implementation.

``rnea`` runs on numpy (one frame, or a whole motion ``(n, T)`` at once: every line is a
vectorised operation over frames) and on CasADi symbols (it then builds the expression
graph). Gravity enters as a fictitious root acceleration ``a_0 = -g``. External wrenches
are world-frame spatial forces (moment about the world origin; force), keyed by body
index. The root wrench ``h0`` is the total external wrench the motion needs, in the world
frame about the world origin, ordered (moment; force) — docs/method.md (M3.5): c = h0.
"""

from __future__ import annotations

import weakref
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from solver import spatial as sp
from solver.character import Character, Model
from solver.environment import STANDARD_GRAVITY_VECTOR
from solver.kinematics import forward_kinematics

DEFAULT_GRAVITY = STANDARD_GRAVITY_VECTOR

Motion6 = tuple[sp.Vec3, sp.Vec3]


def _to_body(model: Model, k: int, c: Any, s: Any, qk: Any, m: Motion6) -> Motion6:
    """Motion vector in parent coordinates -> body k coordinates."""
    w, l = sp.motion_to_child(model.rot0[k], model.pos0[k], m)
    if model.revolute[k]:
        return sp.rotzT_apply(c, s, w), sp.rotzT_apply(c, s, l)
    return w, (sp.add(l[0], sp.mul(qk, w[1])), sp.sub(l[1], sp.mul(qk, w[0])), l[2])


def _to_parent(model: Model, k: int, c: Any, s: Any, qk: Any, f: Motion6) -> Motion6:
    """Force vector in body k coordinates -> parent coordinates."""
    n, fl = f
    if model.revolute[k]:
        n, fl = sp.rotz_apply(c, s, n), sp.rotz_apply(c, s, fl)
    else:
        n = (sp.sub(n[0], sp.mul(qk, fl[1])), sp.add(n[1], sp.mul(qk, fl[0])), n[2])
    return sp.force_to_parent(model.rot0[k], model.pos0[k], (n, fl))


@dataclass(frozen=True)
class RneaResult:
    tau: Any  # (n, ...) joint forces (N for slides, N·m for hinges)
    h0: Any  # (6, ...) root wrench, world frame about the origin: (moment; force)


def rnea(
    character: Character,
    q: Any,
    qd: Any,
    qdd: Any,
    gravity: Any = DEFAULT_GRAVITY,
    fext: Mapping[int, Any] | None = None,
) -> RneaResult:
    """Joint forces and root wrench for (q, q̇, q̈), gravity and external wrenches.

    ``fext`` maps a body index (see :meth:`Model.point_on_body` / ``model.seg_body``) to a
    6-vector (moment about the world origin; force), world frame.
    """
    model = character.model
    n = model.n
    qs, qds, qdds = sp.components(q, n), sp.components(qd, n), sp.components(qdd, n)
    g = sp.components(gravity, 3)
    cs = [(sp.cos(qs[k]), sp.sin(qs[k])) if model.revolute[k] else (None, None) for k in range(n)]

    ext_local: dict[int, Motion6] = {}
    if fext:
        pose = forward_kinematics(character, q)
        for body, w in fext.items():
            if not 0 <= body < n:
                raise ValueError(f"external wrench on unknown body {body}")
            wc = sp.components(w, 6)
            f_world = ((wc[0], wc[1], wc[2]), (wc[3], wc[4], wc[5]))
            ext_local[body] = sp.force_to_child(pose.rot[body], pose.pos[body], f_world)

    zero = (sp.ZERO3, sp.ZERO3)
    a_root: Motion6 = (sp.ZERO3, (sp.neg(g[0]), sp.neg(g[1]), sp.neg(g[2])))
    v: list[Motion6] = []
    acc: list[Motion6] = []
    f: list[Motion6] = []
    for k in range(n):
        par = model.parent[k]
        c, s = cs[k]
        vp, ap = (zero, a_root) if par < 0 else (v[par], acc[par])
        vk = _to_body(model, k, c, s, qs[k], vp)
        ak = _to_body(model, k, c, s, qs[k], ap)
        qdk, qddk = qds[k], qdds[k]
        w, l = vk
        aw, al = ak
        if model.revolute[k]:
            w = (w[0], w[1], sp.add(w[2], qdk))
            # a = X a_p + S q̈ + v x S q̇ with S = (e_z; 0)
            aw = (sp.add(aw[0], sp.mul(qdk, w[1])), sp.sub(aw[1], sp.mul(qdk, w[0])), sp.add(aw[2], qddk))
            al = (sp.add(al[0], sp.mul(qdk, l[1])), sp.sub(al[1], sp.mul(qdk, l[0])), al[2])
        else:
            l = (l[0], l[1], sp.add(l[2], qdk))
            al = (sp.add(al[0], sp.mul(qdk, w[1])), sp.sub(al[1], sp.mul(qdk, w[0])), sp.add(al[2], qddk))
        vk, ak = (w, l), (aw, al)
        v.append(vk)
        acc.append(ak)
        if model.mass[k] > 0.0:
            ia = sp.inertia_apply(model.mass[k], model.com[k], model.inertia[k], ak)
            iv = sp.inertia_apply(model.mass[k], model.com[k], model.inertia[k], vk)
            vxiv = sp.motion_cross_force(vk, iv)
            fk = (sp.vadd(ia[0], vxiv[0]), sp.vadd(ia[1], vxiv[1]))
        else:
            fk = zero
        if k in ext_local:
            e = ext_local[k]
            fk = (sp.vsub(fk[0], e[0]), sp.vsub(fk[1], e[1]))
        f.append(fk)

    tau: list[Any] = [0.0] * n
    h0: Motion6 = zero
    for k in range(n - 1, -1, -1):
        fk = f[k]
        tau[k] = fk[0][2] if model.revolute[k] else fk[1][2]
        c, s = cs[k]
        fp = _to_parent(model, k, c, s, qs[k], fk)
        par = model.parent[k]
        if par < 0:
            h0 = (sp.vadd(h0[0], fp[0]), sp.vadd(h0[1], fp[1]))
        else:
            f[par] = (sp.vadd(f[par][0], fp[0]), sp.vadd(f[par][1], fp[1]))
    like = q
    return RneaResult(tau=sp.stack(tau, like=like), h0=sp.stack(list(h0[0]) + list(h0[1]), like=like))


def root_wrench(character: Character, q: Any, qd: Any, qdd: Any, gravity: Any = DEFAULT_GRAVITY) -> Any:
    """h0 with no external wrench: the total ground wrench the motion needs (docs/method.md (M3.5))."""
    return rnea(character, q, qd, qdd, gravity).h0


_CASADI_CACHE: weakref.WeakKeyDictionary[Character, dict] = weakref.WeakKeyDictionary()


def casadi_functions(character: Character) -> dict:
    """CasADi SX functions built from :func:`rnea` (once per character).

    ``rnea(q, qd, qdd, g) -> (tau, h0)`` and ``h0(q, qd, qdd, g) -> h0``.
    """
    cached = _CASADI_CACHE.get(character)
    if cached is not None:
        return cached
    import casadi as ca  # lazy: keeps CasADi out of numpy-only paths and OpenSim's child process

    n = character.n
    q, qd, qdd = ca.SX.sym("q", n), ca.SX.sym("qd", n), ca.SX.sym("qdd", n)
    g = ca.SX.sym("g", 3)
    res = rnea(character, q, qd, qdd, g)
    fns = {
        "rnea": ca.Function("rnea", [q, qd, qdd, g], [res.tau, res.h0], ["q", "qd", "qdd", "g"], ["tau", "h0"]),
        "h0": ca.Function("h0", [q, qd, qdd, g], [res.h0], ["q", "qd", "qdd", "g"], ["h0"]),
    }
    _CASADI_CACHE[character] = fns
    return fns
