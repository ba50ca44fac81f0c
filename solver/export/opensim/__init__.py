"""A motion written on an OpenSim model: coordinates, ground reactions, ExternalLoads, the
model, an inverse-dynamics setup, checked by OpenSim's own tools.

A motion made from an OpenSim trial is written on the trial's own model (its context's
``rig``, an :class:`~solver.io.opensim.rig.OpenSimRig`, holds the model and the trial); a
motion of another source, with ``model="generic"``, on OpenSim's gait2354 model scaled to its
character (:func:`generic_rig`). The folder holds:

* ``<model>.osim``: the model (a 3.x-era file whose sockets name bodies as ``../body`` gets
  those paths rewritten to ``/bodyset/body``, nothing else changed; its ``<gravity>`` set to
  the motion's when that differs);
* ``coordinates.mot``: the model's coordinates (degrees and metres, ``inDegrees=yes``, the
  header of OpenSim's InverseKinematicsTool), ``CYCLES`` repetitions of the gait cycle sampled
  at ``RATE_HZ`` from the motion's own interpolation (the optimizer's C² spline);
* ``grf.mot``: per foot ``ground_force_{r,l}_v{x,y,z}`` (N), ``ground_force_{r,l}_p{x,y,z}``
  (centre of pressure on the floor, m) and ``ground_torque_{r,l}_{x,y,z}`` (the free moment
  about the floor's normal), in the model's ground frame (x forward, y up, z right);
* ``external_loads.xml``: the two forces applied to the model's feet (``calcn_r``, ``calcn_l``),
  force and point expressed in ground;
* ``setup_id.xml``: OpenSim's InverseDynamicsTool on these files over the middle cycle (the
  outer ones keep a filter's edges away from it), muscles excluded, the coordinates not
  filtered by default (``LOWPASS_HZ``: they sample a smooth motion; ``lowpass=6.0`` writes
  OpenSim's examples' 6 Hz);
* ``summary.json`` and ``README.md``: what was written, how, and the residuals OpenSim's
  InverseDynamicsTool reports on exactly these files.

**Coordinates.** The motion drives our segments; the model has its own bodies. At each
captured frame of the cycle the importer's OpenSim evaluation gives every body's pose, and the
capture skeleton's fit gives our segments' poses: the rigid map between a body and its
*anchor* segment (the segment it belongs to when the motion's character has it) is the
*calibration*, a smooth periodic function of the gait phase
(:class:`~solver.export.opensim.calibration.OpenSimCalibration`, the OpenSim rig's
:class:`~solver.retargeting.Calibration`: ``rig.calibrated(motion)`` fits it, its ``pose`` places
the bodies). It holds what our character does not model (subtalar, knee translations, toes…) as
the trial had it at that phase. A motion
time ``t`` is at phase ``φ = t / D`` (``D`` the motion's cycle) and so at capture time
``t_start + φ · period`` (the motion's ``context.cycle``): each body is placed at the motion's
anchor pose composed with the calibration there. Bodies whose segment the character merged
(the torso and arms of a HalfBoy, lumped into its pelvis) stay rigid on it, in the model's own
posture at the cycle's mean coordinates; a torso shared by our abdomen, thorax and head
follows their mass-weighted mean pose. Four body-fixed virtual markers per body (its centre of
mass and 10 cm along each axis) follow those poses; OpenSim's InverseKinematicsTool fits the
model to them (``.trc`` and a copy of the model carrying the markers in a scratch folder, not
in the export) and Gauss–Newton iterations finish its fit
(:func:`~solver.export.opensim.child._refine`).

**Ground reactions.** The motion's wrenches, linear between the frames and midpoints where the
optimizer's equations hold (frames 1…T−2; frame T−2 and the midpoint after it stand for frame
0 and the midpoint of [0, 1], whose stored wrench is not constrained), are carried to the
model's ground frame (:func:`~solver.export.opensim.sampling.export_frame`: a slope's tilted
gravity turned down, a treadmill trial's belt velocity included) and written as force, centre
of pressure on the floor plane and free moment: the same wrench exactly (a foot loaded below
1 % of the body weight keeps its last centre of pressure and takes the remainder as torque).

**Residual reduction** (``reduce_residuals=True``, the default). The model is not our
character: its joints differ (knee translations, oblique ankle axes), the merged bodies are
where the character held them only on average. OpenSim's InverseDynamicsTool is run on the
written files; its pelvis residuals ``r`` (generalised forces of the six ground-pelvis
coordinates) are the external wrench ``W`` the model still misses, ``r = G W`` where the
rows of ``G`` are the twists each pelvis coordinate imparts to the whole model (computed by
OpenSim at every row). That wrench is added to the feet in contact (in proportion to their
loads) and the ground-reaction file rewritten; the summary reports by how much the forces,
centres of pressure and free moments moved (and flags a large adjustment). Then the
InverseDynamicsTool is run again on the folder as written: those are the residuals reported.

OpenSim runs in a child process (CasADi and OpenSim cannot share one: see
:mod:`solver.io.opensim.worker`); :func:`~solver.export.opensim.child.child_main` is its entry
point.

The modules, by job: :mod:`~solver.export.opensim.base` (settings, file names, the error, what
a motion must carry), :mod:`~solver.export.opensim.sampling` (the motion over repeated cycles,
its world mapped to OpenSim ground), :mod:`~solver.export.opensim.calibration` (the model's
bodies on the motion, virtual markers), :mod:`~solver.export.opensim.ground` (ground
reactions, residual reduction on the feet), :mod:`~solver.export.opensim.files` (OpenSim's
text files), :mod:`~solver.export.opensim.child` (the child process and its jobs),
:mod:`~solver.export.opensim.residuals` (inverse-dynamics residuals),
:mod:`~solver.export.opensim.generic` (the generic model) and
:mod:`~solver.export.opensim.folder` (the folder and its zip). This package re-exports the
names used elsewhere.
"""

from solver.export.opensim.base import OpenSimExportError, source_rig
from solver.export.opensim.calibration import PREVIEW_RATE, model_bodies, preview_times
from solver.export.opensim.folder import to_opensim, write_opensim
from solver.export.opensim.generic import generic_rig
from solver.export.opensim.ground import GRF_LABELS
from solver.export.opensim.residuals import capture_residuals, opensim_residuals

__all__ = ["GRF_LABELS", "PREVIEW_RATE", "OpenSimExportError", "capture_residuals", "generic_rig", "model_bodies",
           "opensim_residuals", "preview_times", "source_rig", "to_opensim", "write_opensim"]
