"""C3D file access: units, parameters, markers in metres, gap filling, subject parameters."""

from __future__ import annotations

import logging
import math
import re
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from solver.environment import STANDARD_GRAVITY
from solver.errors import InputError

log = logging.getLogger("solver.io.c3d")

G = STANDARD_GRAVITY
SIDES = ("r", "l")
FEET = ("right", "left")


class C3DError(InputError):
    """The file cannot be turned into a trial (missing plates or markers, gaps, units, ...);
    ``parameter`` names the argument that would fix it, when one would (e.g. "mass")."""


# ----------------------------------------------------------------------------------------
# units


_LENGTH_UNITS = {
    "mm": 1e-3, "millimeter": 1e-3, "millimeters": 1e-3, "millimetre": 1e-3, "millimetres": 1e-3,
    "cm": 1e-2, "centimeter": 1e-2, "centimeters": 1e-2,
    "dm": 0.1,
    "m": 1.0, "meter": 1.0, "meters": 1.0, "metre": 1.0, "metres": 1.0,
    "in": 0.0254, "inch": 0.0254, "inches": 0.0254,
    "ft": 0.3048, "feet": 0.3048,
}
_FORCE_UNITS = {"n": 1.0, "newton": 1.0, "newtons": 1.0, "kn": 1e3, "lbf": 4.4482216152605, "lb": 4.4482216152605}
_VOLT_UNITS = {"v": 1.0, "mv": 1e-3, "volt": 1.0, "volts": 1.0, "uv": 1e-6}


def length_unit(text: str) -> float:
    """Metres per unit for a C3D length unit string ('mm', 'cm', 'm', ...)."""
    key = text.strip().lower()
    if key not in _LENGTH_UNITS:
        raise C3DError(f"unknown length unit {text!r} (known: mm, cm, m, in, ft)")
    return _LENGTH_UNITS[key]


def _force_unit(text: str) -> float | None:
    return _FORCE_UNITS.get(text.strip().lower())


def _moment_unit(text: str) -> float | None:
    """N·m per unit for strings like 'Nmm', 'N.mm', 'N*m', 'N-m', 'Nm', 'kNm', 'lbf.in'."""
    key = re.sub(r"[\s.*·\-_]", "", text.strip().lower())
    for f_name, f in sorted(_FORCE_UNITS.items(), key=lambda kv: -len(kv[0])):
        if key.startswith(f_name):
            rest = key[len(f_name):]
            if rest in _LENGTH_UNITS:
                return f * _LENGTH_UNITS[rest]
    return None


# ----------------------------------------------------------------------------------------
# raw file access


@dataclass(frozen=True)
class _Raw:
    path: Path
    params: Mapping[str, Any]
    labels: tuple[str, ...]  # point labels, upper case, subject prefix stripped
    points: np.ndarray  # (3, P, T) in metres, lab frame, NaN where invalid
    point_rate: float
    first_frame: int  # 1-based frame number of the first frame in the file
    analogs: np.ndarray  # (A, N) scaled analog values (ezc3d applies SCALE, OFFSET, GEN_SCALE)
    analog_labels: tuple[str, ...]
    analog_units: tuple[str, ...]
    analog_rate: float
    unit_m: float  # metres per POINT unit


def _param(params: Mapping[str, Any], group: str, name: str, default: Any = None) -> Any:
    g = params.get(group)
    if not isinstance(g, Mapping):
        return default
    p = g.get(name)
    if not isinstance(p, Mapping) or "value" not in p:
        return default
    v = p["value"]
    if isinstance(v, (list, tuple)) and len(v) == 0:
        return default
    if isinstance(v, np.ndarray) and v.size == 0:
        return default
    return v


def _scalar(v: Any) -> float | None:
    if v is None:
        return None
    try:
        a = np.asarray(v, dtype=float).ravel()
    except (TypeError, ValueError):
        return None
    return float(a[0]) if a.size else None


def _strings(v: Any) -> list[str]:
    if v is None:
        return []
    if isinstance(v, str):
        return [v]
    return [str(s) for s in v]


def _clean_label(s: str) -> str:
    s = s.strip()
    if ":" in s:  # subject prefix "Name:LASI"
        s = s.rsplit(":", 1)[1]
    return s.strip().upper()


def _read_raw(path: Path) -> _Raw:
    try:
        import ezc3d  # optional at import time: a missing ezc3d is reported as a C3DError
    except ImportError as e:  # pragma: no cover - dependency declared in pyproject
        raise C3DError("reading C3D needs the 'ezc3d' package") from e
    if not path.is_file():
        raise C3DError(f"{path}: no such file")
    try:
        c = ezc3d.c3d(str(path))
    except (OSError, RuntimeError, ValueError) as e:
        raise C3DError(f"{path}: not a readable C3D file ({e})") from e
    params = c["parameters"]
    pts = np.asarray(c["data"]["points"], dtype=float)  # (4, P, T)
    labels = tuple(_clean_label(s) for s in _strings(_param(params, "POINT", "LABELS")))
    # long label lists continue in LABELS2, LABELS3, ...
    k = 2
    while len(labels) < pts.shape[1] and _param(params, "POINT", f"LABELS{k}") is not None:
        labels += tuple(_clean_label(s) for s in _strings(_param(params, "POINT", f"LABELS{k}")))
        k += 1
    labels = labels[: pts.shape[1]]
    rate = _scalar(_param(params, "POINT", "RATE")) or float(c["header"]["points"]["frame_rate"])
    if not rate or rate <= 0:
        raise C3DError(f"{path.name}: POINT:RATE missing or not positive")
    units = _strings(_param(params, "POINT", "UNITS"))
    xyz = pts[:3].copy()
    res = c["data"]["meta_points"].get("residuals") if "meta_points" in c["data"] else None
    bad = ~np.isfinite(xyz).all(axis=0) | (np.abs(xyz).sum(axis=0) == 0.0)
    if res is not None and np.asarray(res).shape[-2:] == xyz.shape[1:]:
        bad |= np.asarray(res)[0] < 0
    xyz[:, bad] = np.nan
    if units and units[0].strip():
        unit_m = length_unit(units[0])
    else:
        unit_m = _guess_length_unit(xyz)
        log.warning("%s: POINT:UNITS missing; marker heights suggest %g m per unit", path.name, unit_m)
    analogs = np.asarray(c["data"]["analogs"], dtype=float)
    analogs = analogs[0] if analogs.ndim == 3 else analogs.reshape(0, 0)
    alabels = tuple(s.strip() for s in _strings(_param(params, "ANALOG", "LABELS")))
    aunits = tuple(s.strip() for s in _strings(_param(params, "ANALOG", "UNITS")))
    arate = _scalar(_param(params, "ANALOG", "RATE")) or float(c["header"]["analogs"]["frame_rate"] or 0.0)
    first = int(c["header"]["points"]["first_frame"]) + 1
    return _Raw(
        path=path, params=params, labels=labels, points=xyz * unit_m, point_rate=float(rate),
        first_frame=first, analogs=analogs, analog_labels=alabels, analog_units=aunits,
        analog_rate=float(arate), unit_m=unit_m,
    )


def _guess_length_unit(xyz: np.ndarray) -> float:
    """Without POINT:UNITS: the spread of the markers (a person is 1-2 m tall)."""
    finite = xyz[:, np.isfinite(xyz).all(axis=0)]
    if finite.size == 0:
        raise C3DError("POINT:UNITS missing and no valid marker to infer it from")
    spread = float(np.max(np.percentile(finite, 99, axis=1) - np.percentile(finite, 1, axis=1)))
    for unit in (1e-3, 1e-2, 1.0):
        if 0.3 < spread * unit < 50.0:
            return unit
    raise C3DError(f"POINT:UNITS missing and marker spread {spread:g} fits no length unit")



def _runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) of the runs of True in a 1-D boolean array."""
    m = np.concatenate([[False], np.asarray(mask, dtype=bool), [False]])
    d = np.diff(m.astype(np.int8))
    return list(zip(np.nonzero(d == 1)[0].tolist(), np.nonzero(d == -1)[0].tolist()))


def fill_gaps(x: np.ndarray, max_gap: int) -> tuple[np.ndarray, list[tuple[int, int]]]:
    """Cubic-spline fill of interior NaN gaps up to ``max_gap`` frames in a (3, T) trajectory.

    Returns the filled copy and the gaps left (interior longer gaps and gaps at the ends,
    as [start, stop) frame ranges).
    """
    from scipy.interpolate import CubicSpline  # lazy: scipy.interpolate costs ~0.4 s to import

    x = np.array(x, dtype=float, copy=True)
    T = x.shape[1]
    good = np.isfinite(x).all(axis=0)
    left: list[tuple[int, int]] = []
    if good.all():
        return x, left
    if good.sum() < 4:
        return x, [(0, T)]
    idx = np.nonzero(good)[0]
    spline = CubicSpline(idx, x[:, idx], axis=1)
    for a, b in _runs(~good):
        if a == 0 or b == T or b - a > max_gap:
            left.append((a, b))
            continue
        x[:, a:b] = spline(np.arange(a, b))
    return x, left


def _rigid_fill(target: np.ndarray, donors: Sequence[np.ndarray]) -> np.ndarray:
    """Fill NaN frames of a marker from >= 3 donor markers of the same rigid cluster.

    The target's coordinates in the donors' local frame are averaged over the frames
    where all are seen, then mapped back where the target is missing.
    """
    out = target.copy()
    if len(donors) < 3:
        return out
    d = np.stack(donors)  # (k, 3, T)
    seen_d = np.isfinite(d).all(axis=(0, 1))
    seen_t = np.isfinite(target).all(axis=0)
    both = seen_d & seen_t
    need = seen_d & ~seen_t
    if both.sum() < 3 or not need.any():
        return out

    def frames(mask: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        o = d[0][:, mask]
        e1 = _unit(d[1][:, mask] - o)
        e3 = _unit(np.cross(e1, d[2][:, mask] - o, axis=0))
        e2 = np.cross(e3, e1, axis=0)
        return o, np.stack([e1, e2, e3], axis=1)  # (3, T), (3 [xyz], 3 [axes], T)

    o, r = frames(both)
    local = np.einsum("iat,it->at", r, target[:, both] - o).mean(axis=1)
    o, r = frames(need)
    out[:, need] = o + np.einsum("iat,a->it", r, local)
    return out


def _unit(v: np.ndarray) -> np.ndarray:
    n = np.linalg.norm(v, axis=0, keepdims=True)
    with np.errstate(invalid="ignore", divide="ignore"):
        return v / n


def _perp(v: np.ndarray, axis: np.ndarray) -> np.ndarray:
    """Component of v orthogonal to the unit vector(s) ``axis`` (both (3, T) or (3,))."""
    return v - np.sum(v * axis, axis=0) * axis


def _mid(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return 0.5 * (a + b)


# ----------------------------------------------------------------------------------------
# subject parameters


@dataclass(frozen=True)
class SubjectParams:
    """Anthropometry used by the joint-centre definitions (metres, kg)."""

    mass: float | None
    height: float | None
    marker_radius: float
    leg_length: dict[str, float | None]
    asis_trochanter: dict[str, float | None]
    inter_asis: float | None
    knee_width: dict[str, float | None]
    ankle_width: dict[str, float | None]
    shoulder_offset: dict[str, float | None]
    elbow_width: dict[str, float | None]


def _length_param(value: Any, lo: float, hi: float) -> float | None:
    """A PROCESSING length in an unstated unit (usually mm): the scale that lands in [lo, hi] m."""
    v = _scalar(value)
    if v is None or not math.isfinite(v) or v <= 0:
        return None
    for scale in (1e-3, 1e-2, 1.0):
        if lo <= v * scale <= hi:
            return v * scale
    return None


def _first_param(params: Mapping[str, Any], names: Sequence[tuple[str, str]]) -> Any:
    for g, n in names:
        v = _param(params, g, n)
        if v is not None:
            return v
    return None


def _subject_params(params: Mapping[str, Any]) -> SubjectParams:
    def proc(name: str) -> Any:
        return _first_param(params, [("PROCESSING", name), ("SUBJECTS", name.upper()), ("SUBJECT", name.upper())])

    mass_v = _scalar(_first_param(params, [
        ("PROCESSING", "Bodymass"), ("PROCESSING", "BodyMass"), ("PROCESSING", "Mass"),
        ("SUBJECTS", "MASS"), ("SUBJECTS", "WEIGHT"), ("SUBJECT", "MASS"), ("SUBJECT", "WEIGHT"),
        ("PROCESSING", "BODYMASS"), ("PROCESSING", "Weight"),
    ]))
    mass = mass_v if mass_v is not None and 5.0 <= mass_v <= 400.0 else None
    height = _length_param(_first_param(params, [
        ("PROCESSING", "Height"), ("PROCESSING", "HEIGHT"), ("SUBJECTS", "HEIGHT"), ("SUBJECT", "HEIGHT"),
    ]), 0.5, 2.5)
    diam = _length_param(proc("MarkerDiameter"), 0.003, 0.04)

    def sided(name: str, lo: float, hi: float) -> dict[str, float | None]:
        out: dict[str, float | None] = {}
        for s in SIDES:
            out[s] = _length_param(proc(f"{s.upper()}{name}"), lo, hi) or _length_param(proc(name), lo, hi)
        return out

    return SubjectParams(
        mass=mass,
        height=height,
        marker_radius=(diam / 2.0) if diam else 0.007,
        leg_length=sided("LegLength", 0.3, 1.4),
        asis_trochanter=sided("AsisTrocanterDistance", 0.01, 0.2),
        inter_asis=_length_param(proc("InterAsisDistance"), 0.1, 0.5),
        knee_width=sided("KneeWidth", 0.04, 0.25),
        ankle_width=sided("AnkleWidth", 0.02, 0.2),
        shoulder_offset=sided("ShoulderOffset", 0.005, 0.15),
        elbow_width=sided("ElbowWidth", 0.02, 0.2),
    )


