"""Arm swing for captures whose arms did not move (issue: true to the subject).

A model or marker set without arms (OpenSim's gait2354, a lower-body C3D) leaves the capture
skeleton's arms hanging still: a full-body tutor then walks with frozen arms and makes up for
their missing angular momentum with its trunk. People swing their arms in antiphase with their
legs: the shoulder flexes as its own side's hip extends (the shared captures with arms: correlation
−0.87 to −0.96), through ~25-40° at natural speed, the elbow flexed ~20-30° and flexing with the
shoulder (Collins, Adamczyk & Kuo 2009, Proc R Soc B 276:3679; Meyns, Bruijn & Duysens 2013, Gait
Posture 38:555). :func:`arm_swing` gives such a capture's arms that swing.
"""

from __future__ import annotations

from typing import Any

import numpy as np

#: a capture's arms are still when neither elbow's flexion moves more than ``STILL_DEG`` over the cycle and
#: neither shoulder's more than ``STILL_SHOULDER_DEG`` (degrees; hanging arms follow the trunk a little;
#: swinging ones move their shoulders 15-40° and their elbows 10-25°)
STILL_DEG = 1.0
STILL_SHOULDER_DEG = 3.0
#: the swing given to still arms (degrees): shoulder flexion about its mean, amplitude (half the range),
#: elbow flexion mean and amplitude, shoulder adduction (the arm a little away from the trunk)
SHOULDER_MEAN, SHOULDER_AMPLITUDE = -2.0, 12.0
ELBOW_MEAN, ELBOW_AMPLITUDE = 25.0, 8.0
SHOULDER_ADDUCTION = -6.0
SOURCES = ("Collins, Adamczyk & Kuo 2009, Proc R Soc B 276:3679 (dynamic arm swinging in human walking); "
           "Meyns, Bruijn & Duysens 2013, Gait Posture 38:555 (the how and why of arm swing)")


def arms_still(names: list[str] | tuple[str, ...], q: np.ndarray) -> bool:
    """Whether a capture (coordinates ``names``, cycle ``q``) has arms and none of them swings."""
    joints = {"shoulder_flexion": STILL_SHOULDER_DEG, "elbow_flexion": STILL_DEG}
    rows = [(names.index(f"{j}_{s}"), lim) for j, lim in joints.items() for s in ("r", "l") if f"{j}_{s}" in names]
    if len(rows) < 4:
        return False
    N = q.shape[1] - 2 if q.shape[1] > 4 else q.shape[1]
    return all(float(np.degrees(np.ptp(q[i, :N]))) < lim for i, lim in rows)


def arm_swing(names: list[str] | tuple[str, ...], q: np.ndarray,
              still: bool | None = None) -> tuple[np.ndarray, dict[str, Any] | None]:
    """(q, what was done): a cycle whose arms are still given the published arm swing, each
    shoulder in antiphase with its own side's hip flexion (scaled to ``SHOULDER_AMPLITUDE``), each
    elbow flexing with its shoulder; unchanged (None) when the arms move or there are none.
    ``still``: whether they are, decided already (on the captured cycle), else ``arms_still``."""
    if not (arms_still(names, q) if still is None else still):
        return q, None
    out = np.array(q, dtype=float, copy=True)
    N = q.shape[1] - 2 if q.shape[1] > 4 else q.shape[1]
    for s in ("r", "l"):
        hip = f"hip_flexion_{s}"
        if hip not in names:
            return q, None
        h = q[names.index(hip)]
        half = max(0.5 * float(np.ptp(h[:N])), 1e-6)
        phase = -(h - float(np.mean(h[:N]))) / half  # +1: the hip furthest back, the arm furthest forward
        out[names.index(f"shoulder_flexion_{s}")] = np.radians(SHOULDER_MEAN + SHOULDER_AMPLITUDE * phase)
        out[names.index(f"elbow_flexion_{s}")] = np.radians(ELBOW_MEAN + ELBOW_AMPLITUDE * phase)
        if f"shoulder_adduction_{s}" in names:
            out[names.index(f"shoulder_adduction_{s}")] = np.radians(SHOULDER_ADDUCTION)
    return out, {"synthesized": True, "shoulder_range_deg": 2 * SHOULDER_AMPLITUDE,
                 "elbow_deg": [ELBOW_MEAN - ELBOW_AMPLITUDE, ELBOW_MEAN + ELBOW_AMPLITUDE], "source": SOURCES}
