"""Characters from a skeleton description: segment specs, ellipsoid inertias, Winter's anthropometric table."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from solver import spatial as sp
from solver.character.base import Character, CharacterError, ContactPoint, Dof, FootBox, Segment


def ellipsoid(length: float, mass: float, density: float) -> tuple[float, float, np.ndarray]:
    """Prolate ellipsoid of a segment (docs/method.md (M1.1)-(M1.3)).

    Returns (a, b, inertia) with a = l/2, b = c = sqrt(3 m / (4 rho pi a)) and the inertia
    about the centre, in axes (along, across, across): diag(m(b²+c²)/5, m(a²+c²)/5, m(a²+b²)/5).
    """
    if length <= 0 or mass < 0 or density <= 0:
        raise CharacterError(f"ellipsoid needs length > 0, mass >= 0, density > 0 (got {length}, {mass}, {density})")
    a = length / 2.0
    b = math.sqrt(3.0 * mass / (4.0 * density * math.pi * a)) if mass > 0 else 0.0
    c = b
    return a, b, np.diag([mass * (b * b + c * c) / 5.0, mass * (a * a + c * c) / 5.0, mass * (a * a + b * b) / 5.0])


def ellipsoid_inertia_in_segment(direction: np.ndarray, inertia_axes: np.ndarray) -> np.ndarray:
    """Rotate the (along, across, across) ellipsoid inertia so 'along' = direction."""
    d = np.asarray(direction, dtype=float)
    d = d / np.linalg.norm(d)
    # basis with first column = d
    a = sp.align_z(d)  # a @ ez = d
    basis = np.column_stack([a[:, 2], a[:, 0], a[:, 1]])
    return basis @ inertia_axes @ basis.T


@dataclass(frozen=True, eq=False)
class SegmentSpec:
    """A segment as a user describes it: bone length and direction, mass, joint axes.

    Inertia comes from the prolate ellipsoid (docs/method.md (M1.1)-(M1.3)) unless ``inertia``/``com``
    are given (e.g. taken from an OpenSim model).
    """

    name: str
    parent: str | None
    offset: sp.Vec
    dofs: Sequence[Dof]
    length: float
    mass: float
    direction: sp.Vec = (0.0, 0.0, 1.0)
    density: float = 1050.0
    orientation: sp.Mat | None = None
    com: sp.Vec | None = None
    inertia: sp.Mat | None = None


def build_segment(spec: SegmentSpec) -> Segment:
    d = np.asarray(spec.direction, dtype=float)
    if not np.all(np.isfinite(d)) or np.linalg.norm(d) == 0:
        raise CharacterError(f"segment {spec.name!r}: direction must be a non-zero finite vector")
    d = d / np.linalg.norm(d)
    if not (np.isfinite(spec.length) and spec.length > 0):
        raise CharacterError(f"segment {spec.name!r}: length must be > 0 (got {spec.length})")
    a, b, i_axes = ellipsoid(spec.length, spec.mass, spec.density)
    com = np.asarray(spec.com, dtype=float) if spec.com is not None else d * a
    inertia = (
        np.asarray(spec.inertia, dtype=float)
        if spec.inertia is not None
        else ellipsoid_inertia_in_segment(d, i_axes)
    )
    return Segment(
        name=spec.name,
        parent=spec.parent,
        offset=np.asarray(spec.offset, dtype=float),
        dofs=tuple(spec.dofs),
        mass=float(spec.mass),
        com=com,
        inertia=inertia,
        length=float(spec.length),
        direction=d,
        radius=b,
        orientation=np.eye(3) if spec.orientation is None else np.asarray(spec.orientation, dtype=float),
    )


def build_character(
    name: str,
    segments: Sequence[SegmentSpec],
    contacts: Sequence[ContactPoint] = (),
    feet: Sequence[FootBox] = (),
    height: float = 0.0,
    description: str = "",
) -> Character:
    """Build a character from a skeleton description (used by the importers)."""
    return Character(
        name=name,
        segments=tuple(build_segment(s) for s in segments),
        contacts=tuple(contacts),
        feet=tuple(feet),
        height=height,
        description=description,
    )


# --- Winter's anthropometric table ------------------------------------------------------

#: Segment mass as a fraction of body mass and density (kg/m³), after Winter,
#: *Biomechanics and Motor Control of Human Movement* (4th ed., Table 4.1; densities
#: from Dempster via Winter). The trunk's pelvis/abdomen (no density in the table) use
#: the abdomen+pelvis value; the clavicles take 1 % of body mass each from the thorax
#: (Winter's "shoulder mass" density); toes take 20 % of the foot.
WINTER: dict[str, tuple[float, float]] = {
    "hand": (0.006, 1160.0),
    "forearm": (0.016, 1130.0),
    "upper_arm": (0.028, 1070.0),
    "foot": (0.0116, 1100.0),
    "toes": (0.0029, 1100.0),
    "shank": (0.0465, 1090.0),
    "thigh": (0.100, 1050.0),
    "head_neck": (0.081, 1110.0),
    "thorax": (0.196, 920.0),
    "clavicle": (0.010, 1040.0),
    "abdomen": (0.139, 1010.0),
    "pelvis": (0.142, 1010.0),
    "hat": (0.678, 1050.0),  # head, arms and trunk lumped (Winter's HAT)
}

#: Segment lengths as fractions of body height (Drillis & Contini, via Winter Fig. 4.1).
WINTER_LENGTH: dict[str, float] = {
    "thigh": 0.245,
    "shank": 0.246,
    "ankle_height": 0.039,
    "foot_length": 0.152,
    "foot_width": 0.055,
    "hip_half_width": 0.0475,  # hip joint centres, each side of the mid-pelvis
    "upper_arm": 0.186,
    "forearm": 0.146,
    "hand": 0.108,
    "shoulder_half_width": 0.129,
    "head_neck": 0.182,
}


def winter_mass(segment_kind: str, total_mass: float) -> float:
    try:
        return WINTER[segment_kind][0] * total_mass
    except KeyError:
        raise CharacterError(f"no Winter entry for {segment_kind!r}; known: {sorted(WINTER)}") from None


def winter_density(segment_kind: str) -> float:
    return WINTER[segment_kind][1]
