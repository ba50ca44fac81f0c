"""C3D trials: markers -> anatomical landmarks, force plates -> measured ground reactions.

``read_c3d(path)`` returns a :class:`~solver.io.track.SkeletonTrack` in OUR world frame
(Z up, X forward = walking direction, Y left, metres, ground at z = 0) with

* landmarks: joint centres and segment tips from the marker set (Plug-in-Gait and
  close relatives: Davis/Newington hip joint centres, PiG "chord" knee and ankle centres,
  or the mid-points of lateral/medial epicondyle and malleolus markers when present),
* segment orientations of the pelvis, thighs, shanks and feet,
* ``measured``: per foot force, centre of pressure and free moment from the force plates
  (C3D ``FORCE_PLATFORM`` types 1, 2, 3 and 4), box-averaged onto the marker times, with
  the ``valid`` mask of frames where every loaded foot stands on a plate,
* ``contacts`` (heel_r, toe_r, heel_l, toe_l) from the plates where the feet are on
  plates and from kinematics (calibrated on the plate contacts) elsewhere,
* ``frame``: the :class:`~solver.capture.GroundFrame` back to the file's lab frame and
  length unit; mass and height from the file (or the plates, or the caller).

``load_c3d(path)`` fits the capture character to the track (``solver.io.fit``).

Units are read from the file (``POINT:UNITS``, ``ANALOG:UNITS``, ``FORCE_PLATFORM``);
the vertical comes from the plate surfaces (or the markers), the forward direction
from the pelvis' travel. See ``docs/c3d.md``.

Package layout: ``reader`` (file access, units, gaps, subject parameters), ``plates``
(force platforms), ``markers`` (marker sets and roles), ``axes``, ``landmarks``, ``events``
(plates -> feet, gait events, contacts), ``trial`` (the reader functions).
"""

from solver.io.c3d.markers import MARKER_SETS, ROLES, detect_marker_set, parse_mapping
from solver.io.c3d.plates import PlateSignal, PlateSpec
from solver.io.c3d.reader import C3DError, SubjectParams, fill_gaps, length_unit
from solver.io.c3d.trial import C3DTrial, load_c3d, read_c3d, read_c3d_trial, trial_files

__all__ = ["MARKER_SETS", "ROLES", "C3DError", "C3DTrial", "PlateSignal", "PlateSpec", "SubjectParams",
           "detect_marker_set", "fill_gaps", "length_unit", "load_c3d", "parse_mapping", "read_c3d", "read_c3d_trial",
           "trial_files"]
