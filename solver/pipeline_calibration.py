"""A captured cycle set on the ground before its tutor is made: each foot's sole levelled (its heel
and toe points at one height while the foot is flat) and the motion lowered so that its contact
points in stance rest on the ground."""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from solver.character import Character, CharacterError
from solver.io.fit import CONTACT_INSET
from solver.kinematics import contact_points, segment_frames


def contact_plane_calibration(character: Character, q: np.ndarray, contacts: np.ndarray) -> tuple[np.ndarray, float]:
    """Lower the motion so the active contact points rest on z = 0 (median over stance).

    The model's contact points sit inside the foot box (docs/method.md (M1)), above the sole, so a
    capture whose soles touch the floor has them hovering; without this the correction
    would pull the whole body down. Returns the shifted motion and the shift (m).
    """

    cp = contact_points(character, q)
    z = cp[:, 2, :][np.asarray(contacts, dtype=bool)]
    if z.size == 0:
        return q, 0.0
    h = float(np.median(z))
    out = np.array(q, copy=True)
    out[2] -= h
    return out, h


#: a foot's heel and toe contact points more than this apart in height at flat foot are levelled (m)
SOLE_LEVEL_TOL = 0.003


def sole_calibration(character: Character, q: np.ndarray, contacts: np.ndarray) -> tuple[Character, dict]:
    """Level each foot's sole: heel and toe contact points at the same height while the foot is
    flat on the ground (the frames where both are in contact).

    The capture skeleton's sole is the line through its heel and toe landmarks (foot frame
    ``x``); where the landmarks sit at different heights above the real sole (a retargeted
    skeleton, markers on the shoe), a flat foot stands on its heel or toe point alone, and
    heel rise and toe clearance mean nothing. The two points are moved in opposite directions
    along the foot's vertical axis (by half the median difference each) and the foot box
    follows (its bottom stays 1 cm below the lower point). Returns the character and what was
    moved, per foot (mm)."""
    A = np.asarray(contacts, dtype=bool)
    N = A.shape[1] - 2 if A.shape[1] > 4 else A.shape[1]
    cp = contact_points(character, q)
    rots, _ = segment_frames(character, q)
    names = [sg.name for sg in character.segments]
    pts = list(character.contacts)
    feet = list(character.feet)
    moved: dict[str, float] = {}
    for side in ("right", "left"):
        try:
            heel, toe = character.sole_indices(side)  # by name (``Character.sole``)
        except CharacterError:  # not a heel and a toe point on one segment
            continue
        flat = A[heel, :N] & A[toe, :N]
        if flat.sum() < 2:
            continue
        dz = float(np.median(cp[heel, 2, :N][flat] - cp[toe, 2, :N][flat]))
        if abs(dz) < SOLE_LEVEL_TOL:
            continue
        seg = pts[heel].segment
        kz = float(np.median(rots[names.index(seg), 2, 2, :N][flat]))  # world z of the segment's z axis
        if kz < 0.5:
            continue
        s_ = 0.5 * dz / kz
        pts[heel] = replace(pts[heel], position=np.asarray(pts[heel].position) - np.array([0.0, 0.0, s_]))
        pts[toe] = replace(pts[toe], position=np.asarray(pts[toe].position) + np.array([0.0, 0.0, s_]))
        for i, f in enumerate(feet):
            if f.side == side:
                top = float(f.center[2] + f.half[2])
                bottom = min(float(pts[heel].position[2]), float(pts[toe].position[2])) - CONTACT_INSET
                feet[i] = replace(f, center=np.array([f.center[0], f.center[1], 0.5 * (top + bottom)]),
                                  half=np.array([f.half[0], f.half[1], 0.5 * (top - bottom)]))
        moved[side] = 1e3 * dz
    if not moved:
        return character, {}
    return replace(character, contacts=tuple(pts), feet=tuple(feet)), {"heel_above_toe_mm": moved}
