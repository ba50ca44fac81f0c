"""The world an export is written in, and the ground the walk stands on in it.

The solver computes every motion in its *ground frame*: the ground is the level plane z = 0
(or, on stairs, treads at heights above it) and a slope exists only as tilted gravity
(``docs/continuation.md``). A file for Blender, three.js or a game engine wants the opposite:
gravity straight down and the ground as the walk found it — a ramp, stairs, a curved path.

- :func:`world_of` gives the :class:`World` of an export: ``world="gravity"`` (the default of
  every exporter) turns the ground frame about its origin by the smallest rotation that makes
  the motion's gravity point straight down, so a slope walk climbs an inclined plane (root and
  feet rise by travel × tan(slope)); on level ground and on stairs that rotation is the
  identity (stairs already climb their treads in the ground frame, a curve already follows
  its path). ``world="ground"`` keeps the ground frame (the files as they were before worlds
  existed: a slope walk on level ground under tilted gravity).
- Only the root's transform changes: :func:`world_transforms` (the character's skeleton: JSON
  clip, glTF, BVH) and :func:`world_rig_pose` (the input's own rig: BVH, glTF and DeepMimic
  with ``rig="source"``) apply the same rotation, so every exporter writes the same world.
- :func:`ground_of_motion` describes the ground in that world: a strip along the walk's path
  (the plane, or a ramp on a slope) or, on stairs, one tread per stance and the risers between
  them; :meth:`Ground.mesh` is its triangle mesh (the GLB's ``ground`` node),
  :meth:`Ground.to_json` its description (the JSON clip's ``ground``, a BVH's sidecar:
  :func:`ground_json`).
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from solver.environment import ground_of, stair_rise, stances
from solver.export import (
    AXES_Y_UP,
    AXES_Z_UP,
    DEFAULT_WORLD,
    LENGTH_UNITS,
    Y_UP,
    ExportError,
    LocalTransforms,
    local_transforms,
    source_rig,
)
from solver.formats import EXPORT_WORLDS
from solver.motion import FEET, Motion
from solver.stairs import flight_of

log = logging.getLogger(__name__)

#: the worlds an export can be written in (the ``world`` option of every exporter)
WORLDS: Mapping[str, str] = EXPORT_WORLDS

#: the drawn ground reaches this far beyond the feet (m), sideways and at both ends of the path
MARGIN_M = 0.15
#: the drawn ground is at least this wide (m)
MIN_WIDTH_M = 0.6


def check_world(world: object) -> str:
    """``world`` when it names a world; an :class:`ExportError` listing them otherwise."""
    if not isinstance(world, str) or world not in WORLDS:
        known = " or ".join(f"{k!r} ({v})" for k, v in WORLDS.items())
        raise ExportError(f"world must be {known}, got {world!r}")
    return world


@dataclass(frozen=True, eq=False)
class World:
    """Where an export puts the motion: a point p of the ground frame is at ``rotation @ p`` (the
    rotation is about the ground frame's origin, so the ramp of a slope passes through it)."""

    name: str
    rotation: np.ndarray  # (3, 3) ground frame -> this world, our axes (Z up)
    gravity: np.ndarray  # (3,) the motion's gravity in this world (m/s²)

    @property
    def identity(self) -> bool:
        return bool(np.array_equal(self.rotation, np.eye(3)))

    def points(self, p: np.ndarray) -> np.ndarray:
        """Points or vectors (..., 3) of the ground frame in this world."""
        return np.asarray(p, dtype=float) @ self.rotation.T

    def rotations(self, r: np.ndarray) -> np.ndarray:
        """World rotations (..., 3, 3) of the ground frame in this world."""
        return np.einsum("ij,...jk->...ik", self.rotation, r)

    def to_json(self, axes: np.ndarray | None = None, decimals: int | None = 6) -> dict[str, Any]:
        """The world in a file: its name, the gravity vector and the rotation from the solver's
        ground frame (a unit quaternion x, y, z, w), in the file's ``axes`` (3x3, default ours)."""
        from solver.export import matrix_to_quaternion

        A = np.eye(3) if axes is None else np.asarray(axes, dtype=float)
        return {"name": self.name, "gravity": _values(A @ self.gravity, decimals),
                "from_ground_frame": {"rotation": _values(matrix_to_quaternion(A @ self.rotation @ A.T), decimals),
                                      "about": "origin"}}


def _values(a: np.ndarray, decimals: int | None) -> list:
    a = np.asarray(a, dtype=float)
    if decimals is not None:
        a = np.round(a, decimals) + 0.0
    return a.tolist()


def world_of(motion: Motion, world: str = DEFAULT_WORLD) -> World:
    """The :class:`World` of ``motion`` exported with ``world`` ("gravity" or "ground")."""
    check_world(world)
    g = np.array(motion.environment.gravity, dtype=float)
    norm = float(np.linalg.norm(g))
    R = np.eye(3)
    if world == "gravity" and norm > 0:
        down = np.array([0.0, 0.0, -1.0])
        u = g / norm
        axis = np.cross(u, down)
        s, c = float(np.linalg.norm(axis)), float(u @ down)
        if s > 1e-12:  # the smallest rotation taking the gravity direction onto -z (Rodrigues)
            k = axis / s
            K = np.array([[0.0, -k[2], k[1]], [k[2], 0.0, -k[0]], [-k[1], k[0], 0.0]])
            angle = math.atan2(s, c)
            R = np.eye(3) + math.sin(angle) * K + (1.0 - math.cos(angle)) * (K @ K)
        elif c < 0:  # gravity straight up: turned over about the walking direction
            R = np.diag([1.0, -1.0, -1.0])
    R.setflags(write=False)
    return World(world, R, R @ g)


def resolve(motion: Motion, world: str | World) -> World:
    """``world`` as a :class:`World` of ``motion`` (a name is looked up by :func:`world_of`)."""
    return world if isinstance(world, World) else world_of(motion, world)


def world_transforms(motion: Motion, world: str | World = DEFAULT_WORLD, frames: int | None = None) -> LocalTransforms:
    """:func:`solver.export.local_transforms` of ``motion`` (its first ``frames`` frames) with the
    root placed in ``world``: every other segment's transform is relative to its parent and
    does not change."""
    w = resolve(motion, world)
    lt = local_transforms(motion.character, motion.q if frames is None else motion.q[:, :frames])
    if w.identity:
        return lt
    rot, pos = lt.rot.copy(), lt.pos.copy()
    rot[0], pos[0] = w.rotations(rot[0]), w.points(pos[0])
    return replace(lt, rot=rot, pos=pos)


def world_rig_pose(motion: Motion, world: str | World, rig: Any, pose: Any) -> Any:
    """A :class:`solver.rig.RigPose` of ``motion`` on ``rig`` (in the rig's own axes and units)
    with its root placed in ``world``, as :func:`world_transforms` places the character's."""

    w = resolve(motion, world)
    if w.identity:
        return pose
    frame = motion.frame
    t = pose.capture_time  # (F,): the input frame's clock (a treadmill belt's)
    root = frame.point_to_input(w.points(frame.point_from_input(pose.root, t)), t)
    local = np.array(pose.local, dtype=float, copy=True)
    local[:, 0] = frame.R @ w.rotation @ frame.R.T @ local[:, 0]  # the root joint's rotation, input axes
    return replace(pose, local=local, root=root, ankle_target=w.points(pose.ankle_target))


# --- the ground ---------------------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class Tread:
    """One level of the ground along the path: arc lengths [start, end] of the path (m) at
    ``height`` (m above the ground frame's z = 0); on stairs, the stance it carries."""

    start: float
    end: float
    height: float
    foot: str | None = None
    frames: tuple[int, int] | None = None


@dataclass(frozen=True, eq=False)
class Ground:
    """The ground under a motion, as a strip along its path: ``centre`` (N, 2) the path in the
    ground frame's xy (m), ``half_width`` (m) each side of it, ``treads`` the levels along it
    (one on a plane, one per stance on stairs), placed in ``world``."""

    kind: str  # "plane" | "stairs"
    world: World
    centre: np.ndarray
    half_width: float
    treads: tuple[Tread, ...]
    riser: float = 0.0

    @property
    def normal(self) -> np.ndarray:
        """The ground's (the treads') unit normal in the world, our axes."""
        return self.world.points(np.array([0.0, 0.0, 1.0]))

    def _arc(self) -> np.ndarray:
        seg = np.linalg.norm(np.diff(self.centre, axis=0), axis=1)
        return np.r_[0.0, np.cumsum(seg)]

    def _edges(self, s: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Centre, left and right edge points (K, 2) at arc lengths s (K,)."""
        arc, c = self._arc(), self.centre
        tang = np.diff(c, axis=0) / np.diff(arc)[:, None]
        # vertex tangents: the mean of the segments meeting there (a miter)
        vt = np.vstack([tang[:1], tang[:-1] + tang[1:], tang[-1:]])
        vt /= np.linalg.norm(vt, axis=1, keepdims=True)
        i = np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(arc) - 2)
        u = ((s - arc[i]) / (arc[i + 1] - arc[i]))[:, None]
        centre = c[i] * (1 - u) + c[i + 1] * u
        t = vt[i] * (1 - u) + vt[i + 1] * u
        t /= np.linalg.norm(t, axis=1, keepdims=True)
        left = np.c_[-t[:, 1], t[:, 0]]
        return centre, centre + self.half_width * left, centre - self.half_width * left

    def _stations(self, a: float, b: float) -> np.ndarray:
        arc = self._arc()
        inner = arc[(arc > a + 1e-9) & (arc < b - 1e-9)]
        return np.r_[a, inner, b]

    def outline(self, tread: Tread | None = None) -> np.ndarray:
        """(K, 3) the outline of the strip (on the ground frame's plane z = 0) or of one tread's
        top, counter-clockwise seen from above, in the world (our axes)."""
        a, b, h = (tread.start, tread.end, tread.height) if tread else (self.treads[0].start, self.treads[-1].end, 0.0)
        _, left, right = self._edges(self._stations(a, b))
        ring = np.vstack([right, left[::-1]])
        return self.world.points(np.c_[ring, np.full(len(ring), h)])

    def mesh(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The ground's triangles in the world (our axes): vertices (V, 3), normals (V, 3) and
        triangles (F, 3), counter-clockwise seen from above: the top of every tread and, on
        stairs, the risers between them (facing down the stairs)."""
        verts: list[np.ndarray] = []
        norms: list[np.ndarray] = []
        tris: list[np.ndarray] = []

        def add(v: np.ndarray, n: np.ndarray, f: np.ndarray) -> None:
            tris.append(f + sum(len(x) for x in verts))
            verts.append(v)
            norms.append(n)

        for k, tr in enumerate(self.treads):
            _, left, right = self._edges(self._stations(tr.start, tr.end))
            K = len(left)
            v = np.vstack([np.c_[right, np.full(K, tr.height)], np.c_[left, np.full(K, tr.height)]])
            i = np.arange(K - 1)
            f = np.vstack([np.c_[i, i + 1, K + i + 1], np.c_[i, K + i + 1, K + i]])
            add(v, np.tile([0.0, 0.0, 1.0], (2 * K, 1)), f)
            if k + 1 < len(self.treads):
                nxt = self.treads[k + 1]
                lo, hi = min(tr.height, nxt.height), max(tr.height, nxt.height)
                if hi - lo < 1e-9:
                    continue
                c, lft, rgt = self._edges(np.array([tr.end - 1e-3, tr.end]))
                forward = (c[1] - c[0]) / np.linalg.norm(c[1] - c[0])
                n3 = np.r_[-forward if nxt.height > tr.height else forward, 0.0]  # towards the lower tread
                v = np.array([[*rgt[1], lo], [*lft[1], lo], [*lft[1], hi], [*rgt[1], hi]])
                f = np.array([[0, 1, 2], [0, 2, 3]])
                if np.cross(v[1] - v[0], v[2] - v[0]) @ n3 < 0:
                    f = f[:, ::-1]
                add(v, np.tile(n3, (4, 1)), f)
        V = self.world.points(np.vstack(verts))
        N = self.world.points(np.vstack(norms))
        return V, N, np.vstack(tris).astype(int)

    def to_json(self, axes: np.ndarray | None = None, scale: float = 1.0, decimals: int | None = 6,
                origin: np.ndarray | None = None) -> dict[str, Any]:
        """The ground's description in a file's ``axes`` (3x3 rotation, default ours) and length
        unit (``scale`` file units per metre), points moved by ``origin`` (file units)."""
        A = np.eye(3) if axes is None else np.asarray(axes, dtype=float)
        o = np.zeros(3) if origin is None else np.asarray(origin, dtype=float)

        def pts(p: np.ndarray) -> list:
            return _values(np.asarray(p) @ A.T * scale + o, decimals)

        out: dict[str, Any] = {
            "kind": self.kind,
            "normal": _values(A @ self.normal, decimals),
            "point": pts(np.zeros(3)),
            "width": _values(np.array(2.0 * self.half_width * scale), decimals),
            "outline": pts(self.outline()),
            "mesh": "the GLB's node 'ground' (a library's: 'ground <animation>'): the top of the ground (every "
                    "tread's) and, on stairs, the risers",
        }
        if self.kind == "stairs":
            out["riser"] = _values(np.array(self.riser * scale), decimals)
            out["treads"] = [{"height": _values(np.array(t.height * scale), decimals),
                              "point": pts(self.world.points(np.array([0.0, 0.0, t.height]))),
                              "top": pts(self.outline(t)), "foot": t.foot,
                              "frames": list(t.frames) if t.frames else None} for t in self.treads]
        return out


def _smooth(xy: np.ndarray, half: int) -> np.ndarray:
    """Centred moving average over 2 half + 1 frames, the window shortened near the ends."""
    T = len(xy)
    out = np.empty_like(xy)
    for t in range(T):
        h = min(half, t, T - 1 - t)
        out[t] = xy[t - h:t + h + 1].mean(axis=0)
    return out


def _project(centre: np.ndarray, p: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Arc length along the polyline ``centre`` (N, 2) of the nearest point to each of ``p``
    (K, 2) (before 0 or past the end along the end segments' lines), and the distance from it."""
    a, b = centre[:-1], centre[1:]
    d = b - a
    L = np.linalg.norm(d, axis=1)
    arc = np.r_[0.0, np.cumsum(L)]
    rel = p[:, None, :] - a[None]
    u = np.einsum("kmi,mi->km", rel, d) / (L * L)[None]
    lo = np.zeros_like(u)
    hi = np.ones_like(u)
    lo[:, 0], hi[:, -1] = -np.inf, np.inf  # the ends extend along their segments
    u = np.clip(u, lo, hi)
    near = a[None] + u[..., None] * d[None]
    dist = np.linalg.norm(p[:, None, :] - near, axis=2)
    m = np.argmin(dist, axis=1)
    k = np.arange(len(p))
    return arc[m] + u[k, m] * L[m], dist[k, m]


def _path(motion: Motion) -> np.ndarray:
    """The walk's path in the ground frame's xy: the root segment's origin smoothed over half a
    cycle, points closer than 1 mm merged."""
    from solver import kinematics
    from solver.export import game

    _, pos = kinematics.segment_frames(motion.character, motion.q)
    xy = pos[0, :2, :].T
    P = game.loop_frames(motion)
    xy = _smooth(xy, max(P // 4, 1))
    keep = [0]
    for t in range(1, len(xy)):
        if np.linalg.norm(xy[t] - xy[keep[-1]]) > 1e-3:
            keep.append(t)
    path = xy[keep]
    if len(path) < 2 or float(np.sum(np.linalg.norm(np.diff(path, axis=0), axis=1))) < 0.05:
        yaw = float(np.mean(motion.q[game.ROOT_YAW])) if game.has_free_root(motion) else 0.0  # standing: its heading
        h = 0.05 * np.array([math.cos(yaw), math.sin(yaw)])
        mid = xy.mean(axis=0)
        path = np.vstack([mid - h, mid + h])
    return path


def ground_of_motion(motion: Motion, world: str | World = DEFAULT_WORLD) -> Ground:
    """The ground under ``motion`` in ``world``: a strip along its path as wide as its feet need
    (plus :data:`MARGIN_M`), one level (a plane: level ground, or a ramp on a slope in the
    gravity world) or, on stairs, the flight the solver climbed (``solver.stairs.flight_of``:
    treads a going deep, the risers where it stood them; a motion without its flight's placement:
    one tread per stance, the risers half-way between consecutive stances)."""
    from solver import kinematics

    w = resolve(motion, world)
    ch = motion.character
    centre = _path(motion)
    s_all: list[np.ndarray] = []
    d_all: list[np.ndarray] = []
    cp = np.asarray(kinematics.contact_points(ch, motion.q)) if ch.contacts else np.zeros((0, 3, motion.T))
    if len(cp):
        s, d = _project(centre, cp[:, :2, :].transpose(0, 2, 1).reshape(-1, 2))
        s_all.append(s)
        d_all.append(d)
    s_ends, d_max = (np.concatenate(s_all), float(np.concatenate(d_all).max())) if s_all else (np.zeros(1), 0.0)
    half = max(d_max + MARGIN_M, 0.5 * MIN_WIDTH_M)
    arc_end = float(np.sum(np.linalg.norm(np.diff(centre, axis=0), axis=1)))
    start = min(float(s_ends.min()), 0.0) - MARGIN_M
    end = max(float(s_ends.max()), arc_end) + MARGIN_M
    # extend the path along its end segments so that arc length 0 is its new start
    t0 = (centre[1] - centre[0]) / np.linalg.norm(centre[1] - centre[0])
    t1 = (centre[-1] - centre[-2]) / np.linalg.norm(centre[-1] - centre[-2])
    centre = np.vstack([centre[0] + start * t0, centre[1:-1], centre[-1] + (end - arc_end) * t1])
    length = end - start
    env = motion.environment
    if not env.step_height_m or motion.contacts is None or not ch.contacts:
        return Ground("plane", w, centre, half, (Tread(0.0, length, 0.0),))
    flight = flight_of(motion)  # the flight the solver climbed: treads a going deep, risers where it put them
    if flight is not None:
        stances_on: dict[int, tuple[str, tuple[int, int]]] = {}
        for f, a, b in stances(motion.foot_contact()):
            stances_on.setdefault(int(flight.left[f, a]), (FEET[f], (a, b)))
        ks = range(int(min(flight.left.min(), flight.reached.min())),
                   int(max(flight.left.max(), flight.reached.max())) + 1)
        o, u = np.asarray(flight.origin, dtype=float), flight.direction
        edges = [float(_project(centre, (o + k * flight.going * u)[None])[0][0]) for k in ks] + \
            [float(_project(centre, (o + (ks[-1] + 1) * flight.going * u)[None])[0][0])]
        edges[0], edges[-1] = 0.0, length  # the first and last treads run to the strip's ends
        out = tuple(Tread(edges[i], edges[i + 1], float(flight.height(k)), *stances_on.get(k, (None, None)))
                    for i, k in enumerate(ks))
        if np.any(np.diff(edges) <= 0):
            raise ExportError("stairs: the flight's treads do not follow one another along the path")
        return Ground("stairs", w, centre, half, out, riser=env.step_height_m)
    heights = ground_of(motion)  # a stance's ground is one tread (solver.environment.stair_heights)
    treads = []
    for f, a, b in stances(motion.foot_contact()):
        h = float(heights[f, a])
        pts = [k for k, c in enumerate(ch.contacts) if c.side == FEET[f]]
        on = motion.contacts[pts, a:b + 1]
        p = cp[pts, :2, a:b + 1].transpose(0, 2, 1)[on]  # the foot's contact points while down
        s, _ = _project(centre, p)
        treads.append((float(s.min()), float(s.max()), h, FEET[f], (a, b)))
    treads.sort(key=lambda x: 0.5 * (x[0] + x[1]))
    merged: list[list] = []
    for tr in treads:  # consecutive stances on one height stand on one tread
        if merged and abs(merged[-1][2] - tr[2]) < 1e-9:
            merged[-1][1] = max(merged[-1][1], tr[1])
            continue
        merged.append(list(tr))
    bounds = [0.0]
    for prev, nxt in zip(merged, merged[1:]):
        if prev[1] > nxt[0]:
            log.warning("stairs: the stance on %.3f m reaches past the next one's first contact (%.3f > %.3f m "
                        "along the path): the riser between them cuts a foot", prev[2], prev[1], nxt[0])
        bounds.append(0.5 * (prev[1] + nxt[0]))
    bounds.append(length)
    out = tuple(Tread(bounds[k], bounds[k + 1], m[2], m[3], m[4]) for k, m in enumerate(merged))
    if len(out) > 1 and np.any(np.diff(bounds) <= 0):
        raise ExportError("stairs: the stances do not follow one another along the path; the treads cannot be drawn")
    rise = stair_rise(motion.foot_contact(), env.step_height_m)
    log.debug("stairs ground: %d treads, riser %.3f m, rise per cycle %.3f m", len(out), env.step_height_m, rise)
    return Ground("stairs", w, centre, half, out, riser=env.step_height_m)


def ground_json(motion: Motion, *, world: str = DEFAULT_WORLD, y_up: bool = True, units: str = "cm",
                rig: str = "character", decimals: int | None = 6) -> str:
    """The ground under ``motion`` as a JSON document of its own (``format`` "motionx.ground"): the
    world and the ground's description (:meth:`Ground.to_json`) in the axes and unit of the BVH
    it goes beside — Y up (``y_up``, as :func:`solver.export.bvh.to_bvh` writes) or our Z up, in
    ``units`` "cm" (BVH's default) or "m"; with ``rig="source"``, in the input's own axes and unit (those of
    ``to_bvh(motion, rig="source")``)."""

    if units not in LENGTH_UNITS:
        raise ExportError(f"units must be one of {sorted(LENGTH_UNITS)}, got {units!r}")
    if not isinstance(y_up, bool):
        raise ExportError(f"y_up must be a boolean, got {y_up!r}")
    if rig not in ("character", "source"):
        raise ExportError(f"rig must be 'character' or 'source', got {rig!r}")
    g = ground_of_motion(motion, world)
    doc: dict[str, Any] = {"format": "motionx.ground", "version": 1}
    if rig == "source":
        from solver.rig import RIG_FORMATS

        source_rig(motion, RIG_FORMATS, "rig=source needs a motion made from a BVH, skinned glTF or DeepMimic input")
        frame = motion.frame
        doc.update(axes=frame.axes, units={"length": f"{frame.unit_m:g} m"}, world=g.world.to_json(frame.R, decimals),
                   ground=g.to_json(frame.R, 1.0 / frame.unit_m, decimals, origin=frame.offset / frame.unit_m))
    else:
        A = Y_UP if y_up else np.eye(3)
        doc.update(axes=dict(AXES_Y_UP if y_up else AXES_Z_UP), units={"length": units},
                   world=g.world.to_json(A, decimals), ground=g.to_json(A, LENGTH_UNITS[units], decimals))
    return json.dumps(doc, allow_nan=False, separators=(",", ":"))


def source_pose(motion: Motion, formats: tuple[str, ...], what: str, world: str = DEFAULT_WORLD):
    """The motion's source rig (:func:`solver.export.source_rig`) and the motion retargeted onto it
    (:func:`solver.rig.retarget`: one cycle at the rig's frame rate), its root placed in
    ``world`` (:func:`world_rig_pose`); a rig that cannot take the motion
    is an :class:`ExportError`."""
    from solver.rig import RigError, retarget  # lazy: solver.rig only for the input-rig exports

    check_world(world)
    rig = source_rig(motion, formats, what)
    try:
        return rig, world_rig_pose(motion, world, rig, retarget(motion, rig))
    except RigError as e:
        raise ExportError(str(e)) from None
