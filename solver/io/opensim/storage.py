"""OpenSim tables: ``.mot`` / ``.sto`` (coordinates, forces) and ``.trc`` (marker trajectories)."""

from __future__ import annotations

import logging
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from solver.io.opensim.base import OpenSimError

log = logging.getLogger(__name__)


@dataclass(frozen=True, eq=False)
class Storage:
    """An OpenSim table: header key/values, column labels (without ``time``), data."""

    path: str
    header: Mapping[str, str]
    labels: tuple[str, ...]
    time: np.ndarray  # (T,)
    data: np.ndarray  # (T, C)
    in_degrees: bool | None = None  # from the header (None: not stated)
    header_text: str = ""

    def column(self, name: str) -> np.ndarray:
        try:
            return self.data[:, self.labels.index(name)]
        except ValueError:
            raise OpenSimError(f"{self.path}: no column {name!r}") from None


def read_mot(path: str | Path) -> Storage:
    """Read an OpenSim .mot/.sto file (header ended by ``endheader``; tab or space separated)."""
    p = Path(path)
    if not p.is_file():
        raise OpenSimError(f"file not found: {p}")
    lines = p.read_text(errors="replace").splitlines()
    try:
        end = next(i for i, ln in enumerate(lines) if ln.strip().lower() == "endheader")
    except StopIteration:
        raise OpenSimError(f"{p}: not an OpenSim .mot/.sto file (no 'endheader' line)") from None
    header: dict[str, str] = {}
    for ln in lines[:end]:
        if "=" in ln:
            k, v = ln.split("=", 1)
            header[k.strip()] = v.strip()
    body = [ln for ln in lines[end + 1:] if ln.strip()]
    if not body:
        raise OpenSimError(f"{p}: no column labels after 'endheader'")
    labels = body[0].split("\t") if "\t" in body[0] else body[0].split()
    labels = [s.strip() for s in labels]
    while labels and labels[-1] == "":
        labels.pop()
    if not labels or labels[0].lower() != "time":
        raise OpenSimError(f"{p}: the first column must be 'time', got {labels[:1]}")
    if len(set(labels)) != len(labels):
        dup = sorted({x for x in labels if labels.count(x) > 1})
        raise OpenSimError(f"{p}: duplicate column labels {dup}")
    rows = []
    for i, ln in enumerate(body[1:]):
        parts = ln.split()
        if len(parts) != len(labels):
            raise OpenSimError(f"{p}: data row {i + 1} has {len(parts)} values, expected {len(labels)}")
        try:
            rows.append([float(x) for x in parts])
        except ValueError:
            raise OpenSimError(f"{p}: data row {i + 1} is not numeric: {ln[:80]!r}") from None
    if not rows:
        raise OpenSimError(f"{p}: no data rows")
    arr = np.array(rows)
    bad = ~np.isfinite(arr)
    if np.any(bad):
        r, c = np.argwhere(bad)[0]
        nrows = int(np.any(bad, axis=1).sum())
        raise OpenSimError(f"{p}: {nrows} row(s) contain NaN/inf values (first: row {r + 1}, column {labels[c]!r})")
    t = arr[:, 0]
    if len(t) > 1 and not np.all(np.diff(t) > 0):
        i = int(np.argmax(np.diff(t) <= 0))
        raise OpenSimError(f"{p}: time must increase strictly (row {i + 2}: {t[i + 1]} after {t[i]})")
    if "nRows" in header and header["nRows"].isdigit() and int(header["nRows"]) != len(t):
        log.info("%s: header says nRows=%s but the file has %d rows (using the rows)", p, header["nRows"], len(t))
    deg = header.get("inDegrees")
    in_deg = None if deg is None else deg.strip().lower() in ("yes", "true", "1")
    return Storage(str(p), header, tuple(labels[1:]), t, arr[:, 1:], in_deg, "\n".join(lines[:end]))

