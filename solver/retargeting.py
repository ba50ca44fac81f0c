"""The retargeting interface: a motion's source rig (:class:`Rig`) and how the rig follows a
motion of the synthesis character (:class:`Calibration`).

A trial read from a BVH, a skinned glTF, a DeepMimic clip or an OpenSim model and its motion
comes with a rig of its own: the input's skeleton, or its musculoskeletal model. The importer
keeps it beside the capture (``Capture.rig``) and every motion made from the capture carries it
in its context (``Motion.context.rig``, always a :class:`Rig`), so tutors, λ optima and library
cells can be delivered on the user's own rig. Each kind of rig is one :class:`Rig` class (an
immutable value; plain data in the motion file, :meth:`Rig.to_dict` / :meth:`Rig.from_dict`)
with one :class:`Calibration` class:

* :meth:`Calibration.fit`: the rig against a *reference* motion of the synthesis character over
  the captured gait cycle (``reference.context.cycle``): each of the rig's joints or bodies
  relative to the segment of the character that moves it, as a function of the gait phase;
* :meth:`Calibration.pose`: any motion of that character on the rig, at given times and the
  motion's coordinates there: what an exporter writes;
* :meth:`Calibration.to_dict` / :meth:`Calibration.from_dict`: plain data.

A rig is calibrated by :meth:`Rig.calibrated` (its format's calibration class fitted against the
reference: the rig with it); the exporters then call :meth:`Calibration.pose` on
``rig.calibration``.

The two kinds:

* :class:`solver.rig_skeleton.SkeletonRig` (BVH, glTF, DeepMimic: joints, hierarchy, channels,
  the captured animation) with :class:`solver.rig_retarget.RotationCalibration` (each driving
  joint's rotation in its segment at the captured frames, interpolated by slerp; fitted when the
  tutor is made, against the simplified cycle, and kept in the rig; its pose: the joints' local
  rotations, legs closed by a two-bone IK, :class:`solver.rig_skeleton.RigPose`);
* :class:`solver.io.opensim.rig.OpenSimRig` (the trial's ``.osim`` model and coordinates) with
  :class:`solver.export.opensim.calibration.OpenSimCalibration` (each model body in its anchor
  segment as a Fourier series of the gait phase; fitted by the OpenSim export, against the
  motion's character and the capture skeleton's fit of the trial; its pose: the bodies' frames in
  OpenSim's ground, which OpenSim's inverse kinematics turns into the model's coordinates).

:data:`RIG_KINDS` names the class of each format's rigs (imported when a rig of that format is
read) and of its calibrations: a new kind adds its line there. Pure Python; no web or database
code.
"""

from __future__ import annotations

import importlib
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import replace
from typing import TYPE_CHECKING, Any, Generic, Self, TypeVar

from solver.errors import InputError
from solver.jsonable import jsonable

if TYPE_CHECKING:
    import numpy as np

#: the formats whose rigs are skeletons (:class:`solver.rig_skeleton.SkeletonRig`): the exporters
#: of BVH, glTF and DeepMimic write a motion on them (``rig="source"``)
RIG_FORMATS = ("bvh", "gltf", "deepmimic")
_SKELETON = ("solver.rig_skeleton:SkeletonRig", "solver.rig_retarget:RotationCalibration")
#: rig format -> (its :class:`Rig` class, its :class:`Calibration` class) as ``module:class``
#: names, imported when a rig of that format is read or calibrated (those modules import this one)
RIG_KINDS = {**dict.fromkeys(RIG_FORMATS, _SKELETON),
             "opensim": ("solver.io.opensim.rig:OpenSimRig", "solver.export.opensim.calibration:OpenSimCalibration")}


class RigError(InputError):
    """A motion cannot be written on its source rig, or a rig is unreadable; the message says why."""


def _kinds(fmt: Any) -> tuple[str, str]:
    kinds = RIG_KINDS.get(fmt) if isinstance(fmt, str) else None
    if kinds is None:
        raise RigError(f"unknown rig format {fmt!r}; known: {sorted(RIG_KINDS)}")
    return kinds


def _resolve(where: str) -> Any:
    module, name = where.split(":")
    return getattr(importlib.import_module(module), name)


def rig_kind(fmt: Any) -> type[Rig]:
    """The :class:`Rig` class of a rig format (:data:`RIG_KINDS`)."""
    kind = _resolve(_kinds(fmt)[0])
    assert isinstance(kind, type) and issubclass(kind, Rig)
    return kind


def calibration_kind(fmt: Any) -> type[Calibration[Any, Any]]:
    """The :class:`Calibration` class of a rig format's rigs (:data:`RIG_KINDS`)."""
    kind = _resolve(_kinds(fmt)[1])
    assert isinstance(kind, type) and issubclass(kind, Calibration)
    return kind


class Rig(ABC):
    """A motion's source rig (see the module doc). Every kind has ``format`` (:data:`RIG_KINDS`),
    ``frame`` (a :class:`solver.capture.GroundFrame`: our world → the input's axes, length unit
    and clock), ``times`` (the captured frames it holds, s on the capture's clock),
    ``calibration`` (its format's :class:`Calibration`, None until fitted: :meth:`calibrated`)
    and ``file_data`` (the plain data it was read from, None for a rig made in code).

    Subclasses are frozen dataclasses implementing :meth:`read` and :meth:`data`; a rig read from
    plain data is written back as read (:meth:`to_dict`)."""

    format: str
    frame: Any
    times: np.ndarray
    calibration: Calibration[Any, Any] | None
    file_data: Mapping[str, Any] | None

    @classmethod
    @abstractmethod
    def read(cls, d: Mapping[str, Any]) -> Self:
        """The rig from its plain data (:meth:`from_dict` checks the format and keeps ``d``)."""

    @abstractmethod
    def data(self) -> dict[str, Any]:
        """The rig as plain data (JSON-able; ``format`` first)."""

    def calibrated(self, reference: Any) -> Self:
        """The rig with its :attr:`calibration` fitted against ``reference`` (a
        :class:`solver.motion.Motion`; :meth:`Calibration.fit` of its format's calibration)."""
        return self.evolve(calibration=calibration_kind(self.format).fit(self, reference))

    @classmethod
    def read_calibration(cls, d: Mapping[str, Any]) -> Calibration[Any, Any] | None:
        """The calibration in a rig's plain data ``d`` (its ``calibration`` key), or None."""
        cal = d.get("calibration")
        return calibration_kind(d.get("format")).from_dict(cal) if cal else None

    def to_dict(self) -> dict[str, Any]:
        """The rig as the motion file holds it: the data it was read from, else :meth:`data`."""
        return dict(self.file_data) if self.file_data is not None else self.data()

    @classmethod
    def from_dict(cls, d: Any) -> Self:
        """A rig from its plain data, of the class its ``format`` names (:data:`RIG_KINDS`); on a
        subclass, only a rig of that class. An unreadable rig is a :class:`RigError`."""
        if not isinstance(d, Mapping):
            raise RigError(f"a rig must be an object, got {type(d).__name__}")
        kind = rig_kind(d.get("format"))
        if not issubclass(kind, cls):
            raise RigError(f"a {d.get('format')!r} rig is not a {cls.__name__}")
        try:
            rig = kind.read(d)
        except (KeyError, TypeError, ValueError, IndexError) as e:
            if isinstance(e, RigError):
                raise
            raise RigError(f"the motion's source rig is unreadable ({e.__class__.__name__}: {e})") from None
        object.__setattr__(rig, "file_data", dict(d))
        return rig  # kind is cls or a subclass of it

    def as_stored(self) -> Self:
        """The rig as a motion file holds it (read back from its plain data; itself when it was
        read from plain data): what a motion's context keeps, so that a motion in memory and the
        same motion read from its file are delivered on the rig alike."""
        return self if self.file_data is not None else type(self).from_dict(jsonable(self.to_dict()))

    def evolve(self, **changes: Any) -> Self:
        """A new rig with some fields replaced (its ``file_data`` dropped: written from its values)."""
        return replace(self, **changes)  # type: ignore[type-var]  # subclasses are dataclasses


RigT = TypeVar("RigT", bound=Rig)
PoseT = TypeVar("PoseT")


class Calibration(ABC, Generic[RigT, PoseT]):
    """How a rig of kind ``RigT`` follows a motion of the synthesis character (see the module
    doc); :meth:`pose` returns a ``PoseT``. Implementations are frozen dataclasses. The motions
    are :class:`solver.motion.Motion` values (which hold a :class:`Rig`: typed ``Any`` here)."""

    @classmethod
    @abstractmethod
    def fit(cls, rig: RigT, reference: Any) -> Self:
        """``rig`` calibrated against ``reference``: a motion of the synthesis character over the
        captured cycle (its context's ``cycle``, the capture's clock, and ``frame``)."""

    @abstractmethod
    def pose(self, motion: Any, rig: RigT, times: np.ndarray, q: np.ndarray, duration: float) -> PoseT:
        """``motion`` (of the character the calibration was fitted against) on ``rig`` at ``times``
        (s from its cycle's start; gait phase ``times / duration``), ``q`` (n, S) its coordinates
        there (the root moved on over repeated cycles)."""

    @abstractmethod
    def to_dict(self) -> dict[str, Any]:
        """Plain (JSON-able) data."""

    @classmethod
    @abstractmethod
    def from_dict(cls, d: Mapping[str, Any]) -> Self:
        """Inverse of :meth:`to_dict`."""
