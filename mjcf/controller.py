"""What a controller of the forward simulation is (:class:`Controller`) and the default end of a run
(:class:`FallTermination`).

The run (``mjcf.rollout``) talks to its controller through these hooks only, in the manner of
dm_control's ``Task`` (``initialize_episode``, ``before_step``, ``after_step``,
``get_termination``), with the reference's clock as a hook of its own. Per simulation step s, with
``t_ref`` the reference's clock:

1. ``control(data, t_ref)`` every ``control_period`` steps: the actuator controls, held in
   ``data.ctrl`` until the next call;
2. ``measures(data)`` every 10 ms, before the step: the controller's own series for the report;
3. ``mujoco.mj_step``, then ``mujoco.mj_forward`` (the new state's kinematics and contacts);
4. ``after_step(data)``;
5. ``clock_rate(data, t_ref)``: ``t_ref`` advances by ``timestep × rate``;
6. ``termination(data, t_ref)``: a reason (text) ends the run as its fall, None goes on.

``initialize(data, t0)`` comes before the first step, with ``data`` at the start's state; the
preloaded start (``mjcf.rollout._start``) also calls ``initialize`` then ``control`` to probe the
first torques, so a controller's ``control`` right after ``initialize`` depends on the state only.

A controller is made by a :data:`ControllerFactory` from the motion, the compiled model, its
:class:`~mjcf.performable.ModelGeometry` and the :class:`~mjcf.reference.Reference`
(``mjcf.simulate.simulate(..., controller=factory)``); the default is ``mjcf.tracker.Tracker``.
:class:`ControllerBase` gives every hook but ``control`` its default, the fall as termination.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, Protocol

import mujoco
import numpy as np

from mjcf.performable import ModelGeometry
from mjcf.reference import ROOT_Z, Reference
from solver.motion import Motion

#: the pelvis has sunk (a fall) below this fraction of its height at the start (the reference's own
#: change of height since the start taken off: stairs)
PELVIS_SUNK = 0.6


class Controller(Protocol):
    """The hooks a run calls (module docstring for their order)."""

    #: control every this many simulation steps (the controls are held in between)
    control_period: int
    #: per motor (``ModelGeometry.motors``) the largest |control| the controller allows, for the
    #: report (``torque_limit_nm``); None: no limit of its own
    torque_limit: np.ndarray | None

    def initialize(self, data: mujoco.MjData, t0: float) -> None:
        """Start a run at reference time ``t0`` from the state in ``data`` (after ``mj_forward``):
        reset whatever the controller carries from step to step."""

    def control(self, data: mujoco.MjData, t_ref: float) -> np.ndarray:
        """The actuator controls (``model.nu``, actuator order) for the state in ``data`` at
        reference time ``t_ref``."""

    def clock_rate(self, data: mujoco.MjData, t_ref: float) -> float:
        """How fast the reference's clock runs over the next step (1: real time)."""

    def after_step(self, data: mujoco.MjData) -> None:
        """Called after each step, ``data`` at the new state (after ``mj_forward``)."""

    def termination(self, data: mujoco.MjData, t_ref: float) -> str | None:
        """Why the run ends at the state in ``data`` (the report's fall reason), or None."""

    def measures(self, data: mujoco.MjData) -> dict[str, Any]:
        """The controller's own series, sampled every 10 ms before the step (the run's
        ``series``, beside its own: foot forces, reference, coordinates, centre of mass)."""


#: makes a run's controller: (motion, model, geometry, reference) -> Controller
ControllerFactory = Callable[[Motion, mujoco.MjModel, ModelGeometry, Reference], Controller]


class FallTermination:
    """The default termination: a fall. Reasons, the first that holds: the state is not finite
    (the simulation diverged); a segment geom that only the ground touches
    (``ModelGeometry.fall_geoms``: not the feet) is in contact; the pelvis is below
    ``PELVIS_SUNK`` of its start height, the reference's change of root height since the start
    (stairs) taken off."""

    def __init__(self, model: mujoco.MjModel, geometry: ModelGeometry, reference: Reference) -> None:
        self.model, self.geometry, self.ref = model, geometry, reference
        self.pelvis_h0 = float("nan")
        self.root_z0 = 0.0

    def start(self, data: mujoco.MjData, t0: float) -> None:
        """The heights the run starts from (pelvis, the reference's root)."""
        self.pelvis_h0 = float(data.xpos[self.geometry.pelvis][2])
        self.root_z0 = float(self.ref.state(t0)[0][ROOT_Z])

    def __call__(self, data: mujoco.MjData, t_ref: float) -> str | None:
        if not np.all(np.isfinite(data.qpos)):
            return "the simulation diverged"
        fall = self.geometry.fall_geoms
        for i in range(data.ncon):
            c = data.contact[i]
            if c.geom1 in fall or c.geom2 in fall:
                gb = c.geom1 if c.geom1 in fall else c.geom2
                return f"{mujoco.mj_id2name(self.model, mujoco.mjtObj.mjOBJ_GEOM, gb)} touches the ground"
        ph = float(data.xpos[self.geometry.pelvis][2]) - float(self.ref.state(t_ref)[0][ROOT_Z] - self.root_z0)
        if ph < PELVIS_SUNK * self.pelvis_h0:
            return f"pelvis height {ph:.3f} m (start {self.pelvis_h0:.3f} m)"
        return None


class ControllerBase:
    """Every hook of :class:`Controller` but ``control``, at its default: control every step, no
    torque limit, the reference's clock at real time, nothing after a step, the fall
    (:class:`FallTermination`) as termination, nothing measured. A subclass that overrides
    ``initialize`` calls this one's (it starts the fall detection)."""

    control_period: int = 1
    torque_limit: np.ndarray | None = None

    def __init__(self, model: mujoco.MjModel, geometry: ModelGeometry, reference: Reference) -> None:
        self.fall = FallTermination(model, geometry, reference)

    def initialize(self, data: mujoco.MjData, t0: float) -> None:
        self.fall.start(data, t0)

    def control(self, data: mujoco.MjData, t_ref: float) -> np.ndarray:
        raise NotImplementedError

    def clock_rate(self, data: mujoco.MjData, t_ref: float) -> float:
        return 1.0

    def after_step(self, data: mujoco.MjData) -> None:
        return None

    def termination(self, data: mujoco.MjData, t_ref: float) -> str | None:
        return self.fall(data, t_ref)

    def measures(self, data: mujoco.MjData) -> dict[str, Any]:
        return {}
