"""Importers: real mocap formats -> :class:`solver.capture.Capture`.

Public API::

    load_trial(paths, *, mass=None, belt_speed=None, lower_only=None, **options) -> Capture

looks the reader up in the registry (:data:`solver.formats.READERS`: suffixes, options, the
function sorting a trial's files by content and the load function; ``solver.io.readers``
does the lookup) and imports it then (the OpenSim one runs OpenSim in a child process):

=================================  ========================================================
files                              reader
=================================  ========================================================
``.osim`` + ``.mot``/``.sto``      :func:`solver.io.opensim.load_opensim`; a second ``.mot``
or ``.trc`` (+ GRF ``.mot``,       whose columns are forces is the GRF, an ``.xml`` the
ExternalLoads ``.xml``)            ExternalLoads (``belt_speed`` for treadmill trials); a
                                   ``.trc`` (markers) instead of coordinates: OpenSim's
                                   inverse kinematics with the model's marker set first
``.c3d``                           ``solver.io.c3d.load_c3d(path, mass=...)``
``.bvh``                           :func:`solver.io.bvh.load_bvh` (``mass`` required)
``.txt``/``.json`` (DeepMimic)     :func:`solver.io.deepmimic.load_deepmimic`: the motion
                                   (``"Frames"``) and the character (``"Skeleton"``) file
=================================  ========================================================

``options`` are passed to the reader (e.g. ``units="cm"`` for BVH, ``in_degrees=True`` for
OpenSim; an option of another reader is refused). Unknown or incomplete sets of files are
refused with a message saying what is expected.
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Any

from solver.capture import Capture
from solver.errors import InputError
from solver.formats import READERS as FORMAT_READERS
from solver.formats import reader_suffixes
from solver.io.readers import TrialError, load_files

__all__ = ["READERS", "InputError", "TrialError", "load_trial"]

#: reader name -> its files in words, from the registry (solver.formats.READERS: suffixes, options)
READERS = {r.name: r.files for r in FORMAT_READERS}


def load_trial(
    paths: Sequence[str | Path] | str | Path,
    *,
    mass: float | None = None,
    belt_speed: float | str | None = None,
    lower_only: bool | None = None,
    **options: Any,
) -> Capture:
    """Import a trial from its files, whatever the format (see the module doc)."""
    if isinstance(paths, (str, Path)):
        paths = [paths]
    ps = [Path(p) for p in paths]
    if not ps:
        raise TrialError("no files given")
    for p in ps:
        if p.is_dir():
            suffixes = reader_suffixes()
            found = sorted(q.name for q in p.iterdir() if q.is_file() and q.suffix.lower() in suffixes)
            held = (f"trial files there: {', '.join(found[:8])}{', …' if len(found) > 8 else ''}" if found else
                    f"it holds no {'/'.join(suffixes)} file")
            raise TrialError(f"{p} is a folder; give the trial's files, not their folder ({held})")
        if not p.is_file():
            raise TrialError(f"file not found: {p}")
    return load_files(ps, {"mass": mass, "belt_speed": belt_speed, "lower_only": lower_only, **options})
