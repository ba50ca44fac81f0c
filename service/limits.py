"""What one request may cost: limits that follow the method (docs/service.md, "Limits").

A tutor is one gait cycle, so a motion used as a tutor (an extrapolation's input) is short:
at most ``MAX_TUTOR_S`` seconds and ``MAX_TUTOR_FRAMES`` frames (4 s of walking: 61 frames
at 15 fps, 121 at 30 fps; a cycle of walking lasts about 1-1.3 s), of a character with at most
``MAX_TUTOR_COORDINATES`` coordinates (HalfBoy has 16, the full body 43). The spacetime NLP
grows with frames x coordinates and its solve time faster than that (measured: a HalfBoy base
solve takes ~1.5 s at 59 frames, ~20 s at 116, ~260 s at 382), so these bounds are what keep
one job to minutes.

A capture (the input of the tutor pipeline, which cuts one cycle out of it) lasts at most
``MAX_CAPTURE_S`` seconds and has at most ``MAX_CAPTURE_FRAMES`` frames and
``MAX_COORDINATES`` coordinates; any stored motion obeys these too.

Physical ranges (fps, coordinates, masses, inertias, lengths, forces) are checked where the
values are built: :mod:`solver.motion` and :mod:`solver.character`.
"""

from __future__ import annotations

import math
import re
from typing import Any

MAX_TUTOR_S = 4.0
MAX_TUTOR_FRAMES = 121
MAX_TUTOR_COORDINATES = 64
MAX_TUTOR_FPS = 30.0
MIN_TUTOR_FPS = 5.0

MAX_CAPTURE_S = 120.0
MAX_CAPTURE_FRAMES = 30_000
MAX_COORDINATES = 128
MAX_SEGMENTS = 128
MAX_CONTACT_POINTS = 32

#: names the service stores in SQL columns or shows (motion labels, character and joint names)
MAX_NAME_CHARS = 200
#: JSON bodies: nesting depth (a motion file needs 6) and digits of an integer literal
MAX_JSON_DEPTH = 64
MAX_INT_DIGITS = 32


class LimitError(ValueError):
    """A request would cost more than the limits allow (the message names the limit)."""


def check_motion(*, frames: int, fps: float, coordinates: int, segments: int, contacts: int) -> None:
    """Any stored motion: a capture at most (``MAX_CAPTURE_S``, ``MAX_CAPTURE_FRAMES``, ...)."""
    if frames > MAX_CAPTURE_FRAMES:
        raise LimitError(f"a motion has at most {MAX_CAPTURE_FRAMES} frames, this one has {frames}")
    duration = (frames - 1) / fps if fps > 0 else math.inf
    if duration > MAX_CAPTURE_S:
        raise LimitError(f"a capture lasts at most {MAX_CAPTURE_S:g} s, this one lasts {duration:.6g} s "
                         f"({frames} frames at {fps:g} fps)")
    if coordinates > MAX_COORDINATES:
        raise LimitError(f"a character has at most {MAX_COORDINATES} coordinates, this one has {coordinates}")
    if segments > MAX_SEGMENTS:
        raise LimitError(f"a character has at most {MAX_SEGMENTS} segments, this one has {segments}")
    if contacts > MAX_CONTACT_POINTS:
        raise LimitError(f"a character has at most {MAX_CONTACT_POINTS} contact points, this one has {contacts}")


def check_tutor(*, frames: int, fps: float, coordinates: int, made: bool = False) -> None:
    """A motion used as a tutor: one gait cycle (``made``: the tutor the job just made from a capture)."""
    duration = (frames - 1) / fps if fps > 0 else math.inf
    if frames > MAX_TUTOR_FRAMES or duration > MAX_TUTOR_S:
        hint = ("the capture's gait cycle is too long to extrapolate" if made else
                "Upload the raw capture instead (the job cuts one cycle out of it and makes the tutor), or one "
                "cycle of this motion")
        raise LimitError(
            f"a tutor is one gait cycle: at most {MAX_TUTOR_FRAMES} frames and {MAX_TUTOR_S:g} s; this "
            f"{'tutor' if made else 'motion'} has {frames} frames ({duration:.6g} s at {fps:g} fps). {hint}")
    if coordinates > MAX_TUTOR_COORDINATES:
        raise LimitError(f"a tutor's character has at most {MAX_TUTOR_COORDINATES} coordinates, this one has "
                         f"{coordinates}")


def check_source(*, kind: str, frames: int, fps: float, coordinates: int) -> None:
    """The source motion of an extrapolation job: a tutor (used directly) or a raw capture."""
    if kind == "capture":
        check_motion(frames=frames, fps=fps, coordinates=coordinates, segments=0, contacts=0)
    else:
        check_tutor(frames=frames, fps=fps, coordinates=coordinates)


def json_depth_ok(x: Any, limit: int = MAX_JSON_DEPTH) -> bool:
    """Whether parsed JSON nests at most ``limit`` levels (iterative: no recursion)."""
    stack = [(x, 1)]
    while stack:
        v, d = stack.pop()
        if isinstance(v, dict):
            vals = v.values()
        elif isinstance(v, list):
            vals = v
        else:
            continue
        if d > limit:
            return False
        for c in vals:
            if isinstance(c, (dict, list)):
                stack.append((c, d + 1))
    return True


def clip(text: str, n: int = 300) -> str:
    """A message fragment that never echoes a large input."""
    text = str(text)
    return text if len(text) <= n else text[: n - 1] + "…"


#: what a library's internals say, and what a person reads instead
_INTERNALS = (
    (re.compile(r"std::bad_alloc"), "out of memory"),
    (re.compile(r"\bstd::[A-Za-z_:]+"), "an internal error of a library"),
    (re.compile(r"\bSimTK\b[^.;]*"), "the model could not be read"),
    (re.compile(r":\s*line \d+, column \d+"), ""),  # an XML parser's position (expat)
)


def plain(text: str) -> str:
    """A message without C++ or parser internals (``std::bad_alloc``, a parser's line and
    column): every ``detail`` passes through it."""
    for pattern, repl in _INTERNALS:
        text = pattern.sub(repl, text)
    return text


def refusal_text(e: BaseException, fallback: str, n: int = 500) -> str:
    """What a client may read about exception ``e``: the message of a refusal our own code
    raised on purpose (a subclass of ``ValueError`` defined in ``solver``, ``mjcf`` or
    ``service``: ``InputError``, ``MotionError``, ``PipelineError``, ...), cut to ``n``
    characters; else ``fallback`` — a bare ``ValueError``, ``TypeError`` or a library's error
    names internals (the caller logs it in full)."""
    ours = type(e).__module__.split(".")[0] in ("solver", "mjcf", "service")
    if isinstance(e, ValueError) and type(e) is not ValueError and ours and str(e):
        return clip(plain(str(e)), n)
    return fallback
