"""Turning an upload into a stored motion: parsing, validation, encoding.

These functions run in the API's compute processes (:mod:`service.work`), never on its
event loop, each with a time and memory limit; they return an :class:`Encoded` motion (the
compressed motion file and the columns of its row), so the API process only stores it.

- ``application/json``: a motion file (v2; v1 read too). Non-finite numbers (``NaN``, ``Infinity``,
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

import base64
import binascii
import dataclasses
import json
import logging
import math
import os
import re
import struct
import tempfile
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from service import limits
from service.limits import LimitError, clip, refusal_text
from solver import axes as registry
from solver.formats import BVH_UNITS, reader_suffixes
from solver.motion import FORMAT as MOTION_FORMAT
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
    data: bytes  # zlib-compressed motion file v2
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
    _check_rig_asset(motion)
    if classify(motion) == "capture":
        _check_capture(motion)


def _check_rig_asset(motion: Motion) -> None:
    """A glTF rig's asset (``provenance.rig.extra.asset`` in the file, the motion's ``context.rig``;
    a GLB the ``rig=source`` exports carry into what they write) is checked like an imported glTF
    file: never passed on unchecked."""
    from solver.rig import SkeletonRig  # lazy: runs in a compute process

    rig = motion.context.rig
    if not isinstance(rig, SkeletonRig) or rig.format != "gltf":
        return
    from solver.io.gltf import GltfError, parse_gltf  # lazy: runs in a compute process

    asset = rig.extra.get("asset")
    try:
        if not isinstance(asset, str):
            raise GltfError("provenance.rig: a glTF rig without its asset")
        parse_gltf(base64.b64decode(asset, validate=True), "provenance.rig.extra.asset")
    except (GltfError, binascii.Error, ValueError) as e:
        raise UploadError(clip(str(e), 500)) from None


def _check_capture(motion: Motion) -> None:
    """A raw capture's provenance (``source``, ``frame``, ``t0``) rebuilds the capture the job's
    tutor pipeline starts from (``solver.pipeline.motion_capture``): a value of the wrong type
    there (``"source": true``) is refused now rather than failing the job later."""
    from solver.pipeline import motion_capture  # lazy: runs in a compute process; the API process does not load it

    try:
        motion_capture(motion)
    except (TypeError, ValueError, KeyError, AttributeError, IndexError, OverflowError) as e:
        log.info("capture provenance refused: %r", e)
        raise UploadError("provenance of a capture: " + refusal_text(
            e, "'source' must be an object, 'frame' a ground frame and 't0' a number")) from None


def _check_environment(motion: Motion) -> None:
    """The motion's environment (``provenance.environment``) within the axes' domains: gravity
    magnitude, friction and riser height a job can start from (a stored motion whose environment
    no solve, plot or export can use would answer errors later; one of the wrong kind is refused
    when the file is read, ``MotionContext.split``)."""
    env = motion.environment
    for name, value in (("gravity", env.gravity_magnitude), ("friction", env.friction),
                        ("step_height_m", env.step_height_m)):
        try:
            registry.axis(name).check(value)
        except ValueError as e:
            raise UploadError(f"provenance.environment: {e}") from None


def motion_from_upload(d: Any) -> Motion:
    """A motion file (already parsed) -> Motion, with shape errors named precisely."""
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
    except (ValueError, TypeError, KeyError, OverflowError, IndexError) as e:
        log.info("motion file refused: %r", e, exc_info=True)
        raise UploadError("invalid motion file: " + refusal_text(
            e, "its values do not fit the motion file's schema (solver/schemas/motion-v2.schema.json)")) from None
    check_motion(motion)
    return motion


def motion_upload(body: bytes) -> Encoded:
    """``POST /motions`` with a motion file: the body -> a validated, encoded motion."""
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
            return _storage_extent(content)
        elif low.endswith(".trc"):
            return _trc_extent(content)
        elif low.endswith(".c3d"):
            return _c3d_extent(content)
    except (ValueError, IndexError, TypeError, RecursionError, struct.error):
        return None, None  # the importer names the problem
    return None, None


def _data_lines(body: bytes) -> tuple[int, bytes, bytes]:
    """(lines, first line, last line) of ``body`` without splitting it into lines."""
    body = body.strip()
    if not body:
        return 0, b"", b""
    first_end = body.find(b"\n")
    return body.count(b"\n") + 1, (body if first_end < 0 else body[:first_end]), body[body.rfind(b"\n") + 1:]


def _storage_extent(content: bytes) -> tuple[int | None, float | None]:
    """An OpenSim .mot/.sto: its rows and time span, from its line count and its first and last
    rows. A file of forces (``*force_vx`` columns) has no frame limit: plates sample at 1 kHz."""
    end = content.find(b"endheader")
    start = content.find(b"\n", end) + 1 if end >= 0 else 0
    body = content[start:].strip()
    labels_end = body.find(b"\n")
    if labels_end < 0:
        return None, None  # the reader names what is missing
    rows, first, last = _data_lines(body[labels_end + 1:])
    seconds = abs(float(last.split()[0]) - float(first.split()[0])) if rows >= 2 else None
    forces = any(lab.endswith(b"_vx") and b"force" in lab for lab in body[:labels_end].split())
    return (None if forces else rows), seconds


def _trc_extent(content: bytes) -> tuple[int | None, float | None]:
    """A .trc marker file: its frames (data lines after the five header lines) and their
    duration at its DataRate (third line, first value)."""
    n, _, _ = _data_lines(content)
    header = content[:4096].splitlines()
    frames = max(n - 5, 0)
    rate = float(header[2].split()[0]) if len(header) > 2 else 0.0
    return frames, (frames - 1) / rate if rate > 0 and frames > 1 else None


def _c3d_extent(content: bytes) -> tuple[int | None, float | None]:
    """A C3D file's frames and duration from its header block: first and last frame (16-bit
    words 4 and 5, 0xFFFF when the file has more frames than that) and the frame rate (words
    11-12), in the byte order of its processor type (parameter block header byte 4: 84 Intel,
    85 DEC, 86 MIPS)."""
    if len(content) < 512 or content[1] != 0x50:
        return None, None
    param = (content[0] - 1) * 512
    proc = content[param + 3] if 0 <= param + 3 < len(content) else 84
    order = ">" if proc == 86 else "<"
    first, last = struct.unpack_from(order + "HH", content, 6)
    rate = struct.unpack_from(order + "f", content, 20)[0] / (4.0 if proc == 85 else 1.0)
    frames = last - first + 1 if last >= first else None
    if last == 0xFFFF:
        frames = 0xFFFF  # at least: the header's 16-bit counter is full
    ok_rate = math.isfinite(rate) and rate > 0
    return frames, ((frames - 1) / rate if frames and ok_rate else None)


def _precheck_trial(names: list[str], files: list[tuple[str, bytes]]) -> None:
    for name, (_, content) in zip(names, files):
        frames, seconds = _trial_extent(name, content)
        if frames is not None and frames > limits.MAX_CAPTURE_FRAMES:
            raise UploadError(f"{name}: a capture has at most {limits.MAX_CAPTURE_FRAMES} frames, this one has "
                              f"{frames}")
        if seconds is not None and not seconds <= limits.MAX_CAPTURE_S * 1.01:
            raise UploadError(f"{name}: a capture lasts at most {limits.MAX_CAPTURE_S:g} s, this one lasts "
                              f"{_seconds(seconds)}")


def motion_from_trial(files: list[tuple[str, bytes]], *, mass: float | None, belt_speed: float | None,
                      **options: Any) -> Motion:
    """Mocap files (name, content) -> the raw capture as a Motion (``options``: the other
    importer options, :func:`trial_options`)."""
    if not files:
        raise UploadError("no files: send the trial's files as multipart field 'files'")
    if len(files) > MAX_FILES:
        raise UploadError(f"at most {MAX_FILES} files per trial, got {len(files)}")
    for v, name in ((mass, "mass"), (belt_speed, "belt_speed")):
        if v is not None and not math.isfinite(v):
            raise UploadError(f"{name} must be finite")
    if mass is not None and not 1.0 <= mass <= 500.0:
        raise UploadError(f"mass must be a subject's mass in kg (1 to 500), got {mass:g}")
    if belt_speed is not None and not 0.0 <= belt_speed <= 20.0:
        raise UploadError(f"belt_speed must be a treadmill's speed in m/s (0 to 20), got {belt_speed:g}")
    names = [_safe_name(n, i) for i, (n, _) in enumerate(files)]
    if len(set(names)) != len(names):
        raise UploadError(f"file names must be distinct, got {clip(str(names), 200)}")
    bad = [n for n in names if not n.lower().endswith(TRIAL_SUFFIXES)]
    if bad:
        raise UploadError(f"unsupported file type(s) {clip(str(bad), 200)}; supported: {list(TRIAL_SUFFIXES)}")
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
            capture = load_trial(paths, mass=mass, belt_speed=belt_speed, **options)
            motion = capture_motion(capture)
        except MemoryError:
            raise
        except Exception as e:  # the parsing boundary: whatever a reader trips on is bad input
            log.info("trial import failed: %s", e, exc_info=True)
            known = refusal_text(e, "")
            why = client_message(e, tmp) if known else (f"{', '.join(names)}: not a well-formed trial of a supported "
                                                          "format (the server's log has the reader's error)")
            raise UploadError(clip(f"could not import the trial: {why}", 500)) from None
        summary = input_summary(capture, tmp)
        rig = motion.context.rig
        if rig is not None:
            rig = type(rig).from_dict(_hide_paths(rig.to_dict(), tmp))
        motion = motion.evolve(provenance={**_hide_paths(dict(motion.provenance), tmp), "input": summary},
                               context=motion.context.with_(rig=rig))
    check_motion(motion)
    return motion


def is_motion_file(files: list[tuple[str, bytes]]) -> bool:
    """Whether a multipart upload is one motion file (``-F files=@tutor.json``) rather than a
    trial: a single ``.json`` file holding a JSON object with the motion file's ``format`` (or,
    without it, its ``coordinates`` and ``frames``). A DeepMimic trial is two files."""
    if len(files) != 1 or not files[0][0].lower().endswith(".json") or files[0][1].lstrip()[:1] != b"{":
        return False
    try:
        d = json.loads(files[0][1])
    except (ValueError, RecursionError):
        return False  # not JSON at all: the trial readers say what it is not
    return isinstance(d, dict) and (d.get("format") == MOTION_FORMAT or {"coordinates", "frames"} <= d.keys())


#: the importer options a trial upload takes as form fields beside ``mass`` and ``belt_speed``
#: (``solver.formats.reader_options()``; a test checks that every one is here)
OPTION_FIELDS = ("lower_only", "markers", "units", "up", "in_degrees", "joints", "animation")
_BOOLEAN = {"true": True, "false": False, "1": True, "0": False, "yes": True, "no": False}
_ROLE = re.compile(r"^[A-Za-z][A-Za-z0-9_]{0,31}$")


def _role_map(text: str, field: str = "markers") -> dict[str, str]:
    """``ROLE=label,ROLE=label``: C3D roles -> the file's marker labels (``markers``, roles upper
    case) or BVH joint roles -> the file's joint names (``joints``, roles lower case); an empty
    label: do not use the role. Only the inline form: the server reads no mapping file."""
    out: dict[str, str] = {}
    parts = [p for p in text.split(",") if p.strip()]
    what, example = ("label", "LASI=L_IAS") if field == "markers" else ("NAME", "hip_l=Thigh_L")
    if not parts or len(parts) > 64:
        raise UploadError(f"{field} must be 1 to 64 entries ROLE={what}, separated by commas")
    for part in parts:
        role, sep, label = part.partition("=")
        role, label = role.strip(), label.strip()
        if not sep or not _ROLE.match(role) or len(label) > 64 or _CONTROL.search(label):
            raise UploadError(f"{field}: {clip(part, 60)!r} is not ROLE={what} (e.g. {example})")
        out[role.upper() if field == "markers" else role.lower()] = label
    return out


def trial_options(fields: Mapping[str, str]) -> dict[str, Any]:
    """The importer options of a trial upload's form (``OPTION_FIELDS``; absent or empty: the
    reader's default) as ``load_trial`` keywords, each checked."""
    out: dict[str, Any] = {}
    for key in OPTION_FIELDS:
        v = fields.get(key)
        if v is None or not v.strip():
            continue
        v = v.strip()
        if key in ("lower_only", "in_degrees"):
            if v.lower() not in _BOOLEAN:
                raise UploadError(f"{key} must be true or false, got {clip(v, 20)!r}")
            out[key] = _BOOLEAN[v.lower()]
        elif key == "units":
            if v not in BVH_UNITS:
                raise UploadError(f"units must be one of {', '.join(BVH_UNITS)}, got {clip(v, 20)!r}")
            out[key] = v
        elif key == "up":
            if v not in ("y", "z"):
                raise UploadError(f"up must be y or z, got {clip(v, 20)!r}")
            out[key] = v
        elif key == "animation":
            if len(v) > 128 or _CONTROL.search(v):
                raise UploadError("animation must be the glTF animation's name or index (at most 128 characters, "
                                  "no control characters)")
            out[key] = v
        else:
            out[key] = _role_map(v, key)
    return out


def trial_upload(files: list[tuple[str, bytes]], mass: float | None, belt_speed: float | None,
                 options: Mapping[str, Any] | None = None) -> Encoded:
    """``POST /motions`` with a multipart trial: files -> the validated, encoded raw capture,
    with the input summary (``Encoded.input``) the upload response shows. A single motion file
    sent this way is read as the JSON body would be (:func:`motion_upload`). ``options``: the
    other importer options (:func:`trial_options`)."""
    if is_motion_file(files):
        if mass is not None or belt_speed is not None or options:
            raise UploadError("mass, belt_speed and the importer options go with a mocap trial; a motion file "
                              "states its character itself")
        return motion_upload(files[0][1])
    motion = motion_from_trial(files, mass=mass, belt_speed=belt_speed, **(options or {}))
    return dataclasses.replace(encode(motion), input=(motion.provenance or {}).get("input"))


#: importer parameters (``solver.errors.InputError.parameter``) -> how a client sends them
FORM_FIELDS = {"mass": "send the form field 'mass' (kg)", "belt_speed": "send the form field 'belt_speed' (m/s)",
               "joints": "send the form field 'joints' (ROLE=NAME,...)",
               "animation": "send the form field 'animation' (the glTF animation's name or index)"}


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
