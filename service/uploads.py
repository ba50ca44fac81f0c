"""Turning an upload into a :class:`~solver.motion.Motion` (validated synchronously).

- ``application/json``: a motion file v1. Non-finite numbers (``NaN``, ``Infinity``,
  ``1e999``) and ragged arrays are refused with a message naming where.
- ``multipart/form-data``: a mocap trial, read by ``solver.io.load_trial`` (OpenSim
  .osim + .mot, C3D with ``mass``, BVH, DeepMimic), kept as a raw capture
  (``solver.pipeline.capture_motion``); the extrapolation job makes its tutor.

Every failure raises :class:`UploadError` (→ 422) with a message naming the problem.
"""

from __future__ import annotations

import json
import logging
import math
import re
import tempfile
from pathlib import Path
from typing import Any

from solver.motion import Motion, MotionError, motion_from_dict

log = logging.getLogger(__name__)

TRIAL_SUFFIXES = (".osim", ".mot", ".sto", ".trc", ".xml", ".c3d", ".bvh", ".txt", ".json")
MAX_FILES = 8


class UploadError(ValueError):
    pass


class ImporterUnavailable(RuntimeError):
    pass


def _finite_float(s: str) -> float:
    v = float(s)
    if not math.isfinite(v):
        raise UploadError(f"number {s!r} is not finite (JSON numbers must be finite)")
    return v


def _no_constant(name: str) -> Any:
    raise UploadError(f"{name} is not allowed: numbers must be finite")


def parse_json(body: bytes) -> Any:
    try:
        text = body.decode("utf-8")
    except UnicodeDecodeError:
        raise UploadError("the body is not UTF-8 text") from None
    try:
        return json.loads(text, parse_float=_finite_float, parse_constant=_no_constant)
    except json.JSONDecodeError as e:
        raise UploadError(f"not valid JSON: {e}") from None


def _check_rows(rows: Any, width: int, where: str, what: str) -> None:
    if not isinstance(rows, list):
        return  # the schema names it
    for i, r in enumerate(rows):
        if not isinstance(r, list) or len(r) != width:
            got = len(r) if isinstance(r, list) else type(r).__name__
            raise UploadError(f"{where}[{i}] has {got} values, expected {width} ({what})")


def motion_from_upload(d: Any) -> Motion:
    """A motion file v1 (already parsed) -> Motion, with shape errors named precisely."""
    if isinstance(d, dict):
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
        return motion_from_dict(d)
    except MotionError as e:
        raise UploadError(str(e)) from None
    except (ValueError, TypeError, KeyError) as e:
        raise UploadError(f"invalid motion file: {e}") from None


def classify(motion: Motion) -> str:
    """``capture`` (raw: a job first makes its tutor) or ``motion`` (usable as a tutor)."""
    step = str((motion.provenance or {}).get("step", ""))
    if step == "capture" or motion.wrenches is None or motion.contacts is None:
        return "capture"
    return "motion"


_SAFE = re.compile(r"[^A-Za-z0-9._-]+")


def _safe_name(name: str, i: int) -> str:
    base = _SAFE.sub("_", Path(name or f"file{i}").name).strip("._") or f"file{i}"
    return base[:120]


def motion_from_trial(files: list[tuple[str, bytes]], *, mass: float | None, belt_speed: float | None) -> Motion:
    """Mocap files (name, content) -> the raw capture as a Motion."""
    if not files:
        raise UploadError("no files: send the trial's files as multipart field 'files'")
    if len(files) > MAX_FILES:
        raise UploadError(f"at most {MAX_FILES} files per trial, got {len(files)}")
    for v, name in ((mass, "mass"), (belt_speed, "belt_speed")):
        if v is not None and not math.isfinite(v):
            raise UploadError(f"{name} must be finite")
    if mass is not None and not mass > 0:
        raise UploadError("mass must be positive (kg)")
    names = [_safe_name(n, i) for i, (n, _) in enumerate(files)]
    if len(set(names)) != len(names):
        raise UploadError(f"file names must be distinct, got {names}")
    bad = [n for n in names if not n.lower().endswith(TRIAL_SUFFIXES)]
    if bad:
        raise UploadError(f"unsupported file type(s) {bad}; supported: {list(TRIAL_SUFFIXES)}")
    try:
        from solver.io import load_trial
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
        except Exception as e:  # the parsing boundary: whatever a reader trips on is bad input
            log.info("trial import failed: %s", e, exc_info=True)
            raise UploadError(f"could not import the trial: {client_message(e, tmp)}") from None
        return motion.evolve(provenance={**motion.provenance, "input": input_summary(capture, tmp)})


#: importer parameters (``solver.io.errors.InputError.parameter``) -> how a client sends them
FORM_FIELDS = {"mass": "send the form field 'mass' (kg)", "belt_speed": "send the form field 'belt_speed' (m/s)"}


def _hide_folder(text: str, tmp: str) -> str:
    """``text`` without the server's temporary folder (the client's file names stay)."""
    for folder in {tmp, str(Path(tmp).resolve())}:
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
    from solver.io.summary import describe
    from solver.pipeline import jsonable

    try:
        return _hide_paths(jsonable(describe(capture)), tmp)
    except Exception:  # noqa: BLE001 - a description must never fail an upload that imported
        log.warning("could not describe the uploaded trial", exc_info=True)
        return None


def _hide_paths(obj: Any, tmp: str) -> Any:
    if isinstance(obj, str):
        return _hide_folder(obj, tmp)
    if isinstance(obj, dict):
        return {k: _hide_paths(v, tmp) for k, v in obj.items()}
    if isinstance(obj, list):
        return [_hide_paths(v, tmp) for v in obj]
    return obj
