"""What an OpenSim trial keeps for writing results back on the subject's own model.

The importer fills ``Capture.rig`` with a JSON-able mapping (``format: "opensim"``) that
every motion made from the capture carries in its context (``Motion.context.rig``) (tutor, λ optima,
library cells), so :mod:`solver.export.opensim` can write any of them on the model the
trial came with:

* ``model``: the ``.osim`` file as given (its text, xz-compressed and base64-encoded: a
  scaled model is 0.5–1 MB of XML, 15–30 kB so), its file name and SHA-256;
* ``coordinates``: the trial's coordinates as OpenSim evaluated them (the ``.mot`` columns
  that are coordinates of the model, or the inverse kinematics of a ``.trc``), in the model's
  units (radians, metres), at ``times`` (the capture's times, seconds);
* ``fit``: the capture skeleton's coordinates at the same times (our units), with their
  names: what the model's bodies are calibrated against (the motion's segments at a gait
  phase ↔ the model's bodies at the captured time of that phase);
* ``bodies``: the model's bodies and, per body, the segment of ours it belongs to;
  ``feet``: the bodies the ground reactions are applied to (``calcn_r``, ``calcn_l``);
* ``frame``: the capture's :class:`~solver.capture.GroundFrame` (our world → OpenSim
  ground, the belt velocity of a treadmill trial included);
* ``plates`` (a trial with force plates): the GRF file and ExternalLoads paths as imported and
  the span (s) where every loaded foot is on a plate — to check the trial's own inverse
  dynamics beside an export's, where those files still are.
"""

from __future__ import annotations

import base64
import hashlib
import lzma
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import numpy as np

from solver.capture import Capture
from solver.io.opensim.base import OpenSimError

#: digits kept of the coordinate tables (1e-6 rad, 1 µm)
DIGITS = 6


def pack_model(text: bytes) -> str:
    """An ``.osim`` file's bytes as base64 text of their xz compression."""
    return base64.b64encode(lzma.compress(text)).decode("ascii")


def unpack_model(packed: str) -> bytes:
    """Inverse of :func:`pack_model`."""
    try:
        return lzma.decompress(base64.b64decode(packed.encode("ascii"), validate=True))
    except (ValueError, lzma.LZMAError) as e:
        raise OpenSimError(f"the motion's OpenSim model cannot be unpacked ({e})") from None


def _table(a: np.ndarray) -> list:
    return np.round(np.asarray(a, dtype=float), DIGITS).tolist()


def opensim_rig(model: str | Path, res: Mapping[str, Any], capture: Capture) -> dict[str, Any]:
    """The rig of an OpenSim capture (see the module doc) from the model file, OpenSim's
    evaluation of it along the trial (:func:`solver.io.opensim.model.opensim_evaluation`) and
    the fitted capture."""
    p = Path(model)
    text = p.read_bytes()
    names, values = res["coordinates"]
    values = np.asarray(values, dtype=float)
    if values.shape != (capture.T, len(names)):
        raise OpenSimError(f"{p.name}: {values.shape[0]} coordinate frames for {capture.T} capture frames")
    seg_of = dict(capture.source.get("body_to_segment") or {})
    feet = {}
    for side, s in (("right", "r"), ("left", "l")):
        body = f"calcn_{s}"
        if body not in seg_of:
            raise OpenSimError(f"{p.name}: no body {body!r} to apply the {side} foot's ground reaction to")
        feet[side] = body
    return {
        "format": "opensim",
        "model": {"file": p.name, "name": res.get("model_name"), "sha256": hashlib.sha256(text).hexdigest(),
                  "osim_xz_b64": pack_model(text)},
        "model_coordinates": list(res["coord_names"]),
        "coordinates": {"names": list(names), "values": _table(values)},
        "times": _table(capture.times),
        "fit": {"names": list(capture.character.coordinate_names), "q": _table(capture.q)},
        "bodies": list(res["body_names"]),
        "body_segments": {b: seg_of.get(b) for b in res["body_names"]},
        "feet": feet,
        "frame": capture.frame.to_dict(),
    }
