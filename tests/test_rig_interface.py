"""The retargeting interface (``solver.retargeting``): every rig format's rig is a ``Rig`` value
and its calibration a ``Calibration``; the rig travels in the motion file as plain data, written
back as read; the exporters reach a rig's calibration only through the interface, so a new format
that registers its two classes in ``RIG_KINDS`` is delivered by them."""

from __future__ import annotations

import ast
import json
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from solver.character import reference
from solver.export.opensim.calibration import BodySeries, EvaluatedModel, OpenSimCalibration
from solver.export.world import source_pose
from solver.io.opensim.rig import OpenSimRig
from solver.motion import Cycle, Motion, MotionContext
from solver.retargeting import RIG_KINDS, Calibration, Rig, RigError, calibration_kind, rig_kind
from solver.rig import RigPose, SkeletonRig, retarget

ROOT = Path(__file__).resolve().parents[1]


def test_each_format_has_one_rig_class_and_one_calibration_class():
    kinds = {fmt: (rig_kind(fmt), calibration_kind(fmt)) for fmt in RIG_KINDS}
    assert {fmt: (r.__name__, c.__name__) for fmt, (r, c) in kinds.items()} == {
        "bvh": ("SkeletonRig", "RotationCalibration"), "gltf": ("SkeletonRig", "RotationCalibration"),
        "deepmimic": ("SkeletonRig", "RotationCalibration"), "opensim": ("OpenSimRig", "OpenSimCalibration")}
    for r, c in kinds.values():
        assert issubclass(r, Rig) and issubclass(c, Calibration)
    with pytest.raises(RigError, match="unknown rig format 'fbx'"):
        rig_kind("fbx")


def test_one_class_is_called_calibration():
    """The interface is the one ``Calibration`` in solver/; each implementation has its own name."""
    named = [str(p.relative_to(ROOT)) for p in sorted((ROOT / "solver").rglob("*.py"))
             for node in ast.walk(ast.parse(p.read_text()))
             if isinstance(node, ast.ClassDef) and node.name == "Calibration"]
    assert named == ["solver/retargeting.py"]


# --- plain data --------------------------------------------------------------------------------


def _opensim_rig_data() -> dict[str, Any]:
    return {"format": "opensim", "model": {"file": "m.osim", "name": "m", "sha256": None, "osim_xz_b64": "AA=="},
            "model_coordinates": ["a", "b"], "coordinates": {"names": ["a", "b"], "values": [[0.1, 0.2], [0.3, 0.4]]},
            "times": [0.0, 0.01], "fit": {"names": ["x"], "q": [[1.0, 2.0]]}, "bodies": ["pelvis", "calcn_r"],
            "body_segments": {"pelvis": "pelvis", "calcn_r": None}, "feet": {"right": "calcn_r", "left": "calcn_r"},
            "frame": {"R": np.eye(3).tolist(), "offset": [0.0, 0.0, 0.0], "unit_m": 1.0, "velocity": [0.0, 0.0, 0.0],
                      "axes": "y up"},
            "plates": {"grf": "/somewhere/grf.mot", "external_loads": None, "complete_s": None}}


def test_an_opensim_rig_is_a_rig_written_back_as_read():
    d = _opensim_rig_data()
    rig = Rig.from_dict(json.loads(json.dumps(d)))
    assert isinstance(rig, OpenSimRig) and rig.bodies == ("pelvis", "calcn_r") and rig.coordinates.shape == (2, 2)
    assert rig.to_dict() == d and rig.as_stored() is rig
    made = rig.evolve(plates=None)  # made in code: written from its values
    assert made.file_data is None and made.to_dict() == {k: v for k, v in d.items() if k != "plates"}
    with pytest.raises(RigError, match="is not a SkeletonRig"):
        SkeletonRig.from_dict(d)
    with pytest.raises(RigError, match="unreadable"):
        Rig.from_dict({k: v for k, v in d.items() if k != "bodies"})


def test_the_opensim_calibration_round_trips_through_plain_data():
    rng = np.random.default_rng(1)
    B, K = 2, 2
    series = BodySeries({"pelvis": "pelvis", "calcn_r": "foot_r"}, np.tile(np.eye(3), (B, 1, 1)),
                        0.1 * rng.standard_normal((B, 2 * K + 1, 3)), rng.standard_normal((B, 2 * K + 1, 3)), K,
                        0.5, 1.5, np.tile(np.eye(3), (B, 1, 1)), np.zeros((B, 3)))
    model = EvaluatedModel({"pelvis": "ground", "calcn_r": "pelvis"}, rng.standard_normal((B, 3)),
                           {"a": True, "b": False}, (np.tile(np.eye(3), (B, 1, 1)), rng.standard_normal((B, 3))))
    cal = OpenSimCalibration(series, {"pelvis": ((series, 2.0), (series, 1.0))}, model)
    back = OpenSimCalibration.from_dict(json.loads(json.dumps(cal.to_dict())))
    assert back.to_dict() == cal.to_dict()
    phase = np.linspace(0.0, 1.0, 7)
    for a, b in zip(cal.bodies.at(phase), back.bodies.at(phase)):
        assert np.array_equal(a, b)
    assert back.blend["pelvis"][0][1] == 2.0 and back.model is not None and back.model.coordinates == {"a": True,
                                                                                                        "b": False}


# --- a rig format of one's own: registered, calibrated and delivered through the interface ------


@dataclass(frozen=True, eq=False)
class ToyCalibration(Calibration[SkeletonRig, RigPose]):
    """Every joint at its first captured rotation, the root where the motion's pelvis is."""

    lift: float = 0.0

    @classmethod
    def fit(cls, rig: SkeletonRig, reference: Motion) -> ToyCalibration:
        return cls(lift=float(reference.context.cycle.period_s))  # type: ignore[union-attr]

    def pose(self, motion: Motion, rig: SkeletonRig, times: np.ndarray, q: np.ndarray, duration: float) -> RigPose:
        F = times.size
        root = np.zeros((F, 3))
        root[:, 0], root[:, 2] = q[0], self.lift
        return RigPose(times, np.broadcast_to(rig.local[0], (F, *rig.local.shape[1:])).copy(), root, None, times,
                       np.full((F, 2, 3), np.nan), ())

    def to_dict(self) -> dict[str, Any]:
        return {"lift": self.lift}

    @classmethod
    def from_dict(cls, d: Any) -> ToyCalibration:
        return cls(float(d["lift"]))


def test_a_rig_format_of_ones_own_is_calibrated_stored_and_delivered(monkeypatch):
    monkeypatch.setitem(RIG_KINDS, "toy", ("solver.rig_skeleton:SkeletonRig", f"{__name__}:ToyCalibration"))
    ch = reference("halfboy")
    T, fps = 12, 15.0
    q = 0.02 * np.random.default_rng(0).standard_normal((ch.n, T))
    walk = Motion(ch, fps, q, reference_name="halfboy", cyclic=True, interpolation="cubic-spline",
                  context=MotionContext(cycle=Cycle(0.1, 0.6)))
    F = 40
    rig = SkeletonRig("toy", ("root", "leg"), (-1, 0), np.array([[0.0, 0.0, 0.0], [0.0, -0.4, 0.0]]),
                      (("Xposition", "Yposition", "Zposition", "Zrotation"), ("Zrotation",)), {"pelvis": 0},
                      np.arange(F) / 30.0, np.tile(np.eye(3), (F, 2, 1, 1)), np.zeros((F, 3)))
    calibrated = rig.calibrated(walk)  # the format's calibration, fitted
    assert isinstance(calibrated.calibration, ToyCalibration) and calibrated.calibration.lift == 0.6
    assert calibrated.times[0] <= 0.1 and calibrated.times[-1] >= 0.7 and calibrated.times.size < F
    motion = walk.evolve(context=walk.context.with_(rig=calibrated))
    again = Motion.from_dict(json.loads(motion.to_json()))  # the file holds it as plain data
    assert isinstance(again.context.rig, SkeletonRig) and isinstance(again.context.rig.calibration, ToyCalibration)
    assert again.context.rig.to_dict() == motion.context.rig.to_dict()
    # what the rig exporters call: the rig's calibration, whatever its class
    pose = retarget(again, again.context.rig)
    assert np.all(pose.root[:, 2] == 0.6)
    src, placed = source_pose(again, ("toy",), "needs a toy rig", world="ground")
    assert src is again.context.rig and np.array_equal(placed.root, pose.root)
