"""Exporters: pure functions from a :class:`~solver.motion.Motion` to the bytes/text of a file.

Formats (see ``docs/export.md``):

- ``json``: the motionx clip (:func:`solver.export.clip.to_clip_json`), a compact
  game-oriented clip with a published JSON Schema (``clip.schema.json``);
- ``gltf`` (alias ``glb``): glTF 2.0 skinned character and animation, binary ``.glb`` by
  default (:func:`solver.export.gltf.to_gltf`; ``binary=False`` gives the ``.gltf`` JSON
  with its buffer embedded);
- ``bvh``: Biovision hierarchy (:func:`solver.export.bvh.to_bvh`);
- ``opensim``: the motion on the OpenSim model of the trial it was made from, a folder
  (coordinates, ground reactions, ExternalLoads, model, inverse-dynamics setup) zipped
  (:func:`solver.export.opensim.to_opensim`; :func:`solver.export.opensim.write_opensim` writes
  the folder).

Every exporter writes the motion in a *world* (``world="gravity"``, the default: gravity points
down, so a slope walk climbs its ramp; ``"ground"``: the solver's frame) with the ground it walks
on beside it (:mod:`solver.export.world`).

The JSON clip and the glTF animations carry the game-ready data of :mod:`solver.export.game`
(loop points, root motion, foot contacts, cycle metadata); ``gltf``/``glb`` with ``loop=True``
animate one cycle, and :func:`solver.export.gltf.to_library_glb` writes a motion library.

This module holds what the formats share: the local transform of every segment relative
to its parent (our intrinsic joint sequences composed into one rotation and translation),
the Z-up -> Y-up axis change, rotation matrix -> quaternion conversion, and the ground
reaction (force, centre of pressure, free moment) of each foot derived from the contact
wrenches. :func:`export_motion` dispatches on a format name and refuses unknown options.
"""

from __future__ import annotations

import importlib
import inspect
import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from solver import spatial as sp
from solver.character import Character
from solver.formats import EXPORT_WORLDS, EXPORTERS
from solver.motion import Motion, MotionContext

if TYPE_CHECKING:
    from solver.rig import SkeletonRig

__all__ = [
    "DEFAULT_WORLD",
    "FORMATS",
    "Y_UP",
    "ExportError",
    "GroundReaction",
    "LocalTransforms",
    "export_choices",
    "export_motion",
    "ground_reactions",
    "local_transforms",
    "matrix_to_quaternion",
    "media_type",
]

#: Z-up (ours: X forward, Y left, Z up) -> Y-up (glTF's: X left, Y up, Z forward).
#: A proper rotation (cyclic permutation, det = +1): out = Y_UP @ ours, i.e.
#: x_out = y (left), y_out = z (up), z_out = x (forward).
Y_UP = np.array([[0.0, 1.0, 0.0], [0.0, 0.0, 1.0], [1.0, 0.0, 0.0]])
Y_UP.setflags(write=False)

#: the length units the BVH and ground exports write (metres -> unit: the factor)
LENGTH_UNITS = {"cm": 100.0, "m": 1.0}

AXES_Z_UP = {"up": "+z", "forward": "+x", "left": "+y", "handedness": "right"}
#: the world every exporter writes in unless told otherwise (``solver.export.world``)
DEFAULT_WORLD = next(iter(EXPORT_WORLDS))
AXES_Y_UP = {"up": "+y", "forward": "+z", "left": "+x", "handedness": "right"}


class ExportError(ValueError):
    """An export request is invalid (unknown format or option, bad option value)."""


def _check_motion(motion: Any) -> Motion:
    if not isinstance(motion, Motion):
        raise ExportError(f"expected a solver.motion.Motion, got {type(motion).__name__}")
    return motion


# --- local transforms -------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class LocalTransforms:
    """Every segment's frame in its parent segment's frame (the world for the root).

    ``rot[i, t]`` (S, T, 3, 3) is parent <- segment, ``pos[i, t]`` (S, T, 3) the segment
    origin in parent coordinates, i.e. ``orientation · Π joint(q)`` and
    ``offset + (slides)``. ``moving_rot[i]`` / ``moving_pos[i]`` tell whether segment i has
    a hinge / a slide (otherwise its rotation / translation is the rest value).
    """

    rot: np.ndarray
    pos: np.ndarray
    moving_rot: tuple[bool, ...]
    moving_pos: tuple[bool, ...]


#: the name tests and older code use: rotations about a unit axis by each angle, (T, 3, 3)
_axis_rotations = sp.rotation_about


def local_transforms(character: Character, q: np.ndarray) -> LocalTransforms:
    """Compose each segment's joint sequence into one local rotation and translation.

    A segment hangs at ``offset`` with rest rotation ``orientation`` and then moves through
    its DOF in order (intrinsic): a hinge right-multiplies the rotation by a rotation about
    its axis, a slide moves the origin along its axis expressed in the current frame.
    """
    q = np.asarray(q, dtype=float)
    if q.ndim != 2 or q.shape[0] != character.n:
        raise ExportError(f"q must have shape (n={character.n}, T), got {q.shape}")
    T = q.shape[1]
    S = len(character.segments)
    rot = np.empty((S, T, 3, 3))
    pos = np.empty((S, T, 3))
    moving_rot, moving_pos = [], []
    k = 0
    for i, seg in enumerate(character.segments):
        r = np.broadcast_to(seg.orientation, (T, 3, 3)).copy()
        p = np.broadcast_to(seg.offset, (T, 3)).copy()
        for dof in seg.dofs:
            if dof.kind == "hinge":
                r = r @ _axis_rotations(dof.axis, q[k])
            else:
                p = p + np.einsum("tij,j->ti", r, dof.axis) * q[k][:, None]
            k += 1
        rot[i], pos[i] = r, p
        moving_rot.append(any(d.kind == "hinge" for d in seg.dofs))
        moving_pos.append(any(d.kind == "slide" for d in seg.dofs))
    return LocalTransforms(rot, pos, tuple(moving_rot), tuple(moving_pos))


def change_axes(rot: np.ndarray, pos: np.ndarray, y_up: bool) -> tuple[np.ndarray, np.ndarray]:
    """Express rotations (..., 3, 3) and points (..., 3) in Y-up axes (conjugation by Y_UP)."""
    if not y_up:
        return rot, pos
    return Y_UP @ rot @ Y_UP.T, pos @ Y_UP.T


def matrix_to_quaternion(rot: np.ndarray) -> np.ndarray:
    """Unit quaternions (..., 4) in (x, y, z, w) order (glTF's) of rotation matrices (..., 3, 3).

    Shepperd's method (largest diagonal pivot), so it is accurate for every rotation.
    The sign is chosen with w >= 0; use :func:`continuous_quaternions` along time.
    """
    m = np.asarray(rot, dtype=float)
    shape = m.shape[:-2]
    m = m.reshape(-1, 3, 3)
    tr = m[:, 0, 0] + m[:, 1, 1] + m[:, 2, 2]
    diag = np.stack([m[:, 0, 0], m[:, 1, 1], m[:, 2, 2], tr], axis=1)
    pivot = np.argmax(diag, axis=1)
    out = np.empty((m.shape[0], 4))
    # pivot w
    i = pivot == 3
    s = np.sqrt(1.0 + tr[i]) * 2.0
    out[i, 3] = 0.25 * s
    out[i, 0] = (m[i, 2, 1] - m[i, 1, 2]) / s
    out[i, 1] = (m[i, 0, 2] - m[i, 2, 0]) / s
    out[i, 2] = (m[i, 1, 0] - m[i, 0, 1]) / s
    # pivot x
    i = pivot == 0
    s = np.sqrt(1.0 + m[i, 0, 0] - m[i, 1, 1] - m[i, 2, 2]) * 2.0
    out[i, 3] = (m[i, 2, 1] - m[i, 1, 2]) / s
    out[i, 0] = 0.25 * s
    out[i, 1] = (m[i, 0, 1] + m[i, 1, 0]) / s
    out[i, 2] = (m[i, 0, 2] + m[i, 2, 0]) / s
    # pivot y
    i = pivot == 1
    s = np.sqrt(1.0 + m[i, 1, 1] - m[i, 0, 0] - m[i, 2, 2]) * 2.0
    out[i, 3] = (m[i, 0, 2] - m[i, 2, 0]) / s
    out[i, 0] = (m[i, 0, 1] + m[i, 1, 0]) / s
    out[i, 1] = 0.25 * s
    out[i, 2] = (m[i, 1, 2] + m[i, 2, 1]) / s
    # pivot z
    i = pivot == 2
    s = np.sqrt(1.0 + m[i, 2, 2] - m[i, 0, 0] - m[i, 1, 1]) * 2.0
    out[i, 3] = (m[i, 1, 0] - m[i, 0, 1]) / s
    out[i, 0] = (m[i, 0, 2] + m[i, 2, 0]) / s
    out[i, 1] = (m[i, 1, 2] + m[i, 2, 1]) / s
    out[i, 2] = 0.25 * s
    out /= np.linalg.norm(out, axis=1, keepdims=True)
    out[out[:, 3] < 0] *= -1.0
    return out.reshape(shape + (4,))


def continuous_quaternions(quat: np.ndarray) -> np.ndarray:
    """Flip signs along the time axis (second to last) so consecutive quaternions have a
    non-negative dot product: linear interpolation/slerp then takes the short way."""
    qt = np.array(quat, dtype=float, copy=True)
    dots = np.sum(qt[..., 1:, :] * qt[..., :-1, :], axis=-1)
    flips = np.cumsum(dots < 0, axis=-1) % 2 == 1
    qt[..., 1:, :][flips] *= -1.0
    return qt


# --- ground reactions ---------------------------------------------------------------------


@dataclass(frozen=True, eq=False)
class GroundReaction:
    """Per foot (right, left) and frame, in the motion's ground frame (Z up).

    ``force`` (2, T, 3) N; ``loaded`` (2, T) bool (vertical force above the threshold);
    ``cop`` (2, T, 3) the centre of pressure on the ground under the foot (z = 0, or the
    tread's height on stairs; NaN when unloaded); ``free_moment`` (2, T) N·m, the vertical
    moment about the CoP (NaN when unloaded).
    """

    force: np.ndarray
    cop: np.ndarray
    free_moment: np.ndarray
    loaded: np.ndarray
    threshold: float


def ground_reactions(motion: Motion, min_load: float | None = None) -> GroundReaction:
    """Decompose each foot's wrench (moment about the world origin; force) on the ground.

    The centre of pressure is the point p = (x, y, h) on the ground under the foot (h = 0, or
    the tread's height on stairs: ``solver.environment.ground_of``) about which the moment's
    horizontal components vanish: m - p × f has zero x and y components, so
    x = (h f_x - m_y) / f_z and y = (m_x + h f_y) / f_z; the free moment is the remaining
    vertical component m_z - (x f_y - y f_x). A foot is *loaded* when f_z > ``min_load`` (N;
    default 1 % of the character's weight); CoP and free moment are defined only then.
    """
    from solver.environment import ground_of

    _check_motion(motion)
    if motion.wrenches is None:
        raise ExportError("the motion has no contact wrenches")
    threshold = 0.01 * motion.character.weight if min_load is None else float(min_load)
    if not (math.isfinite(threshold) and threshold > 0):
        raise ExportError(f"min_load must be a positive finite force (N), got {min_load!r}")
    w = np.transpose(motion.wrenches, (0, 2, 1))  # (2, T, 6)
    m, f = w[..., :3], w[..., 3:]
    h = ground_of(motion)  # (2, T)
    loaded = f[..., 2] > threshold
    fz = np.where(loaded, f[..., 2], 1.0)
    x = (h * f[..., 0] - m[..., 1]) / fz
    y = (m[..., 0] + h * f[..., 1]) / fz
    free = m[..., 2] - (x * f[..., 1] - y * f[..., 0])
    cop = np.stack([x, y, h], axis=-1)
    cop[~loaded] = np.nan
    free[~loaded] = np.nan
    return GroundReaction(force=f.copy(), cop=cop, free_moment=free, loaded=loaded, threshold=threshold)


# --- dispatch -------------------------------------------------------------------------------

#: format name -> (module, function, media type), from the registry (solver.formats.EXPORTERS)
FORMATS: dict[str, tuple[str, str, str]] = {n: (e.module, e.function, e.media_type) for n, e in EXPORTERS.items()}


def _exporter(fmt: str):
    try:
        module, func, _ = FORMATS[fmt]
    except KeyError:
        raise ExportError(f"unknown export format {fmt!r}; known: {sorted(FORMATS)}") from None
    return getattr(importlib.import_module(module), func)


#: (format, option, value) -> media type when that option changes the result's type
_MEDIA_BY_OPTION: dict[tuple[str, str, Any], str] = {
    (n, key, value): mt for n, e in EXPORTERS.items() for (key, value), mt in e.media_by_option.items()}


def media_type(fmt: str, **options: Any) -> str:
    """The media type of ``export_motion(motion, fmt, **options)`` (``gltf`` with
    ``binary=False`` is ``model/gltf+json``, otherwise ``model/gltf-binary``)."""
    _exporter(fmt)
    for (f, key, value), mt in _MEDIA_BY_OPTION.items():
        if f == fmt and key in options and options[key] is value:
            return mt
    return FORMATS[fmt][2]


def export_options(fmt: str) -> tuple[str, ...]:
    """The keyword options a format accepts."""
    sig = inspect.signature(_exporter(fmt))
    return tuple(p.name for p in sig.parameters.values() if p.kind is inspect.Parameter.KEYWORD_ONLY)


#: the rig formats each format writes a motion on with ``rig="source"`` (solver.rig.RIG_FORMATS)
ON_RIG = {"bvh": ("bvh",), "gltf": ("bvh", "gltf", "deepmimic", "opensim"),
          "glb": ("bvh", "gltf", "deepmimic", "opensim"), "deepmimic": ("deepmimic",)}
#: formats that only a motion from a trial of that kind can be written in (its rig's format)
NEEDS_RIG = {"deepmimic": "deepmimic", "opensim": "opensim"}
#: formats that write the same file as another (the alias is left out of the choices)
ALIASES = {"glb": "gltf"}


def export_choices(context: MotionContext, provenance: Mapping[str, Any]) -> dict[str, Any]:
    """What a motion of this ``context`` and ``provenance`` can be exported as (a motion file's
    ``provenance`` object gives both: :meth:`MotionContext.split`), for a front end that offers one
    button per distinct file: ``formats`` (every exporter but aliases — ``glb`` is ``gltf`` — and
    the formats that need a trial of their own kind: ``deepmimic`` a DeepMimic clip, ``opensim``
    an OpenSim trial; ``opensim`` with ``model="generic"`` remains possible for any motion),
    ``on_rig`` (the formats that write it on the input's own skeleton, ``rig="source"``), ``rig``
    (the format of that skeleton, or None) and ``source`` (the trial's format, or None)."""
    rig_format = context.rig.format if context.rig is not None else None
    src = provenance.get("source")
    source = src.get("format") if isinstance(src, Mapping) else None
    formats = [f for f in EXPORTERS if f not in ALIASES and NEEDS_RIG.get(f, rig_format) == rig_format]
    on_rig = [f for f in formats if rig_format in ON_RIG.get(f, ())]
    return {"formats": formats, "on_rig": on_rig, "rig": rig_format, "source": source}


def export_motion(motion: Motion, fmt: str, path: str | Path | None = None, **options: Any) -> str | bytes:
    """Export ``motion`` as ``fmt`` (json, gltf, glb, bvh, opensim, …): text for text formats,
    bytes for binary glTF (``gltf`` by default, ``glb``) and for the zip archive of a folder
    format (``opensim``); written to ``path`` too when given — a folder format's folder,
    unpacked there (:func:`write_folder`).

    Unknown options are refused with an :class:`ExportError` naming the accepted ones.
    """
    func = _exporter(fmt)
    known = export_options(fmt)
    unknown = sorted(set(options) - set(known))
    if unknown:
        raise ExportError(f"unknown option(s) {unknown} for format {fmt!r}; accepted: {list(known)}")
    data = func(motion, **options)
    if path is not None and EXPORTERS[fmt].folder:
        write_folder(data, path)
    elif path is not None:
        Path(path).parent.mkdir(parents=True, exist_ok=True)
        Path(path).write_bytes(data if isinstance(data, bytes) else data.encode())
    return data


def write_folder(archive: bytes, path: str | Path) -> Path:
    """A folder format's zip archive unpacked into ``path`` (created; files of the same names replaced)."""
    import io
    import zipfile

    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ExportError(f"{out} exists and is not a folder: this format writes a folder")
    out.mkdir(parents=True, exist_ok=True)
    with zipfile.ZipFile(io.BytesIO(archive)) as z:
        for name in z.namelist():
            if Path(name).name != name:
                raise ExportError(f"unexpected entry {name!r} in the archive")
            (out / name).write_bytes(z.read(name))
    return out


def source_rig(motion: Motion, formats: tuple[str, ...], what: str) -> SkeletonRig:
    """The motion's source rig (``motion.context.rig``), a skeleton (:class:`solver.rig.SkeletonRig`)
    of one of ``formats``; otherwise an :class:`ExportError` naming ``what`` it needs and where the
    motion came from."""
    from solver.rig import SkeletonRig  # lazy: solver.rig only for the input-rig exports

    rig = motion.context.rig
    if not isinstance(rig, SkeletonRig) or rig.format not in formats:
        why = f"this one came from {rig.format}" if rig is not None else "this one has no source rig"
        raise ExportError(f"{what} ({why})")
    return rig
def check_decimals(decimals: object) -> None:
    """Text exporters write 1 to 12 decimals."""
    if isinstance(decimals, bool) or not isinstance(decimals, int) or not 1 <= decimals <= 12:
        raise ExportError(f"decimals must be an integer in [1, 12], got {decimals!r}")
