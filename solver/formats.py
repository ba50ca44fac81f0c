"""The registries of the file formats the solver reads and writes (standard library only, so
that front ends enumerate them without importing numpy or a reader).

- :data:`READERS`: the trial readers (``solver.io.load_trial`` looks a trial's files up here),
  each with its file suffixes, the options it takes beside the files, and where its two
  functions live: one that sorts a trial's files into the load function's arguments by their
  suffixes and content, and the load function itself (both imported when a trial calls for them);
- :data:`EXPORTERS`: the motion exporters (``solver.export.export_motion``), each with its
  function and media type; :data:`EXPORT_WORLDS`: the worlds they write in.

The command line, the upload route and the export route enumerate these (suffixes accepted,
``--format`` choices, the ``format`` query parameter, response media types): a new reader or
exporter is one entry here plus its module.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Any


@dataclass(frozen=True)
class Reader:
    name: str
    #: file suffix -> what a file with it is
    suffixes: MappingProxyType[str, str]
    #: the files of one trial, in words (error messages, help)
    files: str
    #: reader options beside the files -> their meaning (``load_trial(..., **options)``)
    options: MappingProxyType[str, str]
    #: the module holding the two functions below (imported when a trial calls for this reader)
    module: str
    #: files (list of Path) -> the load function's file arguments (name -> Path or None), from
    #: their suffixes and content; an ``solver.io.TrialError`` says what is wrong otherwise
    trial_files: str
    #: ``load(**files, **options) -> Capture``
    load: str
    #: a suffix that makes a set of files this reader's whatever the others (OpenSim's model);
    #: otherwise a reader takes the files whose suffixes are all its own
    claims: str | None = None


def _ro(d: dict[str, str]) -> MappingProxyType[str, str]:
    return MappingProxyType(d)


#: the length units a BVH file may be read in (``solver.io.bvh.UNIT_M`` and "auto")
BVH_UNITS = ("auto", "cm", "m", "mm", "in", "cmu")

_COMMON = {"mass": "the subject's mass (kg) when the files do not state it",
           "lower_only": "fit the lower body only (None: the whole body when the data allow)"}

_IN_PLACE = ("an in-place clip (no root motion): its walking speed (m/s), 'auto' (the stance foot's), 0 (not in "
             "place); default: detected")

READERS: tuple[Reader, ...] = (
    Reader("opensim", _ro({".osim": "OpenSim model", ".mot": "OpenSim motion", ".sto": "OpenSim storage",
                           ".trc": "marker trajectories", ".xml": "OpenSim ExternalLoads"}),
           ".osim + .mot/.sto coordinates or .trc markers (+ GRF .mot, ExternalLoads .xml)",
           _ro({**_COMMON, "belt_speed": "treadmill belt speed (m/s) or 'auto'",
                "in_degrees": "the coordinates file is in degrees (default: its header says)"}),
           "solver.io.opensim", "trial_files", "load_opensim", claims=".osim"),
    Reader("c3d", _ro({".c3d": "C3D"}), ".c3d",
           _ro({**_COMMON, "markers": "marker label mapping (role -> label)"}),
           "solver.io.c3d", "trial_files", "load_c3d"),
    Reader("bvh", _ro({".bvh": "BVH"}), ".bvh",
           _ro({**_COMMON, "units": f"length unit of the file ({', '.join(BVH_UNITS)})",
                "up": "the file's up axis ('y' or 'z')",
                "belt_speed": _IN_PLACE,
                "joints": "joint role mapping (role -> joint name, e.g. hip_l=Thigh_L) for unrecognised names"}),
           "solver.io.bvh", "trial_files", "load_bvh"),
    Reader("deepmimic", _ro({".txt": "DeepMimic motion or character", ".json": "DeepMimic motion or character"}),
           "DeepMimic motion .txt/.json + character .txt/.json", _ro(dict(_COMMON)),
           "solver.io.deepmimic", "trial_files", "load_deepmimic"),
    Reader("gltf", _ro({".glb": "glTF 2.0 binary", ".gltf": "glTF 2.0 (buffers embedded)"}),
           "one skinned, animated .glb or .gltf character (buffers embedded)",
           _ro({**_COMMON,
                "joints": "joint role mapping (role -> joint name, e.g. hip_l=Thigh_L) for unrecognised names",
                "animation": "glTF: the animation to read, its name or index (default: the first)",
                "belt_speed": _IN_PLACE}),
           "solver.io.gltf", "trial_files", "load_gltf"),
)


def reader_options() -> dict[str, str]:
    """Every option some reader takes -> its meaning (first reader wins): what a front end
    offers beside a trial's files."""
    out: dict[str, str] = {}
    for r in READERS:
        for name, meaning in r.options.items():
            out.setdefault(name, meaning)
    return out


def reader_suffixes() -> dict[str, str]:
    """Every suffix a trial file may have -> what it is (first reader wins)."""
    out: dict[str, str] = {}
    for r in READERS:
        for suffix, kind in r.suffixes.items():
            out.setdefault(suffix, kind)
    return out


@dataclass(frozen=True)
class Exporter:
    name: str
    module: str
    function: str
    media_type: str
    description: str
    #: (option, value) -> the media type when that option changes the result's type
    media_by_option: MappingProxyType[tuple[str, Any], str] = field(default_factory=lambda: MappingProxyType({}))
    #: the result is a folder, as a zip archive (``export_motion(..., path=DIR)`` and the CLI write the folder)
    folder: bool = False


EXPORTERS: MappingProxyType[str, Exporter] = MappingProxyType({e.name: e for e in (
    Exporter("json", "solver.export.clip", "to_clip_json", "application/json",
             "the JSON clip (local transforms, contacts, ground reactions)"),
    Exporter("gltf", "solver.export.gltf", "to_gltf", "model/gltf-binary",
             "glTF 2.0, binary (.glb); binary=False: the .gltf JSON with its buffer embedded; rig=source: on the "
             "input's own glTF character, BVH or DeepMimic skeleton",
             MappingProxyType({("binary", False): "model/gltf+json"})),
    Exporter("glb", "solver.export.gltf", "to_glb", "model/gltf-binary",
             "binary glTF 2.0 (.glb); rig=source: on the input's own character or skeleton"),
    Exporter("bvh", "solver.export.bvh", "to_bvh", "text/plain",
             "BVH (Y up); rig=source: on the input BVH's own skeleton"),
    Exporter("deepmimic", "solver.export.deepmimic", "to_deepmimic", "application/json",
             "DeepMimic motion on the input DeepMimic character (rig=source)"),
    Exporter("opensim", "solver.export.opensim", "to_opensim", "application/zip",
             "the motion on its OpenSim trial's model: coordinates and GRF .mot, ExternalLoads, the model, an "
             "inverse-dynamics setup and its residuals (a folder; zipped over HTTP)", folder=True),
)})


#: the worlds a motion is exported in (``solver.export.world``; every exporter's ``world`` option):
#: name -> meaning, the default first
EXPORT_WORLDS: MappingProxyType[str, str] = MappingProxyType({
    "gravity": "the default: gravity points down, a slope walk climbs its ramp, stairs rise",
    "ground": "the solver's frame: level ground, a slope as tilted gravity",
})


def export_media_types() -> tuple[str, ...]:
    """Every media type an export may have, in registry order."""
    out: list[str] = []
    for e in EXPORTERS.values():
        for mt in (e.media_type, *e.media_by_option.values()):
            if mt not in out:
                out.append(mt)
    return tuple(out)
