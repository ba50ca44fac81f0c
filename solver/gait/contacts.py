"""Contact detection (kinematics or force plates) and gait events.

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

import numpy as np

from solver.capture import MeasuredGRF
from solver.character import Character
from solver.gait.base import GaitError, lowpass
from solver.kinematics import contact_points, points_world


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

    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[0] != character.n:
        raise GaitError(f"detect_contacts: q must be (n={character.n}, T), got {q.shape}")
    if not character.contacts:
        raise GaitError(f"character {character.name!r} has no contact points")
    T = q.shape[1]
    if T < 5:
        raise GaitError(f"detect_contacts: at least 5 frames are needed, got {T}")
    if not np.all(np.isfinite(q)):
        raise GaitError("detect_contacts: q contains NaN/inf")
    if not (np.isfinite(fps) and fps > 0):
        raise GaitError(f"detect_contacts: fps must be positive, got {fps}")
    cp = contact_points(character, q)  # (P, 3, T)
    for side in ("right", "left"):
        rows = [i for i, c in enumerate(character.contacts) if c.side == side]
        lowest = float(np.min(np.percentile(cp[rows, 2], 5, axis=1)))
        if lowest > floor_tol:
            raise GaitError(
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
            raise GaitError("contacts_from_plates: fps is needed with kinematics")
        kin = detect_contacts(character, q, fps)
        if kin.shape[1] != T:
            raise GaitError(f"contacts_from_plates: kinematics have {kin.shape[1]} frames, plates {T}")
        if kin.shape[0] != 4:
            raise GaitError("contacts_from_plates: expected 4 contact points (heel_r, toe_r, heel_l, toe_l)")
    out = np.zeros((4, T), dtype=bool)
    for k in range(2):
        rows = np.array([2 * k, 2 * k + 1])
        if kin is None:
            out[rows] = loaded[k]
            continue

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


#: a scheduled contact point more than this above its stance level at the edge of its contact run
#: is taken off the ground (m): see :func:`tighten_contacts`
TIGHT_CONTACT_TOL = 0.010


def tighten_contacts(character: Character, q: np.ndarray, contacts: np.ndarray, *,
                     tol: float = TIGHT_CONTACT_TOL) -> tuple[np.ndarray, list[dict]]:
    """A gait cycle's schedule (P, T, frames T−2, T−1 repeating frames 0, 1) whose contact points
    are where the capture has them: a point scheduled on the ground at the start or the end of
    its contact run while it stands more than ``tol`` above its stance level (the median of its
    heights in contact) is taken off, run edge after run edge, unless it is the only point of
    its foot on the ground at that frame (the foot is loaded: the plates or the kinematic
    detection said so).

    The detection (:func:`detect_contacts`) takes a point within 4 cm of its level and still: a
    heel rising through 1–3 cm at heel-off, a toe still 3 cm up a frame after heel strike. An
    optimizer that pins such a point to the ground has to bend the leg to reach it (the treadmill
    walk's HalfBoy knee: 11° RMS from the capture). Returns the schedule and what was changed."""
    A = np.array(contacts, dtype=bool, copy=True)
    T = A.shape[1]
    N = T - 2
    if N < 4 or A.shape[0] != len(character.contacts):
        return A, []
    z = contact_points(character, q)[:, 2, :N]
    side = [c.side for c in character.contacts]
    changes: list[dict] = []
    for i in range(A.shape[0]):
        on = A[i, :N]
        if not on.any() or on.all():
            continue
        high = z[i] - float(np.median(z[i][on])) > tol
        mates = [j for j in range(A.shape[0]) if j != i and side[j] == side[i]]
        changed = True
        while changed:
            changed = False
            for t in range(N):
                if not (A[i, t] and high[t]) or (A[i, (t - 1) % N] and A[i, (t + 1) % N]):
                    continue
                if not any(A[j, t] for j in mates):
                    continue
                A[i, t] = False
                changed = True
                changes.append({"point": character.contacts[i].name, "frame": t,
                                "height_above_stance_m": float(z[i, t] - np.median(z[i][on]))})
    A[:, N:] = A[:, :2]
    return A, changes


def ensure_double_support(character: Character, q: np.ndarray, contacts: np.ndarray, *,
                          height_tol: float = 0.03) -> tuple[np.ndarray, list[dict]]:
    """A gait cycle's schedule (P, T, frames T−2, T−1 repeating frames 0, 1) with at least one
    frame of double support at every change of support.

    At a coarse frame rate a double support shorter than a frame can vanish: one foot's last
    contact frame is the frame before the other's first (the DeepMimic walk at 15 frames/s).
    The change of support is then given one shared frame — the leading foot's heel a frame
    earlier or the trailing foot's toe a frame later, whichever point is lower at that frame
    (and within ``height_tol`` of its stance height, the median of its heights in contact).
    Walking keeps both feet loaded at every change of support (Perry; Winter: ~10 % of the
    cycle each), which the optimizer's shared-load bounds need frames for. Returns the
    schedule and what was changed."""
    A = np.array(contacts, dtype=bool, copy=True)
    T = A.shape[1]
    N = T - 2
    if N < 4 or A.shape[0] != len(character.contacts) or not character.has_soles:
        return A, []
    cp = contact_points(character, q)
    rows = {s: [i for i, c in enumerate(character.contacts) if c.side == s] for s in ("right", "left")}
    heel = {s: character.sole_indices(s)[0] for s in rows}  # by name (``Character.sole``)
    toe = {s: character.sole_indices(s)[1] for s in rows}

    def foot(s: str) -> np.ndarray:
        return np.asarray(A[rows[s], :N].any(axis=0))

    changes = []
    for lead, trail in (("right", "left"), ("left", "right")):
        fl, ft = foot(lead), foot(trail)
        for a in range(N):
            if not (fl[a] and not fl[a - 1]):  # a touch-down of the leading foot at frame a
                continue
            if ft[a] or not ft[a - 1]:  # already shared, or a flight phase: left as it is
                continue
            cands = []
            for i, t in ((heel[lead], (a - 1) % N), (toe[trail], a % N)):
                on = A[i, :N]
                stance_z = float(np.median(cp[i, 2, :N][on])) if on.any() else 0.0
                dz = float(cp[i, 2, t]) - stance_z
                if dz < height_tol:
                    cands.append((dz, i, t))
            if not cands:
                continue
            dz, i, t = min(cands)
            A[i, t] = True
            changes.append({"point": character.contacts[i].name, "frame": int(t), "height_above_stance_m": dz})
    A[:, N:] = A[:, :2]
    return A, changes
