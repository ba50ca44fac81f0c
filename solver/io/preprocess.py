"""Trial preprocessing: resampling, filtering, contact detection and gait-cycle extraction.

Public API::

    resample(capture, fps) -> Capture
    lowpass(x, fps, cutoff_hz, *, order=4, axis=-1) -> ndarray
    detect_contacts(character, q, fps, *, height_tol=0.03, speed_tol=None, min_frames=2) -> (P, T) bool
    contacts_from_plates(measured, *, threshold=20.0, character=None, q=None, fps=None) -> (P, T) bool
    gait_events(contacts, times) -> dict
    extract_cycle(capture, fps=None, *, start="right_heel_strike", contacts=None, cycle=0)
        -> (Capture, contacts (P, T))

Contact rows follow ``character.contacts``; the capture skeletons built by
:func:`solver.io.fit.fit_track` order them heel_r, toe_r, heel_l, toe_l.

Kinematic contact detection (:func:`detect_contacts`): a contact point is on the ground
when it is both *low* — within ``height_tol`` of its own contact level, the 5th
percentile of its height over the trial (robust to a floor a centimetre off) — and
*still* — horizontal speed below ``speed_tol`` (default: half the walking speed, at least
0.3 m/s; central differences after a zero-phase low-pass at 12 Hz, a third of the rate at
most). The toe row also looks at the toes' tip and the metatarsal heads (the foot-fixed
toe point rolls away when the toes bend at push-off). Runs and gaps shorter than
``min_frames`` are removed. It needs
overground(-equivalent) kinematics: on a treadmill, shift the root by the belt speed first
(``load_opensim(..., belt_speed=...)``).
"""

from __future__ import annotations

import logging

import numpy as np

from solver.capture import Capture, MeasuredGRF
from solver.character import Character

log = logging.getLogger(__name__)

__all__ = [
    "PreprocessError",
    "contacts_from_plates",
    "detect_contacts",
    "extract_cycle",
    "gait_events",
    "lowpass",
    "resample",
    "unroll_loop",
]


class PreprocessError(ValueError):
    """A trial cannot be preprocessed as asked; the message says why."""


# --- filtering and resampling --------------------------------------------------------------


def lowpass(x: np.ndarray, fps: float, cutoff_hz: float, *, order: int = 4, axis: int = -1) -> np.ndarray:
    """Zero-phase Butterworth low-pass (``scipy.signal.filtfilt``, second-order sections).

    ``order`` is the order of the one-way filter (the zero-phase result has twice the
    attenuation, no phase lag). NaN is refused (fill gaps first).
    """
    from scipy.signal import butter, sosfiltfilt

    x = np.asarray(x, dtype=float)
    if not (np.isfinite(fps) and fps > 0):
        raise PreprocessError(f"lowpass: fps must be positive, got {fps}")
    if not (np.isfinite(cutoff_hz) and 0 < cutoff_hz < fps / 2):
        raise PreprocessError(f"lowpass: cutoff {cutoff_hz} Hz must lie in (0, fps/2 = {fps / 2} Hz)")
    if np.any(~np.isfinite(x)):
        raise PreprocessError("lowpass: the signal contains NaN/inf (fill the gaps first)")
    sos = butter(order, cutoff_hz, btype="low", fs=fps, output="sos")
    n = x.shape[axis]
    padlen = min(3 * (2 * len(sos) + 1), n - 1)
    if n < 4:
        raise PreprocessError(f"lowpass: at least 4 samples are needed, got {n}")
    return sosfiltfilt(sos, x, axis=axis, padlen=padlen)


def _unwrapped(character: Character, q: np.ndarray) -> np.ndarray:
    q = np.array(q, dtype=float, copy=True)
    for i, k in enumerate(character.dof_kinds):
        if k == "hinge":
            q[i] = np.unwrap(q[i])
    return q


def resample(capture: Capture, fps: float) -> Capture:
    """The capture sampled at ``fps`` from its first time to its last (cubic spline).

    Hinge angles are unwrapped first (continuous), so values at times common to both grids
    are preserved exactly. Contact schedules take the nearest sample; measured GRF is
    interpolated linearly (``valid`` where both neighbours are valid).
    """
    from scipy.interpolate import CubicSpline

    if not (np.isfinite(fps) and fps > 0):
        raise PreprocessError(f"resample: fps must be a positive number, got {fps}")
    t = capture.times
    if capture.T < 2:
        raise PreprocessError("resample: the capture has fewer than 2 frames")
    n = int(np.floor((t[-1] - t[0]) * fps + 0.01)) + 1  # a last frame within 1 % of a step is kept
    if n < 2:
        raise PreprocessError(f"resample: {t[-1] - t[0]:.3f} s at {fps} fps gives fewer than 2 frames")
    tn = t[0] + np.arange(n) / fps
    q = _unwrapped(capture.character, capture.q)
    qn = CubicSpline(t, q, axis=1)(tn) if capture.T >= 4 else np.stack([np.interp(tn, t, r) for r in q])
    contacts = None
    idx = np.clip(np.searchsorted(t, tn), 1, len(t) - 1)
    nearest = np.where(np.abs(t[idx - 1] - tn) <= np.abs(t[idx] - tn), idx - 1, idx)
    if capture.contacts is not None:
        contacts = capture.contacts[:, nearest]
    measured = None
    if capture.measured is not None:
        m = capture.measured

        def li(a: np.ndarray) -> np.ndarray:
            flat = a.reshape(-1, a.shape[-1])
            return np.stack([np.interp(tn, t, r) for r in flat]).reshape(a.shape[:-1] + (n,))

        lo = np.clip(np.searchsorted(t, tn, side="right") - 1, 0, len(t) - 1)
        hi = np.clip(lo + 1, 0, len(t) - 1)
        exact = np.isclose(t[lo], tn, atol=1e-9)
        valid = m.valid[lo] & (exact | m.valid[hi])
        measured = MeasuredGRF(force=li(m.force), cop=li(m.cop), free_moment=li(m.free_moment), valid=valid,
                               source=m.source)
    src = dict(capture.source)
    src["resampled_fps"] = float(fps)
    return capture.evolve(q=qn, times=tn, contacts=contacts, measured=measured, source=src)


# --- contacts --------------------------------------------------------------------------------


def _clean_runs(b: np.ndarray, min_frames: int) -> np.ndarray:
    """Remove True runs and False gaps shorter than ``min_frames`` (interior ones)."""
    b = b.copy()
    if min_frames <= 1:
        return b
    for value in (False, True):  # fill short gaps first, then drop short blips
        T = b.size
        i = 0
        while i < T:
            if b[i] == value:
                j = i
                while j < T and b[j] == value:
                    j += 1
                if j - i < min_frames and i > 0 and j < T:
                    b[i:j] = not value
                i = j
            else:
                i += 1
    return b


def _toe_candidates(character: Character, contact) -> list[tuple[str, np.ndarray]]:
    """Points that mean "the toe region touches": the contact point, and when the foot has a
    toes segment, the toes' tip and the metatarsal heads (toes origin) — the foot-fixed toe
    point alone would rise and move when the toes bend at push-off."""
    pts = [(contact.segment, contact.position)]
    if not contact.name.startswith("toe"):
        return pts
    for s in character.segments:
        if s.parent == contact.segment and s.length > 0:
            pts.append((s.name, s.marker))
            pts.append((s.name, np.zeros(3)))
    return pts


def detect_contacts(
    character: Character,
    q: np.ndarray,
    fps: float,
    *,
    height_tol: float = 0.04,
    speed_tol: float | None = None,
    min_frames: int = 2,
    floor_tol: float = 0.08,
    cutoff_hz: float = 12.0,
) -> np.ndarray:
    """(P, T) bool: each contact point on the ground or not, from kinematics (see module doc).

    A candidate point is *on* when it is within ``height_tol`` of its contact level (its 5th
    percentile height) and its horizontal speed is below ``speed_tol`` (default half the
    walking speed, at least 0.3 m/s). The heel row uses the heel contact point; the toe row
    is on when any of the toe contact point, the toes' tip or the metatarsal heads is on.
    Raises when a foot never comes within ``floor_tol`` of the floor (z = 0).
    """
    from solver.kinematics import contact_points, points_world

    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[0] != character.n:
        raise PreprocessError(f"detect_contacts: q must be (n={character.n}, T), got {q.shape}")
    if not character.contacts:
        raise PreprocessError(f"character {character.name!r} has no contact points")
    T = q.shape[1]
    if T < 5:
        raise PreprocessError(f"detect_contacts: at least 5 frames are needed, got {T}")
    if not np.all(np.isfinite(q)):
        raise PreprocessError("detect_contacts: q contains NaN/inf")
    if not (np.isfinite(fps) and fps > 0):
        raise PreprocessError(f"detect_contacts: fps must be positive, got {fps}")
    cp = contact_points(character, q)  # (P, 3, T)
    for side in ("right", "left"):
        rows = [i for i, c in enumerate(character.contacts) if c.side == side]
        lowest = float(np.min(np.percentile(cp[rows, 2], 5, axis=1)))
        if lowest > floor_tol:
            raise PreprocessError(
                f"the {side} foot never touches the ground: its contact points stay {lowest * 100:.1f} cm or more "
                f"above the floor (z = 0); check the floor height / axes of the input"
            )
    if speed_tol is None:
        root = points_world(character, q, [(character.segments[0].name, np.zeros(3))])[0]
        walk = np.linalg.norm(root[:2, -1] - root[:2, 0]) / max((T - 1) / fps, 1e-9)
        speed_tol = max(0.3, 0.5 * walk)
    cut = min(cutoff_hz, fps / 3.0)
    out = np.zeros((len(character.contacts), T), dtype=bool)
    for i, c in enumerate(character.contacts):
        cands = _toe_candidates(character, c)
        p = points_world(character, q, cands)  # (K, 3, T)
        ps = lowpass(p, fps, cut, axis=-1) if T >= 12 else p
        hspeed = np.linalg.norm(np.gradient(ps[:, :2], 1.0 / fps, axis=-1), axis=1)  # (K, T)
        on = np.zeros(T, dtype=bool)
        for k in range(len(cands)):
            zref = max(float(np.percentile(ps[k, 2], 5)), -0.05)
            on |= (ps[k, 2] < zref + height_tol) & (hspeed[k] < speed_tol)
        out[i] = _clean_runs(on, min_frames)
    return out


def contacts_from_plates(
    measured: MeasuredGRF,
    *,
    threshold: float = 20.0,
    character: Character | None = None,
    q: np.ndarray | None = None,
    fps: float | None = None,
) -> np.ndarray:
    """(4, T) contact schedule from force plates (a foot is on the ground when F_z > threshold).

    With kinematics (``character``, ``q``, ``fps``) the loaded foot's heel/toe split comes from
    :func:`detect_contacts` (the lower point when neither is detected), and frames where the
    plates are incomplete (``measured.valid`` False) use the kinematic schedule. Without
    kinematics both points of a loaded foot are on.
    """
    fz = np.asarray(measured.force)[:, 2]  # (2, T)
    T = fz.shape[1]
    loaded = fz > threshold
    kin = None
    if character is not None and q is not None:
        if fps is None:
            raise PreprocessError("contacts_from_plates: fps is needed with kinematics")
        kin = detect_contacts(character, q, fps)
        if kin.shape[1] != T:
            raise PreprocessError(f"contacts_from_plates: kinematics have {kin.shape[1]} frames, plates {T}")
        if kin.shape[0] != 4:
            raise PreprocessError("contacts_from_plates: expected 4 contact points (heel_r, toe_r, heel_l, toe_l)")
    out = np.zeros((4, T), dtype=bool)
    for k in range(2):
        rows = np.array([2 * k, 2 * k + 1])
        if kin is None:
            out[rows] = loaded[k]
            continue
        from solver.kinematics import contact_points

        assert character is not None  # kin comes from the character's kinematics
        z = contact_points(character, q)[rows, 2]
        sub = kin[rows] & loaded[k]
        none = loaded[k] & ~sub.any(axis=0)
        lower = np.argmin(z, axis=0)
        for j in range(2):
            sub[j] |= none & (lower == j)
        out[rows] = sub
        bad = ~np.asarray(measured.valid, dtype=bool)
        out[np.ix_(rows, np.where(bad)[0])] = kin[np.ix_(rows, np.where(bad)[0])]
    return out


def gait_events(contacts: np.ndarray, times: np.ndarray) -> dict[str, list[float]]:
    """Heel strikes (first contact of a foot) and toe-offs (last contact) per foot, in seconds.

    An event is the first/last frame of a run of foot contact (heel or toe) that lies
    strictly inside the clip (runs touching the clip's ends have no observed start/end).
    """
    c = np.asarray(contacts, dtype=bool)
    t = np.asarray(times, dtype=float)
    out: dict[str, list[float]] = {}
    for k, side in enumerate(("right", "left")):
        foot = c[2 * k] | c[2 * k + 1]
        d = np.diff(foot.astype(int))
        out[f"{side}_heel_strike"] = [float(t[i + 1]) for i in np.where(d == 1)[0]]
        out[f"{side}_toe_off"] = [float(t[i]) for i in np.where(d == -1)[0]]
    return out


def unroll_loop(capture: Capture, repeats: int = 2) -> Capture:
    """A looping clip (its last frame is the phase of its first) repeated ``repeats`` times.

    As DeepMimic's ``"Loop": "wrap"``: each repetition is translated horizontally by the
    clip's root displacement (last - first frame, vertical component ignored); orientations
    are not accumulated. The first frame of every repetition after the first is dropped (it
    is the previous repetition's last frame). Hinge angles are unwrapped first.
    """
    if repeats < 1:
        raise PreprocessError("unroll_loop: repeats must be >= 1")
    if capture.T < 3:
        raise PreprocessError("unroll_loop: a loop needs at least 3 frames")
    ch = capture.character
    q = _unwrapped(ch, capture.q)
    t = capture.times
    names = ch.coordinate_names
    period = t[-1] - t[0]
    disp = np.zeros(ch.n)
    for nm in ("root_tx", "root_ty"):
        if nm in names:
            i = names.index(nm)
            disp[i] = q[i, -1] - q[i, 0]
    qs, ts = [q], [t]
    contacts = capture.contacts
    cs = [contacts] if contacts is not None else None
    for r in range(1, repeats):
        qs.append(q[:, 1:] + r * disp[:, None])
        ts.append(t[1:] + r * period)
        if cs is not None and contacts is not None:
            cs.append(contacts[:, 1:])
    src = dict(capture.source)
    src["unrolled_loops"] = repeats
    return capture.evolve(q=np.hstack(qs), times=np.concatenate(ts),
                          contacts=None if cs is None else np.hstack(cs), measured=None, source=src)


def extract_cycle(
    capture: Capture,
    fps: float | None = None,
    *,
    start: str = "right_heel_strike",
    contacts: np.ndarray | None = None,
    cycle: int = 0,
) -> tuple[Capture, np.ndarray]:
    """One gait cycle with the two overlap frames the cyclic constraint needs (SPEC §6).

    The capture is first resampled to ``fps`` (if given). The contact schedule is ``contacts``
    if given, else the capture's own (e.g. from force plates), else :func:`detect_contacts`.
    With strikes of the ``start`` foot
    at frames s and s + N (the next strike), the cycle is frames s .. s + N + 1 (T = N + 2):
    frames T-1 and T repeat frames 1 and 2 one period later (q_1 = q_{T-1}, q_2 = q_T for the
    non-root coordinates). ``cycle`` picks which complete cycle (0 = the first). A looping
    clip (``capture.source["loop"] == "wrap"``, its last frame at the phase of its first) is
    one cycle already: the cycle is the clip plus the loop's second frame (T = clip + 1),
    starting at the clip's boundary when the ``start`` strike is within 2 frames of it
    (cyclically), otherwise at the strike (the loop's closure error then falls inside the
    cycle). Returns the cycle's Capture (its ``contacts`` set) and its (P, T) contacts.
    """
    if start == "auto":
        errors = []
        for st in ("right_heel_strike", "left_heel_strike", "best_loop"):
            try:
                return extract_cycle(capture, fps, start=st, contacts=contacts, cycle=cycle)
            except PreprocessError as e:
                errors.append(str(e))
        raise PreprocessError("extract_cycle: no gait cycle found: " + " | ".join(errors))
    if start not in ("right_heel_strike", "left_heel_strike", "best_loop"):
        raise PreprocessError("extract_cycle: start must be 'right_heel_strike', 'left_heel_strike', 'best_loop' "
                              f"or 'auto', not {start!r}")
    cap = resample(capture, fps) if fps is not None else capture
    if contacts is None:
        contacts = cap.contacts  # e.g. from force plates (resampled with the capture); else detected below
    if cap.source.get("loop") == "wrap":
        return _extract_loop_cycle(cap, start, contacts)
    if contacts is None:
        contacts = detect_contacts(cap.character, cap.q, cap.fps)
    contacts = np.asarray(contacts, dtype=bool)
    if contacts.shape != (len(cap.character.contacts), cap.T):
        raise PreprocessError(f"extract_cycle: contacts must be ({len(cap.character.contacts)}, T={cap.T}), "
                              f"got {contacts.shape}")
    if contacts.shape[0] != 4:
        raise PreprocessError("extract_cycle: expected 4 contact points (heel_r, toe_r, heel_l, toe_l)")
    feet = np.stack([contacts[0] | contacts[1], contacts[2] | contacts[3]])
    for k, side in enumerate(("right", "left")):
        if not feet[k].any():
            raise PreprocessError(f"extract_cycle: the {side} foot is never on the ground in this clip")
    if start == "best_loop":
        return _best_loop_cycle(cap, contacts, feet)
    k = 0 if start.startswith("right") else 1
    d = np.diff(feet[k].astype(int))
    strikes = np.where(d == 1)[0] + 1
    side = "right" if k == 0 else "left"
    if strikes.size == 0:
        raise PreprocessError(f"extract_cycle: no {side} heel strike found in {cap.T} frames "
                              f"({cap.times[-1] - cap.times[0]:.2f} s)")
    usable = [s for s in strikes[:-1] if s + 1 + (strikes[strikes > s][0] - s) < cap.T] if strikes.size > 1 else []
    if len(usable) <= cycle:
        raise PreprocessError(
            f"extract_cycle: clip too short for a gait cycle: {strikes.size} {side} heel strike(s) at "
            f"{[round(float(cap.times[s]), 3) for s in strikes]} s; a cycle needs two strikes and one frame after "
            f"the second (cycle={cycle} asked)"
        )
    s0 = usable[cycle]
    s1 = strikes[strikes > s0][0]
    sl = slice(s0, s1 + 2)
    cc = contacts[:, sl]
    fc = feet[:, sl][:, :-2]
    if not np.any(fc[0] & fc[1]):
        raise PreprocessError("extract_cycle: no double support in the cycle (is this a walk? running has none)")
    if not fc[1 - k].any():
        raise PreprocessError(f"extract_cycle: the {'left' if k == 0 else 'right'} foot never touches the ground "
                              "during the cycle")
    cycle_info = {"start": start, "index": cycle, "frames": [int(s0), int(s1 + 1)],
                  "t_start": float(cap.times[s0]), "period_s": float(cap.times[s1] - cap.times[s0]),
                  "overlap_frames": 2}
    return _cycle_capture(cap, sl, cc, cycle_info), cc


def _cycle_capture(cap: Capture, sl: slice, contacts: np.ndarray, cycle_info: dict) -> Capture:
    """The frames ``sl`` of a capture (plates included) with the cycle recorded in its source."""
    m = cap.measured
    meas = None
    if m is not None:
        meas = MeasuredGRF(force=m.force[..., sl], cop=m.cop[..., sl], free_moment=m.free_moment[..., sl],
                           valid=m.valid[sl], source=m.source)
    src = dict(cap.source)
    src["cycle"] = cycle_info
    return Capture(character=cap.character, q=cap.q[:, sl], times=cap.times[sl], frame=cap.frame, source=src,
                   contacts=contacts, measured=meas)


#: plausible walking cycle durations (s) searched by the best-loop cycle
LOOP_PERIOD_S = (0.7, 2.0)


def _best_loop_cycle(cap: Capture, contacts: np.ndarray, feet: np.ndarray) -> tuple[Capture, np.ndarray]:
    """A cycle for trials shorter than two strikes of one foot: the period N and start s whose
    frames (s, s+1) best match (s+N, s+N+1) — joint coordinates, root height, pitch and roll,
    and the contact schedule (which must repeat exactly) — as in motion-graph loop detection.
    The cycle must contain double support and both feet's stances."""
    T, fps = cap.T, cap.fps
    lo = max(4, int(round(LOOP_PERIOD_S[0] * fps)))
    hi = min(T - 2, int(round(LOOP_PERIOD_S[1] * fps)))
    if hi < lo:
        raise PreprocessError(f"extract_cycle: {T} frames ({cap.times[-1] - cap.times[0]:.2f} s) are too few for "
                              f"a gait cycle of at least {LOOP_PERIOD_S[0]} s plus two overlap frames")
    periodic = np.zeros(cap.character.n, dtype=bool)
    periodic[6:] = True
    periodic[[2, 4, 5]] = True
    qp = cap.q[periodic]
    scale = np.maximum(np.std(qp, axis=1, keepdims=True), 1e-3)
    qn = qp / scale
    best = None
    for N in range(lo, hi + 1):
        for s0 in range(0, T - N - 1):
            if not np.array_equal(contacts[:, s0 : s0 + 2], contacts[:, s0 + N : s0 + N + 2]):
                continue
            fc = feet[:, s0 : s0 + N]
            if not (np.any(fc[0] & fc[1]) and fc[0].any() and fc[1].any() and (~fc[0]).any() and (~fc[1]).any()):
                continue
            err = float(np.sum((qn[:, s0 : s0 + 2] - qn[:, s0 + N : s0 + N + 2]) ** 2))
            if best is None or err < best[0]:
                best = (err, s0, N)
    if best is None:
        raise PreprocessError("extract_cycle: no loop of a walking period closes in this clip (the contact schedule "
                              "never repeats with double support and both stances inside)")
    err, s0, N = best
    sl = slice(s0, s0 + N + 2)
    cc = contacts[:, sl]
    cycle_info = {"start": "best_loop", "index": 0, "frames": [int(s0), int(s0 + N + 1)],
                  "t_start": float(cap.times[s0]), "period_s": float(N / fps), "overlap_frames": 2,
                  "loop_mismatch_rms_std": float(np.sqrt(err / (2 * qn.shape[0])))}
    return _cycle_capture(cap, sl, cc, cycle_info), cc


def _extract_loop_cycle(cap: Capture, start: str, contacts: np.ndarray | None) -> tuple[Capture, np.ndarray]:
    Tc = cap.T - 1  # the last frame is the first one's phase
    if Tc < 4:
        raise PreprocessError(f"extract_cycle: a looping clip of {cap.T} frames is too short for a gait cycle")
    if contacts is None:
        contacts = detect_contacts(cap.character, cap.q, cap.fps)
    contacts = np.asarray(contacts, dtype=bool)
    if contacts.shape != (4, cap.T):
        raise PreprocessError(f"extract_cycle: contacts must be (4, T={cap.T}), got {contacts.shape}")
    cyc = contacts[:, :Tc]
    feet = np.stack([cyc[0] | cyc[1], cyc[2] | cyc[3]])
    for k, side in enumerate(("right", "left")):
        if not feet[k].any():
            raise PreprocessError(f"extract_cycle: the {side} foot is never on the ground in this clip")
        if feet[k].all():
            raise PreprocessError(f"extract_cycle: the {side} foot never leaves the ground in this clip")
    if not np.any(feet[0] & feet[1]):
        raise PreprocessError("extract_cycle: no double support in the clip (is this a walk? running has none)")
    k = 0 if start.startswith("right") else 1
    strikes = [i for i in range(Tc) if feet[k][i] and not feet[k][i - 1]]
    side = "right" if k == 0 else "left"
    if not strikes:
        raise PreprocessError(f"extract_cycle: no {side} heel strike found in the looping clip")
    dist = [min(i, Tc - i) for i in strikes]
    s0 = 0 if min(dist) <= 2 else strikes[0]
    u = unroll_loop(cap, 3)
    sl = slice(s0, s0 + Tc + 2)
    idx = np.arange(s0, s0 + Tc + 2) % Tc
    cc = cyc[:, idx]
    src = dict(cap.source)
    src["cycle"] = {"start": start, "index": 0, "frames": [int(s0), int(s0 + Tc)],
                    "t_start": float(u.times[s0]), "period_s": float(u.times[s0 + Tc] - u.times[s0]),
                    "overlap_frames": 2, "loop": True,
                    "strike_frame": int(strikes[int(np.argmin(dist))])}
    if s0 != 0:
        log.warning("extract_cycle: the looping clip's boundary falls inside the cycle (closure error of the loop "
                    "included)")
    out = Capture(character=cap.character, q=u.q[:, sl], times=u.times[sl], frame=cap.frame, source=src,
                  contacts=cc, measured=None)
    return out, cc
