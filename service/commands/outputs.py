"""What the command line writes, named one way for ``motionx extrapolate`` and ``motionx demo``.

Every λ optimum of a job is ``step_NNN_lambda_L.<kind>``: ``NNN`` the accepted step (000 is
λ = 0, the base problem), ``L`` its λ with four decimals, ``<kind>`` one of
``motion.json`` (motion file v1), ``clip.json`` (JSON clip), ``glb``, ``bvh`` and
``validation.json`` (plausibility report). Beside them: ``progress.csv``/``progress.png``
(the progress curve), ``summary.json``, and the final motion's plots.
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Iterable, Mapping
from pathlib import Path

from service.cli import CliError
from solver import axes as registry

#: the suffixes of one λ optimum's files (motion file, exports, plausibility report)
STEP_KINDS = ("motion.json", "clip.json", "glb", "bvh", "validation.json")
#: the environment columns of progress.csv
ENVIRONMENT_KEYS = registry.names()  # one column per homotopy axis (solver.axes)
PROGRESS_COLUMNS = ("phase", "wall_time_s", "lambda", *ENVIRONMENT_KEYS, "iterations", "accepted", "status",
                    "lambda_reached")
#: files a job folder holds besides the steps (extrapolate's plots are grf/residuals.png,
#: the demo's final.grf/final.residuals.png, tutor.motion.json and job.json)
JOB_FILES = ("progress.csv", "progress.png", "summary.json", "grf.png", "residuals.png", "final.grf.png",
             "final.residuals.png", "tutor.motion.json", "job.json")
#: step files of earlier versions (motion_003_lambda_1.0000.json, lambda_1.0000.motion.json)
LEGACY_STEP_GLOBS = ("motion_[0-9][0-9][0-9]_lambda_*.json", "lambda_[0-9].[0-9][0-9][0-9][0-9].*")


def step_stem(step: int, lam: float) -> str:
    """``step_003_lambda_1.0000``: the name of the λ optimum of accepted step ``step``."""
    return f"step_{int(step):03d}_lambda_{float(lam):.4f}"


def written_here(folder: Path) -> list[Path]:
    """The files in ``folder`` that a job's output consists of (and nothing else)."""
    found: set[Path] = set()
    for kind in STEP_KINDS:
        found.update(folder.glob(f"step_[0-9][0-9][0-9]_lambda_*.{kind}"))
    for pattern in LEGACY_STEP_GLOBS:
        found.update(folder.glob(pattern))
    found.update(folder / name for name in JOB_FILES if (folder / name).exists())
    return sorted(p for p in found if p.is_file())


def prepare_output_dir(out: Path, *, force: bool, flag: str = "--force") -> list[Path]:
    """Makes ``out`` ready for a job's files: created when missing; an existing non-empty
    folder is refused unless ``force``, which removes only the files a job writes (others
    stay). Returns the files removed."""
    if out.exists() and not out.is_dir():
        raise CliError(f"--out {out} exists and is not a directory")
    if out.is_dir() and any(out.iterdir()):
        if not force:
            raise CliError(f"--out {out} is not empty (an earlier run's files would mix with this run's); "
                           f"choose a new folder, or pass {flag} to replace the files this command writes there")
        removed = written_here(out)
        for p in removed:
            p.unlink()
        return removed
    try:
        out.mkdir(parents=True, exist_ok=True)
    except OSError as e:
        raise CliError(f"cannot create {out}: {e.strerror or e}") from None
    return []


def _num(v, fmt: str) -> str:
    if v is None:
        return "nan"
    v = float(v) + 0.0  # -0.0 -> 0.0
    return "nan" if not math.isfinite(v) else format(v, fmt)


def progress_csv(records: Iterable[Mapping]) -> str:
    """The progress curve as CSV, one row per solve (``PROGRESS_COLUMNS``). ``records`` are the
    API's job ``progress`` points or ``dataclasses.asdict(ProgressRecord)`` (phase
    "extrapolate" when absent); an environment value a record lacks is ``nan``."""
    buf = io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(PROGRESS_COLUMNS)
    for r in records:
        env = r.get("environment") or {}
        w.writerow([r.get("phase", "extrapolate"), _num(r["wall_time"], ".4f"), _num(r["lam"], ".6f"),
                    *[_num(env.get(k), ".6g") for k in ENVIRONMENT_KEYS], int(r.get("iterations") or 0),
                    int(bool(r["accepted"])), r.get("status") or "", _num(r["lam_reached"], ".6f")])
    return buf.getvalue()
