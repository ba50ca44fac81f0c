"""C3D force platforms (types 1-4): wrench on the surface, zero baseline, reaction on the subject."""

from __future__ import annotations

import logging
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from solver.io.c3d.reader import (
    _LENGTH_UNITS,
    _VOLT_UNITS,
    C3DError,
    _force_unit,
    _moment_unit,
    _param,
    _Raw,
    _runs,
    _scalar,
)

log = logging.getLogger("solver.io.c3d")


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
            raise C3DError(f"{raw.path.name}: force plate {i + 1} (type {t}) needs {k} channels in "
                           "FORCE_PLATFORM:CHANNEL")
        ch = tuple(int(c) - 1 for c in chans[:k, i])
        if min(ch) < 0 or max(ch) >= raw.analogs.shape[0]:
            raise C3DError(f"{raw.path.name}: force plate {i + 1} channels {[c + 1 for c in ch]} outside the "
                           "analog data")
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
        units = [_force_unit(u) for u in us if u]
        return (units[0] if units else None), None
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
        x, y = np.where(np.isfinite(x), x, 0.0), np.where(np.isfinite(y), y, 0.0)  # unloaded: NaN below
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


