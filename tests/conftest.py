import os
from pathlib import Path

import pytest

def _find_data() -> Path:
    if os.environ.get("MOTIONX_DATA"):
        return Path(os.environ["MOTIONX_DATA"])
    for cand in (Path(__file__).resolve().parents[2] / "shared" / "data", Path("/work/shared/data")):
        if cand.is_dir():
            return cand
    return Path(__file__).resolve().parents[2] / "shared" / "data"


SHARED_DATA = _find_data()


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.fail(f"shared walking data not found at {SHARED_DATA} (set MOTIONX_DATA)")
    return SHARED_DATA
