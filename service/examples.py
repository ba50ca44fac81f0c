"""Where the real walking trials shipped with the repository live (``data/``).

The trials (origin and license notices in ``data/README.md`` and each folder's README) are
part of the repository, so the demo, the tests and the benchmarks run on a fresh clone with
nothing beside it. ``MOTIONX_DATA`` points elsewhere (e.g. a held-out set laid out the same way).
"""

from __future__ import annotations

import os
from pathlib import Path

REPO_DATA = Path(__file__).resolve().parents[1] / "data"


def data_dir() -> Path:
    """The trials folder: ``$MOTIONX_DATA`` when set, else the repository's ``data/``."""
    env = os.environ.get("MOTIONX_DATA")
    return Path(env) if env else REPO_DATA
