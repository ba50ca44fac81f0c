"""Plates -> feet, gait events and the contact schedule, per-frame measured ground reactions."""

from __future__ import annotations

import logging
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from solver.capture import MeasuredGRF
from solver.io.c3d.plates import PlateSignal, _loading_periods
from solver.io.c3d.reader import FEET, SIDES, _runs, _unit

log = logging.getLogger("solver.io.c3d")


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
    from scipy.signal import find_peaks  # lazy: scipy.signal costs ~1 s to import

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
    """Foot strikes (heel farthest ahead of the pelvis) and foot offs (forefoot farthest behind),
    completed where the prominence test misses one (:func:`_complete_events`)."""
    heel = np.sum((lm[f"heel_{s}"] - lm["pelvis"]) * fwd, axis=0)
    fore = np.sum((lm[f"mtp_{s}"] - lm["pelvis"]) * fwd, axis=0)
    return _complete_events(_extrema(heel, times, fps, True), _extrema(fore, times, fps, False), heel, fore, times)


#: an extremum added by :func:`_complete_events` stands out this much (m) from its interval's ends
EVENT_DEPTH = 0.01
#: and lies this far (s) from the neighbouring events
EVENT_GAP = 0.1


def _complete_events(hs: np.ndarray, to: np.ndarray, heel: np.ndarray, fore: np.ndarray, times: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """A foot's strikes and offs alternate. Where two events of a kind follow each other, or before
    the first / after the last event of the trial, the event of the other kind that can be missing
    there (find_peaks' prominence is one-sided near the trial's ends, and a stance cut by the end of
    the trial loses its off) is the extremum of its signal (heel: maximum, forefoot: minimum) over
    that interval, when it lies inside it (two frames from the trial's ends, ``EVENT_GAP`` from the
    neighbouring events) and stands out by ``EVENT_DEPTH`` from both of the interval's ends."""
    dt = times[1] - times[0]
    T = times.size
    ev = sorted([(float(t), 0) for t in hs] + [(float(t), 1) for t in to])
    found: list[tuple[float, int]] = []
    bounds = [(times[0] - 1.0, None)] + ev + [(times[-1] + 1.0, None)]
    for (ta, ka), (tb, kb) in zip(bounds[:-1], bounds[1:]):
        if ka is not None and kb is not None and ka != kb:
            continue  # alternating already
        kinds = [1 - ka] if ka is not None else [1 - kb] if kb is not None else [0, 1]
        for kind in kinds:
            y = heel if kind == 0 else -fore
            lo = 2 if ka is None else int(np.searchsorted(times, ta + EVENT_GAP))
            hi = T - 2 if kb is None else int(np.searchsorted(times, tb - EVENT_GAP))
            if hi - lo < 3:
                continue
            i = lo + int(np.argmax(y[lo:hi]))
            a = 0 if ka is None else int(np.clip(np.searchsorted(times, ta), 0, T - 1))
            b = T - 1 if kb is None else int(np.clip(np.searchsorted(times, tb), 0, T - 1))
            if i in (lo, hi - 1) or y[i] - max(y[a], y[b]) < EVENT_DEPTH:
                continue
            den = y[i - 1] - 2 * y[i] + y[i + 1]
            d = 0.5 * (y[i - 1] - y[i + 1]) / den if den != 0 else 0.0
            found.append((float(times[i] + np.clip(d, -0.5, 0.5) * dt), kind))
    if found:
        hs = np.sort(np.concatenate([hs, [t for t, k in found if k == 0]]))
        to = np.sort(np.concatenate([to, [t for t, k in found if k == 1]]))
    return hs, to


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


#: a foot is down when its lowest landmark is this low (m) and slower than ``FOOT_DOWN_SPEED`` m/s
FOOT_DOWN_HEIGHT = 0.03
FOOT_DOWN_SPEED = 0.3
#: shortest run of "foot down" frames counted as a stance the events missed
MIN_STANCE_S = 0.1


def _foot_down(lm: Mapping[str, np.ndarray], s: str, fps: float) -> np.ndarray:
    """Frames where the heel or the metatarsal heads are on the floor and still (horizontal speed by
    central differences below ``FOOT_DOWN_SPEED``): the independent check that no stance is dropped."""
    out = np.zeros(lm[f"heel_{s}"].shape[1], dtype=bool)
    for key in ("heel", "mtp"):
        p = lm[f"{key}_{s}"]
        v = np.linalg.norm(np.gradient(p[:2], 1.0 / fps, axis=1), axis=0)
        out |= (p[2] < FOOT_DOWN_HEIGHT) & (v < FOOT_DOWN_SPEED)
    return out


#: a foot landmark this close to the floor (m) bears load; its contact region starts this far in front of
#: the heel landmark (the back of the heel) and ends this far behind the toe tip
LOW = 0.03
HEEL_PAD, TOE_PAD = 0.02, 0.01


def feet_on_plates(landmarks: Any, corners: Sequence[np.ndarray], margin: float = 0.01) -> np.ndarray:
    """(2, T) bool: each foot (right, left) stands on the plates — every part of it that touches the floor
    (heel, metatarsal heads, toe tip, when lower than ``LOW``) lies inside the union of the plate outlines
    ``corners`` ((4, 3) each, our frame) grown by ``margin`` m. ``landmarks``: ``heel_r``, ``mtp_r``,
    ``toe_r``, ... (3, T) in our frame. A foot in the air is trivially "on the plates"."""
    T = np.asarray(landmarks["heel_r"]).shape[1]
    out = np.ones((2, T), dtype=bool)
    for i, s in enumerate("rl"):
        heel, mtp, toe = (np.asarray(landmarks[f"{k}_{s}"], dtype=float) for k in ("heel", "mtp", "toe"))
        fwd = toe[:2] - heel[:2]
        fwd = fwd / np.maximum(np.linalg.norm(fwd, axis=0), 1e-9)
        pts = [(heel[:2] + HEEL_PAD * fwd, heel[2]), (mtp[:2], mtp[2]), (toe[:2] - TOE_PAD * fwd, toe[2])]
        for p, z in pts:
            inside = np.zeros(T, dtype=bool)
            for poly in corners:
                c = np.asarray(poly)[:, :2]
                ctr = c.mean(axis=0)
                ok = np.ones(T, dtype=bool)
                for k in range(len(c)):
                    a, b = c[k], c[(k + 1) % len(c)]
                    n = np.array([b[1] - a[1], a[0] - b[0]])
                    n /= np.linalg.norm(n)
                    if n @ (ctr - a) > 0:
                        n = -n  # outward
                    ok &= n @ (p - a[:, None]) <= margin
                inside |= ok
            out[i] &= inside | (z > LOW)
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


@dataclass
class _Periods:
    """Plate loading periods assigned to the feet: the plates with their periods, every period
    (for the source), (plate, foot, frames) of each assigned one, each foot's sub-periods
    (first, last + 1 frame, start split, end split) and the frames a plate is loaded by no foot."""

    assigned: list[PlateSignal]
    info: list[dict[str, Any]]
    plate_foot_frames: list[tuple[PlateSignal, str, np.ndarray]]
    sub_periods: dict[str, list[tuple[int, int, bool, bool]]]
    unassigned: np.ndarray


def _assign_periods(signals: Sequence[PlateSignal], lm: Mapping[str, np.ndarray], times: np.ndarray,
                    fps: float, analog_rate: float, name: str) -> _Periods:
    """Plate loading periods, assigned to a foot by the CoP's distance to the foot."""
    T = times.size
    dt = 1.0 / fps
    out = _Periods([], [], [], {f: [] for f in FEET}, np.zeros(T, dtype=bool))
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
                    out.unassigned |= fr
                else:
                    foot = FEET[i_foot]
                    out.plate_foot_frames.append((sig, foot, fr))
                    out.sub_periods[foot].append((int(idx[la]), int(idx[lb - 1]) + 1, la > 0, lb < idx.size))
                periods.append((ts, te, foot))
                # a "split" edge is where the CoP passes from one foot to the other on this plate:
                # not a foot strike / foot off
                out.info.append({"plate": sig.index, "start": ts, "end": te, "foot": foot,
                                 "cop_to_foot_m": dmed, "start_split": la > 0, "end_split": lb < idx.size})
        out.assigned.append(PlateSignal(**{**sig.__dict__, "periods": tuple(periods)}))
    return out


def _foot_wrenches(signals: Sequence[PlateSignal], per: _Periods, times: np.ndarray, dt: float):
    """Each foot's force, centre of pressure and free moment per frame (box-averaged plate
    wrenches about our origin, summed over the plates it stands on) and whether it loads a plate."""
    T = times.size
    force = np.zeros((2, 3, T))
    moment = np.zeros((2, 3, T))
    height_w = np.zeros((2, T))
    for sig in per.assigned:
        cop = np.nan_to_num(sig.cop)
        m = np.cross(cop, sig.force, axis=0)
        m[2] += sig.free_moment
        Fa = _frame_average(sig.force, sig.times, times, dt)
        Ma = _frame_average(m, sig.times, times, dt)
        Ha = _frame_average((cop[2] * sig.force[2])[None], sig.times, times, dt)[0]
        for sig2, foot, fr in per.plate_foot_frames:
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
    return force, cop_out, free, loaded_plate


def _foot_contact(lm: Mapping[str, np.ndarray], times: np.ndarray, fps: float, per: _Periods,
                  loaded_plate: np.ndarray, name: str):
    """Each foot's stance (2, T): kinematic gait events (Zeni et al. 2008) with offsets
    calibrated on the plates, a foot down without events counted, the plates' own loading
    edges where they tell; the events and offsets too."""
    T = times.size
    dt = 1.0 / fps
    fwd = _unit(np.cross(lm["hip_l"] - lm["hip_r"], np.array([0.0, 0.0, 1.0])[:, None], axis=0))
    events = {foot: _zeni_events(lm, s, fwd, times, fps) for foot, s in zip(FEET, SIDES)}
    # (onsets, offsets) in s, foot by foot
    plate_events: dict[str, tuple[list[float], list[float]]] = {foot: ([], []) for foot in FEET}
    for p in per.info:
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
        missed = _foot_down(lm, s, fps) & ~kin
        for a, b in _runs(missed):
            at_end = a == 0 or b == T  # a stance cut by the trial's ends may be short
            long_enough = (b - a) / fps >= MIN_STANCE_S or (at_end and b - a >= 2)
            if long_enough and not kin[max(a - 1, 0):min(b + 1, T)].any():
                log.warning("%s: %s foot down %.2f-%.2f s without gait events there: counted as stance",
                            name, foot, times[a], times[b - 1])
                kin[a:b] = True
        plate = loaded_plate[i]
        c = np.zeros(T, dtype=bool)
        for a, b in _runs(kin | plate):
            subs = [x for x in per.sub_periods[foot] if x[0] < b and x[1] > a]
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
    return contact_foot, events, offsets


def _feet_and_plates(signals: Sequence[PlateSignal], lm: Mapping[str, np.ndarray], times: np.ndarray,
                     fps: float, analog_rate: float, name: str) -> tuple[_FeetResult, list[PlateSignal]]:
    T = times.size
    per = _assign_periods(signals, lm, times, fps, analog_rate, name)
    force, cop_out, free, loaded_plate = _foot_wrenches(signals, per, times, 1.0 / fps)
    contact_foot, events, offsets = _foot_contact(lm, times, fps, per, loaded_plate, name)
    hh = {foot: lm[f"heel_{s}"][2] for foot, s in zip(FEET, SIDES)}
    ht = {foot: np.minimum(lm[f"mtp_{s}"][2], lm[f"toe_{s}"][2]) for foot, s in zip(FEET, SIDES)}
    # --- valid: every foot on the ground is measured by a plate, no plate shared -----------
    valid = np.ones(T, dtype=bool)
    shared = np.zeros(T, dtype=bool)
    for sig, foot, fr in per.plate_foot_frames:
        other = 1 - FEET.index(foot)
        s_o = SIDES[other]
        on_plate = np.zeros(T, dtype=bool)
        for key in ("heel", "mtp", "toe"):
            on_plate |= _inside(sig.corners, lm[f"{key}_{s_o}"], -0.01)
        shared |= fr & contact_foot[other] & on_plate & ~loaded_plate[other]
    on_plates = feet_on_plates(lm, [s.corners for s in signals])
    for i in range(2):
        valid &= ~contact_foot[i] | (loaded_plate[i] & on_plates[i])
    valid &= ~shared & ~per.unassigned
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
    return _FeetResult(measured, contacts, per.info, ev), per.assigned
