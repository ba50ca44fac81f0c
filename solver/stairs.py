"""The stairs a walk climbs, placed: :func:`flight_for` (a walk's frames, its schedule and its
environment) and :func:`flight_of` (a motion) — the one geometry the optimizer's rows, the checks,
the simulation's treads, the plots and the exports read (``solver.environment.stair_flight`` builds it;
this module places it on the walk's feet, which takes the character's kinematics)."""

from __future__ import annotations

from typing import Any

import numpy as np

from solver.environment import Environment, Flight, stair_flight, walker_going
from solver.kinematics import contact_points


def flight_for(character: Any, q: np.ndarray, foot_contact: np.ndarray, env: Environment) -> Flight | None:
    """The stairs of a walk ``q`` of ``character`` in ``env`` (:func:`stair_flight`: the rise, the
    going — the walker's own step when ``env`` has none — and the placement ``env.stairs_at``, else
    fitted to the walk's stance feet); None on flat ground. The one geometry of stairs: the
    optimizer's rows, the checks, the simulation's treads and the plots read it."""
    if not env.step_height_m:
        return None
    B = np.asarray(foot_contact, dtype=bool)
    going = env.step_going_m or walker_going(q, B)
    feet = None
    if env.stairs_at is None:
        cp = contact_points(character, np.asarray(q, dtype=float))
        feet = np.stack([cp[[j for j, c in enumerate(character.contacts) if c.side == side], :2].mean(axis=0)
                         for side in ("right", "left")])
    return stair_flight(feet, B, env.step_height_m, going, env.stairs_at, q)


def flight_of(motion: Any) -> Flight | None:
    """The stairs of a motion (:func:`flight_for` in its own environment); None on flat ground."""
    if motion.contacts is None:
        return None
    return flight_for(motion.character, motion.q, motion.foot_contact(), motion.environment)
