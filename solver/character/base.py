"""Characters: immutable trees of rigid segments joined by chains of 1-DOF joints.

A *segment* is one rigid body of the character (thigh, shank, ...). It hangs from its
parent segment at ``offset`` (parent segment coordinates) with a constant orientation
``orientation`` (parent <- segment at q = 0), and moves relative to it through a
sequence of 1-DOF joints (``dofs``): hinges about, or slides along, an axis given in the
segment frame, applied in order as *intrinsic* rotations (exactly MuJoCo's sequential
joints within one body). A segment with no DOF is welded to its parent.

For the algorithms the character is flattened (:class:`Model`) into one body per
coordinate, as in docs/method.md (M1): every joint revolute about, or prismatic along, its local z;
multi-DOF joints become chains through massless, zero-length bodies; welded segments
are merged into their parent's body. Body frames are therefore ``z`` = joint axis, and
the segment inertia is expressed in the last body of its chain.

Segment frames of the reference characters are world-aligned at q = 0 (Z up, X forward,
Y to the character's left), the bone running along ``direction``; this replaces the
thesis's "x towards the centre of mass" body frame by an equivalent constant rotation.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np

from solver import spatial as sp
from solver.environment import STANDARD_GRAVITY

GRAVITY = STANDARD_GRAVITY

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
        """The segment-tip marker (ã_i = (l, 0, 0, 1) in the thesis's frame, docs/method.md (M2))."""
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
    """The foot's bounding box (segment axes): centre and half extents (δ, docs/method.md (M1))."""

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
class Sole:
    """The foot a character stands on: the rectangle whose back and front edges have the heel and
    toe contact points as midpoints, as wide as the foot box (``half_width``). The optimizer keeps
    the centre of pressure inside it and its corners clear of the ground in swing, the checks read
    it, the exports draw it and MuJoCo simulates it (``Character.sole``)."""

    side: str
    segment: str
    heel: ContactPoint
    toe: ContactPoint
    half_width: float

    @property
    def length(self) -> float:
        return float(np.linalg.norm(np.asarray(self.toe.position) - np.asarray(self.heel.position)))

    def corners(self, roll: float = 0.0, half_width: float | None = None) -> np.ndarray:
        """(4, 3) the sole's corners in its segment's frame, rows heel +w, heel −w, toe +w, toe −w
        (+w: the foot's left, across the heel–toe line in the segment's horizontal plane), turned by
        ``roll`` (rad) about the heel–toe line."""
        w = self.half_width if half_width is None else float(half_width)
        h, t = np.asarray(self.heel.position, dtype=float), np.asarray(self.toe.position, dtype=float)
        ax = (t - h) / np.linalg.norm(t - h)
        y0 = np.cross([0.0, 0.0, 1.0], ax)
        y0 /= np.linalg.norm(y0)
        y = y0 * math.cos(roll) + np.cross(ax, y0) * math.sin(roll)
        return np.array([h + w * y, h - w * y, t + w * y, t - w * y])


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

    def sole(self, side: str) -> Sole:
        """The ``side`` foot's sole (:class:`Sole`): its heel and toe contact points, by name
        (``heel_*``, ``toe_*``; else the rearmost and foremost of its two), on one segment, as wide
        as its foot box."""
        pts = self.contact_points(side)
        if len(pts) != 2:
            raise CharacterError(f"the {side} foot needs exactly two contact points (heel, toe), "
                                 f"character {self.name!r} has {len(pts)}")
        named = {c.name.split("_")[0]: c for c in pts}
        if set(named) == {"heel", "toe"}:
            heel, toe = named["heel"], named["toe"]
        else:
            heel, toe = sorted(pts, key=lambda c: float(c.position[0]))
        if heel.segment != toe.segment:
            raise CharacterError(f"the {side} heel and toe contact points are on different segments")
        return Sole(side, heel.segment, heel, toe, float(self.foot(side).half[1]))

    @cached_property
    def has_soles(self) -> bool:
        """Two feet, each a box with exactly two contact points (a heel and a toe): the feet
        :meth:`sole` is defined on (the naturalness checks, the optimizer's sole, the drawn shoes)."""
        return len(self.feet) == 2 and all(sum(c.side == side for c in self.contacts) == 2
                                           for side in ("right", "left"))

    def sole_indices(self, side: str) -> tuple[int, int]:
        """(heel, toe): the indices in ``contacts`` of the ``side`` foot's sole points (:meth:`sole`)."""
        sole = self.sole(side)
        return (next(i for i, c in enumerate(self.contacts) if c is sole.heel),
                next(i for i, c in enumerate(self.contacts) if c is sole.toe))

    def sole_box(self, side: str) -> tuple[np.ndarray, np.ndarray]:
        """(centre, half extents) in the foot segment's axes of the box the centre of pressure stays
        in: the sole (heel to toe, as wide as the foot box) and the foot box's height (a foot not flat
        on the ground presses on the part of its sole there)."""
        sole, box = self.sole(side), self.foot(side)
        h, t = np.asarray(sole.heel.position, dtype=float), np.asarray(sole.toe.position, dtype=float)
        centre = np.array([0.5 * (h[0] + t[0]), 0.5 * (h[1] + t[1]), float(box.center[2])])
        half = np.array([0.5 * abs(t[0] - h[0]), sole.half_width, float(box.half[2])])
        return centre, half

    def contact_points(self, side: str | None = None) -> tuple[ContactPoint, ...]:
        return tuple(c for c in self.contacts if side is None or c.side == side)

    @cached_property
    def singular_dofs(self) -> tuple[int, ...]:
        """Middle coordinate of every 3-hinge chain (F_sing, Ω_sing: docs/method.md (M5.2))."""
        out = []
        k = 0
        for s in self.segments:
            hinges = [i for i, d in enumerate(s.dofs) if d.kind == "hinge"]
            if len(hinges) == 3:
                out.append(k + hinges[1])
            k += len(s.dofs)
        return tuple(out)

    def reduce(self, locked: Iterable[str], name: str | None = None) -> Character:
        """The character with the ``locked`` coordinates removed (locked at 0, docs/method.md (M5.15)).

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
