"""Characters: immutable trees of rigid segments joined by chains of 1-DOF joints.

A *segment* is one rigid body of the character (thigh, shank, ...). It hangs from its
parent segment at ``offset`` (parent segment coordinates) with a constant orientation
``orientation`` (parent <- segment at q = 0), and moves relative to it through a
sequence of 1-DOF joints (``dofs``): hinges about, or slides along, an axis given in the
segment frame, applied in order as *intrinsic* rotations (exactly MuJoCo's sequential
joints within one body). A segment with no DOF is welded to its parent.

For the algorithms the character is flattened (:class:`Model`) into one body per
coordinate, as in SPEC §2: every joint revolute about, or prismatic along, its local z;
multi-DOF joints become chains through massless, zero-length bodies; welded segments
are merged into their parent's body. Body frames are therefore ``z`` = joint axis, and
the segment inertia is expressed in the last body of its chain.

Segment frames of the reference characters are world-aligned at q = 0 (Z up, X forward,
Y to the character's left), the bone running along ``direction``; this replaces the
thesis's "x towards the centre of mass" body frame by an equivalent constant rotation.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from solver import spatial as sp

GRAVITY = 9.81

#: Physical ranges checked at construction (a human-sized rigid multibody, with wide margins):
#: a segment weighs at most MAX_SEGMENT_MASS kg; lengths (offsets, centres of mass, bones,
#: contact points, foot boxes, height) stay within MAX_LENGTH_M metres. A segment that moves
#: (has DOF) has a positive mass and a positive-definite inertia: a massless moving body has
#: no dynamics (MuJoCo refuses it). Every inertia satisfies the triangle inequality of
#: principal moments (I1 + I2 >= I3), as any physical rigid body does.
MAX_SEGMENT_MASS = 1000.0
MAX_LENGTH_M = 10.0
#: relative tolerance of the inertia checks (rounding in files written with few digits)
INERTIA_RTOL = 1e-6


class CharacterError(ValueError):
    """A character description is inconsistent (unknown names, bad numbers...)."""


def _within(name: str, what: str, values: np.ndarray, limit: float, unit: str) -> None:
    big = float(np.max(np.abs(values))) if np.size(values) else 0.0
    if big > limit:
        raise CharacterError(f"{name}: {what} {big:.6g} {unit} is outside the physical range "
                             f"(at most {limit:g} {unit})")


def check_inertia(name: str, mass: float, inertia: np.ndarray, *, moving: bool) -> None:
    """Physical rigid-body inertia (about the centre of mass): symmetric, principal moments
    non-negative and obeying the triangle inequality; positive definite for a moving body."""
    if not np.allclose(inertia, inertia.T, atol=1e-12):
        raise CharacterError(f"segment {name!r}: inertia must be symmetric")
    ev = np.linalg.eigvalsh(0.5 * (inertia + inertia.T))
    scale = max(float(np.max(np.abs(ev))), 1e-300)
    tol = INERTIA_RTOL * scale
    if ev[0] < -tol:
        raise CharacterError(f"segment {name!r}: inertia must be positive semi-definite "
                             f"(principal moments {', '.join(f'{v:.6g}' for v in ev)} kg*m^2)")
    if ev[0] + ev[1] < ev[2] - tol:
        raise CharacterError(f"segment {name!r}: principal moments {', '.join(f'{v:.6g}' for v in ev)} kg*m^2 "
                             "violate the triangle inequality (I1 + I2 >= I3) of a rigid body")
    if moving and not (mass > 0 and ev[0] > 0):
        raise CharacterError(f"segment {name!r} moves (it has DOF) but has no mass or a singular inertia "
                             f"(mass {mass:g} kg, smallest principal moment {ev[0]:.6g} kg*m^2); "
                             "a moving segment needs a positive mass and inertia")


def _ro(a: sp.Vec | sp.Mat, shape: tuple[int, ...], allow_inf: bool = False) -> np.ndarray:
    arr = np.array(a, dtype=float).reshape(shape)
    if np.any(np.isnan(arr)) or (not allow_inf and not np.all(np.isfinite(arr))):
        raise CharacterError(f"non-finite values in {arr!r}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Dof:
    """One coordinate: a hinge (radians) or a slide (metres) along ``axis`` (segment frame)."""

    name: str
    kind: str  # "hinge" | "slide"
    axis: np.ndarray
    lower: float = -math.inf
    upper: float = math.inf

    def __post_init__(self) -> None:
        if self.kind not in ("hinge", "slide"):
            raise CharacterError(f"dof {self.name!r}: kind must be 'hinge' or 'slide', not {self.kind!r}")
        ax = np.asarray(self.axis, dtype=float).reshape(3)
        n = float(np.linalg.norm(ax))
        if not np.isfinite(n) or n < 1e-12:
            raise CharacterError(f"dof {self.name!r}: axis must be a non-zero finite vector")
        object.__setattr__(self, "axis", _ro(ax / n, (3,)))
        if not (self.lower <= self.upper):
            raise CharacterError(f"dof {self.name!r}: lower limit {self.lower} > upper limit {self.upper}")


@dataclass(frozen=True, eq=False)
class Segment:
    """A rigid segment; inertial data and points in the segment frame."""

    name: str
    parent: str | None
    offset: np.ndarray  # joint location in parent segment coordinates
    dofs: tuple[Dof, ...]
    mass: float
    com: np.ndarray  # centre of mass, segment coordinates
    inertia: np.ndarray  # 3x3 about the com, segment axes
    length: float = 0.0
    direction: np.ndarray = field(default_factory=lambda: _ro([0.0, 0.0, 1.0], (3,)))
    radius: float = 0.0  # ellipsoid semi-axes (length/2, radius, radius) along direction
    orientation: np.ndarray = field(default_factory=lambda: _ro(np.eye(3), (3, 3)))

    def __post_init__(self) -> None:
        object.__setattr__(self, "offset", _ro(self.offset, (3,)))
        object.__setattr__(self, "com", _ro(self.com, (3,)))
        object.__setattr__(self, "inertia", _ro(self.inertia, (3, 3)))
        d = np.asarray(self.direction, dtype=float).reshape(3)
        nd = float(np.linalg.norm(d))
        object.__setattr__(self, "direction", _ro(d / nd if nd > 0 else [0.0, 0.0, 1.0], (3,)))
        rot = np.asarray(self.orientation, dtype=float).reshape(3, 3)
        if not np.allclose(rot @ rot.T, np.eye(3), atol=1e-9) or np.linalg.det(rot) < 0:
            raise CharacterError(f"segment {self.name!r}: orientation is not a rotation matrix")
        object.__setattr__(self, "orientation", _ro(rot, (3, 3)))
        object.__setattr__(self, "dofs", tuple(self.dofs))
        if not (np.isfinite(self.mass) and self.mass >= 0):
            raise CharacterError(f"segment {self.name!r}: mass must be finite and >= 0")
        if self.mass > MAX_SEGMENT_MASS:
            raise CharacterError(f"segment {self.name!r}: mass {self.mass:.6g} kg is outside the physical range "
                                 f"(at most {MAX_SEGMENT_MASS:g} kg)")
        for what, v in (("offset", self.offset), ("centre of mass", self.com), ("length", self.length),
                        ("radius", self.radius)):
            if not np.all(np.isfinite(v)):
                raise CharacterError(f"segment {self.name!r}: {what} must be finite")
            _within(f"segment {self.name!r}", what, np.asarray(v, dtype=float), MAX_LENGTH_M, "m")
        check_inertia(self.name, float(self.mass), self.inertia, moving=bool(self.dofs))

    @property
    def marker(self) -> np.ndarray:
        """The segment-tip marker (SPEC ã_i = (l, 0, 0, 1) in the thesis's frame)."""
        return self.direction * self.length


@dataclass(frozen=True, eq=False)
class ContactPoint:
    name: str  # e.g. "heel_r"
    side: str  # "right" | "left"
    segment: str
    position: np.ndarray  # segment coordinates

    def __post_init__(self) -> None:
        object.__setattr__(self, "position", _ro(self.position, (3,)))
        if self.side not in ("right", "left"):
            raise CharacterError(f"contact point {self.name!r}: side must be 'right' or 'left'")
        _within(f"contact point {self.name!r}", "position", self.position, MAX_LENGTH_M, "m")


@dataclass(frozen=True, eq=False)
class FootBox:
    """The foot's bounding box (segment axes): centre and half extents (SPEC δ)."""

    side: str
    segment: str
    center: np.ndarray
    half: np.ndarray

    def __post_init__(self) -> None:
        object.__setattr__(self, "center", _ro(self.center, (3,)))
        object.__setattr__(self, "half", _ro(self.half, (3,)))
        if np.any(self.half <= 0):
            raise CharacterError(f"foot box {self.side}: half extents must be positive")
        _within(f"foot box {self.side}", "centre", self.center, MAX_LENGTH_M, "m")
        _within(f"foot box {self.side}", "half extent", self.half, MAX_LENGTH_M, "m")


@dataclass(frozen=True, eq=False)
class Character:
    """An immutable character. Build with :func:`build_character` or a reference constructor."""

    name: str
    segments: tuple[Segment, ...]
    contacts: tuple[ContactPoint, ...] = ()
    feet: tuple[FootBox, ...] = ()
    height: float = 0.0
    description: str = ""

    def __post_init__(self) -> None:
        object.__setattr__(self, "segments", tuple(self.segments))
        object.__setattr__(self, "contacts", tuple(self.contacts))
        object.__setattr__(self, "feet", tuple(self.feet))
        seen: set[str] = set()
        for s in self.segments:
            if s.name in seen:
                raise CharacterError(f"duplicate segment name {s.name!r}")
            if s.parent is None:
                if s is not self.segments[0]:
                    raise CharacterError("only the first segment may be the root (parent None)")
            elif s.parent not in seen:
                raise CharacterError(
                    f"segment {s.name!r}: parent {s.parent!r} unknown or not listed before its child"
                )
            seen.add(s.name)
        if not self.segments or self.segments[0].parent is not None:
            raise CharacterError("the first segment must be the root (parent None)")
        names = [d.name for s in self.segments for d in s.dofs]
        if len(set(names)) != len(names):
            raise CharacterError("duplicate coordinate names")
        for c in self.contacts:
            if c.segment not in seen:
                raise CharacterError(f"contact point {c.name!r} on unknown segment {c.segment!r}")
        for f in self.feet:
            if f.segment not in seen:
                raise CharacterError(f"foot box on unknown segment {f.segment!r}")
        if not self.segments[0].dofs:
            raise CharacterError("the root segment needs its 6 DOF")
        if not (math.isfinite(self.height) and 0.0 <= self.height <= MAX_LENGTH_M):
            raise CharacterError(f"height {self.height!r} m is outside the physical range [0, {MAX_LENGTH_M:g}] m")

    # --- basic facts --------------------------------------------------------------
    @cached_property
    def coordinate_names(self) -> tuple[str, ...]:
        return tuple(d.name for s in self.segments for d in s.dofs)

    @property
    def n(self) -> int:
        return len(self.coordinate_names)

    @cached_property
    def total_mass(self) -> float:
        return float(sum(s.mass for s in self.segments))

    @property
    def weight(self) -> float:
        return self.total_mass * GRAVITY

    def segment(self, name: str) -> Segment:
        for s in self.segments:
            if s.name == name:
                return s
        raise CharacterError(f"unknown segment {name!r}; known: {[s.name for s in self.segments]}")

    def index(self, coordinate: str) -> int:
        try:
            return self.coordinate_names.index(coordinate)
        except ValueError:
            raise CharacterError(
                f"unknown coordinate {coordinate!r} for character {self.name!r}"
            ) from None

    @cached_property
    def lower(self) -> np.ndarray:
        return _ro([d.lower for s in self.segments for d in s.dofs], (self.n,), allow_inf=True)

    @cached_property
    def upper(self) -> np.ndarray:
        return _ro([d.upper for s in self.segments for d in s.dofs], (self.n,), allow_inf=True)

    @cached_property
    def dof_kinds(self) -> tuple[str, ...]:
        return tuple(d.kind for s in self.segments for d in s.dofs)

    @cached_property
    def model(self) -> Model:
        return Model.from_character(self)

    def foot(self, side: str) -> FootBox:
        for f in self.feet:
            if f.side == side:
                return f
        raise CharacterError(f"character {self.name!r} has no {side} foot box")

    def contact_points(self, side: str | None = None) -> tuple[ContactPoint, ...]:
        return tuple(c for c in self.contacts if side is None or c.side == side)

    @cached_property
    def singular_dofs(self) -> tuple[int, ...]:
        """Middle coordinate of every 3-hinge chain (SPEC F_sing, Ω_sing)."""
        out = []
        k = 0
        for s in self.segments:
            hinges = [i for i, d in enumerate(s.dofs) if d.kind == "hinge"]
            if len(hinges) == 3:
                out.append(k + hinges[1])
            k += len(s.dofs)
        return tuple(out)

    def reduce(self, locked: Iterable[str], name: str | None = None) -> Character:
        """The character with the ``locked`` coordinates removed (locked at 0, SPEC 5.30).

        Segments left without DOF are welded to their parent (exact rigid merge).
        """
        locked = set(locked)
        unknown = locked - set(self.coordinate_names)
        if unknown:
            raise CharacterError(f"cannot lock unknown coordinates {sorted(unknown)}")
        if any(d.name in locked for d in self.segments[0].dofs):
            raise CharacterError("root coordinates cannot be locked")
        segs = tuple(replace(s, dofs=tuple(d for d in s.dofs if d.name not in locked)) for s in self.segments)
        return replace(self, segments=segs, name=name or f"{self.name}-reduced")

    def summary(self) -> dict:
        return {
            "name": self.name,
            "coordinates": self.n,
            "segments": len(self.segments),
            "total_mass": self.total_mass,
            "height": self.height,
        }


# --- flattened model -----------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Model:
    """Flat arrays over the n bodies (one per coordinate), parents before children.

    Body k: frame = parent frame * (rot0[k], pos0[k]) * joint(q_k) where the joint is a
    rotation about / translation along local z. Inertial data of body k in its frame.
    Folded constants are plain Python floats (see :mod:`solver.spatial`).
    """

    n: int
    parent: tuple[int, ...]
    revolute: tuple[bool, ...]
    rot0: tuple[sp.Mat3, ...]
    pos0: tuple[sp.Vec3, ...]
    mass: tuple[float, ...]
    com: tuple[sp.Vec3, ...]
    inertia: tuple[sp.Mat3, ...]
    seg_body: Mapping[str, int]  # segment -> body carrying it
    seg_rot: Mapping[str, np.ndarray]  # body <- segment rotation
    seg_pos: Mapping[str, np.ndarray]  # segment origin in body coordinates

    @staticmethod
    def from_character(ch: Character) -> Model:
        parent: list[int] = []
        revolute: list[bool] = []
        rot0: list[np.ndarray] = []
        pos0: list[np.ndarray] = []
        mass: list[float] = []
        com: list[np.ndarray] = []
        inertia: list[np.ndarray] = []
        seg_body: dict[str, int] = {}
        seg_rot: dict[str, np.ndarray] = {}
        seg_pos: dict[str, np.ndarray] = {}
        # per body: composite inertia accumulated as (m, m*c, I about body origin)
        acc: list[list] = []

        def add_inertia(body: int, m: float, c_body: np.ndarray, i_com_body: np.ndarray) -> None:
            if m == 0.0 and not np.any(i_com_body):
                return
            a = acc[body]
            a[0] += m
            a[1] = a[1] + m * c_body
            # inertia about the body origin (parallel axis)
            a[2] = a[2] + i_com_body + m * (float(c_body @ c_body) * np.eye(3) - np.outer(c_body, c_body))

        for s in ch.segments:
            if s.parent is None:
                pbody, prot, ppos = -1, np.eye(3), np.zeros(3)
            else:
                pbody, prot, ppos = seg_body[s.parent], seg_rot[s.parent], seg_pos[s.parent]
            # the segment's joint frame, in parent-body coordinates
            base_rot = prot @ s.orientation
            base_pos = ppos + prot @ s.offset
            if not s.dofs:
                if pbody < 0:
                    raise CharacterError("the root segment needs DOF")
                seg_body[s.name], seg_rot[s.name], seg_pos[s.name] = pbody, base_rot, base_pos
                add_inertia(pbody, s.mass, base_pos + base_rot @ s.com, base_rot @ s.inertia @ base_rot.T)
                continue
            prev_a = np.eye(3)  # the previous dof's frame (unused at j == 0)
            for j, d in enumerate(s.dofs):
                a = sp.align_z(d.axis)
                if j == 0:
                    r0, p0 = base_rot @ a, base_pos
                else:
                    r0, p0 = prev_a.T @ a, np.zeros(3)
                parent.append(pbody)
                revolute.append(d.kind == "hinge")
                rot0.append(r0)
                pos0.append(p0)
                acc.append([0.0, np.zeros(3), np.zeros((3, 3))])
                pbody = len(parent) - 1
                prev_a = a
            seg_body[s.name], seg_rot[s.name], seg_pos[s.name] = pbody, prev_a.T, np.zeros(3)
            add_inertia(pbody, s.mass, prev_a.T @ s.com, prev_a.T @ s.inertia @ prev_a)

        for a_body in acc:
            m = a_body[0]
            if m > 0:
                c = a_body[1] / m
                i_com = a_body[2] - m * (float(c @ c) * np.eye(3) - np.outer(c, c))
            else:
                c, i_com = np.zeros(3), np.zeros((3, 3))
            mass.append(m)
            com.append(c)
            inertia.append(0.5 * (i_com + i_com.T))

        for k in (seg_rot, seg_pos):
            for v in k.values():
                v.setflags(write=False)
        return Model(
            n=len(parent),
            parent=tuple(parent),
            revolute=tuple(revolute),
            rot0=tuple(sp.const_mat(r) for r in rot0),
            pos0=tuple(sp.const_vec(p) for p in pos0),
            mass=tuple(float(m) for m in mass),
            com=tuple(sp.const_vec(c) for c in com),
            inertia=tuple(sp.const_mat(i) for i in inertia),
            seg_body=seg_body,
            seg_rot=seg_rot,
            seg_pos=seg_pos,
        )

    def point_on_body(self, segment: str, p_seg: sp.Vec) -> tuple[int, np.ndarray]:
        """A point given in segment coordinates -> (body index, body coordinates)."""
        b = self.seg_body[segment]
        return b, self.seg_pos[segment] + self.seg_rot[segment] @ np.asarray(p_seg, dtype=float)

    def ancestors(self, body: int) -> tuple[int, ...]:
        out = []
        while body >= 0:
            out.append(body)
            body = self.parent[body]
        return tuple(reversed(out))


# --- construction from a skeleton description -----------------------------------------


def ellipsoid(length: float, mass: float, density: float) -> tuple[float, float, np.ndarray]:
    """Prolate ellipsoid of a segment (SPEC 3.1-3.4).

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

    Inertia comes from the prolate ellipsoid (SPEC 3.1-3.4) unless ``inertia``/``com``
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


# --- reference characters -----------------------------------------------------------------

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
    """Heel and toe points 1 cm inside the foot box so the box may penetrate ~1 cm (SPEC §2)."""
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


#: Coordinates the synthesis characters lock at 0 (SPEC: Ω_sup, "simplify").
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


# --- serialization (motion files carry their character) --------------------------------


def _arr(x: np.ndarray) -> list:
    return np.asarray(x, dtype=float).tolist()


def _num(x: float) -> float | None:
    return None if not math.isfinite(x) else float(x)


def character_to_dict(ch: Character) -> dict:
    """A JSON-ready description from which :func:`character_from_dict` rebuilds ``ch`` exactly."""
    return {
        "name": ch.name,
        "height": ch.height,
        "description": ch.description,
        "segments": [
            {
                "name": s.name,
                "parent": s.parent,
                "offset": _arr(s.offset),
                "orientation": _arr(s.orientation),
                "dofs": [
                    {"name": d.name, "kind": d.kind, "axis": _arr(d.axis), "lower": _num(d.lower),
                     "upper": _num(d.upper)}
                    for d in s.dofs
                ],
                "mass": s.mass,
                "com": _arr(s.com),
                "inertia": _arr(s.inertia),
                "length": s.length,
                "direction": _arr(s.direction),
                "radius": s.radius,
            }
            for s in ch.segments
        ],
        "contacts": [
            {"name": c.name, "side": c.side, "segment": c.segment, "position": _arr(c.position)} for c in ch.contacts
        ],
        "feet": [{"side": f.side, "segment": f.segment, "center": _arr(f.center), "half": _arr(f.half)}
                 for f in ch.feet],
    }


def character_from_dict(d: Mapping) -> Character:
    try:
        segs = []
        for s in d["segments"]:
            dofs = tuple(
                Dof(
                    str(j["name"]), str(j["kind"]), np.asarray(j["axis"], dtype=float),
                    -math.inf if j.get("lower") is None else float(j["lower"]),
                    math.inf if j.get("upper") is None else float(j["upper"]),
                )
                for j in s["dofs"]
            )
            segs.append(
                Segment(
                    name=str(s["name"]), parent=s["parent"], offset=np.asarray(s["offset"], dtype=float), dofs=dofs,
                    mass=float(s["mass"]), com=np.asarray(s["com"], dtype=float),
                    inertia=np.asarray(s["inertia"], dtype=float), length=float(s.get("length", 0.0)),
                    direction=np.asarray(s.get("direction", [0, 0, 1]), dtype=float),
                    radius=float(s.get("radius", 0.0)),
                    orientation=np.asarray(s.get("orientation", np.eye(3)), dtype=float),
                )
            )
        contacts = tuple(
            ContactPoint(str(c["name"]), str(c["side"]), str(c["segment"]), np.asarray(c["position"], dtype=float))
            for c in d.get("contacts", [])
        )
        feet = tuple(
            FootBox(str(f["side"]), str(f["segment"]), np.asarray(f["center"], dtype=float),
                    np.asarray(f["half"], dtype=float))
            for f in d.get("feet", [])
        )
    except (KeyError, TypeError, ValueError) as e:
        if isinstance(e, CharacterError):
            raise
        raise CharacterError(f"invalid character description: {e!r}") from None
    return Character(
        name=str(d["name"]), segments=tuple(segs), contacts=contacts, feet=feet,
        height=float(d.get("height", 0.0)), description=str(d.get("description", "")),
    )


def merge_segments(ch: Character, names: Iterable[str], name: str | None = None,
                   pose: Mapping[str, float] | None = None) -> Character:
    """Remove segments (and their descendants' coordinates), lumping their mass into the parent.

    The removed segments are frozen relative to the parent they are merged into, in the
    posture given by ``pose`` (coordinate name -> value; missing coordinates at 0), with an
    exact rigid-body inertia composition. Used to turn a whole-body capture into a
    lower-body one whose pelvis carries head, arms and trunk (in the subject's mean
    posture over the cycle).
    """
    pose = dict(pose or {})
    names = set(names)
    by_name = {s.name: s for s in ch.segments}
    unknown = names - set(by_name)
    if unknown:
        raise CharacterError(f"cannot merge unknown segments {sorted(unknown)}")
    # every descendant of a removed segment is removed too
    removed: set[str] = set()
    for s in ch.segments:
        if s.name in names or (s.parent is not None and s.parent in removed):
            removed.add(s.name)
    if ch.segments[0].name in removed:
        raise CharacterError("cannot merge the root segment")
    # pose of every removed segment in the frame of its nearest kept ancestor (q = 0)
    rel: dict[str, tuple[str, np.ndarray, np.ndarray]] = {}
    for s in ch.segments:
        if s.name not in removed:
            rel[s.name] = (s.name, np.eye(3), np.zeros(3))
            continue
        anc, r, p = rel[s.parent]  # type: ignore[index]
        r, p = r @ s.orientation, p + r @ s.offset
        for d in s.dofs:  # the frozen joint values, applied in order like the joints themselves
            v = float(pose.get(d.name, 0.0))
            if d.kind == "hinge":
                r = r @ sp.rotation_about(d.axis, v)
            else:
                p = p + r @ (d.axis * v)
        rel[s.name] = (anc, r, p)
    extra: dict[str, list] = {}
    for s in ch.segments:
        if s.name in removed:
            anc, r, p = rel[s.name]
            extra.setdefault(anc, []).append((s.mass, p + r @ s.com, r @ s.inertia @ r.T))
    segs = []
    for s in ch.segments:
        if s.name in removed:
            continue
        if s.name not in extra:
            segs.append(s)
            continue
        parts = [(s.mass, s.com, s.inertia)] + extra[s.name]
        m = sum(x[0] for x in parts)
        c = sum(x[0] * x[1] for x in parts) / m
        inertia = np.zeros((3, 3))
        for mi, ci, ii in parts:
            d = ci - c
            inertia += ii + mi * (float(d @ d) * np.eye(3) - np.outer(d, d))
        segs.append(replace(s, mass=m, com=c, inertia=0.5 * (inertia + inertia.T)))
    for c in ch.contacts:
        if c.segment in removed:
            raise CharacterError(f"contact point {c.name!r} is on merged segment {c.segment!r}")
    return replace(ch, segments=tuple(segs), name=name or f"{ch.name}-merged")
