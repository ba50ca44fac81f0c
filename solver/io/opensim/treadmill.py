"""Treadmill trials: the belt speed, and the Galilean shift to overground-equivalent kinematics.

A constant-speed belt is an inertial frame: adding ``v·t`` along x to every landmark gives
the kinematics of the same walk overground, with the same ground reactions.
``GroundFrame.velocity`` records the shift so results map back onto the treadmill.
"""

from __future__ import annotations

import logging
import math

import numpy as np

from solver.gait.base import GaitError
from solver.gait.belt import belt_speed
from solver.io.opensim.base import OpenSimError
from solver.io.opensim.external_loads import read_opensim_grf
from solver.io.track import SkeletonTrack, feet_points, shift_ground

log = logging.getLogger(__name__)


def estimate_belt_speed(track: SkeletonTrack, *, stance: np.ndarray | None = None) -> float:
    """Belt speed (m/s) of a treadmill trial: median backward speed of the stance foot.

    The stance foot is, at each frame, the foot whose heel/mtp are lower (or ``stance``
    (2, T) bool per foot when known, e.g. from force plates); its forward velocity is
    -v_belt. Frames with the foot moving vertically faster than 0.1 m/s are skipped.
    """
    try:
        return belt_speed(track.times, feet_points(track), stance=stance)
    except GaitError as e:
        raise OpenSimError(str(e)) from None


def belt_shift(track: SkeletonTrack, belt_speed: float | str, grf, grf_xml) -> SkeletonTrack:
    if isinstance(belt_speed, str):
        if belt_speed != "auto":
            raise OpenSimError(f"belt_speed must be a number (m/s) or 'auto', got {belt_speed!r}")
        stance = None
        if grf is not None:
            g = read_opensim_grf(grf, grf_xml, times=track.times, frame=track.frame)
            stance = g.force[:, 2] > 200.0
        v = estimate_belt_speed(track, stance=stance)
        how = "auto (stance-foot velocity)"
    else:
        v = float(belt_speed)
        if not math.isfinite(v) or abs(v) > 10:
            raise OpenSimError(f"belt_speed {belt_speed!r} m/s is not plausible")
        how = "given"
    log.info("treadmill: belt speed %.3f m/s (%s): root shifted by v*t (overground-equivalent)", v, how)
    return shift_ground(track, v, how, "treadmill frame moving at -velocity")
