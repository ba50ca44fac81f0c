"""Cross-check of our inverse dynamics against MuJoCo on random states."""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from mjcf.replay import MujocoReplay
from solver.character import Character
from solver.dynamics import rnea
from solver.environment import STANDARD_GRAVITY


def random_states(character: Character, samples: int, rng: np.random.Generator) -> dict[str, Any]:
    """Random configurations within joint limits, velocities, accelerations, gravity, foot wrenches."""
    n = character.n
    lo = np.where(np.isfinite(character.lower), character.lower, -1.0)
    hi = np.where(np.isfinite(character.upper), character.upper, 1.0)
    lo, hi = np.maximum(lo, -math.pi), np.minimum(hi, math.pi)
    q = rng.uniform(lo[:, None], hi[:, None], (n, samples))
    qd = rng.normal(0.0, 2.0, (n, samples))
    qdd = rng.normal(0.0, 10.0, (n, samples))
    g = rng.normal(size=(3, samples))
    g *= STANDARD_GRAVITY / np.linalg.norm(g, axis=0)
    wrenches = {f.segment: rng.normal(0.0, 100.0, (6, samples)) for f in character.feet}
    return {"q": q, "qd": qd, "qdd": qdd, "g": g, "fext": wrenches}


def check_dynamics(character: Character, samples: int = 100, seed: int = 0) -> dict:
    """Max relative error (inf-norm per sample) of joint forces and root wrench vs MuJoCo."""
    if samples < 1:
        raise ValueError("samples must be >= 1")
    rng = np.random.default_rng(seed)
    st = random_states(character, samples, rng)
    replay = MujocoReplay.create(character)
    model = character.model
    err_tau = np.zeros(samples)
    err_h0 = np.zeros(samples)
    for t in range(samples):
        fext = {model.seg_body[s]: w[:, t] for s, w in st["fext"].items()}
        ours = rnea(character, st["q"][:, t], st["qd"][:, t], st["qdd"][:, t], st["g"][:, t], fext)
        replay.set_gravity(st["g"][:, t])
        tau, h0 = replay.inverse(
            st["q"][:, t], st["qd"][:, t], st["qdd"][:, t], {s: w[:, t] for s, w in st["fext"].items()}
        )
        err_tau[t] = np.abs(ours.tau - tau[:, 0]).max() / max(np.abs(tau).max(), 1e-300)
        err_h0[t] = np.abs(ours.h0 - h0[:, 0]).max() / max(np.abs(h0).max(), 1e-300)
    return {
        "character": character.name,
        "coordinates": character.n,
        "samples": samples,
        "max_rel_err_joint": float(err_tau.max()),
        "max_rel_err_root": float(err_h0.max()),
        "tolerance": 1e-9,
        "ok": bool(err_tau.max() <= 1e-9 and err_h0.max() <= 1e-9),
    }
