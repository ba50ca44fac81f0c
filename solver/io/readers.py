"""The trial readers' lookup: which registered reader (:data:`solver.formats.READERS`) a set of
files calls for, and the call.

A reader is chosen by the files' suffixes: one that *claims* a suffix present (OpenSim's
``.osim``) takes the set, otherwise the reader whose suffixes cover every file. Its
``trial_files`` function then sorts the files into its load function's arguments by suffix
and content (which ``.mot`` holds forces, which DeepMimic JSON is the character) or says
what is wrong; the options given are checked against what the load function takes.
"""

from __future__ import annotations

import importlib
import inspect
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from typing import Any

from solver.capture import Capture
from solver.errors import InputError
from solver.formats import READERS, Reader, reader_options


class TrialError(InputError):
    """The files given do not form a trial any reader understands."""


def one_file(paths: Sequence[Path], suffix: str) -> Path:
    """The single file of a one-file format (``.c3d``, ``.bvh``)."""
    if len(paths) != 1:
        raise TrialError(f"one {suffix} file expected, got {len(paths)}")
    return paths[0]


def by_suffix(paths: Sequence[Path]) -> dict[str, list[Path]]:
    """Files grouped by their lower-case suffix, in the order given."""
    out: dict[str, list[Path]] = {}
    for p in paths:
        out.setdefault(p.suffix.lower(), []).append(p)
    return out


def reader_for(paths: Sequence[Path]) -> Reader:
    """The registered reader for these files (a :class:`TrialError` listing the formats otherwise)."""
    exts = set(by_suffix(paths))
    for r in READERS:
        if r.claims is not None and r.claims in exts:
            other = exts - set(r.suffixes)
            if other:
                raise TrialError(f"unexpected files with a {r.name} trial: {sorted(other)}")
            return r
    for r in READERS:
        if r.claims is None and exts <= set(r.suffixes):
            return r
    if ".fbx" in exts:
        raise TrialError(f"{[p.name for p in paths if p.suffix.lower() == '.fbx']}: FBX is not read (no maintained "
                         "reader on PyPI); convert it to glTF 2.0 and give the .glb: Blender (File > Import > FBX, "
                         "then File > Export > glTF 2.0 with Animation on) or FBX2glTF (npx fbx2gltf --binary "
                         "FILE.fbx); docs/import.md")
    raise TrialError(f"unknown trial format for files {[p.name for p in paths]}; supported: "
                     + "; ".join(f"{r.name}: {r.files}" for r in READERS))


def _function(reader: Reader, name: str) -> Callable[..., Any]:
    try:
        module = importlib.import_module(reader.module)  # lazy: the reader the files call for
    except ImportError as e:
        raise TrialError(f"the {reader.name} reader is not available ({e})") from None
    return getattr(module, name)


def load_files(paths: Sequence[Path], options: Mapping[str, Any]) -> Capture:
    """Read a trial with the reader its files call for; ``options`` whose value is None are
    left to the reader's defaults, the others must be options the reader takes."""
    reader = reader_for(paths)
    files = _function(reader, reader.trial_files)(list(paths))
    load = _function(reader, reader.load)
    params = inspect.signature(load).parameters
    takes_any = any(p.kind is inspect.Parameter.VAR_KEYWORD for p in params.values())
    other_readers = reader_options()
    given = {k: v for k, v in options.items() if v is not None or k in params}
    foreign = [k for k in given if k in files or (k in other_readers and k not in reader.options)
               or (k not in params and not takes_any)]
    if foreign:
        where = {k: [r.name for r in READERS if k in r.options] for k in foreign}
        raise TrialError("; ".join(f"{k} is supported for {' and '.join(w)} trials only" if w else
                                   f"{k} is not an option of the {reader.name} reader" for k, w in where.items()))
    return load(**files, **given)
