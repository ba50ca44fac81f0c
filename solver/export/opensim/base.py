"""The OpenSim export's settings and file names, its error, and what a motion must carry to be
written on an OpenSim model (:func:`exportable`, :func:`source_rig`)."""

from __future__ import annotations

from solver.export import ExportError
from solver.io.opensim.rig import OpenSimRig
from solver.motion import Motion

#: sampling rate of the written files (Hz)
RATE_HZ = 100.0
#: gait cycles written (the inverse-dynamics setup analyses the middle one)
CYCLES = 3
#: low-pass cut-off of the written coordinates in the inverse-dynamics setup (Hz; None: no filter).
#: They are samples of a smooth motion, not measurements: a filter would take away part of the
#: motion the ground reactions balance (the optimizer's spline has content up to half its frame rate)
LOWPASS_HZ: float | None = None
#: OpenSim's examples' cut-off for measured coordinates: the trial's own check, and the written
#: files' figures reported under it for information
CAPTURE_LOWPASS_HZ = 6.0

COORDINATES_FILE = "coordinates.mot"
GRF_FILE = "grf.mot"
EXTERNAL_LOADS_FILE = "external_loads.xml"
SETUP_FILE = "setup_id.xml"
ID_OUTPUT_FILE = "inverse_dynamics.sto"
SUMMARY_FILE = "summary.json"
README_FILE = "README.md"


class OpenSimExportError(ExportError):
    """A motion cannot be written on an OpenSim model; the message says why."""


def exportable(motion: Motion) -> Motion:
    """``motion`` if the OpenSim export can write it (ground reactions, a gait cycle, the captured
    cycle it stands for); refused otherwise."""
    if not isinstance(motion, Motion):
        raise OpenSimExportError(f"expected a solver.motion.Motion, got {type(motion).__name__}")
    if motion.wrenches is None:
        raise OpenSimExportError("the motion has no ground reactions (contact wrenches): the OpenSim export "
                                 "writes them as the model's external loads; export a tutor or a λ optimum, "
                                 "not a capture")
    if not motion.cyclic:
        raise OpenSimExportError("the OpenSim export writes gait cycles: this motion is not a cycle "
                                 "(motion.cyclic is false)")
    cycle = motion.context.cycle
    if cycle is None or cycle.t_start is None or cycle.period_s is None:
        raise OpenSimExportError("the motion does not record the captured gait cycle it stands for "
                                 "(its context's cycle, source.cycle in the motion file, with t_start and period_s)")
    return motion


def _cycle(motion: Motion) -> tuple[float, float]:
    """(t_start, period_s) of the captured cycle an :func:`exportable` motion stands for."""
    cycle = motion.context.cycle
    assert cycle is not None and cycle.t_start is not None and cycle.period_s is not None  # exportable
    return cycle.t_start, cycle.period_s


def source_rig(motion: Motion) -> OpenSimRig:
    """The OpenSim rig a motion carries (``motion.context.rig``), checked; refused otherwise."""
    exportable(motion)
    rig = motion.context.rig
    if not isinstance(rig, OpenSimRig):
        fmt = (motion.provenance.get("source") or {}).get("format")
        have = f"its source is {fmt!r}" if fmt else "it records no source"
        raise OpenSimExportError(
            f"the OpenSim export writes a motion on the OpenSim model of the trial it was made from; this motion "
            f"carries no OpenSim model ({have}; its rig is {'absent' if rig is None else repr(rig.format)})."
            " Make the tutor from an OpenSim trial (.osim + coordinates or markers), or pass model='generic' "
            "(motionx export --generic-model) to write it on the generic gait2354 model scaled to its character")
    return rig
