"""Anatomical landmarks and segment orientations from the markers."""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from solver.filtering import zero_phase_lowpass
from solver.io.c3d.markers import _Markers
from solver.io.c3d.reader import SIDES, C3DError, SubjectParams, _mid, _perp, _rigid_fill, _unit, fill_gaps
from solver.io.track import add_pelvis

log = logging.getLogger("solver.io.c3d")


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


#: largest angle (deg) between a wand's offset from the segment (proximal centre -> lateral marker)
#: and the body's lateral direction for PiG's chord: a wand that stands forward (some Helen Hayes
#: exports put it on the front of the thigh) would put the joint centre behind the joint
WAND_MAX_TURN_DEG = 45.0


def _wand_turn(wand: np.ndarray, proximal: np.ndarray, lateral: np.ndarray, outward: np.ndarray) -> float:
    """Median angle (deg) between the wand's offset from the line proximal -> lateral marker and
    the outward (lateral) direction, both ⟂ that line."""
    axis = _unit(lateral - proximal)
    off = _unit(_perp(wand - proximal, axis))
    out = _unit(_perp(outward, axis))
    return float(np.degrees(np.arccos(np.clip(np.nanmedian(np.sum(off * out, axis=0)), -1.0, 1.0))))


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
    upper_body: dict[str, str]  # part -> "markers" or how it was modelled
    marker_xyz: dict[str, np.ndarray]  # label of each marker used -> (3, T) in our frame (short gaps filled)


def _landmarks(mk: _Markers, R: np.ndarray, floor: float, sp: SubjectParams, height_est: float,
               frames: slice, max_gap: int, name: str, fps: float, upper: str = "auto") -> _Built:
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
                raise C3DError(mk.missing_message([key]))
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

    def need(role: str, side: str | None = None) -> np.ndarray:
        """A required marker (a C3DError when it is missing or has a long gap)."""
        x = marker(role, side)
        assert x is not None  # marker() raises for a required one
        return x

    mr = sp.marker_radius
    H = sp.height or height_est
    # --- pelvis -------------------------------------------------------------------------
    rasi, lasi = need("ASI", "R"), need("ASI", "L")
    mpsi = _back_of_pelvis(marker, mk)
    masi = _mid(lasi, rasi)
    px, py, pz = _pelvis_axes(rasi, lasi, mpsi)
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
        kne = need("KNE", S)
        ank = need("ANK", S)
        asi = lasi if s == "l" else rasi
        leg = sp.leg_length[s]
        if leg is None:
            leg = float(np.median(np.linalg.norm(asi - kne, axis=0) + np.linalg.norm(kne - ank, axis=0)))
            notes.append(f"{S} leg length estimated from markers: {leg:.3f} m")
        hip = _hip_centre(leg, sp.asis_trochanter[s], mr, sgn, inter_asis, masi, (px, py, pz))
        lm[f"hip_{s}"] = hip
        medial_dir = -sgn * py  # towards the body's midline
        def centre(lateral: np.ndarray, medial_role: str, wand_role: str, width: float | None, frac: float,
                   proximal: np.ndarray, what: str, S: str = S,
                   medial_dir: np.ndarray = medial_dir) -> np.ndarray:
            """Mid-point of the lateral and medial markers, else PiG's chord (wand) or a medial shift."""
            medial = marker(medial_role, S, required=False)
            if medial is not None:
                return _mid(lateral, medial)
            wand = marker(wand_role, S, required=False)
            if width is None:
                width = frac * H
                notes.append(f"{S} {what} width estimated {width:.3f} m ({frac} H)")
            delta = width / 2 + mr
            if wand is not None:
                turn = _wand_turn(wand, proximal, lateral, -medial_dir)
                if turn <= WAND_MAX_TURN_DEG:
                    return _chord(delta, proximal, wand, lateral)
                notes.append(f"{S}{wand_role} not used for the {what} centre: it stands {turn:.0f}° from lateral "
                             f"(more than {WAND_MAX_TURN_DEG:g}°; the chord would put the centre behind the {what})")
            return _medial_shift(lateral, proximal, medial_dir, delta)

        knee = centre(kne, "KNM", "THI", sp.knee_width[s], 0.065, hip, "knee")
        lm[f"knee_{s}"] = knee
        knee_lat[s] = kne
        ankle = centre(ank, "MED", "TIB", sp.ankle_width[s], 0.045, knee, "ankle")
        lm[f"ankle_{s}"] = ankle
        ankle_lat[s] = ank
        # foot: heel and toe markers sit at the same height above the sole (PiG); the toe
        # marker is on the 2nd metatarsal head. Sole = their heights during stance.
        hee = need("HEE", S)
        toe_m = marker("TOE", S, required=False)
        if toe_m is None:
            mt1, mt5 = marker("MT1", S, required=False), marker("MT5", S, required=False)
            if mt1 is None or mt5 is None:
                raise C3DError(f"{name}: required marker {S}TOE (or {S}MT1 and {S}MT5) not found")
            toe_m = _mid(mt1, mt5)
        lm[f"heel_{s}"], lm[f"mtp_{s}"], lm[f"toe_{s}"], f, u = _sole(hee, toe_m, ankle, 0.01 * H)
        # segment orientations (x forward, y left, z up in the neutral pose)
        ori[f"thigh_{s}"] = _long_bone_frame(hip, knee, kne, s)
        ori[f"shank_{s}"] = _long_bone_frame(knee, ankle, ank, s)
        ori[f"foot_{s}"] = np.stack([f, np.cross(u, f, axis=0), u], axis=1)
    add_pelvis(lm)
    # --- upper body: markers where there are some, modelled elsewhere ---------------------------
    how: dict[str, str] = {}
    if upper != "none":
        up_lm, up_ori, how = _upper_landmarks(marker, lm, masi, px, pz, inter_asis, sp, H, mr, fps)
        lm.update(up_lm)
        ori.update(up_ori)
        modelled = [f"{k}: {v}" for k, v in how.items() if v != "markers"]
        if modelled:
            notes.append("upper body " + "; ".join(modelled))
            log.info("%s: upper body %s", name, "; ".join(modelled))
    return _Built(lm, ori, notes, used, how, {lbl: filled[lbl] for lbl in used.values()})


def _back_of_pelvis(marker: Callable[..., np.ndarray | None], mk: _Markers) -> np.ndarray:
    """The mid-point of the posterior superior iliac spines, else the sacral marker (a
    C3DError naming both when neither is there)."""
    rpsi, lpsi = marker("PSI", "R", required=False), marker("PSI", "L", required=False)
    if rpsi is not None and lpsi is not None:
        return _mid(rpsi, lpsi)
    sacr = marker("SACR", None, required=False)
    if sacr is None:
        raise C3DError(mk.missing_message([k for k, x in (("RPSI", rpsi), ("LPSI", lpsi)) if x is None] + ["SACR"]))
    return sacr


def _pelvis_axes(rasi: np.ndarray, lasi: np.ndarray, mpsi: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The pelvis' forward, left and up axes: left along the ASIS line, forward from the
    mid-PSIS (or sacrum) towards the mid-ASIS."""
    py = _unit(lasi - rasi)
    px = _unit(_perp(_mid(lasi, rasi) - mpsi, py))
    return px, py, np.cross(px, py, axis=0)


def _long_bone_frame(proximal: np.ndarray, distal: np.ndarray, lateral: np.ndarray, side: str) -> np.ndarray:
    """A thigh's or shank's orientation (3, 3, T), x forward, y left, z up in the neutral pose:
    z from the distal joint centre to the proximal one, y along the lateral marker's offset
    from the distal centre (pointing left)."""
    y = (distal - lateral) if side == "r" else (lateral - distal)
    z = _unit(proximal - distal)
    y = _unit(_perp(y, z))
    return np.stack([np.cross(y, z, axis=0), y, z], axis=1)


def _hip_centre(leg: float, asis_troch: float | None, mr: float, sgn: float, inter_asis: float, masi: np.ndarray,
                axes: tuple[np.ndarray, np.ndarray, np.ndarray]) -> np.ndarray:
    """Davis (1991) / Newington hip joint centre (the regression in mm), from the pelvis frame
    (origin mid-ASIS, axes px, py, pz); ``sgn`` +1 left, -1 right."""
    px, py, pz = axes
    Lmm = leg * 1000.0
    xdis = (asis_troch * 1000.0) if asis_troch else 0.1288 * Lmm - 48.56
    C = 0.115 * Lmm - 15.3
    theta, beta = 0.5, 0.314
    mm = mr * 1000.0
    hx = C * math.cos(theta) * math.sin(beta) - (xdis + mm) * math.cos(beta)
    hy = sgn * (inter_asis * 500.0 - C * math.sin(theta))
    hz = -C * math.cos(theta) * math.cos(beta) - (xdis + mm) * math.sin(beta)
    return masi + (px * hx + py * hy + pz * hz) / 1000.0


def _sole(hee: np.ndarray, toe_m: np.ndarray, ankle: np.ndarray, mtp_h: float):
    """Heel, metatarsal heads and toe tip on the sole, and the foot's forward and up axes: heel
    and toe markers sit at the same height above the sole (PiG), the toe marker on the 2nd
    metatarsal head; the sole is their height during stance, the metatarsal heads ``mtp_h``
    above it (as the capture character)."""
    f_raw = toe_m - hee
    u = _unit(_perp(ankle - hee, _unit(f_raw)))  # foot up, ⟂ heel-toe line
    f = _unit(_perp(f_raw, u))
    h_heel = float(np.percentile(hee[2], 5))
    h_toe = float(np.percentile(toe_m[2], 5))
    heel = hee - u * h_heel
    mtp = toe_m - u * max(h_toe - mtp_h, 0.0)
    toes_len = float(np.median(np.sum((mtp - heel) * f, axis=0))) / 3.0  # heel-mtp : mtp-tip = 3 : 1
    return heel, mtp, _toe_tip(mtp, f, u, toes_len, mtp_h), f, u


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


#: Proportions of the modelled upper body (fractions of the height H; capture_full's trunk and
#: Winter's table, Drillis & Contini): lumbar -> neck, neck -> vertex, shoulder below the neck and
#: to the side, upper arm, forearm, hand
TRUNK_H, HEAD_H, SHOULDER_DROP_H, SHOULDER_HALF_H = 0.24, 0.182, 0.025, 0.129
UPPER_ARM_H, FOREARM_H, HAND_H = 0.186, 0.146, 0.108
#: cut-off (Hz) of the walking heading the modelled trunk faces (below the stride frequency)
HEADING_HZ = 0.5


def _heading(lm: dict[str, np.ndarray], fps: float) -> tuple[np.ndarray, np.ndarray]:
    """Horizontal forward and left unit vectors (3, T) of the walk: the hips' left-right axis
    made horizontal, low-passed below the stride frequency (the pelvis' own yaw oscillation
    at the stride frequency is not the trunk's: the thorax counter-rotates)."""
    y = lm["hip_l"] - lm["hip_r"]
    y = _unit(np.vstack([y[:2], np.zeros((1, y.shape[1]))]))
    T = y.shape[1]
    if T > 6 and fps / 2 > HEADING_HZ:
        y = _unit(zero_phase_lowpass(y, fps, HEADING_HZ, order=2, axis=1, padlen=min(T - 1, int(3 * fps / HEADING_HZ))))
    up = np.zeros_like(y)
    up[2] = 1.0
    return np.cross(y, up, axis=0), y


def _upper_landmarks(marker: Callable[..., np.ndarray | None], lm: dict[str, np.ndarray], masi: np.ndarray,
                     px: np.ndarray, pz: np.ndarray, inter_asis: float, sp: SubjectParams, H: float, mr: float,
                     fps: float) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray], dict[str, str]]:
    """Upper-body landmarks from whatever upper-body markers the trial has; the parts without
    markers are modelled (an upright trunk facing the walking direction, the head upright on it,
    arms hanging), never lumped into the pelvis. Returns (landmarks, orientations of modelled
    segments, how each part was obtained)."""
    out: dict[str, np.ndarray] = {}
    ori: dict[str, np.ndarray] = {}
    how: dict[str, str] = {}
    fwd, left = _heading(lm, fps)
    vert = np.zeros_like(fwd)
    vert[2] = 1.0
    upright = np.stack([fwd, left, vert], axis=1)  # (3, 3, T): x forward, y left, z up
    # lumbar joint (L5/S1) from the pelvis (Reed 1999 / Dumas 2007: ~34 % of the ASIS width behind mid-ASIS)
    out["lumbar"] = masi - 0.34 * inter_asis * px + 0.01 * inter_asis * pz
    # --- trunk: C7 and the jugular notch, else upright -------------------------------------------------
    c7, clav = marker("C7", None, required=False), marker("CLAV", None, required=False)
    t10, strn = marker("T10", None, required=False), marker("STRN", None, required=False)
    if c7 is not None and clav is not None:
        low = [x for x in (t10, strn) if x is not None]
        base = _mid(low[0], low[-1]) if low else out["lumbar"]
        t_up = _unit(_mid(c7, clav) - base)
        # C7/T1 (base of the neck): 55 % of the C7-CLAV distance from C7, 8° above that line (Dumas 2007)
        d = clav - c7
        dn = np.linalg.norm(d, axis=0)
        dh = d / dn
        up_d = _unit(_perp(t_up, dh))
        a = math.radians(8.0)
        out["neck"] = c7 + 0.55 * dn * (math.cos(a) * dh + math.sin(a) * up_d)
        out["sternum"] = _mid(clav, strn) if strn is not None else clav
        how["trunk"] = "markers"
    else:
        t_up = vert
        out["neck"] = out["lumbar"] + TRUNK_H * H * vert
        out["sternum"] = out["neck"] - 0.07 * H * vert + 0.06 * H * fwd
        ori["abdomen"] = ori["thorax"] = upright
        how["trunk"] = "modelled: upright, facing the walking direction (no C7/CLAV markers)"
    # --- head: three or four head markers, else upright on the neck -------------------------------------
    heads = {k: marker(r, sd, required=False, partial=True) for k, (r, sd) in
             {"lf": ("FHD", "L"), "rf": ("FHD", "R"), "lb": ("BHD", "L"), "rb": ("BHD", "R")}.items()}
    hd = {k: v for k, v in heads.items() if v is not None and np.isfinite(v).all(axis=0).sum() >= 3}
    for k in list(hd):  # a marker's long gaps rebuilt from the other three (rigid head)
        if not np.isfinite(hd[k]).all():
            hd[k] = _rigid_fill(hd[k], [hd[j] for j in hd if j != k])
    if len(hd) >= 3 and all(np.isfinite(v).all() for v in hd.values()):
        if len(hd) == 3:  # the fourth, never seen: a parallelogram (front/back pairs)
            k = next(j for j in ("lf", "rf", "lb", "rb") if j not in hd)
            o = {"lf": ("rf", "lb", "rb"), "rf": ("lf", "rb", "lb"), "lb": ("rb", "lf", "rf"),
                 "rb": ("lb", "rf", "lf")}[k]
            hd[k] = hd[o[0]] + hd[o[1]] - hd[o[2]]
        centre = (hd["lf"] + hd["rf"] + hd["lb"] + hd["rb"]) / 4.0
        h_fwd = _mid(hd["lf"], hd["rf"]) - _mid(hd["lb"], hd["rb"])
        h_left = _mid(hd["lf"], hd["lb"]) - _mid(hd["rf"], hd["rb"])
        h_up = _unit(np.cross(h_fwd, h_left, axis=0))
        out["head_top"] = centre + 0.05 * H * h_up  # vertex ~5 % of stature above the head band
        how["head"] = "markers"
    else:
        out["head_top"] = out["neck"] + HEAD_H * H * vert
        ori["head"] = upright
        how["head"] = "modelled: upright on the neck (fewer than three head markers)"
    # --- arms -----------------------------------------------------------------------------------------
    if how["trunk"] == "markers":
        sl, sr = marker("SHO", "L", required=False), marker("SHO", "R", required=False)
        t_left = _unit(_perp(sl - sr, t_up)) if sl is not None and sr is not None else left
    else:
        t_left = left
    for s in SIDES:
        S = s.upper()
        sgn = 1.0 if s == "l" else -1.0
        parts = []
        sho = marker("SHO", S, required=False)
        if sho is not None:
            off = sp.shoulder_offset[s] or 0.033 * H
            shoulder = sho - t_up * (off + mr)
            parts.append("shoulder")
        else:
            shoulder = out["neck"] - SHOULDER_DROP_H * H * t_up + sgn * SHOULDER_HALF_H * H * t_left
        elb, elm = marker("ELB", S, required=False), marker("ELM", S, required=False)
        if elb is not None and elm is not None:
            elbow = _mid(elb, elm)
            parts.append("elbow")
        elif elb is not None:
            ew = sp.elbow_width[s] or 0.053 * H
            elbow = _medial_shift(elb, shoulder, -sgn * t_left, ew / 2 + mr)
            parts.append("elbow")
        else:
            elbow = shoulder - UPPER_ARM_H * H * t_up
        wra, wrb = marker("WRA", S, required=False), marker("WRB", S, required=False)
        wrists = [x for x in (wra, wrb) if x is not None]
        if wrists:
            wrist = _mid(wrists[0], wrists[1]) if len(wrists) == 2 else wrists[0]
            parts.append("wrist")
        else:
            wrist = elbow + FOREARM_H * H * _unit(elbow - shoulder)
        fin, fi5 = marker("FIN", S, required=False), marker("FI5", S, required=False)
        if fin is not None:
            hand = _mid(fin, fi5) if fi5 is not None else fin
            parts.append("hand")
        else:
            hand = wrist + HAND_H * H * _unit(wrist - elbow)
        out[f"shoulder_{s}"], out[f"elbow_{s}"], out[f"wrist_{s}"], out[f"hand_{s}"] = shoulder, elbow, wrist, hand
        how[f"arm_{s}"] = ("markers" if len(parts) == 4 else
                           f"markers: {', '.join(parts)}; modelled: the rest (hanging / straight)" if parts else
                           "modelled: hanging from the shoulder")
    return out, ori, how


def _height_estimate(mk: _Markers, R: np.ndarray, floor: float, sp: SubjectParams) -> float:
    if sp.height:
        return sp.height
    heads = [h for h in (mk.find(r, s) for r in ("FHD", "BHD") for s in ("L", "R")) if h]
    if heads:
        z = np.nanmedian(np.stack([R[2] @ mk.get(h) for h in heads]), axis=0) - floor
        return float(np.nanmedian(z) / 0.955)
    legs = [v for v in sp.leg_length.values() if v]
    if legs:
        return float(np.mean(legs) / 0.53)
    asis = [mk.find("ASI", s) for s in ("L", "R")]
    z = np.nanmedian(np.stack([R[2] @ mk.get(a) for a in asis if a])) - floor
    return float(z / 0.55)


