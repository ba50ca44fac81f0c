"""The tutors many test files share, made once per run of the suite.

The DeepMimic walk's HalfBoy tutor is what a dozen test files start from. Rather than a spacetime
solve per file, the first process that needs it makes it with ``solver.pipeline.make_tutor`` and
keeps it on disk, and the others (pytest-xdist workers included: a file lock makes them wait for
the maker) read it back. The key is the solver's
source, the trial's bytes and the call, so a change to the solver or the data makes it again;
``tests/test_spacetime.py`` and the pipeline's own tests still call ``make_tutor`` directly.
"""

from __future__ import annotations

import fcntl
import hashlib
import os
import pickle
from pathlib import Path

import casadi
import numpy as np

from solver.io import load_trial
from solver.pipeline import TutorResult, capture_motion, make_tutor

ROOT = Path(__file__).resolve().parents[1]
CACHE = Path(os.environ.get("MOTIONX_TEST_TUTORS", ROOT / ".pytest_cache" / "motionx-tutors"))
DEEPMIMIC = ("deepmimic_humanoid3d_walk/humanoid3d_walk.txt", "deepmimic_humanoid3d_walk/humanoid3d_character.txt")


def _solver_source() -> bytes:
    h = hashlib.sha256()
    for p in sorted((ROOT / "solver").rglob("*")):
        if p.is_file() and p.suffix in (".py", ".json"):
            h.update(str(p.relative_to(ROOT)).encode())
            h.update(p.read_bytes())
    return h.digest()


def tutor(data: Path, files: tuple[str, ...] = DEEPMIMIC, *, as_motion: bool = False, character: str = "halfboy",
          fps: float = 15.0) -> TutorResult:
    """``make_tutor`` of the trial ``files`` (under ``data``), as a ``Capture`` or, with
    ``as_motion``, as its capture motion (``capture_motion``); made once per run (see the module)."""
    paths = [data / f for f in files]
    h = hashlib.sha256(_solver_source())
    for p in paths:
        h.update(p.read_bytes())
    h.update(repr((files, as_motion, character, float(fps), np.__version__, casadi.__version__)).encode())
    key = h.hexdigest()[:32]
    CACHE.mkdir(parents=True, exist_ok=True)
    path = CACHE / f"{key}.pkl"
    with open(CACHE / f"{key}.lock", "w") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)  # one maker; the others wait and read
        if path.exists():
            return pickle.loads(path.read_bytes())
        cap = load_trial(paths)
        res = make_tutor(capture_motion(cap) if as_motion else cap, character=character, fps=fps)
        if res.status == "succeeded":
            tmp = path.with_suffix(".tmp")
            tmp.write_bytes(pickle.dumps(res))
            tmp.replace(path)
        return res
