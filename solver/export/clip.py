"""The motionx JSON clip: a compact, game-oriented animation clip of one motion.

Layout (schema ``clip.schema.json`` beside this file, documented in ``docs/export.md``):
skeleton (segments with parent, rest offset and rest rotation), per frame the local
rotation quaternion (x, y, z, w) of every segment and the root translation, optional
world positions of markers and contact points, per-frame foot contact flags and ground
reaction per foot (force, centre of pressure, free moment), the game-ready data
(``game``: loop points, root motion, foot contacts, cycle metadata; :mod:`solver.export.game`),
the world it is written in and the ground the walk stands on there (``world``, ``ground``:
:mod:`solver.export.world`). Our Z-up axes by default, or glTF-style Y-up (``y_up=True``).
"""

from __future__ import annotations

import json
import logging
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from solver import kinematics
from solver.export import (
    AXES_Y_UP,
    AXES_Z_UP,
    Y_UP,
    ExportError,
    _check_motion,
    change_axes,
    continuous_quaternions,
    game,
    ground_reactions,
    matrix_to_quaternion,
)
from solver.export.world import DEFAULT_WORLD, ground_of_motion, world_of, world_transforms
from solver.motion import FEET, Motion

log = logging.getLogger(__name__)

FORMAT = "motionx.clip"
VERSION = 1
SCHEMA_PATH = Path(__file__).with_name("clip.schema.json")


def _rounded(a: np.ndarray, decimals: int | None) -> list:
    a = np.asarray(a, dtype=float)
    if decimals is not None:
        a = np.round(a, decimals) + 0.0  # + 0.0 turns -0.0 into 0.0
    return a.tolist()


def _nullable(a: np.ndarray, decimals: int | None) -> list:
    """Rows of ``a`` (T, ...) as lists, NaN rows as null."""
    out = _rounded(np.nan_to_num(a), decimals)
    bad = np.isnan(a).reshape(a.shape[0], -1).any(axis=1)
    return [None if b else v for v, b in zip(out, bad)]


def _check_options(decimals: Any, min_load: Any) -> None:
    if decimals is not None and (isinstance(decimals, bool) or not isinstance(decimals, int)
                                 or not 0 <= decimals <= 17):
        raise ExportError(f"decimals must be an integer in [0, 17] or None, got {decimals!r}")
    if min_load is not None and (isinstance(min_load, bool) or not isinstance(min_load, (int, float))):
        raise ExportError(f"min_load must be a number of newtons or None, got {min_load!r}")


def to_clip(
    motion: Motion,
    *,
    y_up: bool = False,
    points: bool = False,
    decimals: int | None = 6,
    min_load: float | None = None,
    world: str = DEFAULT_WORLD,
) -> dict:
    """The clip as a JSON-ready dict.

    ``y_up``: express everything in Y-up axes (x left, y up, z forward, as glTF) instead of
    ours (x forward, y left, z up). ``points``: include world positions of the segment-tip
    markers and the contact points. ``decimals``: round numbers to this many decimals
    (None: full precision). ``min_load``: vertical force (N) above which a foot counts as
    loaded for its centre of pressure (default 1 % of body weight). ``world``: "gravity" (gravity
    down, the ground as the walk found it: a slope's ramp) or "ground" (the solver's ground
    frame: level ground, tilted gravity); see :mod:`solver.export.world`.
    """
    _check_motion(motion)
    _check_options(decimals, min_load)
    w = world_of(motion, world)
    if not isinstance(y_up, bool) or not isinstance(points, bool):
        raise ExportError("y_up and points must be booleans")
    ch = motion.character
    segs = ch.segments
    lt = world_transforms(motion, w)
    rot, pos = change_axes(lt.rot, lt.pos, y_up)
    quat = continuous_quaternions(matrix_to_quaternion(rot))  # (S, T, 4)
    rest_rot, rest_off = change_axes(
        np.array([s.orientation for s in segs]), np.array([s.offset for s in segs]), y_up
    )
    rest_quat = matrix_to_quaternion(rest_rot)
    tips = np.array([s.marker for s in segs])
    if y_up:
        tips = tips @ Y_UP.T
    skeleton = [
        {
            "name": s.name,
            "parent": s.parent,
            "offset": _rounded(rest_off[i], decimals),
            "rotation": _rounded(rest_quat[i], decimals),
            "tip": _rounded(tips[i], decimals),
            "radius": round(float(s.radius), decimals) if decimals is not None else float(s.radius),
        }
        for i, s in enumerate(segs)
    ]
    translated = [i for i, m in enumerate(lt.moving_pos) if m]
    clip: dict[str, Any] = {
        "format": FORMAT,
        "version": VERSION,
        "character": ch.name,
        "axes": dict(AXES_Y_UP if y_up else AXES_Z_UP),
        "units": {"length": "m", "time": "s", "force": "N", "moment": "N*m"},
        "quaternion": "xyzw",
        "fps": float(motion.fps),
        "frame_count": motion.T,
        "duration": (motion.T - 1) / float(motion.fps),
        "skeleton": skeleton,
        "root": segs[0].name,
        "rotations": _rounded(np.transpose(quat, (1, 0, 2)), decimals),
        "root_translation": _rounded(pos[0], decimals),
    }
    extra = [i for i in translated if i != 0]
    if extra:
        clip["translations"] = {segs[i].name: _rounded(pos[i], decimals) for i in extra}
    if points:
        names = [name for name, _ in kinematics.marker_points(ch)]
        mk = np.asarray(kinematics.markers(ch, motion.q))  # (M, 3, T)
        cp = np.asarray(kinematics.contact_points(ch, motion.q)) if ch.contacts else np.zeros((0, 3, motion.T))
        allp = w.points(np.concatenate([mk, cp], axis=0).transpose(2, 0, 1))  # (T, P, 3)
        if y_up:
            allp = allp @ Y_UP.T
        clip["points"] = {
            "names": names + [c.name for c in ch.contacts],
            "kinds": ["marker"] * len(names) + ["contact"] * len(ch.contacts),
            "positions": _rounded(allp, decimals),
        }
    if motion.contacts is not None:
        clip["contacts"] = {
            "feet": list(FEET),
            "flags": motion.foot_contact().T.astype(int).tolist(),
        }
    if motion.wrenches is not None:
        gr = ground_reactions(motion, min_load)
        force, cop = w.points(gr.force), w.points(gr.cop)
        if y_up:
            force, cop = force @ Y_UP.T, cop @ Y_UP.T
        clip["ground_reaction"] = {
            "load_threshold": float(f"{gr.threshold:.9g}"),
            "free_moment_axis": "up" if w.identity else "ground_normal",
            **{
                foot: {
                    "force": _rounded(force[i], decimals),
                    "cop": _nullable(cop[i], decimals),
                    "free_moment": _nullable(gr.free_moment[i], decimals),
                }
                for i, foot in enumerate(FEET)
            },
        }

    if game.has_free_root(motion):
        clip["game"] = game.game_json(motion, axes=Y_UP if y_up else None, decimals=decimals, world=w)
    A = Y_UP if y_up else np.eye(3)
    clip["world"] = w.to_json(A, decimals)
    clip["ground"] = ground_of_motion(motion, w).to_json(A, 1.0, decimals)
    log.debug("clip of %s: %d frames, %d segments", ch.name, motion.T, len(segs))
    return clip


def to_clip_json(
    motion: Motion,
    *,
    y_up: bool = False,
    points: bool = False,
    decimals: int | None = 6,
    min_load: float | None = None,
    world: str = DEFAULT_WORLD,
) -> str:
    """The clip as compact JSON text (see :func:`to_clip` for the options)."""
    return json.dumps(
        to_clip(motion, y_up=y_up, points=points, decimals=decimals, min_load=min_load, world=world),
        allow_nan=False,
        separators=(",", ":"),
    )


@cache
def schema() -> dict:
    return json.loads(SCHEMA_PATH.read_text())


def validate_clip(clip: Any) -> None:
    """Check a clip against the published schema and its array lengths against each other."""
    import jsonschema  # lazy: only validation needs it

    validator = jsonschema.Draft202012Validator(schema())
    errors = sorted(validator.iter_errors(clip), key=lambda e: list(e.absolute_path))
    if errors:
        e = errors[0]
        where = "/".join(str(p) for p in e.absolute_path) or "(top level)"
        raise ExportError(f"clip invalid at {where}: {e.message}")
    T, S = clip["frame_count"], len(clip["skeleton"])
    if len(clip["rotations"]) != T or any(len(r) != S for r in clip["rotations"]):
        raise ExportError(f"clip rotations must be {T} frames x {S} segments")
    if len(clip["root_translation"]) != T:
        raise ExportError(f"clip root_translation must have {T} frames")
