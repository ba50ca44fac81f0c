"""C3D trials: markers -> anatomical landmarks, force plates -> measured ground reactions.

``read_c3d(path)`` returns a :class:`~solver.io.track.SkeletonTrack` in OUR world frame
(Z up, X forward = walking direction, Y left, metres, ground at z = 0) with

* landmarks: joint centres and segment tips from the marker set (Plug-in-Gait and
  close relatives: Davis/Newington hip joint centres, PiG "chord" knee and ankle centres,
  or the mid-points of lateral/medial epicondyle and malleolus markers when present),
* segment orientations of the pelvis, thighs, shanks and feet,
* ``measured``: per foot force, centre of pressure and free moment from the force plates
  (C3D ``FORCE_PLATFORM`` types 1, 2, 3 and 4), box-averaged onto the marker times, with
  the ``valid`` mask of frames where every loaded foot stands on a plate,
* ``contacts`` (heel_r, toe_r, heel_l, toe_l) from the plates where the feet are on
  plates and from kinematics (calibrated on the plate contacts) elsewhere,
* ``frame``: the :class:`~solver.capture.GroundFrame` back to the file's lab frame and
  length unit; mass and height from the file (or the plates, or the caller).

``load_c3d(path)`` fits the capture character to the track (``solver.io.fit``).

Units are read from the file (``POINT:UNITS``, ``ANALOG:UNITS``, ``FORCE_PLATFORM``);
the vertical comes from the plate surfaces (or the markers), the forward direction
from the pelvis' travel. See ``docs/c3d.md``.
"""

from __future__ import annotations

import logging
import math
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from solver.capture import Capture, GroundFrame, MeasuredGRF
from solver.io.errors import InputError
from solver.io.track import SkeletonTrack

log = logging.getLogger(__name__)

G = 9.81
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
        import ezc3d
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


# ----------------------------------------------------------------------------------------
# marker access, gap filling


#: Landmark markers and the names other marker sets use for them ({s}: side letter L/R).
ALIASES: dict[str, tuple[str, ...]] = {
    "ASI": ("{s}ASI", "{s}ASIS", "{s}_ASIS", "{s}_ASI", "{s}IAS", "{s}.ASIS"),
    "PSI": ("{s}PSI", "{s}PSIS", "{s}_PSIS", "{s}_PSI", "{s}IPS", "{s}.PSIS"),
    "THI": ("{s}THI", "{s}_THI", "{s}THL", "{s}TH"),
    "KNE": ("{s}KNE", "{s}_KNE", "{s}KNEL", "{s}LKNE", "{s}LEK", "{s}FLE", "{s}_KNEE_LAT", "{s}LFC"),
    "KNM": ("{s}KNM", "{s}MKNE", "{s}KNEM", "{s}_KNM", "{s}MEK", "{s}FME", "{s}_KNEE_MED", "{s}MFC"),
    "TIB": ("{s}TIB", "{s}_TIB", "{s}TBL", "{s}TI"),
    "ANK": ("{s}ANK", "{s}_ANK", "{s}LMAL", "{s}LM", "{s}FAL", "{s}_ANKLE_LAT", "{s}LAT_MAL"),
    "MED": ("{s}MED", "{s}MMAL", "{s}MM", "{s}TAM", "{s}_ANKLE_MED", "{s}ANM", "{s}MED_MAL"),
    "HEE": ("{s}HEE", "{s}_HEE", "{s}HEEL", "{s}CAL", "{s}FCC", "{s}_HEEL"),
    "TOE": ("{s}TOE", "{s}_TOE", "{s}MT2", "{s}FM2", "{s}_TOE"),
    "MT1": ("{s}MT1", "{s}FM1", "{s}MH1"),
    "MT5": ("{s}MT5", "{s}FM5", "{s}MH5"),
    "SHO": ("{s}SHO", "{s}_SHO", "{s}ACR", "{s}SHOULDER", "{s}CA"),
    "ELB": ("{s}ELB", "{s}_ELB", "{s}LEL", "{s}ELBL", "{s}EL"),
    "WRA": ("{s}WRA", "{s}_WRA", "{s}RSP", "{s}WRR"),
    "WRB": ("{s}WRB", "{s}_WRB", "{s}USP", "{s}WRU"),
    "FIN": ("{s}FIN", "{s}_FIN", "{s}MH2", "{s}HAND"),
    "FHD": ("{s}FHD", "{s}_FHD", "{s}FH"),
    "BHD": ("{s}BHD", "{s}_BHD", "{s}BH"),
}
CENTRAL_ALIASES: dict[str, tuple[str, ...]] = {
    "SACR": ("SACR", "SACRUM", "S1", "MPSI"),
    "C7": ("C7", "CV7"),
    "T10": ("T10", "TV10", "T8"),
    "CLAV": ("CLAV", "IJ", "SJN", "STER", "MAN"),
    "STRN": ("STRN", "PX", "SXS", "XIPH"),
}


class _Markers:
    """Marker lookup by role, with aliases; arrays (3, T) in the lab frame, metres."""

    def __init__(self, raw: _Raw) -> None:
        self._index: dict[str, int] = {}
        for i, name in enumerate(raw.labels):
            self._index.setdefault(name, i)
        self._pts = raw.points
        self.used: dict[str, str] = {}  # role -> label found

    def find(self, role: str, side: str | None = None) -> str | None:
        if side is None:
            cands = CENTRAL_ALIASES.get(role, (role,))
        else:
            cands = tuple(a.format(s=side.upper()) for a in ALIASES[role])
        for c in cands:
            if c in self._index and np.isfinite(self._pts[:, self._index[c]]).any():
                return c
        return None

    def get(self, label: str) -> np.ndarray:
        return self._pts[:, self._index[label]]


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
    from scipy.interpolate import CubicSpline

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


# ----------------------------------------------------------------------------------------
# force plates


@dataclass(frozen=True)
class PlateSpec:
    """One C3D force platform, geometry in the lab frame (metres)."""

    index: int  # 1-based, as in the file
    type: int
    corners: np.ndarray  # (4, 3) lab, metres, C3D order (+x+y, -x+y, -x-y, +x-y of the plate)
    origin: np.ndarray  # (3,) FORCE_PLATFORM:ORIGIN, plate frame, metres (as stored)
    channels: tuple[int, ...]  # 0-based analog indices
    cal: np.ndarray | None  # CAL_MATRIX (k, k) or None

    @property
    def rotation(self) -> np.ndarray:
        """Columns: the plate's x, y, z axes in the lab frame (from the corners)."""
        c = self.corners
        ax = (c[0] - c[1]) + (c[3] - c[2])
        ay = (c[0] - c[3]) + (c[1] - c[2])
        az = np.cross(ax, ay)
        ay = np.cross(az, ax)
        return np.stack([ax / np.linalg.norm(ax), ay / np.linalg.norm(ay), az / np.linalg.norm(az)], axis=1)

    @property
    def center(self) -> np.ndarray:
        return self.corners.mean(axis=0)


@dataclass(frozen=True, eq=False)
class PlateSignal:
    """One plate's reaction on the subject at the analog rate, in OUR frame (SI units).

    ``force`` (3, N) N, ``cop`` (3, N) m (NaN while unloaded), ``free_moment`` (N,) N·m
    about +z, ``loaded`` (N,) vertical force above the threshold, ``times`` (N,) s on the
    markers' clock, ``corners`` (4, 3) m in our frame, ``periods``: loading periods
    (t_start, t_end, foot) with foot 'right', 'left' or 'unassigned'.
    """

    index: int
    type: int
    times: np.ndarray
    force: np.ndarray
    cop: np.ndarray
    free_moment: np.ndarray
    loaded: np.ndarray
    corners: np.ndarray
    threshold: float
    periods: tuple[tuple[float, float, str], ...] = ()
    baseline: str = ""  # how the unloaded offsets were found

    @property
    def peak_vertical(self) -> float:
        return float(np.max(self.force[2])) if self.force.size else 0.0


def _plate_specs(raw: _Raw) -> list[PlateSpec]:
    p = raw.params
    used = _scalar(_param(p, "FORCE_PLATFORM", "USED"))
    if not used:
        return []
    n = int(used)
    types = np.asarray(_param(p, "FORCE_PLATFORM", "TYPE", []), dtype=int).ravel()
    corners = _param(p, "FORCE_PLATFORM", "CORNERS")
    origins = _param(p, "FORCE_PLATFORM", "ORIGIN")
    chans = _param(p, "FORCE_PLATFORM", "CHANNEL")
    cal = _param(p, "FORCE_PLATFORM", "CAL_MATRIX")
    if corners is None or chans is None or types.size < n:
        raise C3DError(f"{raw.path.name}: FORCE_PLATFORM:USED={n} but TYPE/CORNERS/CHANNEL are incomplete")
    corners = np.asarray(corners, dtype=float)
    corners = corners.reshape(3, 4, -1) if corners.ndim != 3 else corners  # ezc3d: (3, 4, n)
    origins = np.zeros((3, n)) if origins is None else np.asarray(origins, dtype=float).reshape(3, -1)
    chans = np.asarray(chans, dtype=int)
    chans = chans.reshape(-1, n) if chans.ndim != 2 else chans  # (k, n)
    cal_arr = None if cal is None else np.asarray(cal, dtype=float)
    if cal_arr is not None and cal_arr.ndim == 2 and cal_arr.shape[0] == cal_arr.shape[1]:
        cal_arr = cal_arr[:, :, None]  # one plate
    elif cal_arr is not None and cal_arr.ndim == 1:
        k = 8 if int(types[0]) == 3 else 6
        cal_arr = cal_arr.reshape((k, k, -1), order="F") if cal_arr.size % (k * k) == 0 else None
    specs = []
    for i in range(n):
        t = int(types[i])
        if t not in (1, 2, 3, 4):
            raise C3DError(
                f"{raw.path.name}: force plate {i + 1} has TYPE {t}; supported types are 1, 2, 3 and 4"
            )
        k = 8 if t == 3 else 6
        if chans.shape[0] < k:
            raise C3DError(f"{raw.path.name}: force plate {i + 1} (type {t}) needs {k} channels in FORCE_PLATFORM:CHANNEL")
        ch = tuple(int(c) - 1 for c in chans[:k, i])
        if min(ch) < 0 or max(ch) >= raw.analogs.shape[0]:
            raise C3DError(f"{raw.path.name}: force plate {i + 1} channels {[c + 1 for c in ch]} outside the analog data")
        m = None
        if cal_arr is not None and cal_arr.ndim == 3 and cal_arr.shape[2] > i and cal_arr.shape[0] >= k:
            m = cal_arr[:k, :k, i]
            if not np.any(m):
                m = None
        if t == 4 and m is None:
            raise C3DError(f"{raw.path.name}: force plate {i + 1} is TYPE 4 but has no FORCE_PLATFORM:CAL_MATRIX")
        specs.append(PlateSpec(
            index=i + 1, type=t, corners=corners[:, :, i].T * raw.unit_m,
            origin=origins[:, i] * raw.unit_m, channels=ch, cal=m,
        ))
    return specs


def _plate_units(raw: _Raw, spec: PlateSpec) -> tuple[float | None, float | None]:
    """(N per force unit, N·m per moment unit) from ANALOG:UNITS (None: not stated)."""
    us = [raw.analog_units[c] if c < len(raw.analog_units) else "" for c in spec.channels]
    if spec.type == 3:
        f = [_force_unit(u) for u in us if u]
        return (f[0] if f else None), None
    if spec.type == 1:  # Fx Fy Fz CoPx CoPy Tz
        f1 = _force_unit(us[0]) if us[0] else None
        m1 = _moment_unit(us[5]) if us[5] else None
        return f1, m1
    f = _force_unit(us[0]) if us[0] else None
    m = _moment_unit(us[3]) if us[3] else None
    if us[0] and f is None and us[0].strip().lower() not in _VOLT_UNITS:
        raise C3DError(f"{raw.path.name}: force plate {spec.index}: unknown force unit {us[0]!r}")
    if us[3] and m is None and us[3].strip().lower() not in _VOLT_UNITS:
        raise C3DError(f"{raw.path.name}: force plate {spec.index}: unknown moment unit {us[3]!r}")
    return f, m


def _plate_wrench_local(raw: _Raw, spec: PlateSpec, up_local: np.ndarray) -> tuple[np.ndarray, np.ndarray, str]:
    """Force and moment about the centre of the plate surface, plate frame, N and N·m.

    The moment unit, when not stated, is chosen (N·m or N·<point unit>) so that the
    centre of pressure falls on the plate. Returns (F (3, N), M (3, N), note).
    """
    a = raw.analogs[list(spec.channels)]
    f_unit, m_unit = _plate_units(raw, spec)
    note = ""
    if f_unit is None:
        f_unit = 1.0
        note += "force unit not stated, N assumed; "
    half = np.abs(spec.rotation.T @ (spec.corners[0] - spec.center))  # plate half extents (plate frame)
    if spec.type == 1:
        # Fx Fy Fz, CoPx CoPy (point units, plate frame about the surface centre), Tz (moment unit)
        F = a[:3] * f_unit
        cu = raw.analog_units[spec.channels[3]].strip().lower() if spec.channels[3] < len(raw.analog_units) else ""
        r = np.vstack([a[3:5] * _LENGTH_UNITS.get(cu, raw.unit_m), np.zeros(a.shape[1])])
        tz_unit = m_unit if m_unit is not None else f_unit * raw.unit_m
        M = np.cross(r, F, axis=0)
        M[2] += a[5] * tz_unit
        return F, M, note
    if spec.type == 3:
        if spec.cal is not None and spec.cal.shape == (8, 8):
            a = spec.cal @ a
        fx12, fx34, fy14, fy23, fz1, fz2, fz3, fz4 = a * f_unit
        ox, oy = abs(spec.origin[0]), abs(spec.origin[1])
        F = np.vstack([fx12 + fx34, fy14 + fy23, fz1 + fz2 + fz3 + fz4])
        M = np.vstack([
            oy * (fz1 + fz2 - fz3 - fz4),
            ox * (fz2 + fz3 - fz1 - fz4),
            oy * (fx34 - fx12) + ox * (fy14 - fy23),
        ])  # about the sensors' centre, in the sensor plane (Kistler)
        d = np.array([0.0, 0.0, abs(spec.origin[2]) * np.sign(up_local[2] or 1.0)])
        return F, M - np.cross(d, F, axis=0), note  # moment about the surface centre
    if spec.type == 4:
        a = spec.cal @ a
    F = a[:3] * f_unit
    m_raw = a[3:6]
    # surface centre relative to the transducer origin: ORIGIN (C3D: surface -> origin), so
    # -ORIGIN, unless the file stores it the other way round (the surface is the side facing up)
    d = -spec.origin
    if np.dot(d, up_local) < 0:
        d = spec.origin
    candidates = [m_unit] if m_unit is not None else [f_unit * raw.unit_m, f_unit]
    best = None
    for mu in candidates:
        M = m_raw * mu - np.cross(d, F, axis=0)
        score = _cop_outside(F, M, half)
        if best is None or score < best[0]:
            best = (score, M, mu)
    assert best is not None
    if m_unit is None:
        note += f"moment unit not stated, {best[2]:g} N·m per unit chosen (centre of pressure on the plate); "
    elif best[0] > 0.5:
        log.warning("%s: plate %d: %.0f%% of loaded centres of pressure fall off the plate",
                    raw.path.name, spec.index, 100 * best[0])
    return F, best[1], note


def _cop_outside(F: np.ndarray, M: np.ndarray, half: np.ndarray) -> float:
    """Fraction of well-loaded samples whose CoP (plate frame) is > 5 cm off the plate."""
    fz = F[2]
    big = np.abs(fz) > 0.25 * np.max(np.abs(fz)) if fz.size and np.max(np.abs(fz)) > 0 else np.zeros(0, bool)
    if not big.any():
        return 0.0
    x, y = -M[1, big] / fz[big], M[0, big] / fz[big]
    out = (np.abs(x) > half[0] + 0.05) | (np.abs(y) > half[1] + 0.05)
    return float(out.mean())


def _baseline(F: np.ndarray, M: np.ndarray, rate: float, rate_ratio: int, zero: Sequence[int] | None,
              nframes: int, threshold: float) -> tuple[np.ndarray, str]:
    """Offsets (6,) of an unloaded plate: from FORCE_PLATFORM:ZERO frames, else quiet unloaded samples."""
    W = np.vstack([F, M])
    fz = F[2]
    N = fz.size
    rng = float(np.ptp(fz)) if N else 0.0
    if rng <= 0.0:
        return np.zeros(6), "constant signal"
    noise_ok = max(0.01 * rng, 1.0)
    lo, hi = float(np.min(fz)), float(np.max(fz))
    w = max(min(int(round(0.05 * rate)), N // 4), 2)  # 50 ms blocks
    nw = N // w
    if nw < 2:
        return np.zeros(6), "too short to zero"
    blocks = fz[: nw * w].reshape(nw, w)
    level, sd = blocks.mean(axis=1), blocks.std(axis=1)
    quiet = sd < noise_ok
    near_lo = quiet & (level - lo < 0.1 * rng)
    near_hi = quiet & (hi - level < 0.1 * rng)
    if zero is not None and len(zero) >= 2 and 1 <= zero[0] <= zero[1] <= nframes:
        a, b = (zero[0] - 1) * rate_ratio, zero[1] * rate_ratio
        seg = fz[a:b]
        if seg.size and np.std(seg) < noise_ok:
            zl = float(np.mean(seg))
            at_lo, at_hi = zl - lo < 0.1 * rng, hi - zl < 0.1 * rng
            # trusted unless the quiet samples say the plate rests at the other end of its range
            # (someone standing on it during the ZERO frames)
            if (at_lo and not (near_hi.any() and not near_lo.any())) or (
                    at_hi and not (near_lo.any() and not near_hi.any())):
                return W[:, a:b].mean(axis=1), f"ZERO frames {zero[0]}-{zero[1]}"
        log.info("FORCE_PLATFORM:ZERO frames %s are not an unloaded quiet window; using unloaded samples", zero)
    if near_lo.any() and near_hi.any():
        pick = near_lo if abs(np.median(level[near_lo])) <= abs(np.median(level[near_hi])) else near_hi
    elif near_lo.any() or near_hi.any():
        pick = near_lo if near_lo.any() else near_hi
    else:
        return np.zeros(6), "no unloaded quiet window; not zeroed"
    cols = np.concatenate([np.arange(i * w, (i + 1) * w) for i in np.nonzero(pick)[0]])
    off = np.median(W[:, cols], axis=1)
    if abs(off[2]) < 0.5 * threshold and np.allclose(off, 0.0, atol=1e-9):
        return np.zeros(6), "already zero"
    return off, f"{len(cols)} unloaded samples"


def _plate_signals(raw: _Raw, specs: Sequence[PlateSpec], R: np.ndarray, floor: float,
                   threshold: float) -> list[PlateSignal]:
    """Every plate's reaction on the subject in our frame, analog rate."""
    out = []
    if raw.analogs.size == 0 or raw.analog_rate <= 0:
        raise C3DError(f"{raw.path.name}: force plates declared but no analog data")
    ratio = max(int(round(raw.analog_rate / raw.point_rate)), 1)
    nframes = raw.points.shape[2]
    N = raw.analogs.shape[1]
    times = np.arange(N) / raw.analog_rate
    up_lab = R[2]
    zero = _param(raw.params, "FORCE_PLATFORM", "ZERO")
    zero = [int(z) for z in np.asarray(zero).ravel()[:2]] if zero is not None else None
    for spec in specs:
        Rp = spec.rotation
        up_local = Rp.T @ up_lab
        F, M, note = _plate_wrench_local(raw, spec, up_local)
        if spec.type != 1:
            off, how = _baseline(F, M, raw.analog_rate, ratio, zero, nframes, threshold)
            F = F - off[:3, None]
            M = M - off[3:, None]
        else:
            how = "type 1: not zeroed"
        # centre of pressure and free moment on the surface (plate frame, about its centre)
        fz = F[2]
        with np.errstate(invalid="ignore", divide="ignore"):
            x, y = -M[1] / fz, M[0] / fz
        tz = M[2] - (x * F[1] - y * F[0])
        F_lab = Rp @ F
        vert = up_lab @ F_lab
        big = np.abs(vert) > threshold
        sign = 1.0
        if big.any() and np.sum(vert[big]) < 0:
            sign = -1.0  # the file stores the action on the plate: the reaction is its opposite
        F_lab = sign * F_lab
        vert = sign * vert
        loaded = vert > threshold
        cop_lab = spec.center[:, None] + Rp[:, :2] @ np.vstack([x, y])
        free = sign * tz * float(Rp[:, 2] @ up_lab)
        force = R @ F_lab
        cop = R @ cop_lab - np.array([0.0, 0.0, floor])[:, None]
        force[:, ~loaded] = 0.0
        cop[:, ~loaded] = np.nan
        free = np.where(loaded, free, 0.0)
        corners = (R @ spec.corners.T).T - np.array([0.0, 0.0, floor])
        log.info("%s: plate %d type %d: zero %s; %s peak vertical %.1f N",
                 raw.path.name, spec.index, spec.type, how, note, float(np.max(force[2], initial=0.0)))
        out.append(PlateSignal(
            index=spec.index, type=spec.type, times=times, force=force, cop=cop, free_moment=free,
            loaded=loaded, corners=corners, threshold=threshold, baseline=how,
        ))
    return out


def _loading_periods(sig: PlateSignal, rate: float) -> list[tuple[int, int]]:
    """Analog-sample [start, stop) runs of loading, gaps < 20 ms merged, runs < 30 ms dropped."""
    runs = _runs(sig.loaded)
    merged: list[list[int]] = []
    for a, b in runs:
        if merged and a - merged[-1][1] < 0.02 * rate:
            merged[-1][1] = b
        else:
            merged.append([a, b])
    return [(a, b) for a, b in merged if b - a >= 0.03 * rate]


# ----------------------------------------------------------------------------------------
# axes


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
    pelvis = np.nanmean(np.stack(list(pelvis_roles.values())), axis=0)  # (3, T)
    feet = [mk.get(lbl) for side in ("L", "R") for role in ("HEE", "TOE", "ANK")
            if (lbl := mk.find(role, side)) is not None]
    foot_c = np.nanmean(np.stack(feet), axis=0) if feet else None
    if specs:
        normals = []
        for s in specs:
            n = s.rotation[:, 2]
            normals.append(n if not normals or n @ normals[0] >= 0 else -n)
        up = np.mean(normals, axis=0)
        info["vertical_from"] = "force plate surfaces"
    else:
        if foot_c is None:
            raise C3DError(f"{raw.path.name}: cannot find the vertical: no force plates and no foot markers")
        up = _floor_normal(np.nanmean(pelvis - foot_c, axis=1), feet)
        info["vertical_from"] = "pelvis above feet"
    up = up / np.linalg.norm(up)
    above = np.nanmean(pelvis - foot_c, axis=1) if foot_c is not None else None
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
        facing = _perp(np.nanmean(pelvis_roles["ASI"] - pelvis_roles["PSI"], axis=1), up)
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


# ----------------------------------------------------------------------------------------
# landmarks


def _chord(delta: float, joint: np.ndarray, wand: np.ndarray, lateral: np.ndarray) -> np.ndarray:
    """PiG chord function: the centre C at distance ``delta`` from the lateral marker, in the
    plane (joint, wand, lateral), with joint-C ⟂ C-lateral, on the side away from the wand."""
    w = joint - lateral
    L = np.linalg.norm(w, axis=0)
    wh = w / L
    along = delta**2 / L
    e = -_unit(_perp(wand - lateral, wh))
    across = np.sqrt(np.clip(delta**2 - along**2, 0.0, None))
    return lateral + along * wh + across * e


def _medial_shift(lateral: np.ndarray, axis_to: np.ndarray, medial_dir: np.ndarray, delta: float) -> np.ndarray:
    """Without a wand or medial marker: shift medially, orthogonal to the segment axis."""
    seg = _unit(axis_to - lateral)
    return lateral + delta * _unit(_perp(medial_dir, seg))


@dataclass
class _Built:
    landmarks: dict[str, np.ndarray]
    orientations: dict[str, np.ndarray]
    notes: list[str]
    markers_used: dict[str, str]


def _landmarks(mk: _Markers, R: np.ndarray, floor: float, sp: SubjectParams, height_est: float,
               frames: slice, max_gap: int, name: str) -> _Built:
    """Landmarks (3, T) in our frame from the markers (lab frame) over ``frames``."""
    notes: list[str] = []
    used: dict[str, str] = {}
    shift = np.array([0.0, 0.0, floor])[:, None]

    def ours(x: np.ndarray) -> np.ndarray:
        return R @ x[:, frames] - shift

    filled: dict[str, np.ndarray] = {}

    def marker(role: str, side: str | None = None, required: bool = True,
               partial: bool = False) -> np.ndarray | None:
        lbl = mk.find(role, side)
        key = f"{side or ''}{role}"
        if lbl is None:
            if required:
                raise C3DError(f"{name}: required marker {key} not found (looked for "
                               f"{', '.join(_alias_names(role, side))})")
            return None
        if lbl not in filled:
            x, gaps = fill_gaps(ours(mk.get(lbl)), max_gap)
            filled[lbl] = x
            if gaps and required:
                a, b = gaps[0]
                raise C3DError(f"{name}: marker {lbl} has a gap of {b - a} frames (> {max_gap}) "
                               f"at frames {a}-{b - 1} of the trial")
        x = filled[lbl]
        if not required and not partial and not np.isfinite(x).all():
            notes.append(f"{lbl} not used (gaps longer than {max_gap} frames)")
            return None
        used[key] = lbl
        return x

    mr = sp.marker_radius
    H = sp.height or height_est
    # --- pelvis -------------------------------------------------------------------------
    rasi, lasi = marker("ASI", "R"), marker("ASI", "L")
    rpsi, lpsi = marker("PSI", "R", required=False), marker("PSI", "L", required=False)
    if rpsi is not None and lpsi is not None:
        mpsi = _mid(rpsi, lpsi)
    else:
        sacr = marker("SACR", None, required=False)
        if sacr is None:
            raise C3DError(f"{name}: required markers RPSI/LPSI (or SACR) not found")
        mpsi = sacr
    masi = _mid(lasi, rasi)
    py = _unit(lasi - rasi)
    px = _unit(_perp(masi - mpsi, py))
    pz = np.cross(px, py, axis=0)
    inter_asis = sp.inter_asis or float(np.median(np.linalg.norm(lasi - rasi, axis=0)))
    lm: dict[str, np.ndarray] = {}
    ori: dict[str, np.ndarray] = {}
    ori["pelvis"] = np.stack([px, py, pz], axis=1)
    knee_lat: dict[str, np.ndarray] = {}
    ankle_lat: dict[str, np.ndarray] = {}
    for s in SIDES:
        S = s.upper()
        sgn = 1.0 if s == "l" else -1.0
        # leg length: parameter, else ASIS -> knee -> ankle path along the markers
        kne = marker("KNE", S)
        ank = marker("ANK", S)
        asi = lasi if s == "l" else rasi
        leg = sp.leg_length[s]
        if leg is None:
            leg = float(np.median(np.linalg.norm(asi - kne, axis=0) + np.linalg.norm(kne - ank, axis=0)))
            notes.append(f"{S} leg length estimated from markers: {leg:.3f} m")
        # Davis (1991) / Newington hip joint centre in the pelvis frame (mm in the regression)
        Lmm = leg * 1000.0
        xdis = (sp.asis_trochanter[s] * 1000.0) if sp.asis_trochanter[s] else 0.1288 * Lmm - 48.56
        C = 0.115 * Lmm - 15.3
        theta, beta = 0.5, 0.314
        mm = mr * 1000.0
        hx = C * math.cos(theta) * math.sin(beta) - (xdis + mm) * math.cos(beta)
        hy = sgn * (inter_asis * 500.0 - C * math.sin(theta))
        hz = -C * math.cos(theta) * math.cos(beta) - (xdis + mm) * math.sin(beta)
        hip = masi + (px * hx + py * hy + pz * hz) / 1000.0
        lm[f"hip_{s}"] = hip
        medial_dir = -sgn * py  # towards the body's midline
        # knee
        knm = marker("KNM", S, required=False)
        thi = marker("THI", S, required=False)
        kw = sp.knee_width[s]
        if knm is not None:
            knee = _mid(kne, knm)
        else:
            if kw is None:
                kw = 0.065 * H
                notes.append(f"{S} knee width estimated {kw:.3f} m (0.065 H)")
            delta = kw / 2 + mr
            knee = _chord(delta, hip, thi, kne) if thi is not None else _medial_shift(kne, hip, medial_dir, delta)
        lm[f"knee_{s}"] = knee
        knee_lat[s] = kne
        # ankle
        med = marker("MED", S, required=False)
        tib = marker("TIB", S, required=False)
        aw = sp.ankle_width[s]
        if med is not None:
            ankle = _mid(ank, med)
        else:
            if aw is None:
                aw = 0.045 * H
                notes.append(f"{S} ankle width estimated {aw:.3f} m (0.045 H)")
            delta = aw / 2 + mr
            ankle = _chord(delta, knee, tib, ank) if tib is not None else _medial_shift(ank, knee, medial_dir, delta)
        lm[f"ankle_{s}"] = ankle
        ankle_lat[s] = ank
        # foot: heel and toe markers sit at the same height above the sole (PiG); the toe
        # marker is on the 2nd metatarsal head. Sole = their heights during stance.
        hee = marker("HEE", S)
        toe_m = marker("TOE", S, required=False)
        if toe_m is None:
            mt1, mt5 = marker("MT1", S, required=False), marker("MT5", S, required=False)
            if mt1 is None or mt5 is None:
                raise C3DError(f"{name}: required marker {S}TOE (or {S}MT1 and {S}MT5) not found")
            toe_m = _mid(mt1, mt5)
        f_raw = toe_m - hee
        u = _unit(_perp(ankle - hee, _unit(f_raw)))  # foot up, ⟂ heel-toe line
        f = _unit(_perp(f_raw, u))
        h_heel = float(np.percentile(hee[2], 5))
        h_toe = float(np.percentile(toe_m[2], 5))
        mtp_h = 0.01 * H  # metatarsal heads above the sole (as the capture character)
        heel = hee - u * h_heel
        mtp = toe_m - u * max(h_toe - mtp_h, 0.0)
        toes_len = float(np.median(np.sum((mtp - heel) * f, axis=0))) / 3.0  # heel-mtp : mtp-tip = 3 : 1
        lm[f"heel_{s}"] = heel
        lm[f"mtp_{s}"] = mtp
        lm[f"toe_{s}"] = _toe_tip(mtp, f, u, toes_len, mtp_h)
        # segment orientations (x forward, y left, z up in the neutral pose)
        ky = (knee - kne) if s == "r" else (kne - knee)
        tz = _unit(hip - knee)
        ty = _unit(_perp(ky, tz))
        ori[f"thigh_{s}"] = np.stack([np.cross(ty, tz, axis=0), ty, tz], axis=1)
        ay = (ankle - ank) if s == "r" else (ank - ankle)
        sz = _unit(knee - ankle)
        sy = _unit(_perp(ay, sz))
        ori[f"shank_{s}"] = np.stack([np.cross(sy, sz, axis=0), sy, sz], axis=1)
        ori[f"foot_{s}"] = np.stack([f, np.cross(u, f, axis=0), u], axis=1)
    lm["pelvis"] = _mid(lm["hip_r"], lm["hip_l"])
    # --- upper body (optional) ------------------------------------------------------------
    try:
        upper = _upper_landmarks(marker, masi, px, pz, inter_asis, sp, H, mr)
    except _NoUpper as e:
        notes.append(f"upper body not built: {e}")
        log.info("%s: upper body not built: %s", name, e)
    else:
        lm.update(upper)
    return _Built(lm, ori, notes, used)


def _toe_tip(mtp: np.ndarray, f: np.ndarray, u: np.ndarray, length: float, mtp_h: float) -> np.ndarray:
    """Tip of the toes, on the sole ``length`` ahead of the metatarsal heads; during push-off
    the toes stay on the floor (z >= 0) while the foot rotates about the MTP joints."""
    tip = mtp + f * length - u * mtp_h
    low = tip[2] < 0.0
    if low.any():
        reach = math.hypot(length, mtp_h)
        dz = np.clip(-mtp[2, low], -reach, reach)
        h = _unit(np.vstack([f[:2, low], np.zeros((1, int(low.sum())))]))
        tip[:, low] = mtp[:, low] + h * np.sqrt(reach**2 - dz**2) + np.vstack([np.zeros((2, dz.size)), dz])
    return tip


class _NoUpper(Exception):
    pass


def _alias_names(role: str, side: str | None) -> list[str]:
    if side is None:
        return list(CENTRAL_ALIASES.get(role, (role,)))
    return [a.format(s=side.upper()) for a in ALIASES[role]]


def _upper_landmarks(marker: Callable[..., np.ndarray | None], masi: np.ndarray, px: np.ndarray,
                     pz: np.ndarray, inter_asis: float, sp: SubjectParams, H: float, mr: float
                     ) -> dict[str, np.ndarray]:
    def need(role: str, side: str | None = None) -> np.ndarray:
        x = marker(role, side, required=False)
        if x is None:
            raise _NoUpper(f"marker {(side or '') + role} missing or with long gaps")
        return x

    c7, clav = need("C7"), need("CLAV")
    t10 = marker("T10", None, required=False)
    strn = marker("STRN", None, required=False)
    if t10 is None and strn is None:
        raise _NoUpper("neither T10 nor STRN")
    lower_back = t10 if t10 is not None else strn
    lower_front = strn if strn is not None else t10
    assert lower_back is not None and lower_front is not None
    t_up = _unit(_mid(c7, clav) - _mid(lower_back, lower_front))
    # head: four markers (one may be rebuilt from the other three)
    heads = {k: marker(r, sd, required=False, partial=True) for k, (r, sd) in
             {"lf": ("FHD", "L"), "rf": ("FHD", "R"), "lb": ("BHD", "L"), "rb": ("BHD", "R")}.items()}
    present = {k: v for k, v in heads.items() if v is not None and np.isfinite(v).all(axis=0).sum() >= 3}
    if len(present) < 3:
        raise _NoUpper("fewer than three head markers")
    out: dict[str, np.ndarray] = {}
    # lumbar joint (L5/S1) from the pelvis (Reed 1999 / Dumas 2007: ~34 % of the ASIS width behind mid-ASIS)
    out["lumbar"] = masi - 0.34 * inter_asis * px + 0.01 * inter_asis * pz
    # C7/T1 (base of the neck): 55 % of the C7-CLAV distance from C7, 8° above that line (Dumas 2007)
    d = clav - c7
    dn = np.linalg.norm(d, axis=0)
    dh = d / dn
    up_d = _unit(_perp(t_up, dh))
    a = math.radians(8.0)
    out["neck"] = c7 + 0.55 * dn * (math.cos(a) * dh + math.sin(a) * up_d)
    out["sternum"] = _mid(clav, strn) if strn is not None else clav
    hd = dict(present)
    for k in list(hd):  # a marker's long gaps rebuilt from the other three (rigid head)
        if not np.isfinite(hd[k]).all():
            hd[k] = _rigid_fill(hd[k], [hd[j] for j in hd if j != k])
    if not all(np.isfinite(v).all() for v in hd.values()):
        raise _NoUpper("head markers with gaps that the other head markers cannot fill")
    if len(hd) == 3:  # the fourth, never seen: a parallelogram (front/back pairs)
        k = next(j for j in ("lf", "rf", "lb", "rb") if j not in hd)
        o = {"lf": ("rf", "lb", "rb"), "rf": ("lf", "rb", "lb"), "lb": ("rb", "lf", "rf"), "rb": ("lb", "rf", "lf")}[k]
        hd[k] = hd[o[0]] + hd[o[1]] - hd[o[2]]
    centre = (hd["lf"] + hd["rf"] + hd["lb"] + hd["rb"]) / 4.0
    h_fwd = _mid(hd["lf"], hd["rf"]) - _mid(hd["lb"], hd["rb"])
    h_left = _mid(hd["lf"], hd["lb"]) - _mid(hd["rf"], hd["rb"])
    h_up = _unit(np.cross(h_fwd, h_left, axis=0))
    out["head_top"] = centre + 0.05 * H * h_up  # vertex ~5 % of stature above the head band
    t_left = None
    for s in SIDES:
        S = s.upper()
        sgn = 1.0 if s == "l" else -1.0
        sho, elb = need("SHO", S), need("ELB", S)
        wra, wrb, fin = need("WRA", S), need("WRB", S), need("FIN", S)
        if t_left is None:
            t_left = _unit(_perp(need("SHO", "L") - need("SHO", "R"), t_up))
        off = sp.shoulder_offset[s] or 0.033 * H
        shoulder = sho - t_up * (off + mr)
        ew = sp.elbow_width[s] or 0.053 * H
        elbow = _medial_shift(elb, shoulder, -sgn * t_left, ew / 2 + mr)
        out[f"shoulder_{s}"] = shoulder
        out[f"elbow_{s}"] = elbow
        out[f"wrist_{s}"] = _mid(wra, wrb)
        out[f"hand_{s}"] = fin
    return out


# ----------------------------------------------------------------------------------------
# contacts, plates -> feet, resampling


def _frame_average(sig: np.ndarray, times: np.ndarray, frame_times: np.ndarray, dt: float) -> np.ndarray:
    """Box average of (k, N) samples over [t - dt/2, t + dt/2) around each frame time."""
    eps = 1e-6 * dt  # a sample exactly on a window edge belongs to the later window
    lo = np.searchsorted(times, frame_times - dt / 2 - eps)
    hi = np.searchsorted(times, frame_times + dt / 2 - eps)
    cs = np.concatenate([np.zeros((sig.shape[0], 1)), np.cumsum(sig, axis=1)], axis=1)
    n = np.maximum(hi - lo, 1)
    return (cs[:, hi] - cs[:, lo]) / n


def _seg_distance(p: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Horizontal distance of points p from segments a-b, all (3, T)."""
    p2, a2, b2 = p[:2], a[:2], b[:2]
    ab = b2 - a2
    t = np.clip(np.sum((p2 - a2) * ab, axis=0) / np.maximum(np.sum(ab * ab, axis=0), 1e-12), 0.0, 1.0)
    return np.linalg.norm(p2 - (a2 + t * ab), axis=0)


def _inside(poly: np.ndarray, p: np.ndarray, margin: float) -> np.ndarray:
    """Points p (3, T) inside the convex polygon (4, 3) grown by ``margin`` (horizontal)."""
    c = poly[:, :2].mean(axis=0)
    ok = np.ones(p.shape[1], dtype=bool)
    for i in range(len(poly)):
        a, b = poly[i, :2], poly[(i + 1) % len(poly), :2]
        n = np.array([b[1] - a[1], a[0] - b[0]])
        n /= np.linalg.norm(n)
        if n @ (c - a) > 0:
            n = -n  # outward normal
        ok &= (n @ (p[:2] - a[:, None])) <= margin
    return ok


#: a heel or toe tip (both on the sole) below this height, during stance, touches the floor
CONTACT_HEIGHT = 0.015


def _extrema(x: np.ndarray, times: np.ndarray, fps: float, maxima: bool) -> np.ndarray:
    """Times of the prominent maxima (or minima) of x, refined by a parabola through 3 frames."""
    from scipy.signal import find_peaks

    y = x if maxima else -x
    if not np.isfinite(y).all() or np.ptp(y) <= 0:
        return np.zeros(0)
    idx, _ = find_peaks(y, prominence=0.2 * np.ptp(y), distance=max(int(0.4 * fps), 1))
    out = []
    for i in idx:
        if 0 < i < y.size - 1:
            a, b, c = y[i - 1], y[i], y[i + 1]
            den = a - 2 * b + c
            d = 0.5 * (a - c) / den if den != 0 else 0.0
            out.append(times[i] + float(np.clip(d, -0.5, 0.5)) * (times[1] - times[0]))
    return np.asarray(out)


def _zeni_events(lm: Mapping[str, np.ndarray], s: str, fwd: np.ndarray, times: np.ndarray,
                 fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Foot strikes (heel farthest ahead of the pelvis) and foot offs (forefoot farthest behind)."""
    heel = np.sum((lm[f"heel_{s}"] - lm["pelvis"]) * fwd, axis=0)
    fore = np.sum((lm[f"mtp_{s}"] - lm["pelvis"]) * fwd, axis=0)
    return _extrema(heel, times, fps, True), _extrema(fore, times, fps, False)


def _event_offsets(events: Mapping[str, tuple[np.ndarray, np.ndarray]],
                   plate_events: Mapping[str, tuple[list, list]]) -> dict[str, tuple[float, float]]:
    """Per foot (strike, off) time offsets plate - kinematics: that foot's plate events, else
    both feet's, else 0 (the kinematic events as they are)."""
    diffs: dict[str, tuple[list, list]] = {foot: ([], []) for foot in events}
    for foot in events:
        for k in (0, 1):
            kin = events[foot][k]
            for t in plate_events[foot][k]:
                if kin.size:
                    j = int(np.argmin(np.abs(kin - t)))
                    if abs(kin[j] - t) < 0.15:
                        diffs[foot][k].append(t - kin[j])
    out = {}
    for foot in events:
        pair = []
        for k in (0, 1):
            own = diffs[foot][k]
            pooled = [d for f in diffs for d in diffs[f][k]]
            pair.append(float(np.median(own)) if own else float(np.median(pooled)) if pooled else 0.0)
        out[foot] = (pair[0], pair[1])
    return out


def _stance_from_events(hs: np.ndarray, to: np.ndarray, times: np.ndarray, low: np.ndarray) -> np.ndarray:
    """Frames from each strike to the next off (nearest-frame rounding); the ends of the trial
    count as stance when the foot is down there (its lowest point within 3 cm of the floor)."""
    T = times.size
    dt = times[1] - times[0]
    out = np.zeros(T, dtype=bool)
    ev = sorted([(t, 0) for t in hs] + [(t, 1) for t in to])
    start = times[0] - dt if (ev and ev[0][1] == 1 and low[0] < 0.03) else None
    for t, kind in ev:
        if kind == 0:
            start = t
        elif start is not None:
            out |= (times >= start - dt / 2) & (times < t + dt / 2)
            start = None
    if start is not None and low[-1] < 0.03:
        out |= times >= start - dt / 2
    if not ev:
        out = low < 0.03
    return out


@dataclass
class _FeetResult:
    measured: MeasuredGRF
    contacts: np.ndarray
    periods: list[dict[str, Any]]
    events: dict[str, Any]


def _nearest_runs(dist: np.ndarray, min_len: int) -> list[tuple[int, int, int]]:
    """Runs [a, b) of frames with the same nearest foot (row of ``dist`` (2, n), NaN unknown);
    runs shorter than ``min_len`` join their neighbour; -1 when no distance is known at all."""
    n = dist.shape[1]
    known = np.isfinite(dist).any(axis=0)
    if not known.any():
        return [(0, n, -1)]
    lab = np.where(known, np.argmin(np.where(np.isfinite(dist), dist, np.inf), axis=0), -1)
    ki = np.nonzero(known)[0]
    lab = lab[ki[np.clip(np.searchsorted(ki, np.arange(n)), 0, ki.size - 1)]]  # fill unknown frames
    edges = np.r_[0, np.nonzero(lab[1:] != lab[:-1])[0] + 1, n]
    runs = [[int(a), int(b), int(lab[a])] for a, b in zip(edges[:-1], edges[1:])]
    changed = True
    while changed and len(runs) > 1:
        changed = False
        for i, (a, b, _) in enumerate(runs):
            if b - a < min_len:
                j = i - 1 if i > 0 else i + 1
                runs[j][0], runs[j][1] = min(runs[j][0], a), max(runs[j][1], b)
                del runs[i]
                merged = [runs[0]]
                for r in runs[1:]:
                    if r[2] == merged[-1][2]:
                        merged[-1][1] = r[1]
                    else:
                        merged.append(r)
                runs = merged
                changed = True
                break
    return [(a, b, f) for a, b, f in runs]


def _feet_and_plates(signals: Sequence[PlateSignal], lm: Mapping[str, np.ndarray], times: np.ndarray,
                     fps: float, analog_rate: float, name: str) -> tuple[_FeetResult, list[PlateSignal]]:
    T = times.size
    dt = 1.0 / fps
    # --- plate loading periods, assigned to a foot by the CoP's distance to the foot -------
    assigned: list[PlateSignal] = []
    per_foot_frames = {f: np.zeros(T, dtype=bool) for f in FEET}
    unassigned = np.zeros(T, dtype=bool)
    periods_info: list[dict[str, Any]] = []
    plate_foot_frames: list[tuple[PlateSignal, str, np.ndarray]] = []
    sub_periods: dict[str, list[tuple[int, int, bool, bool]]] = {f: [] for f in FEET}
    for sig in signals:
        periods = []
        for a, b in _loading_periods(sig, analog_rate):
            t0, t1 = float(sig.times[a]), float(sig.times[b - 1])
            idx = np.nonzero((times >= t0 - dt / 2) & (times <= t1 + dt / 2))[0]
            if idx.size == 0:
                continue
            # the foot nearest to the CoP at each frame (a long plate may take both feet in turn)
            k = np.clip(np.searchsorted(sig.times, times[idx]), a, b - 1)
            cop = sig.cop[:, k]
            dist = np.vstack([
                np.minimum(_seg_distance(cop, lm[f"heel_{s}"][:, idx], lm[f"toe_{s}"][:, idx]),
                           _seg_distance(cop, lm[f"ankle_{s}"][:, idx], lm[f"toe_{s}"][:, idx]))
                for s in SIDES
            ])
            for la, lb, i_foot in _nearest_runs(dist, max(int(round(0.03 * fps)), 3)):
                ts = t0 if la == 0 else float(times[idx[la]] - dt / 2)
                te = t1 if lb == idx.size else float(times[idx[lb - 1]] + dt / 2)
                fr = np.zeros(T, dtype=bool)
                fr[idx[la:lb]] = True
                dmed = float(np.nanmedian(dist[i_foot, la:lb])) if i_foot >= 0 else float("inf")
                if not dmed <= 0.25:
                    log.warning("%s: plate %d loaded %.3f-%.3f s by no foot (CoP %.2f m from the nearest)",
                                name, sig.index, ts, te, dmed)
                    foot = "unassigned"
                    unassigned |= fr
                else:
                    foot = FEET[i_foot]
                    per_foot_frames[foot] |= fr
                    plate_foot_frames.append((sig, foot, fr))
                    sub_periods[foot].append((int(idx[la]), int(idx[lb - 1]) + 1, la > 0, lb < idx.size))
                periods.append((ts, te, foot))
                # a "split" edge is where the CoP passes from one foot to the other on this plate:
                # not a foot strike / foot off
                periods_info.append({"plate": sig.index, "start": ts, "end": te, "foot": foot,
                                     "cop_to_foot_m": dmed, "start_split": la > 0, "end_split": lb < idx.size})
        assigned.append(PlateSignal(**{**sig.__dict__, "periods": tuple(periods)}))
    # --- per-frame wrenches: force and moment about our origin, box-averaged -------------
    force = np.zeros((2, 3, T))
    moment = np.zeros((2, 3, T))
    height_w = np.zeros((2, T))
    for sig in assigned:
        cop = np.nan_to_num(sig.cop)
        m = np.cross(cop, sig.force, axis=0)
        m[2] += sig.free_moment
        Fa = _frame_average(sig.force, sig.times, times, dt)
        Ma = _frame_average(m, sig.times, times, dt)
        Ha = _frame_average((cop[2] * sig.force[2])[None], sig.times, times, dt)[0]
        for sig2, foot, fr in plate_foot_frames:
            if sig2 is not None and sig2.index == sig.index:
                i = FEET.index(foot)
                # frames of this period only (a plate may carry both feet in turn)
                win = fr.copy()
                force[i][:, win] += Fa[:, win]
                moment[i][:, win] += Ma[:, win]
                height_w[i, win] += Ha[win]
    cop_out = np.full((2, 3, T), np.nan)
    free = np.zeros((2, T))
    thr = min(s.threshold for s in signals) if signals else 20.0
    loaded_plate = np.zeros((2, T), dtype=bool)
    for i in range(2):
        F, M = force[i], moment[i]
        ok = F[2] > thr
        loaded_plate[i] = ok
        h = np.where(ok, height_w[i] / np.where(ok, F[2], 1.0), 0.0)
        x = np.where(ok, (h * F[0] - M[1]) / np.where(ok, F[2], 1.0), np.nan)
        y = np.where(ok, (M[0] + h * F[1]) / np.where(ok, F[2], 1.0), np.nan)
        cop_out[i] = np.vstack([x, y, np.where(ok, h, np.nan)])
        free[i] = np.where(ok, M[2] - (x * F[1] - y * F[0]), 0.0)
        force[i][:, ~ok] = 0.0
    # --- kinematic stance (Zeni et al. 2008), event offsets calibrated on the plates -------
    fwd = _unit(np.cross(lm["hip_l"] - lm["hip_r"], np.array([0.0, 0.0, 1.0])[:, None], axis=0))
    events = {foot: _zeni_events(lm, s, fwd, times, fps) for foot, s in zip(FEET, SIDES)}
    plate_events = {foot: ([], []) for foot in FEET}  # (onsets, offsets) in s, foot by foot
    for p in periods_info:
        if p["foot"] in FEET:
            if p["start"] > times[0] + dt and not p["start_split"]:
                plate_events[p["foot"]][0].append(p["start"])
            if p["end"] < times[-1] - dt and not p["end_split"]:
                plate_events[p["foot"]][1].append(p["end"])
    offsets = _event_offsets(events, plate_events)
    contact_foot = np.zeros((2, T), dtype=bool)
    for i, (foot, s) in enumerate(zip(FEET, SIDES)):
        hs = events[foot][0] + offsets[foot][0]
        to = events[foot][1] + offsets[foot][1]
        low = np.minimum(lm[f"heel_{s}"][2], lm[f"mtp_{s}"][2])
        kin = _stance_from_events(hs, to, times, low)
        plate = loaded_plate[i]
        c = np.zeros(T, dtype=bool)
        for a, b in _runs(kin | plate):
            subs = [x for x in sub_periods[foot] if x[0] < b and x[1] > a]
            pf = np.nonzero(plate[a:b])[0] + a
            if not subs or pf.size == 0:
                c[a:b] = kin[a:b]
                continue
            # the plate's own loading edges replace the kinematic strike / off; where the
            # plate's period ends because the other foot took over the plate, kinematics decide
            first, last = min(subs), max(subs, key=lambda x: x[1])
            s0 = a if first[2] else int(pf[0])
            e0 = b if last[3] else int(pf[-1]) + 1
            c[s0:e0] = True
        contact_foot[i] = c
    hh = {foot: lm[f"heel_{s}"][2] for foot, s in zip(FEET, SIDES)}
    ht = {foot: np.minimum(lm[f"mtp_{s}"][2], lm[f"toe_{s}"][2]) for foot, s in zip(FEET, SIDES)}
    # --- valid: every foot on the ground is measured by a plate, no plate shared -----------
    valid = np.ones(T, dtype=bool)
    shared = np.zeros(T, dtype=bool)
    for sig, foot, fr in plate_foot_frames:
        other = 1 - FEET.index(foot)
        s_o = SIDES[other]
        on_plate = np.zeros(T, dtype=bool)
        for key in ("heel", "mtp", "toe"):
            on_plate |= _inside(sig.corners, lm[f"{key}_{s_o}"], -0.01)
        shared |= fr & contact_foot[other] & on_plate & ~loaded_plate[other]
    for i in range(2):
        valid &= ~contact_foot[i] | loaded_plate[i]
    valid &= ~shared & ~unassigned
    if shared.any():
        log.warning("%s: %d frames with both feet on one plate marked invalid", name, int(shared.sum()))
    # --- heel / toe contact flags ------------------------------------------------------------
    contacts = np.zeros((4, T), dtype=bool)
    for i, foot in enumerate(FEET):
        c = contact_foot[i]
        heel_on = c & (hh[foot] < CONTACT_HEIGHT)
        toe_on = c & (ht[foot] < CONTACT_HEIGHT)
        neither = c & ~heel_on & ~toe_on
        heel_on |= neither & (hh[foot] <= ht[foot])
        toe_on |= neither & (ht[foot] < hh[foot])
        contacts[2 * i], contacts[2 * i + 1] = heel_on, toe_on
    measured = MeasuredGRF(force=force, cop=cop_out, free_moment=free, valid=valid, source=f"c3d:{name}")
    ev = {foot: {"foot_strike": [round(float(x), 3) for x in events[foot][0] + offsets[foot][0]],
                 "foot_off": [round(float(x), 3) for x in events[foot][1] + offsets[foot][1]],
                 "offsets_s": [round(float(x), 3) for x in offsets[foot]]} for foot in FEET}
    return _FeetResult(measured, contacts, periods_info, ev), assigned


# ----------------------------------------------------------------------------------------
# the reader


@dataclass(frozen=True, eq=False)
class C3DTrial:
    """Everything read from a C3D file: the track and the plates' analog-rate signals."""

    track: SkeletonTrack
    plates: tuple[PlateSignal, ...]


def read_c3d_trial(path: str | Path, *, mass: float | None = None, require_plates: bool = True,
                   max_gap_s: float = 0.1, fz_threshold: float = 20.0) -> C3DTrial:
    """Read a C3D trial: see the module docstring. ``max_gap_s``: longest marker gap filled."""
    path = Path(path)
    raw = _read_raw(path)
    name = path.name
    T_all = raw.points.shape[2]
    if T_all < 10:
        raise C3DError(f"{name}: only {T_all} marker frames")
    mk = _Markers(raw)
    sp = _subject_params(raw.params)
    specs = _plate_specs(raw)
    if not specs and require_plates:
        raise C3DError(f"{name}: no force plates (FORCE_PLATFORM:USED is 0 or missing); "
                       "pass require_plates=False to read the kinematics alone")
    # pelvis markers first: they decide the walking direction
    roles = {}
    for role in ("ASI", "PSI"):
        pair = [mk.find(role, s) for s in ("R", "L")]
        if all(pair):
            roles[role] = _mid(mk.get(pair[0]), mk.get(pair[1]))
    if "ASI" not in roles:
        raise C3DError(f"{name}: required markers RASI and LASI not found (looked for "
                       f"{', '.join(_alias_names('ASI', 'R') + _alias_names('ASI', 'L'))})")
    if "PSI" not in roles and mk.find("SACR") is not None:
        roles["PSI"] = mk.get(mk.find("SACR"))  # type: ignore[arg-type]
    R, floor, axes_info = _detect_axes(raw, mk, specs, roles)
    # frames where every required lower-body marker is seen (after short-gap filling)
    max_gap = max(int(round(max_gap_s * raw.point_rate)), 1)
    required = _required_lower(mk, name)
    good = np.ones(T_all, dtype=bool)
    for lbl in required:
        x, gaps = fill_gaps(mk.get(lbl), max_gap)
        interior = [(a, b) for a, b in gaps if a > 0 and b < T_all]
        if interior:
            a, b = interior[0]
            raise C3DError(f"{name}: marker {lbl} has a gap of {b - a} frames ({(b - a) / raw.point_rate:.2f} s "
                           f"> {max_gap_s} s) at {a / raw.point_rate:.2f}-{(b - 1) / raw.point_rate:.2f} s")
        good &= np.isfinite(x).all(axis=0)
    if not good.any():
        raise C3DError(f"{name}: the required markers are never all visible together")
    idx = np.nonzero(good)[0]
    first, last = int(idx[0]), int(idx[-1]) + 1
    if (last - first) / raw.point_rate < 0.5:
        raise C3DError(f"{name}: only {(last - first) / raw.point_rate:.2f} s with every required marker")
    if first > 0 or last < T_all:
        log.warning("%s: frames %d-%d kept (required markers missing at the ends)", name, first, last - 1)
    frames = slice(first, last)
    times = np.arange(first, last) / raw.point_rate
    # height estimate (only for defaults when the file has none)
    height_est = _height_estimate(mk, R, floor, sp)
    built = _landmarks(mk, R, floor, sp, height_est, frames, max_gap, name)
    lm = built.landmarks
    frame = GroundFrame(R=R.T, offset=R[2] * floor, unit_m=raw.unit_m,
                        axes=_axes_text(R))
    source: dict[str, Any] = {
        "format": "c3d", "path": str(path), "first_frame": raw.first_frame + first,
        "point_rate": raw.point_rate, "analog_rate": raw.analog_rate, "point_unit_m": raw.unit_m,
        "frames_kept": (first, last), "axes": axes_info, "floor_m": floor, "markers": built.markers_used,
        "notes": built.notes, "height_estimate_m": height_est,
        "manufacturer": _strings(_param(raw.params, "MANUFACTURER", "COMPANY"))[:1],
    }
    measured = contacts = None
    plates: tuple[PlateSignal, ...] = ()
    if specs:
        sigs = _plate_signals(raw, specs, R, floor, fz_threshold)
        feet, assigned = _feet_and_plates(sigs, lm, times, raw.point_rate, raw.analog_rate, name)
        measured, contacts, plates = feet.measured, feet.contacts, tuple(assigned)
        source["plates"] = [
            {"index": s.index, "type": s.type, "peak_vertical_N": s.peak_vertical,
             "periods": [list(p) for p in s.periods], "zero": s.baseline} for s in plates
        ]
        source["gait_events"] = feet.events
        if not any(p[2] in FEET for s in plates for p in s.periods):
            log.warning("%s: no foot lands on a force plate", name)
    # subject mass: argument, file, plates over a complete stride
    if mass is not None:
        m, how = float(mass), "argument"
    elif sp.mass is not None:
        m, how = sp.mass, "file"
    else:
        m_pl = _mass_from_plates(measured, contacts, times) if measured is not None else None
        if m_pl is None:
            raise C3DError(f"{name}: subject mass unknown: the file has no PROCESSING:Bodymass and the plates "
                           "never measure a complete stride", parameter="mass", unit="kg")
        m, how = m_pl, "plates (mean vertical force over a stride / g)"
    if not 5.0 <= m <= 400.0:
        raise C3DError(f"{name}: implausible subject mass {m:g} kg")
    source["mass_from"] = how
    if measured is not None:
        peak = float(np.max(measured.force[:, 2].sum(axis=0)))
        if not 0.5 * m * G < peak < 5.0 * m * G:
            log.warning("%s: peak vertical plate force %.0f N is %.2f body weights", name, peak, peak / (m * G))
    track = SkeletonTrack(
        times=times, landmarks=lm, orientations=built.orientations, frame=frame, mass=m,
        height=sp.height, measured=measured, contacts=contacts, source=source,
    )
    return C3DTrial(track=track, plates=plates)


def _required_lower(mk: _Markers, name: str) -> list[str]:
    out = []
    for s in ("R", "L"):
        for role in ("ASI", "KNE", "ANK", "HEE"):
            lbl = mk.find(role, s)
            if lbl is None:
                raise C3DError(f"{name}: required marker {s}{role} not found (looked for "
                               f"{', '.join(_alias_names(role, s))})")
            out.append(lbl)
        toe = mk.find("TOE", s)
        if toe is None:
            mt = [mk.find("MT1", s), mk.find("MT5", s)]
            if not all(mt):
                raise C3DError(f"{name}: required marker {s}TOE not found (looked for "
                               f"{', '.join(_alias_names('TOE', s))}, or {s}MT1 and {s}MT5)")
            out += [m for m in mt if m]
        else:
            out.append(toe)
    psi = [mk.find("PSI", s) for s in ("R", "L")]
    if all(psi):
        out += [p for p in psi if p]
    elif mk.find("SACR") is not None:
        out.append(mk.find("SACR"))  # type: ignore[arg-type]
    else:
        raise C3DError(f"{name}: required markers RPSI and LPSI (or SACR) not found")
    return out


def _height_estimate(mk: _Markers, R: np.ndarray, floor: float, sp: SubjectParams) -> float:
    if sp.height:
        return sp.height
    heads = [mk.find(r, s) for r in ("FHD", "BHD") for s in ("L", "R")]
    heads = [h for h in heads if h]
    if heads:
        z = np.nanmedian(np.stack([R[2] @ mk.get(h) for h in heads]), axis=0) - floor
        return float(np.nanmedian(z) / 0.955)
    legs = [v for v in sp.leg_length.values() if v]
    if legs:
        return float(np.mean(legs) / 0.53)
    asis = [mk.find("ASI", s) for s in ("L", "R")]
    z = np.nanmedian(np.stack([R[2] @ mk.get(a) for a in asis if a])) - floor
    return float(z / 0.55)


def _axes_text(R: np.ndarray) -> str:
    names = []
    for row, ours in zip(R, ("forward", "left", "up")):
        k = int(np.argmax(np.abs(row)))
        if abs(row[k]) > 1 - 1e-9:
            names.append(f"{'+' if row[k] > 0 else '-'}{'XYZ'[k]} {ours}")
        else:
            names.append(f"{np.round(row, 3).tolist()} {ours}")
    return "input " + ", ".join(names)


def _mass_from_plates(measured: MeasuredGRF, contacts: np.ndarray | None, times: np.ndarray) -> float | None:
    """Mean vertical reaction / g over a whole stride (heel strike to heel strike) of complete GRF."""
    if contacts is None:
        return None
    for foot in range(2):
        c = contacts[2 * foot] | contacts[2 * foot + 1]
        starts = [a for a, _ in _runs(c) if a > 0]
        for a, b in zip(starts, starts[1:]):
            if measured.valid[a:b + 1].all():
                fz = measured.force[:, 2, a:b].sum(axis=0)
                return float(np.mean(fz) / G)
    return None


def read_c3d(path: str | Path, *, mass: float | None = None, require_plates: bool = True,
             max_gap_s: float = 0.1, fz_threshold: float = 20.0) -> SkeletonTrack:
    """Landmarks, measured ground reactions and contacts of a C3D trial, in our frame."""
    return read_c3d_trial(path, mass=mass, require_plates=require_plates, max_gap_s=max_gap_s,
                          fz_threshold=fz_threshold).track


def load_c3d(path: str | Path, *, mass: float | None = None, require_plates: bool = True,
             max_gap_s: float = 0.1, fz_threshold: float = 20.0, **fit_options: Any) -> Capture:
    """The capture of a C3D trial: ``fit_track(read_c3d(path, ...), **fit_options)``
    (``fit_options``: e.g. ``lower_only``, ``orientation_weight``; see ``solver.io.fit``)."""
    from solver.io.fit import fit_track

    track = read_c3d(path, mass=mass, require_plates=require_plates, max_gap_s=max_gap_s,
                     fz_threshold=fz_threshold)
    return fit_track(track, **fit_options)
