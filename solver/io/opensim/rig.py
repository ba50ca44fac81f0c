"""What an OpenSim trial keeps for writing results back on the subject's own model.

The importer fills ``Capture.rig`` with an :class:`OpenSimRig` (a
:class:`~solver.retargeting.Rig`; ``format: "opensim"``) that every motion made from the capture
carries in its context (``Motion.context.rig``) (tutor, λ optima, library cells), so
:mod:`solver.export.opensim` can write any of them on the model the trial came with. Its
calibration is :class:`~solver.export.opensim.calibration.OpenSimCalibration`, fitted by the
export (it runs OpenSim). Its fields, under these keys in the motion file:

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
  dynamics beside an export's, where those files still are;
* ``generic`` (a rig the export made for a motion of another source,
  :func:`solver.export.opensim.generic_rig`): the generic model's name, scale factors and mass.
"""

from __future__ import annotations

import base64
import hashlib
import lzma
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from solver.capture import Capture, GroundFrame
from solver.io.opensim.base import OpenSimError
from solver.retargeting import Calibration, Rig, RigError

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


def _frozen(a: Any) -> np.ndarray:
    a = np.array(a, dtype=float, copy=True)
    a.setflags(write=False)
    return a


#: the keys of an OpenSim rig's plain data (``plates`` and ``generic`` optional)
KEYS = ("format", "model", "model_coordinates", "coordinates", "times", "fit", "bodies", "body_segments", "feet",
        "frame", "plates", "generic")


@dataclass(frozen=True, eq=False)
class OpenSimRig(Rig):
    """An OpenSim trial's model and coordinates, and the capture skeleton's fit of it (see the
    module doc): ``coordinates`` (T, C) the model's ``coordinate_names`` at ``times`` (model units),
    ``fit_q`` (n, T) the capture skeleton's ``fit_names`` there (ours), ``body_segments`` each
    model body -> the capture segment it belongs to (or None), ``feet`` ``right``/``left`` -> the
    bodies the ground reactions are applied to. ``extra``: other keys of its plain data, kept.
    ``calibration``: an :class:`~solver.export.opensim.calibration.OpenSimCalibration` once
    calibrated against a motion to write (:meth:`calibrated`, which runs OpenSim)."""

    model: Mapping[str, Any]
    model_coordinates: tuple[str, ...]
    coordinate_names: tuple[str, ...]
    coordinates: np.ndarray  # (T, C)
    times: np.ndarray  # (T,)
    fit_names: tuple[str, ...]
    fit_q: np.ndarray  # (n, T)
    bodies: tuple[str, ...]
    body_segments: Mapping[str, str | None]
    feet: Mapping[str, str]
    frame: GroundFrame = field(default_factory=GroundFrame)
    plates: Mapping[str, Any] | None = None
    generic: Mapping[str, Any] | None = None
    extra: Mapping[str, Any] = field(default_factory=dict)
    calibration: Calibration[Any, Any] | None = None
    format: str = "opensim"
    file_data: Mapping[str, Any] | None = field(default=None, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.format != "opensim":
            raise RigError(f"an OpenSim rig's format is 'opensim', got {self.format!r}")
        for name in ("coordinates", "times", "fit_q"):
            object.__setattr__(self, name, _frozen(getattr(self, name)))
        T, C, n = self.times.size, len(self.coordinate_names), len(self.fit_names)
        if self.times.shape != (T,) or self.coordinates.shape != (T, C) or self.fit_q.shape != (n, T):
            raise RigError(f"OpenSim rig: expected times (T,), coordinates (T, C={C}), fit (n={n}, T); got "
                           f"{self.times.shape}, {self.coordinates.shape}, {self.fit_q.shape}")
        if not isinstance(self.model, Mapping) or not isinstance(self.model.get("osim_xz_b64"), str):
            raise RigError("OpenSim rig: its model is missing (model.osim_xz_b64)")
        if set(self.feet) != {"right", "left"}:
            raise RigError(f"OpenSim rig: feet must name the right and left bodies, got {sorted(self.feet)}")
        for name in ("model_coordinates", "coordinate_names", "fit_names", "bodies"):
            object.__setattr__(self, name, tuple(str(x) for x in getattr(self, name)))
        object.__setattr__(self, "model", dict(self.model))
        object.__setattr__(self, "body_segments", {str(b): None if s is None else str(s)
                                                   for b, s in self.body_segments.items()})
        object.__setattr__(self, "feet", {str(k): str(v) for k, v in self.feet.items()})
        for name in ("plates", "generic"):
            v = getattr(self, name)
            object.__setattr__(self, name, None if v is None else dict(v))
        object.__setattr__(self, "extra", dict(self.extra))

    def data(self) -> dict[str, Any]:
        d: dict[str, Any] = {
            "format": self.format, "model": dict(self.model), "model_coordinates": list(self.model_coordinates),
            "coordinates": {"names": list(self.coordinate_names), "values": self.coordinates.tolist()},
            "times": self.times.tolist(), "fit": {"names": list(self.fit_names), "q": self.fit_q.tolist()},
            "bodies": list(self.bodies), "body_segments": dict(self.body_segments), "feet": dict(self.feet),
            "frame": self.frame.to_dict()}
        for name in ("plates", "generic"):
            if getattr(self, name) is not None:
                d[name] = getattr(self, name)
        d.update(self.extra)
        if self.calibration is not None:
            d["calibration"] = self.calibration.to_dict()
        return d

    @classmethod
    def read(cls, d: Mapping[str, Any]) -> OpenSimRig:
        calibration = cls.read_calibration(d)
        coords, fit = d["coordinates"], d["fit"]
        return cls(dict(d["model"]), tuple(d.get("model_coordinates") or coords["names"]), tuple(coords["names"]),
                   np.asarray(coords["values"], dtype=float), np.asarray(d["times"], dtype=float),
                   tuple(fit["names"]), np.asarray(fit["q"], dtype=float), tuple(d["bodies"]),
                   dict(d["body_segments"]), dict(d["feet"]), GroundFrame.from_dict(d["frame"]), d.get("plates"),
                   d.get("generic"), {k: v for k, v in d.items() if k not in KEYS and k != "calibration"},
                   calibration)


def opensim_rig(model: str | Path, res: Mapping[str, Any], capture: Capture) -> OpenSimRig:
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
    return OpenSimRig(
        model={"file": p.name, "name": res.get("model_name"), "sha256": hashlib.sha256(text).hexdigest(),
               "osim_xz_b64": pack_model(text)},
        model_coordinates=tuple(res["coord_names"]), coordinate_names=tuple(names),
        coordinates=np.asarray(_table(values)), times=np.asarray(_table(capture.times)),
        fit_names=tuple(capture.character.coordinate_names), fit_q=np.asarray(_table(capture.q)),
        bodies=tuple(res["body_names"]), body_segments={b: seg_of.get(b) for b in res["body_names"]}, feet=feet,
        frame=capture.frame)
