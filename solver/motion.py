"""Motions: immutable (character, fps, Q n×T, contact schedule, contact wrenches) values.

The *motion file v2* (JSON; schema in ``solver/schemas/motion-v2.schema.json``, which also
reads version 1 files) stores one motion, self-contained: the character is either a reference name or its full
description (characters scaled to a subject are not reference characters).

Contact wrenches are per foot and frame, spatial forces in the **world frame** (Z up),
ordered (mx, my, mz, fx, fy, fz), the moment taken **about the world origin** — the
convention of the dynamics (docs/method.md (M3.5)): the sum of the two feet's wrenches equals the
root wrench h0 of a plausible motion.

Version 2 adds ``trajectory``: how the motion continues between its frames (see
``solver.trajectory``): the optimizer's motions are C² cubic splines through their frames
(periodic for a gait cycle), whose equations of motion hold at the frames and midpoints;
version 1 files mean central differences.
"""

from __future__ import annotations

import json
import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from functools import cache
from pathlib import Path
from typing import Any

import numpy as np

from solver.character import REFERENCE, Character, CharacterError, character_from_dict, character_to_dict, reference

FORMAT = "motionx.motion"
VERSION = 2
FEET = ("right", "left")
WRENCH_ORDER = ("mx", "my", "mz", "fx", "fy", "fz")
SCHEMA_PATH = Path(__file__).with_name("schemas") / "motion-v2.schema.json"
MAX_FRAMES = 100_000
#: Physical ranges checked at construction (generous for human motion capture, tight enough
#: that every derived quantity — velocities, exports in cm, residuals — stays finite):
#: sampling rate, slide coordinates (m), hinge coordinates (rad, unwrapped turns allowed),
#: contact forces (N) and their moments about the world origin (N*m).
MIN_FPS, MAX_FPS = 1.0, 10_000.0
MAX_SLIDE_M = 10_000.0
MAX_HINGE_RAD = 10_000.0
MAX_FORCE_N = 1.0e6
MAX_MOMENT_NM = 1.0e10


class MotionError(ValueError):
    """A motion (or motion file) is malformed; the message names the problem."""


def foot_schedule_of(character: Character, contacts: np.ndarray) -> np.ndarray:
    """The contact matrix B from A (docs/method.md (M5.3)): (P, T) contact points -> (2, T) feet (right, left), a foot
    being in contact when any of its points is."""
    c = np.asarray(contacts, dtype=bool)
    out = np.zeros((2, c.shape[1]), dtype=bool)
    for i, p in enumerate(character.contacts):
        out[FEET.index(p.side)] |= c[i]
    return out


def _frozen(a: np.ndarray) -> np.ndarray:
    a = np.array(a, copy=True)
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Motion:
    character: Character
    fps: float
    q: np.ndarray  # (n, T)
    contacts: np.ndarray | None = None  # (P, T) bool, P = len(character.contacts), same order
    wrenches: np.ndarray | None = None  # (2, 6, T): feet (right, left) x (moment about origin; force)
    provenance: Mapping[str, Any] = field(default_factory=dict)
    report: Mapping[str, Any] | None = None
    reference_name: str | None = None  # set when ``character`` is an unmodified reference character
    #: how the motion continues between frames (``solver.trajectory``): "central-differences"
    #: (file v1, captures) or "cubic-spline" (the spacetime optimizer's C² spline)
    interpolation: str = "central-differences"
    cyclic: bool = False  # a gait cycle: frames T-2, T-1 repeat frames 0, 1 (under the cycle's transform)

    def __post_init__(self) -> None:
        if not (isinstance(self.fps, (int, float)) and math.isfinite(self.fps) and self.fps > 0):
            raise MotionError(f"fps must be a positive finite number, got {self.fps!r}")
        if not MIN_FPS <= self.fps <= MAX_FPS:
            raise MotionError(f"fps {self.fps:.6g} is outside the physical range [{MIN_FPS:g}, {MAX_FPS:g}] "
                              "frames per second")
        q = np.asarray(self.q, dtype=float)
        n = self.character.n
        if q.ndim != 2 or q.shape[0] != n:
            raise MotionError(f"q must have shape (n={n}, T), got {q.shape}")
        if q.shape[1] < 3:
            raise MotionError(f"a motion needs at least 3 frames, got {q.shape[1]}")
        if q.shape[1] > MAX_FRAMES:
            raise MotionError(f"a motion may have at most {MAX_FRAMES} frames, got {q.shape[1]}")
        if not np.all(np.isfinite(q)):
            bad = np.argwhere(~np.isfinite(q))[0]
            raise MotionError(
                f"coordinate {self.character.coordinate_names[bad[0]]!r} is not finite at frame {bad[1]}"
            )
        _check_ranges(self.character, q)
        object.__setattr__(self, "q", _frozen(q))
        T = q.shape[1]
        if self.contacts is not None:
            c = np.asarray(self.contacts)
            P = len(self.character.contacts)
            if c.shape != (P, T):
                raise MotionError(f"contact schedule must have shape (points={P}, T={T}), got {c.shape}")
            object.__setattr__(self, "contacts", _frozen(c.astype(bool)))
        if self.wrenches is not None:
            w = np.asarray(self.wrenches, dtype=float)
            if w.shape != (2, 6, T):
                raise MotionError(f"wrenches must have shape (2 feet, 6, T={T}), got {w.shape}")
            if not np.all(np.isfinite(w)):
                raise MotionError("contact wrenches must be finite")
            for rows, limit, what in ((slice(3, 6), MAX_FORCE_N, "force (N)"),
                                      (slice(0, 3), MAX_MOMENT_NM, "moment about the origin (N*m)")):
                big = float(np.max(np.abs(w[:, rows, :]))) if w.size else 0.0
                if big > limit:
                    raise MotionError(f"contact {what} {big:.6g} is outside the physical range (at most {limit:g})")
            object.__setattr__(self, "wrenches", _frozen(w))
        if self.interpolation not in ("central-differences", "cubic-spline"):
            raise MotionError(f"unknown interpolation {self.interpolation!r}")
        if self.cyclic and T < 5:
            raise MotionError(f"a cyclic motion needs at least 5 frames, got {T}")
        object.__setattr__(self, "cyclic", bool(self.cyclic))
        object.__setattr__(self, "provenance", dict(self.provenance))
        if self.report is not None:
            object.__setattr__(self, "report", dict(self.report))

    @property
    def T(self) -> int:
        return int(self.q.shape[1])

    @property
    def n(self) -> int:
        return int(self.q.shape[0])

    @property
    def dt(self) -> float:
        return 1.0 / float(self.fps)

    @property
    def times(self) -> np.ndarray:
        return np.arange(self.T) * self.dt

    @property
    def coordinate_names(self) -> tuple[str, ...]:
        return self.character.coordinate_names

    def coordinate(self, name: str) -> np.ndarray:
        return self.q[self.character.index(name)]

    def foot_contact(self) -> np.ndarray:
        """B (docs/method.md (M5.3)): (2, T) bool, a foot is in contact when any of its points is."""
        if self.contacts is None:
            raise MotionError("motion has no contact schedule")
        return foot_schedule_of(self.character, self.contacts)

    def evolve(self, **changes: Any) -> Motion:
        """A new motion with some fields replaced (motions are immutable)."""
        return replace(self, **changes)

    # --- motion file v2 -------------------------------------------------------------
    def to_dict(self) -> dict:
        ch = self.character
        d: dict[str, Any] = {
            "format": FORMAT,
            "version": VERSION,
            "character": (
                {"reference": self.reference_name}
                if self.reference_name
                else {"definition": character_to_dict(ch)}
            ),
            "fps": float(self.fps),
            "coordinates": list(ch.coordinate_names),
            "units": {"slide": "m", "hinge": "rad"},
            "frames": self.q.T.tolist(),
            "trajectory": {"interpolation": self.interpolation, "cyclic": bool(self.cyclic)},
        }
        if self.contacts is not None:
            d["contacts"] = {
                "points": [c.name for c in ch.contacts],
                "feet": [c.side for c in ch.contacts],
                "active": self.contacts.T.astype(int).tolist(),
            }
        if self.wrenches is not None:
            d["wrenches"] = {
                "frame": "world",
                "reference_point": "world origin",
                "order": list(WRENCH_ORDER),
                "units": {"moment": "N*m", "force": "N"},
                "feet": {foot: self.wrenches[i].T.tolist() for i, foot in enumerate(FEET)},
            }
        prov = dict(self.provenance)
        prov.setdefault("created", datetime.now(UTC).isoformat(timespec="seconds"))
        d["provenance"] = prov
        if self.report is not None:
            d["report"] = self.report
        return d

    def to_json(self) -> str:
        return json.dumps(self.to_dict(), allow_nan=False, separators=(",", ":"))

    def save(self, path: str | Path) -> None:
        """Write the motion file (its folder created when missing)."""
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(self.to_json())

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> Motion:
        return motion_from_dict(d)

    @staticmethod
    def load(path: str | Path) -> Motion:
        p = Path(path)
        try:
            data = json.loads(p.read_text())
        except FileNotFoundError:
            raise MotionError(f"motion file not found: {p}") from None
        except json.JSONDecodeError as e:
            raise MotionError(f"{p}: not valid JSON ({e})") from None
        return motion_from_dict(data)


def _check_ranges(character: Character, q: np.ndarray) -> None:
    """Coordinates within physical ranges: slides in metres, hinges in radians."""
    kinds = [d.kind for s in character.segments for d in s.dofs]
    for kind, limit, unit in (("slide", MAX_SLIDE_M, "m"), ("hinge", MAX_HINGE_RAD, "rad")):
        rows = [i for i, k in enumerate(kinds) if k == kind]
        if not rows:
            continue
        a = np.abs(q[rows])
        if float(a.max()) > limit:
            i, t = np.unravel_index(int(np.argmax(a)), a.shape)
            name = character.coordinate_names[rows[i]]
            raise MotionError(f"coordinate {name!r} = {q[rows[i], t]:.6g} {unit} at frame "
                              f"{t} is outside the physical range (|{kind}| at most {limit:g} {unit})")


@cache
def schema() -> dict:
    return json.loads(SCHEMA_PATH.read_text())


@cache
def _validator():
    """jsonschema-rs when installed (a 3,600-frame file in ~6 ms instead of ~2.7 s), else jsonschema."""
    try:
        import jsonschema_rs  # optional: the fast validator when installed

        return "rs", jsonschema_rs.validator_for(schema())
    except ImportError:
        import jsonschema  # lazy: only validation needs it

        return "py", jsonschema.Draft202012Validator(schema())


def _schema_value(path: Sequence[Any]) -> Any:
    node: Any = schema()
    for p in path:
        try:
            node = node[p]
        except (KeyError, IndexError, TypeError):
            return None
    return node


def validate_schema(d: Any) -> None:
    """Check a motion file's structure against the published JSON Schema. The message names
    where and which rule, and never repeats a large part of the input."""
    kind, validator = _validator()
    errors = []
    for e in validator.iter_errors(d):
        if kind == "rs":
            path, keyword, value = list(e.instance_path), (list(e.schema_path) or [""])[-1], None
            value = _schema_value(list(e.schema_path))
        else:
            path, keyword, value = list(e.absolute_path), e.validator, e.validator_value
        errors.append((path, str(keyword), value, e.message))
        if len(errors) >= 50:
            break
    if errors:
        path, keyword, value, message = min(errors, key=lambda x: [str(p) for p in x[0]])
        where = "/".join(str(p) for p in path) or "(top level)"
        if len(message) > 200:  # the validator quoted the (large) value: name the rule instead
            rule = json.dumps(value, separators=(",", ":")) if value is not None else ""
            message = f"does not satisfy {keyword!r}" + (f" {rule[:80]}" if rule else "")
        raise MotionError(f"motion file invalid at {where}: {message}")


def motion_from_dict(d: Any) -> Motion:
    validate_schema(d)
    cd = d["character"]
    try:
        if "reference" in cd:
            if cd["reference"] not in REFERENCE:
                raise MotionError(f"unknown reference character {cd['reference']!r}; known: {sorted(REFERENCE)}")
            ch, ref = reference(cd["reference"]), cd["reference"]
        else:
            ch, ref = character_from_dict(cd["definition"]), None
    except CharacterError as e:
        raise MotionError(str(e)) from None
    names = list(d["coordinates"])
    unknown = [nm for nm in names if nm not in ch.coordinate_names]
    if unknown:
        raise MotionError(f"unknown joints for character {ch.name!r}: {unknown}")
    missing = [nm for nm in ch.coordinate_names if nm not in names]
    if missing:
        raise MotionError(f"missing coordinates for character {ch.name!r}: {missing}")
    frames = np.asarray(d["frames"], dtype=float)
    if frames.ndim != 2 or frames.shape[1] != len(names):
        raise MotionError(f"every frame needs {len(names)} values (one per coordinate)")
    order = [names.index(nm) for nm in ch.coordinate_names]
    q = frames[:, order].T
    contacts = None
    if "contacts" in d:
        pts = list(d["contacts"]["points"])
        want = [c.name for c in ch.contacts]
        if sorted(pts) != sorted(want):
            raise MotionError(f"contact points {pts} do not match the character's {want}")
        act = np.asarray(d["contacts"]["active"], dtype=bool)
        if act.ndim != 2 or act.shape != (q.shape[1], len(pts)):
            raise MotionError(f"contacts.active must have one row of {len(pts)} flags per frame")
        contacts = act[:, [pts.index(nm) for nm in want]].T
    wrenches = None
    if "wrenches" in d:
        w = d["wrenches"]
        if w.get("frame") != "world" or w.get("reference_point") != "world origin":
            raise MotionError("wrenches must be given in the world frame about the world origin")
        try:
            wrenches = np.stack([np.asarray(w["feet"][f], dtype=float).T for f in FEET])
        except ValueError:
            raise MotionError("wrenches.feet must hold one 6-vector per frame for each foot") from None
    traj = (d.get("trajectory") or {}) if d.get("version") == 2 else {}
    return Motion(
        character=ch, fps=float(d["fps"]), q=q, contacts=contacts, wrenches=wrenches,
        provenance=d.get("provenance", {}), report=d.get("report"), reference_name=ref,
        interpolation=traj.get("interpolation", "central-differences"), cyclic=bool(traj.get("cyclic", False)),
    )
