"""Inverse-dynamics timings (issue: physics core)."""

from __future__ import annotations

import time

import mujoco
import numpy as np

from bench.trials import best_time
from mjcf.check import random_states
from mjcf.replay import MujocoReplay
from solver import character as C
from solver.dynamics import casadi_functions, rnea


def run() -> dict:
    out = {}
    for name in ("halfboy", "fullbody"):
        ch = C.reference(name)
        res: dict = {"coordinates": ch.n}
        st = random_states(ch, 10000, np.random.default_rng(0))
        q, qd, qdd = st["q"], st["qd"], st["qdd"]
        g = np.array([0.0, 0.0, -9.81])
        res["numeric_single_frame_us"] = 1e6 * best_time(lambda: rnea(ch, q[:, 0], qd[:, 0], qdd[:, 0], g), 50)
        for T in (1000, 10000):
            res[f"numeric_batched_T{T}_us_per_frame"] = 1e6 * best_time(
                lambda: rnea(ch, q[:, :T], qd[:, :T], qdd[:, :T], g), 5
            ) / T
        t = time.perf_counter()
        f = casadi_functions(ch)["rnea"]
        res["casadi_build_s"] = time.perf_counter() - t
        res["casadi_instructions"] = int(f.n_instructions())
        args = (q[:, 0], qd[:, 0], qdd[:, 0], g)
        res["casadi_eval_single_us"] = 1e6 * best_time(lambda: [f(*args) for _ in range(200)], 3) / 200
        T = 1000
        fm = f.map(T)
        gg = np.tile(g[:, None], (1, T))
        res["casadi_eval_map_T1000_us_per_frame"] = (1e6 * best_time(lambda: fm(q[:, :T], qd[:, :T], qdd[:, :T], gg), 5)
                                                      / T)
        rep = MujocoReplay.create(ch)
        m, d = rep.model, rep.data
        d.qpos[rep.qpos_index] = q[:, 0]
        d.qvel[rep.dof_index] = qd[:, 0]
        d.qacc[rep.dof_index] = qdd[:, 0]
        res["mujoco_mj_inverse_us"] = 1e6 * best_time(lambda: [mujoco.mj_inverse(m, d) for _ in range(2000)], 3) / 2000
        out[name] = res
    return out
