"""Turning an upload into a stored motion: parsing, validation, encoding.

These functions run in the API's compute processes (:mod:`service.work`), never on its
event loop, each with a time and memory limit; they return an :class:`Encoded` motion (the
compressed motion file and the columns of its row), so the API process only stores it.

- ``application/json``: a motion file v1. Non-finite numbers (``NaN``, ``Infinity``,
  ``1e999``), integer literals of more than ``MAX_INT_DIGITS`` digits, nesting deeper than
  ``MAX_JSON_DEPTH`` and ragged arrays are refused with a message naming where.
- ``multipart/form-data``: a mocap trial, read by ``solver.io.load_trial`` (OpenSim
  .osim + .mot, C3D with ``mass``, BVH, DeepMimic), kept as a raw capture
  (``solver.pipeline.capture_motion``); the extrapolation job makes its tutor.

Sizes are checked against :mod:`service.limits` before the expensive steps, physical ranges
by :mod:`solver.motion` and :mod:`solver.character`. Every failure raises
:class:`UploadError` (→ 422) with a message that names the problem and never echoes the input
(nor a server path).
"""

from __future__ import annotations

import dataclasses
import json
import logging
import math
import os
import re
import tempfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from service import limits
from service.limits import LimitError, clip
from solver import axes as registry
from solver.environment import environment_of
from solver.formats import reader_suffixes
from solver.motion import Motion, MotionError, motion_from_dict

log = logging.getLogger(__name__)

#: every suffix a trial file may have (the readers' registry, solver.formats)
TRIAL_SUFFIXES = tuple(reader_suffixes())
MAX_FILES = 8
#: characters refused in names (SQL text columns, exports): control characters
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")


class UploadError(ValueError):
    pass


class ImporterUnavailable(RuntimeError):
    pass


@dataclass(frozen=True)
class Encoded:
    """A validated motion, ready to store (``service.store.add_encoded``)."""

    kind: str  # capture | motion
    character: str
    n: int
    frames: int
    fps: float
    has_wrenches: bool
    data: bytes  # zlib-compressed motion file v1
    sha256: str  # of the uncompressed JSON
    input: dict | None = None  # uploaded trials: the input summary (``input_summary``) for the response


def encode(motion: Motion) -> Encoded:
    from service.store import encode_motion  # lazy: runs in a compute process; the API process does not load the solver

    data, digest = encode_motion(motion)
    return Encoded(kind=classify(motion), character=motion.reference_name or motion.character.name, n=motion.n,
                   frames=motion.T, fps=float(motion.fps), has_wrenches=motion.wrenches is not None, data=data,
                   sha256=digest)


# --- JSON ---------------------------------------------------------------------------------


def _finite_float(s: str) -> float:
    v = float(s)
    if not math.isfinite(v):
        raise UploadError(f"number {clip(s, 40)!r} is not finite (JSON numbers must be finite)")
    return v


def _bounded_int(s: str) -> int:
    if len(s.lstrip("-")) > limits.MAX_INT_DIGITS:
        raise UploadError(f"an integer literal has {len(s.lstrip('-'))} digits; at most {limits.MAX_INT_DIGITS} "
                          "are allowed")
    return int(s)


def _no_constant(name: str) -> Any:
    raise UploadError(f"{name} is not allowed: numbers must be finite")


def parse_json(body: bytes) -> Any:
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError:
        raise UploadError("the body is not UTF-8 text") from None
    try:
        d = json.loads(text, parse_float=_finite_float, parse_int=_bounded_int, parse_constant=_no_constant)
    except json.JSONDecodeError as e:
        raise UploadError(f"not valid JSON: {e.msg} (line {e.lineno}, column {e.colno})") from None
    except RecursionError:
        raise UploadError(f"the JSON nests too deeply (at most {limits.MAX_JSON_DEPTH} levels)") from None
    if not limits.json_depth_ok(d):
        raise UploadError(f"the JSON nests too deeply (at most {limits.MAX_JSON_DEPTH} levels)")
    return d


def _check_rows(rows: Any, width: int, where: str, what: str) -> None:
    if not isinstance(rows, list):
        return  # the schema names it
    for i, r in enumerate(rows):
        if not isinstance(r, list) or len(r) != width:
            got = len(r) if isinstance(r, list) else type(r).__name__
            raise UploadError(f"{where}[{i}] has {got} values, expected {width} ({what})")


def _check_sizes(d: dict) -> None:
    """The limits, before the schema validation (whose cost grows with the arrays)."""
    frames, coords = d.get("frames"), d.get("coordinates")
    if isinstance(frames, list) and len(frames) > limits.MAX_CAPTURE_FRAMES:  # the duration: once fps is checked
        raise UploadError(f"a motion has at most {limits.MAX_CAPTURE_FRAMES} frames, this one has {len(frames)}")
    if isinstance(coords, list) and len(coords) > limits.MAX_COORDINATES:
        raise UploadError(f"a character has at most {limits.MAX_COORDINATES} coordinates, this one has {len(coords)}")
    ch = d.get("character")
    definition = ch.get("definition") if isinstance(ch, dict) else None
    if isinstance(definition, dict):
        for key, cap in (("segments", limits.MAX_SEGMENTS), ("contacts", limits.MAX_CONTACT_POINTS),
                         ("feet", 2)):
            v = definition.get(key)
            if isinstance(v, list) and len(v) > cap:
                raise UploadError(f"character.definition.{key} has {len(v)} entries; at most {cap}")


def check_motion(motion: Motion) -> None:
    """Limits and names of a motion about to be stored (uploads and imports alike)."""
    ch = motion.character
    try:
        limits.check_motion(frames=motion.T, fps=float(motion.fps), coordinates=motion.n,
                            segments=len(ch.segments), contacts=len(ch.contacts))
    except LimitError as e:
        raise UploadError(str(e)) from None
    names = [("character name", ch.name)] + [("segment name", s.name) for s in ch.segments]
    names += [("coordinate name", c) for c in ch.coordinate_names] + [("contact point name", c.name)
                                                                        for c in ch.contacts]
    for what, nm in names:
        if not nm or len(nm) > limits.MAX_NAME_CHARS or _CONTROL.search(nm):
            raise UploadError(f"{what} {clip(nm, 60)!r} must be 1 to {limits.MAX_NAME_CHARS} characters without "
                              "control characters")
    _check_environment(motion)


def _check_environment(motion: Motion) -> None:
    """The motion's environment (``provenance.environment``) within the axes' domains: gravity
    magnitude, friction and riser height a job can start from (a stored motion whose environment
    no solve, plot or export can use would answer errors later)."""
    try:
        env = environment_of(motion)
    except (ValueError, TypeError, AttributeError, OverflowError) as e:
        raise UploadError(clip(f"provenance.environment: {e}", 300)) from None
    for name, value in (("gravity", env.gravity_magnitude), ("friction", env.friction),
                        ("step_height_m", env.step_height_m)):
        try:
            registry.axis(name).check(value)
        except ValueError as e:
            raise UploadError(f"provenance.environment: {e}") from None


def motion_from_upload(d: Any) -> Motion:
    """A motion file v1 (already parsed) -> Motion, with shape errors named precisely."""
    if isinstance(d, dict):
        _check_sizes(d)
        coords = d.get("coordinates")
        if isinstance(coords, list):
            _check_rows(d.get("frames"), len(coords), "frames", "one per coordinate")
        c = d.get("contacts")
        if isinstance(c, dict) and isinstance(c.get("points"), list):
            _check_rows(c.get("active"), len(c["points"]), "contacts.active", "one flag per contact point")
        w = d.get("wrenches")
        if isinstance(w, dict) and isinstance(w.get("feet"), dict):
            for foot in ("right", "left"):
                _check_rows(w["feet"].get(foot), 6, f"wrenches.feet.{foot}", "mx, my, mz, fx, fy, fz")
    try:
        motion = motion_from_dict(d)
    except MotionError as e:
        raise UploadError(clip(str(e), 500)) from None
    except (ValueError, TypeError, KeyError, OverflowError) as e:
        raise UploadError(clip(f"invalid motion file: {e}", 500)) from None
    check_motion(motion)
    return motion


def motion_upload(body: bytes) -> Encoded:
    """``POST /motions`` with a motion file v1: the body -> a validated, encoded motion."""
    return encode(motion_from_upload(parse_json(body)))


def classify(motion: Motion) -> str:
    """``capture`` (raw: a job first makes its tutor) or ``motion`` (usable as a tutor)."""
    step = str((motion.provenance or {}).get("step", ""))
    if step == "capture" or motion.wrenches is None or motion.contacts is None:
        return "capture"
    return "motion"


# --- mocap trials ---------------------------------------------------------------------------

_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


def _safe_name(name: str, i: int) -> str:
    base = _SAFE.sub("_", Path(name or f"file{i}").name).strip("._") or f"file{i}"
    return base[:120]


_BVH_FRAMES = re.compile(rb"^\s*Frames:\s*(\d+)", re.M)
_BVH_TIME = re.compile(rb"^\s*Frame Time:\s*([-+0-9.eE]+)", re.M)


def _seconds(x: float) -> str:
    return f"{x:.6g} s"


def _trial_extent(name: str, content: bytes) -> tuple[int | None, float | None]:
    """(frames, seconds) a text trial file declares, read cheaply before the import (whose
    cost grows with the frames); (None, None) when unknown (binary C3D: checked after)."""
    low = name.lower()
    try:
        if low.endswith(".bvh"):
            f, t = _BVH_FRAMES.search(content), _BVH_TIME.search(content)
            if f and t:
                n = int(f.group(1))
                return n, n * float(t.group(1))
        elif low.endswith((".txt", ".json")) and content.lstrip()[:1] == b"{":
            frames = json.loads(content).get("Frames")  # DeepMimic: each frame starts with its duration
            if isinstance(frames, list):
                dts = [fr[0] for fr in frames[:-1] if isinstance(fr, list) and fr and isinstance(fr[0], (int, float))]
                return len(frames), float(sum(abs(dt) for dt in dts))
        elif low.endswith((".mot", ".sto")):
            text = content.decode("utf-8", "replace")
            body = text.split("endheader", 1)[1] if "endheader" in text else text
            rows = [ln.split() for ln in body.strip().splitlines()[1:] if ln.strip()]
            if len(rows) >= 2:
                return None, abs(float(rows[-1][0]) - float(rows[0][0]))  # rows of forces can be 1 kHz
    except (ValueError, IndexError, TypeError, RecursionError):
        return None, None  # the importer names the problem
    return None, None


def _precheck_trial(names: list[str], files: list[tuple[str, bytes]]) -> None:
    for name, (_, content) in zip(names, files):
        frames, seconds = _trial_extent(name, content)
        if frames is not None and frames > limits.MAX_CAPTURE_FRAMES:
            raise UploadError(f"{name}: a capture has at most {limits.MAX_CAPTURE_FRAMES} frames, this one has "
                              f"{frames}")
        if seconds is not None and not seconds <= limits.MAX_CAPTURE_S * 1.01:
            raise UploadError(f"{name}: a capture lasts at most {limits.MAX_CAPTURE_S:g} s, this one lasts "
                              f"{_seconds(seconds)}")


def motion_from_trial(files: list[tuple[str, bytes]], *, mass: float | None, belt_speed: float | None) -> Motion:
    """Mocap files (name, content) -> the raw capture as a Motion."""
    if not files:
        raise UploadError("no files: send the trial's files as multipart field 'files'")
    if len(files) > MAX_FILES:
        raise UploadError(f"at most {MAX_FILES} files per trial, got {len(files)}")
    for v, name in ((mass, "mass"), (belt_speed, "belt_speed")):
        if v is not None and not math.isfinite(v):
            raise UploadError(f"{name} must be finite")
    if mass is not None and not 1.0 <= mass <= 500.0:
        raise UploadError(f"mass must be a subject's mass in kg (1 to 500), got {mass:g}")
    if belt_speed is not None and not abs(belt_speed) <= 20.0:
        raise UploadError(f"belt_speed must be a treadmill speed in m/s (at most 20), got {belt_speed:g}")
    names = [_safe_name(n, i) for i, (n, _) in enumerate(files)]
    if len(set(names)) != len(names):
        raise UploadError(f"file names must be distinct, got {names}")
    bad = [n for n in names if not n.lower().endswith(TRIAL_SUFFIXES)]
    if bad:
        raise UploadError(f"unsupported file type(s) {bad}; supported: {list(TRIAL_SUFFIXES)}")
    _precheck_trial(names, files)
    try:
        from solver.io import load_trial  # lazy: runs in a compute process; the API process does not load the solver
        from solver.pipeline import capture_motion
    except ImportError as e:
        raise ImporterUnavailable(f"mocap import is not available in this build ({e})") from None
    with tempfile.TemporaryDirectory(prefix="motionx-upload-") as tmp:
        paths = []
        for name, (_, content) in zip(names, files):
            p = Path(tmp) / name
            p.write_bytes(content)
            paths.append(p)
        try:
            capture = load_trial(paths, mass=mass, belt_speed=belt_speed)
            motion = capture_motion(capture)
        except MemoryError:
            raise
        except Exception as e:  # the parsing boundary: whatever a reader trips on is bad input
            log.info("trial import failed: %s", e, exc_info=True)
            raise UploadError(clip(f"could not import the trial: {client_message(e, tmp)}", 500)) from None
        summary = input_summary(capture, tmp)
        motion = motion.evolve(provenance={**_hide_paths(dict(motion.provenance), tmp), "input": summary})
    check_motion(motion)
    return motion


def trial_upload(files: list[tuple[str, bytes]], mass: float | None, belt_speed: float | None) -> Encoded:
    """``POST /motions`` with a multipart trial: files -> the validated, encoded raw capture,
    with the input summary (``Encoded.input``) the upload response shows."""
    motion = motion_from_trial(files, mass=mass, belt_speed=belt_speed)
    return dataclasses.replace(encode(motion), input=(motion.provenance or {}).get("input"))


#: importer parameters (``solver.errors.InputError.parameter``) -> how a client sends them
FORM_FIELDS = {"mass": "send the form field 'mass' (kg)", "belt_speed": "send the form field 'belt_speed' (m/s)"}


def _hide_folder(text: str, tmp: str) -> str:
    """``text`` without the server's temporary folder (the client's file names stay)."""
    for folder in {tmp, os.path.realpath(tmp)}:
        text = text.replace(folder + "/", "").replace(folder, "<upload>")
    return text


def client_message(e: BaseException, tmp: str) -> str:
    """An importer's error as the client may read it: the server's temporary folder is
    never shown (the client's file names stay), and a missing importer parameter is named
    as the upload form's field."""
    param = getattr(e, "parameter", None)
    msg = f"{e.reason}; {FORM_FIELDS[param]}" if param in FORM_FIELDS and getattr(e, "reason", None) else str(e)
    return _hide_folder(msg, tmp)


def input_summary(capture: Any, tmp: str) -> dict | None:
    """What the uploaded trial looks like (``solver.io.summary.describe``): mass, the mass the
    plates imply and a warning when they disagree, fit errors, stance intervals per foot.
    Like the error messages, it never shows the server's temporary folder."""
    from solver.io.summary import describe  # lazy: runs in a compute process; the API process does not load the solver
    from solver.pipeline import jsonable

    try:
        return _hide_paths(jsonable(describe(capture)), tmp)
    except MemoryError:
        raise
    except Exception:
        log.warning("could not describe the uploaded trial", exc_info=True)
        return None


def _hide_paths(obj: Any, tmp: str) -> Any:
    """Provenance, summaries: every string without the server's temporary folder."""
    if isinstance(obj, str):
        return _hide_folder(obj, tmp)
    if isinstance(obj, dict):
        return {k: _hide_paths(v, tmp) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_hide_paths(v, tmp) for v in obj]
    return obj
