import os
from pathlib import Path

import pytest

SHARED_DATA = Path(os.environ.get("MOTIONX_DATA", Path(__file__).resolve().parents[2] / "shared" / "data"))


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.fail(f"shared walking data not found at {SHARED_DATA} (set MOTIONX_DATA)")
    return SHARED_DATA
