"""What the command line writes, named one way for ``motionx extrapolate`` and ``motionx demo``.

Every λ optimum of a job is ``step_NNN_lambda_L.<kind>``: ``NNN`` the accepted step (000 is
λ = 0, the base problem), ``L`` its λ with four decimals, ``<kind>`` one of
``motion.json`` (motion file v2), ``clip.json`` (JSON clip), ``glb``, ``bvh`` and
``validation.json`` (plausibility report). Beside them: ``progress.csv``/``progress.png``
(the progress curve), ``summary.json``, and the final motion's plots.
"""

from __future__ import annotations

from pathlib import Path

from service.cli import CliError

#: the suffixes of one λ optimum's files (motion file, exports, plausibility report)
STEP_KINDS = ("motion.json", "clip.json", "glb", "bvh", "validation.json")
#: ... and of its exports on the input's own rig (``motionx demo``'s full-body job)
SOURCE_RIG_KINDS = ("rig.glb", "rig.bvh", "deepmimic.txt")
#: files a job folder holds besides the steps (extrapolate's plots are grf/residuals.png,
#: the demo's final.grf/final.residuals/final.filmstrip.png, tutor.motion.json and job.json)
JOB_FILES = ("progress.csv", "progress.png", "summary.json", "grf.png", "residuals.png", "final.grf.png",
             "final.residuals.png", "final.filmstrip.png", "tutor.motion.json", "job.json")


def written_here(folder: Path) -> list[Path]:
    """The files in ``folder`` that a job's output consists of (and nothing else)."""
    found: set[Path] = set()
    for kind in STEP_KINDS + SOURCE_RIG_KINDS:
        found.update(folder.glob(f"step_[0-9][0-9][0-9]_lambda_*.{kind}"))
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
