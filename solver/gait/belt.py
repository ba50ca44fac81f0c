"""Treadmill belt speed from the feet: on a constant-speed belt the stance foot moves backwards at
the belt's speed (the reader then shifts its track to overground-equivalent kinematics,
solver/io/opensim/treadmill.py)."""

from __future__ import annotations

import numpy as np

from solver.gait.base import GaitError


def belt_speed(times: np.ndarray, feet: dict[str, np.ndarray], *, stance: np.ndarray | None = None) -> float:
    """Belt speed (m/s): median backward speed of the stance foot.

    ``feet``: ``"r"`` and ``"l"`` -> (3, T) a point of each foot (the mid-point of heel and
    metatarsal heads). The stance foot is, at each frame, the foot that is lower (or ``stance``
    (2, T) bool per foot when known, e.g. from force plates); its forward velocity is -v_belt.
    Frames with the foot moving vertically faster than 0.1 m/s are skipped.
    """
    t = np.asarray(times, dtype=float)
    if t.size < 5:
        raise GaitError("estimate_belt_speed: at least 5 frames are needed")
    vals = []
    for k, s in enumerate("rl"):
        p = np.asarray(feet[s], dtype=float)
        v = np.gradient(p, t, axis=1)
        po = np.asarray(feet["l" if s == "r" else "r"], dtype=float)
        if stance is not None:
            on = np.asarray(stance, dtype=bool)[k]
        else:
            low = p[2] < np.nanpercentile(p[2], 5) + 0.03
            on = low & (p[2] < po[2]) & (np.abs(v[2]) < 0.1)
        vals.append(-v[0][on])
    allv = np.concatenate(vals)
    allv = allv[np.isfinite(allv)]
    if allv.size < 3:
        raise GaitError("estimate_belt_speed: no stance frames found (is this a walking trial?)")
    return float(np.median(allv))
