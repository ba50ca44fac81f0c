"""Characters: immutable trees of rigid segments joined by chains of 1-DOF joints.

    base       the types (Dof, Segment, ContactPoint, FootBox, Character) and the flattened Model
    build      construction from a skeleton description (SegmentSpec, ellipsoids, Winter's table)
    reference  the reference characters (HalfBoy, the full body) and the capture skeletons
    serialize  characters as JSON-ready dicts (motion files carry their character)
    merge      simplification: merging segments into one rigid body

Every name is importable from ``solver.character`` (see base's docstring for the model).
"""

from solver.character.base import (
    GRAVITY,
    INERTIA_RTOL,
    MAX_LENGTH_M,
    MAX_SEGMENT_MASS,
    Character,
    CharacterError,
    ContactPoint,
    Dof,
    FootBox,
    Model,
    Segment,
    check_inertia,
)
from solver.character.build import (
    WINTER,
    WINTER_LENGTH,
    SegmentSpec,
    build_character,
    build_segment,
    ellipsoid,
    ellipsoid_inertia_in_segment,
    winter_density,
    winter_mass,
)
from solver.character.merge import merge_segments
from solver.character.reference import (
    CAPTURE_OF,
    DEG,
    FULL_SUPERFLUOUS,
    FULL_TURN,
    LOWER_SUPERFLUOUS,
    REFERENCE,
    capture_full,
    capture_lower,
    fullbody,
    halfboy,
    reference,
    root_dofs,
)
from solver.character.serialize import character_from_dict, character_to_dict

__all__ = [
    "CAPTURE_OF", "DEG", "FULL_SUPERFLUOUS", "FULL_TURN", "GRAVITY", "INERTIA_RTOL", "LOWER_SUPERFLUOUS",
    "MAX_LENGTH_M", "MAX_SEGMENT_MASS", "REFERENCE", "WINTER", "WINTER_LENGTH", "Character", "CharacterError",
    "ContactPoint", "Dof", "FootBox", "Model", "Segment", "SegmentSpec", "build_character", "build_segment",
    "capture_full", "capture_lower", "character_from_dict", "character_to_dict", "check_inertia", "ellipsoid",
    "ellipsoid_inertia_in_segment", "fullbody", "halfboy", "merge_segments", "reference", "root_dofs",
    "winter_density", "winter_mass",
]
