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

A motion's physical context (:class:`MotionContext`: environment, the axes' values, the input's
ground frame, the source rig, the captured cycle, heading changes, the gait reference) is a typed
field, written where motions are made and read by attribute; ``provenance`` holds only where the
motion came from. The file keeps both in its ``provenance`` object under the keys the earlier
versions wrote (:data:`CONTEXT_KEYS`, and ``source.cycle``), so every file reads back unchanged.
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

from solver.capture import GroundFrame
from solver.character import REFERENCE, Character, CharacterError, character_from_dict, character_to_dict, reference
from solver.environment import Environment
from solver.retargeting import Rig, RigError

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


#: the motion file's ``provenance`` keys that hold the motion's context (:class:`MotionContext`),
#: by its field names; the captured cycle is ``provenance.source.cycle``
CONTEXT_KEYS = {"environment": "environment", "axis_values": "environment_values", "frame": "frame",
                "rig": "rig", "heading_change_deg": "heading_change_deg",
                "tutor_heading_change_deg": "tutor_heading_change_deg",
                "heading_change_requested_deg": "heading_change_requested_deg", "gait_reference": "gait_reference"}


def _number(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) else None


@dataclass(frozen=True)
class Cycle:
    """The captured gait cycle a motion stands for (the importer's record, ``source.cycle`` in the
    file): its start on the capture's clock and its period (s), None when not recorded; ``record``
    everything the importer wrote (start foot, frames, overlap, loop, …), as written."""

    t_start: float | None = None
    period_s: float | None = None
    record: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "t_start", _number(self.t_start))
        object.__setattr__(self, "period_s", _number(self.period_s))
        object.__setattr__(self, "record", dict(self.record))

    def to_dict(self) -> dict[str, Any]:
        out = dict(self.record)
        for k in ("t_start", "period_s"):
            if getattr(self, k) is not None:
                out[k] = getattr(self, k)
        return out

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> Cycle:
        return Cycle(d.get("t_start"), d.get("period_s"), d)


@dataclass(frozen=True)
class GaitReference:
    """What a motion's naturalness is judged against besides the published limits: the captured
    walk's gait figures, the tutor's, and the capture's skeleton fit (``solver.naturalness``)."""

    capture: Mapping[str, Any] | None = None
    tutor: Mapping[str, Any] | None = None
    fit: Mapping[str, Any] | None = None

    def __post_init__(self) -> None:
        for k in ("capture", "tutor", "fit"):
            v = getattr(self, k)
            object.__setattr__(self, k, dict(v) if isinstance(v, Mapping) else None)

    def to_dict(self) -> dict[str, Any]:
        return {"capture": self.capture, **({"tutor": self.tutor} if self.tutor is not None else {}),
                **({"fit": self.fit} if self.fit is not None else {})}

    @staticmethod
    def from_dict(d: Mapping[str, Any]) -> GaitReference:
        return GaitReference(d.get("capture"), d.get("tutor"), d.get("fit"))


@dataclass(frozen=True)
class MotionContext:
    """The physical context a motion lives in, typed (docs/architecture.md, "The motion's context"):

    - ``environment``: gravity, friction, terrain (None: not stated; :attr:`Motion.environment` is then
      standard gravity and μ = 1);
    - ``axis_values``: the homotopy axes' values at the motion (``solver.axes``: slope, curve, …; a
      λ optimum's, empty otherwise);
    - ``frame``: the input's ground frame, the way back to the capture's axes, units and clock;
    - ``rig``: the input's own rig, what the exporters deliver the motion on (a
      :class:`solver.retargeting.Rig`: a skeleton's, ``solver.rig``, or an OpenSim model's,
      ``solver.io.opensim.rig``), kept as the motion file holds it (:meth:`Rig.as_stored`);
    - ``cycle``: the captured gait cycle the motion stands for;
    - ``heading_change_deg``: the heading change over the cycle the optimizer imposed,
      ``tutor_heading_change_deg`` its tutor's, ``heading_change_requested_deg`` an explicit request;
    - ``gait_reference``: the figures naturalness is judged against.

    Written once where a motion is made (capture import, tutor, continuation), read by attribute.
    In the motion file it is stored in ``provenance`` under the keys :data:`CONTEXT_KEYS` (and
    ``source.cycle``), the keys earlier versions wrote."""

    environment: Environment | None = None
    axis_values: Mapping[str, float] = field(default_factory=dict)
    frame: GroundFrame | None = None
    rig: Rig | None = None
    cycle: Cycle | None = None
    heading_change_deg: float | None = None
    tutor_heading_change_deg: float | None = None
    heading_change_requested_deg: float | None = None
    gait_reference: GaitReference | None = None

    def __post_init__(self) -> None:
        for k, kind in (("environment", Environment), ("frame", GroundFrame), ("rig", Rig), ("cycle", Cycle),
                        ("gait_reference", GaitReference)):
            v = getattr(self, k)
            if v is not None and not isinstance(v, kind):
                raise MotionError(f"context.{k} must be a {kind.__name__} or None, got {type(v).__name__}")
        if self.rig is not None:
            object.__setattr__(self, "rig", self.rig.as_stored())
        object.__setattr__(self, "axis_values", {str(k): float(v) for k, v in self.axis_values.items()})
        for k in ("heading_change_deg", "tutor_heading_change_deg", "heading_change_requested_deg"):
            v = getattr(self, k)
            if v is not None and _number(v) is None:
                raise MotionError(f"context.{k} must be a finite number or None, got {v!r}")
            object.__setattr__(self, k, _number(v))

    def with_(self, **changes: Any) -> MotionContext:
        """A new context with some fields replaced."""
        return replace(self, **changes)

    def to_provenance(self) -> dict[str, Any]:
        """The context as the motion file's ``provenance`` keys (``source.cycle`` aside)."""
        out: dict[str, Any] = {}
        values = {"environment": None if self.environment is None else self.environment.to_dict(),
                  "axis_values": dict(self.axis_values) or None,
                  "frame": None if self.frame is None else self.frame.to_dict(),
                  "rig": None if self.rig is None else self.rig.to_dict(),
                  "heading_change_deg": self.heading_change_deg,
                  "tutor_heading_change_deg": self.tutor_heading_change_deg,
                  "heading_change_requested_deg": self.heading_change_requested_deg,
                  "gait_reference": None if self.gait_reference is None else self.gait_reference.to_dict()}
        for name, key in CONTEXT_KEYS.items():
            if values[name] is not None:
                out[key] = values[name]
        return out

    @staticmethod
    def split(provenance: Mapping[str, Any]) -> tuple[MotionContext, dict[str, Any]]:
        """A motion file's ``provenance`` (any version) -> (its context, the provenance proper).
        Files written before the continuation recorded ``environment_values`` give the curve from
        ``target.curve_deg`` × ``lambda``. A value of the wrong kind is a :class:`MotionError` naming it."""
        rest = dict(provenance)
        raw = {name: rest.pop(key, None) for name, key in CONTEXT_KEYS.items()}
        kw: dict[str, Any] = {}
        try:
            where = "environment"
            if raw["environment"] is not None:
                kw["environment"] = Environment.from_dict(raw["environment"])
            where = "environment_values"
            if isinstance(raw["axis_values"], Mapping):
                kw["axis_values"] = {k: float(v) for k, v in raw["axis_values"].items() if _number(v) is not None}
            elif raw["axis_values"] is not None:
                raise ValueError("must be an object of numbers")
            tgt, lam = rest.get("target"), _number(rest.get("lambda"))
            if ("curve_deg" not in kw.get("axis_values", {}) and isinstance(tgt, Mapping)
                    and _number(tgt.get("curve_deg")) is not None and lam is not None):
                kw["axis_values"] = {**kw.get("axis_values", {}), "curve_deg": float(tgt["curve_deg"]) * lam}
            where = "frame"
            if raw["frame"] is not None:
                kw["frame"] = GroundFrame.from_dict(raw["frame"])
            where = "rig"
            if raw["rig"] is not None:
                kw["rig"] = Rig.from_dict(raw["rig"])
            for name in ("heading_change_deg", "tutor_heading_change_deg", "heading_change_requested_deg"):
                where = name
                kw[name] = _number(raw[name])
            where = "gait_reference"
            if isinstance(raw["gait_reference"], Mapping):
                kw["gait_reference"] = GaitReference.from_dict(raw["gait_reference"])
            where = "source.cycle"
            src = rest.get("source")
            if isinstance(src, Mapping) and "cycle" in src:
                src = dict(src)
                cyc = src.pop("cycle")
                if isinstance(cyc, Mapping):
                    kw["cycle"] = Cycle.from_dict(cyc)
                elif cyc is not None:
                    raise ValueError("must be an object")
                rest["source"] = src
        except (KeyError, TypeError, ValueError, AttributeError, OverflowError, RigError) as e:
            raise MotionError(f"provenance.{where}: {e}") from None
        return MotionContext(**kw), rest

    def into(self, provenance: Mapping[str, Any]) -> dict[str, Any]:
        """``provenance`` with the context written back under the file's keys (inverse of :meth:`split`)."""
        out = {**provenance, **self.to_provenance()}
        if self.cycle is not None:
            src = out.get("source")
            out["source"] = {**(src if isinstance(src, Mapping) else {}), "cycle": self.cycle.to_dict()}
        return out


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
    provenance: Mapping[str, Any] = field(default_factory=dict)  # where it came from (history, not physics)
    report: Mapping[str, Any] | None = None
    reference_name: str | None = None  # set when ``character`` is an unmodified reference character
    #: how the motion continues between frames (``solver.trajectory``): "central-differences"
    #: (file v1, captures) or "cubic-spline" (the spacetime optimizer's C² spline)
    interpolation: str = "central-differences"
    cyclic: bool = False  # a gait cycle: frames T-2, T-1 repeat frames 0, 1 (under the cycle's transform)
    context: MotionContext = field(default_factory=MotionContext)  # the physical context (typed)

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
        if not isinstance(self.context, MotionContext):
            raise MotionError(f"context must be a MotionContext, got {type(self.context).__name__}")
        prov = dict(self.provenance)
        held = [k for k in CONTEXT_KEYS.values() if k in prov]
        src = prov.get("source")
        if isinstance(src, Mapping) and "cycle" in src:
            held.append("source.cycle")
        if held:
            raise MotionError(f"provenance keys {held} are the motion's context: pass them as "
                              "context=MotionContext(...) (MotionContext.split reads a file's provenance)")
        if self.context.cycle is not None and src is not None and not isinstance(src, Mapping):
            raise MotionError("a motion with a captured cycle needs provenance.source to be an object")
        object.__setattr__(self, "provenance", prov)
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

    @property
    def environment(self) -> Environment:
        """The environment the motion lives in (standard gravity and μ = 1 when it does not say)."""
        return self.context.environment if self.context.environment is not None else Environment()

    @property
    def frame(self) -> GroundFrame:
        """The input's ground frame (the identity when the motion does not say)."""
        return self.context.frame if self.context.frame is not None else GroundFrame()

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
        prov = self.context.into(self.provenance)
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
    context, provenance = MotionContext.split(d.get("provenance", {}))
    return Motion(
        character=ch, fps=float(d["fps"]), q=q, contacts=contacts, wrenches=wrenches,
        provenance=provenance, context=context, report=d.get("report"), reference_name=ref,
        interpolation=traj.get("interpolation", "central-differences"), cyclic=bool(traj.get("cyclic", False)),
    )
