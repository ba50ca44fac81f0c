"""Importers: real mocap formats -> :class:`solver.capture.Capture`.

Public API::

    load_trial(paths, *, mass=None, belt_speed=None, lower_only=None, **options) -> Capture

chooses the reader from the files given (readers are imported lazily: the OpenSim one
runs OpenSim in a child process, the C3D one belongs to ``solver.io.c3d``):

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
OpenSim). Unknown or incomplete sets of files are refused with a message saying what is
expected.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path
from typing import Any

from solver.capture import Capture
from solver.errors import InputError
from solver.formats import READERS as FORMAT_READERS

__all__ = ["READERS", "InputError", "TrialError", "load_trial"]

#: reader name -> its files in words, from the registry (solver.formats.READERS: suffixes, options)
READERS = {r.name: r.files for r in FORMAT_READERS}


class TrialError(InputError):
    """The files given do not form a trial any reader understands."""


def _is_grf_mot(path: Path) -> bool:
    from solver.io.opensim import read_mot  # lazy: the reader the files call for

    sto = read_mot(path)
    return any(lab.endswith(("force_vx", "_vx")) and "force" in lab for lab in sto.labels)


def _json_kind(path: Path) -> str | None:
    try:
        d = json.loads(path.read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError):
        return None
    if isinstance(d, dict) and "Frames" in d:
        return "motion"
    if isinstance(d, dict) and "Skeleton" in d:
        return "character"
    return None


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
        if not p.is_file():
            raise TrialError(f"file not found: {p}")
    by_ext: dict[str, list[Path]] = {}
    for p in ps:
        by_ext.setdefault(p.suffix.lower(), []).append(p)
    exts = set(by_ext)

    if ".osim" in exts:
        if len(by_ext[".osim"]) != 1:
            raise TrialError(f"one OpenSim model expected, got {by_ext['.osim']}")
        mots = by_ext.get(".mot", []) + by_ext.get(".sto", [])
        grfs = [m for m in mots if _is_grf_mot(m)]
        kin = [m for m in mots if m not in grfs] + by_ext.get(".trc", [])
        if len(kin) != 1:
            raise TrialError(f"an OpenSim trial needs exactly one coordinates .mot/.sto or one markers .trc next to "
                             f"the model; got {[str(k) for k in kin]} (GRF files: {[str(g) for g in grfs]})")
        if len(grfs) > 1:
            raise TrialError(f"at most one GRF .mot, got {[str(g) for g in grfs]}")
        xmls = by_ext.get(".xml", [])
        if len(xmls) > 1 or (xmls and not grfs):
            raise TrialError(f"an ExternalLoads .xml goes with one GRF .mot; got xml {xmls}, GRF {grfs}")
        other = exts - {".osim", ".mot", ".sto", ".trc", ".xml"}
        if other:
            raise TrialError(f"unexpected files with an OpenSim trial: {sorted(other)}")
        from solver.io.opensim import load_opensim  # lazy: the reader the files call for

        return load_opensim(by_ext[".osim"][0], kin[0], mass=mass, belt_speed=belt_speed,
                            grf=grfs[0] if grfs else None, grf_xml=xmls[0] if xmls else None,
                            lower_only=lower_only, **options)
    if belt_speed is not None:
        raise TrialError("belt_speed is supported for OpenSim trials only")
    if exts == {".c3d"}:
        if len(ps) != 1:
            raise TrialError(f"one .c3d file expected, got {len(ps)}")
        if lower_only is not None:
            options["lower_only"] = lower_only
        try:
            from solver.io.c3d import load_c3d  # lazy: the reader the files call for
        except ImportError as e:
            raise TrialError(f"the C3D reader is not available ({e})") from None
        return load_c3d(ps[0], mass=mass, **options)
    if exts == {".bvh"}:
        if len(ps) != 1:
            raise TrialError(f"one .bvh file expected, got {len(ps)}")
        from solver.io.bvh import load_bvh  # lazy: the reader the files call for

        return load_bvh(ps[0], mass=mass, lower_only=lower_only, **options)
    if exts <= {".txt", ".json"}:
        kinds = {p: _json_kind(p) for p in ps}
        motions = [p for p, k in kinds.items() if k == "motion"]
        chars = [p for p, k in kinds.items() if k == "character"]
        if len(motions) == 1 and len(chars) == 1 and len(ps) == 2:
            from solver.io.deepmimic import load_deepmimic  # lazy: the reader the files call for

            return load_deepmimic(motions[0], chars[0], mass=mass, lower_only=lower_only, **options)
        raise TrialError(
            "a DeepMimic trial is one motion file (JSON with 'Frames') and one character file (JSON with "
            f"'Skeleton'); got {[p.name + ': ' + (k or 'not DeepMimic JSON') for p, k in kinds.items()]}"
        )
    raise TrialError(f"unknown trial format for files {[p.name for p in ps]}; supported: "
                     + "; ".join(f"{k}: {v}" for k, v in READERS.items()))
