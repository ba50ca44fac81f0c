"""Our axes in the lab: vertical from the plates (or the floor), forward from the pelvis' travel."""

from __future__ import annotations

import logging
import math
import warnings
from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from solver.io.c3d.markers import _Markers
from solver.io.c3d.plates import PlateSpec
from solver.io.c3d.reader import C3DError, _perp, _Raw, _unit

log = logging.getLogger("solver.io.c3d")


# ----------------------------------------------------------------------------------------
# axes


def _nanmean(a, axis: int) -> np.ndarray:
    """``np.nanmean`` without its "Mean of empty slice" warning: a frame where every marker of the
    set is missing is NaN, as the callers expect."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)
        return np.nanmean(a, axis=axis)


def _snap(v: np.ndarray, deg: float) -> np.ndarray:
    """The nearest lab axis (signed) if within ``deg`` degrees, else v (unit)."""
    v = v / np.linalg.norm(v)
    k = int(np.argmax(np.abs(v)))
    if abs(v[k]) >= math.cos(math.radians(deg)):
        e = np.zeros(3)
        e[k] = math.copysign(1.0, v[k])
        return e
    return v


def _floor_normal(up0: np.ndarray, feet: Sequence[np.ndarray]) -> np.ndarray:
    """Normal of the plane through the foot markers' lowest positions (the floor they stand
    on), starting from a rough up direction; ``up0`` when the plane is ill-defined."""
    up0 = up0 / np.linalg.norm(up0)
    pts = []
    for x in feet:
        h = up0 @ x
        ok = np.isfinite(h)
        if ok.sum() < 10:
            continue
        low = ok & (h <= np.nanpercentile(h, 15))
        pts.append(x[:, low])
    if not pts:
        return up0
    P = np.concatenate(pts, axis=1)
    P = P - P.mean(axis=1, keepdims=True)
    _, sv, vt = np.linalg.svd(P.T, full_matrices=False)
    n = vt[2]
    if sv[1] < 0.05 * np.sqrt(P.shape[1]) or abs(n @ up0) < math.cos(math.radians(20)):
        return up0  # feet along a line only, or a plane far from the rough vertical
    return n if n @ up0 > 0 else -n


def _detect_axes(raw: _Raw, mk: _Markers, specs: Sequence[PlateSpec], pelvis_roles: Mapping[str, np.ndarray]
                 ) -> tuple[np.ndarray, float, dict[str, Any]]:
    """Rotation lab -> ours (rows: our x, y, z in lab coordinates) and the floor height (m, along up)."""
    info: dict[str, Any] = {}
    pelvis = _nanmean(np.stack(list(pelvis_roles.values())), axis=0)  # (3, T)
    feet = [mk.get(lbl) for side in ("L", "R") for role in ("HEE", "TOE", "ANK")
            if (lbl := mk.find(role, side)) is not None]
    foot_c = _nanmean(np.stack(feet), axis=0) if feet else None
    if specs:
        normals: list[np.ndarray] = []
        for s in specs:
            n = s.rotation[:, 2]
            normals.append(n if not normals or n @ normals[0] >= 0 else -n)
        up = np.mean(normals, axis=0)
        info["vertical_from"] = "force plate surfaces"
    else:
        if foot_c is None:
            raise C3DError(f"{raw.path.name}: cannot find the vertical: no force plates and no foot markers")
        up = _floor_normal(_nanmean(pelvis - foot_c, axis=1), feet)
        info["vertical_from"] = "pelvis above feet"
    up = up / np.linalg.norm(up)
    above = _nanmean(pelvis - foot_c, axis=1) if foot_c is not None else None
    if above is not None and above @ up < 0:
        up = -up
    up = _snap(up, 3.0 if specs else 10.0)
    # forward: the pelvis' travel, checked against the way the pelvis faces
    good = np.isfinite(pelvis).all(axis=0)
    idx = np.nonzero(good)[0]
    travel = pelvis[:, idx[-1]] - pelvis[:, idx[0]]
    travel = _perp(travel, up)
    facing = None
    if "ASI" in pelvis_roles and "PSI" in pelvis_roles:
        facing = _perp(_nanmean(pelvis_roles["ASI"] - pelvis_roles["PSI"], axis=1), up)
    if np.linalg.norm(travel) > 0.5:
        fwd = travel
        info["forward_from"] = "pelvis travel"
        if facing is not None and facing @ travel < 0:
            log.warning("%s: the pelvis travels backwards relative to where it faces", raw.path.name)
    elif facing is not None and np.linalg.norm(facing) > 0:
        fwd = facing
        info["forward_from"] = "pelvis facing (little travel: treadmill?)"
        log.warning("%s: pelvis travels only %.2f m: forward taken from the pelvis markers", raw.path.name,
                    float(np.linalg.norm(travel)))
    else:
        raise C3DError(f"{raw.path.name}: cannot find the walking direction (no pelvis travel)")
    fwd = _snap(fwd, 5.0)
    fwd = _unit(_perp(fwd, up))
    left = np.cross(up, fwd)
    R = np.vstack([fwd, left, up])
    if specs:
        floor = float(np.mean([s.center @ up for s in specs]))
        info["floor_from"] = "force plate surfaces"
    else:
        lows = [np.nanpercentile(up @ mk.get(lbl), 2) for side in ("L", "R") for role in ("HEE", "TOE")
                if (lbl := mk.find(role, side)) is not None]
        low = float(min(lows)) if lows else 0.0
        floor = 0.0 if -0.01 <= low <= 0.12 else low - 0.02
        info["floor_from"] = "lab origin" if floor == 0.0 else "lowest foot markers"
    info["walking_speed"] = float(np.linalg.norm(travel) / max((idx[-1] - idx[0]) / raw.point_rate, 1e-9))
    return R, floor, info



def _axes_text(R: np.ndarray) -> str:
    names = []
    for row, ours in zip(R, ("forward", "left", "up")):
        k = int(np.argmax(np.abs(row)))
        if abs(row[k]) > 1 - 1e-9:
            names.append(f"{'+' if row[k] > 0 else '-'}{'XYZ'[k]} {ours}")
        else:
            names.append(f"{np.round(row, 3).tolist()} {ours}")
    return "input " + ", ".join(names)


