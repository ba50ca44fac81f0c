"""The reference characters (HalfBoy, the full body) and the capture skeletons the importers fit."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from solver import spatial as sp
from solver.character.base import Character, CharacterError, ContactPoint, Dof, FootBox
from solver.character.build import WINTER_LENGTH, SegmentSpec, build_character, winter_density, winter_mass

DEG = math.pi / 180.0
FULL_TURN = 2.0 * math.pi


def _dof(name: str, axis: sp.Vec, lo_deg: float | None = None, hi_deg: float | None = None) -> Dof:
    lo = -math.pi if lo_deg is None else lo_deg * DEG
    hi = math.pi if hi_deg is None else hi_deg * DEG
    return Dof(name, "hinge", np.asarray(axis, dtype=float), lo, hi)


def root_dofs(prefix: str = "root") -> tuple[Dof, ...]:
    """3 slides along world x, y, z then hinges z (yaw), y (pitch), x (roll)."""
    return (
        Dof(f"{prefix}_tx", "slide", np.array([1.0, 0, 0])),
        Dof(f"{prefix}_ty", "slide", np.array([0, 1.0, 0])),
        Dof(f"{prefix}_tz", "slide", np.array([0, 0, 1.0])),
        Dof(f"{prefix}_rz", "hinge", np.array([0, 0, 1.0]), -2 * FULL_TURN, 2 * FULL_TURN),
        Dof(f"{prefix}_ry", "hinge", np.array([0, 1.0, 0]), -80 * DEG, 80 * DEG),
        Dof(f"{prefix}_rx", "hinge", np.array([1.0, 0, 0]), -80 * DEG, 80 * DEG),
    )


def _leg_specs(side: str, h: float, m: float, pelvis: str) -> list[SegmentSpec]:
    s = 1.0 if side == "l" else -1.0  # +y is the character's left
    L = WINTER_LENGTH
    thigh, shank = L["thigh"] * h, L["shank"] * h
    ankle_h, foot_len = L["ankle_height"] * h, L["foot_length"] * h
    mtp = np.array([0.55 * foot_len, 0.0, -ankle_h + 0.01 * h])  # metatarsal heads
    toes_len = 0.8 * foot_len - mtp[0]
    # mirrored conventions (as OpenSim): flexion/extension identical, ab/adduction and
    # internal rotation change sign with the side
    return [
        SegmentSpec(
            f"thigh_{side}", pelvis, (0.0, s * L["hip_half_width"] * h, 0.0),
            (
                _dof(f"hip_flexion_{side}", (0, -1, 0), -40, 125),
                _dof(f"hip_adduction_{side}", (-s, 0, 0), -45, 30),
                _dof(f"hip_rotation_{side}", (0, 0, -s), -45, 45),
            ),
            thigh, winter_mass("thigh", m), (0, 0, -1), winter_density("thigh"),
        ),
        SegmentSpec(
            f"shank_{side}", f"thigh_{side}", (0.0, 0.0, -thigh),
            (
                _dof(f"knee_angle_{side}", (0, 1, 0), -10, 150),
                _dof(f"knee_adduction_{side}", (-s, 0, 0), -30, 30),
                _dof(f"knee_rotation_{side}", (0, 0, -s), -45, 45),
            ),
            shank, winter_mass("shank", m), (0, 0, -1), winter_density("shank"),
        ),
        SegmentSpec(
            f"foot_{side}", f"shank_{side}", (0.0, 0.0, -shank),
            (
                _dof(f"ankle_angle_{side}", (0, -1, 0), -60, 45),
                _dof(f"ankle_inversion_{side}", (-s, 0, 0), -40, 40),
                _dof(f"ankle_rotation_{side}", (0, 0, -s), -40, 40),
            ),
            float(np.linalg.norm(mtp)), winter_mass("foot", m), mtp, winter_density("foot"),
        ),
        SegmentSpec(
            f"toes_{side}", f"foot_{side}", tuple(mtp),
            (
                _dof(f"mtp_angle_{side}", (0, -1, 0), -60, 90),
                _dof(f"mtp_adduction_{side}", (-s, 0, 0), -30, 30),
                _dof(f"mtp_rotation_{side}", (0, 0, -s), -30, 30),
            ),
            toes_len, winter_mass("toes", m), (1, 0, 0), winter_density("toes"),
        ),
    ]


def _foot_contacts(side: str, h: float) -> tuple[list[ContactPoint], FootBox]:
    """Heel and toe points 1 cm inside the foot box so the box may penetrate ~1 cm (docs/method.md (M1))."""
    L = WINTER_LENGTH
    foot_len, ankle_h, width = L["foot_length"] * h, L["ankle_height"] * h, L["foot_width"] * h
    heel_x, toe_x = -0.2 * foot_len, 0.8 * foot_len
    sole = -ankle_h
    top = 0.25 * ankle_h
    box = FootBox(
        side="right" if side == "r" else "left",
        segment=f"foot_{side}",
        center=np.array([(heel_x + toe_x) / 2, 0.0, (sole + top) / 2]),
        half=np.array([(toe_x - heel_x) / 2, width / 2, (top - sole) / 2]),
    )
    inset = 0.01
    full = "right" if side == "r" else "left"
    pts = [
        ContactPoint(f"heel_{side}", full, f"foot_{side}", np.array([heel_x + inset, 0.0, sole + inset])),
        ContactPoint(f"toe_{side}", full, f"foot_{side}", np.array([toe_x - 2 * inset, 0.0, sole + inset])),
    ]
    return pts, box


def capture_lower(height: float = 1.20, mass: float = 23.0) -> Character:
    """Capture skeleton of the lower body: root 6 + 3 hinges at hips, knees, ankles, toes (30).

    Head, arms and trunk are lumped into the pelvis segment (Winter's HAT), so the
    character weighs the whole subject and its ground reactions are those of a walk.
    """
    h, m = height, mass
    hat_com_height = 0.18 * h  # Winter: HAT com 0.626 of trochanter->shoulder (0.288 H)
    segs = [
        SegmentSpec("pelvis", None, (0, 0, 0), root_dofs(), 2 * hat_com_height, winter_mass("hat", m),
                    (0, 0, 1), winter_density("hat")),
    ]
    contacts, feet = [], []
    for side in ("r", "l"):
        segs += _leg_specs(side, h, m, "pelvis")
        pts, box = _foot_contacts(side, h)
        contacts += pts
        feet.append(box)
    return build_character("capture-lower", segs, contacts, feet, height=h,
                           description=f"lower-body capture skeleton, {h} m, {m} kg (HAT lumped in pelvis)")


def capture_full(height: float = 1.20, mass: float = 23.0) -> Character:
    """Whole-body capture skeleton: root 6 + 3 hinges at 19 joints (63 coordinates)."""
    h, m = height, mass
    L = WINTER_LENGTH
    pelvis_len, abdomen_len, thorax_len = 0.10 * h, 0.10 * h, 0.14 * h
    lumbar_z = 0.06 * h

    def spine(prefix: str) -> tuple[Dof, ...]:
        return (
            _dof(f"{prefix}_flexion", (0, 1, 0), -30, 60),
            _dof(f"{prefix}_bending", (1, 0, 0), -30, 30),
            _dof(f"{prefix}_rotation", (0, 0, 1), -40, 40),
        )

    segs = [
        SegmentSpec("pelvis", None, (0, 0, 0), root_dofs(), pelvis_len, winter_mass("pelvis", m),
                    (0, 0, 1), winter_density("pelvis")),
        SegmentSpec("abdomen", "pelvis", (0, 0, lumbar_z), spine("lumbar"), abdomen_len,
                    winter_mass("abdomen", m), (0, 0, 1), winter_density("abdomen")),
        SegmentSpec("thorax", "abdomen", (0, 0, abdomen_len), spine("thorax"), thorax_len,
                    winter_mass("thorax", m), (0, 0, 1), winter_density("thorax")),
        SegmentSpec("head", "thorax", (0, 0, thorax_len), spine("neck"), L["head_neck"] * h,
                    winter_mass("head_neck", m), (0, 0, 1), winter_density("head_neck")),
    ]
    for side in ("r", "l"):
        s = 1.0 if side == "l" else -1.0
        clav_len = 0.12 * h
        segs += [
            SegmentSpec(
                f"clavicle_{side}", "thorax", (0, 0, 0.85 * thorax_len),
                (
                    _dof(f"clavicle_elevation_{side}", (s, 0, 0), -20, 40),
                    _dof(f"clavicle_protraction_{side}", (0, 0, -s), -30, 30),
                    _dof(f"clavicle_rotation_{side}", (0, -s, 0), -30, 30),
                ),
                clav_len, winter_mass("clavicle", m), (0, s, 0), winter_density("clavicle"),
            ),
            SegmentSpec(
                f"upper_arm_{side}", f"clavicle_{side}", (0, s * clav_len, 0),
                (
                    _dof(f"shoulder_flexion_{side}", (0, -1, 0), -60, 170),
                    _dof(f"shoulder_adduction_{side}", (-s, 0, 0), -170, 30),
                    _dof(f"shoulder_rotation_{side}", (0, 0, -s), -90, 90),
                ),
                L["upper_arm"] * h, winter_mass("upper_arm", m), (0, 0, -1), winter_density("upper_arm"),
            ),
            SegmentSpec(
                f"forearm_{side}", f"upper_arm_{side}", (0, 0, -L["upper_arm"] * h),
                (
                    _dof(f"elbow_flexion_{side}", (0, -1, 0), -5, 150),
                    _dof(f"elbow_adduction_{side}", (-s, 0, 0), -30, 30),
                    _dof(f"elbow_rotation_{side}", (0, 0, -s), -90, 90),
                ),
                L["forearm"] * h, winter_mass("forearm", m), (0, 0, -1), winter_density("forearm"),
            ),
            SegmentSpec(
                f"hand_{side}", f"forearm_{side}", (0, 0, -L["forearm"] * h),
                (
                    _dof(f"wrist_flexion_{side}", (0, 1, 0), -70, 70),
                    _dof(f"wrist_deviation_{side}", (-s, 0, 0), -30, 30),
                    _dof(f"wrist_rotation_{side}", (0, 0, -s), -60, 60),
                ),
                L["hand"] * h, winter_mass("hand", m), (0, 0, -1), winter_density("hand"),
            ),
        ]
    contacts, feet = [], []
    for side in ("r", "l"):
        segs += _leg_specs(side, h, m, "pelvis")
        pts, box = _foot_contacts(side, h)
        contacts += pts
        feet.append(box)
    return build_character("capture-full", segs, contacts, feet, height=h,
                           description=f"whole-body capture skeleton, {h} m, {m} kg")


#: Coordinates the synthesis characters lock at 0 (docs/method.md (M5.6): Ω_sup, "simplify").
LOWER_SUPERFLUOUS = tuple(
    f"{j}_{s}"
    for s in ("r", "l")
    for j in ("knee_adduction", "knee_rotation", "ankle_inversion", "ankle_rotation",
              "mtp_angle", "mtp_adduction", "mtp_rotation")
)
FULL_SUPERFLUOUS = LOWER_SUPERFLUOUS + tuple(
    f"{j}_{s}" for s in ("r", "l") for j in ("elbow_adduction", "elbow_rotation", "wrist_rotation")
)


def halfboy(height: float = 1.20, mass: float = 23.0) -> Character:
    """HalfBoy (thesis Fig. 5.12/5.14): lower half of a 1.20 m, 23 kg boy, 16 coordinates."""
    ch = capture_lower(height, mass).reduce(LOWER_SUPERFLUOUS, name="halfboy")
    return replace(ch, description=f"HalfBoy: lower half of a {height} m, {mass} kg boy (HAT lumped in pelvis)")


def fullbody(height: float = 1.20, mass: float = 23.0) -> Character:
    """Full-body boy, 43 coordinates (anatomical DOF only)."""
    ch = capture_full(height, mass).reduce(FULL_SUPERFLUOUS, name="fullbody")
    return replace(ch, description=f"full-body boy, {height} m, {mass} kg")


REFERENCE = {
    "halfboy": halfboy,
    "fullbody": fullbody,
    "capture-lower": capture_lower,
    "capture-full": capture_full,
}

#: synthesis character -> the capture skeleton it simplifies from
CAPTURE_OF = {"halfboy": "capture-lower", "fullbody": "capture-full"}


def reference(name: str) -> Character:
    try:
        return REFERENCE[name]()
    except KeyError:
        raise CharacterError(f"unknown character {name!r}; known: {sorted(REFERENCE)}") from None
