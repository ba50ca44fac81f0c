import os
from pathlib import Path

import pytest

from service.config import Settings, enable_native_code
from service.examples import data_dir

# compiled derivatives (solver.spacetime.compiled) are tested on their own (tests/test_compiled.py);
# elsewhere a background compiler per character would only load the CI's two cores
os.environ.setdefault("MOTIONX_COMPILED_DERIVATIVES", "0")
# MUMPS on the optimized BLAS, as in jobs and the CLI (the product's default; CasADi's own OpenBLAS is
# tested in tests/test_blas.py's child processes): bound before this process first loads IPOPT
os.environ.setdefault("MOTIONX_OPTIMIZED_BLAS", "1")
# the services the tests start make HalfBoy tutors unless a request names the character (seconds, where the
# product's default full body takes a minute on two shared cores); tests/test_defaults.py checks the product's
os.environ.setdefault("MOTIONX_DEFAULT_CHARACTER", "halfboy")
enable_native_code(Settings())
SHARED_DATA = data_dir()  # the repository's data/ (or $MOTIONX_DATA)


#: public trials fetched from other labs (docs/c3d.md "Fit quality"): fetched material is not committed to
#: this repository (the tool library's rule), so they are read where ``$MOTIONX_OTHER_LABS_DATA`` says;
#: the tests that need them skip without it
OTHER_LABS = ("c3d_motion_analysis_helen_hayes", "c3d_opensim_walking5", "c3d_bts_davis")


def other_labs_dir() -> Path | None:
    """Where the other labs' trials are (``OTHER_LABS``), or None."""
    d = os.environ.get("MOTIONX_OTHER_LABS_DATA")
    return Path(d) if d and all((Path(d) / f).is_dir() for f in OTHER_LABS) else None


@pytest.fixture(scope="session")
def other_labs_data() -> Path:
    d = other_labs_dir()
    if d is None:
        pytest.skip("the other labs' C3D walks (c3d_motion_analysis_helen_hayes, c3d_opensim_walking5, c3d_bts_davis) "
                    "are not committed here: set $MOTIONX_OTHER_LABS_DATA to the folder that holds them")
    return d


@pytest.fixture(scope="session")
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.fail(f"walking data not found at {SHARED_DATA} (the repository's data/ folder, or $MOTIONX_DATA)")
    return SHARED_DATA


@pytest.fixture(scope="session")
def replay_rollout():
    """Replay a written simulation with MuJoCo's own API only: from ``qpos0``/``qvel0``, one
    ``mj_step`` per written ``ctrl``; returns the qpos after each step and the final time."""
    import mujoco
    import numpy as np

    def replay(model, rollout) -> tuple:
        d = mujoco.MjData(model)
        d.qpos[:] = rollout["qpos0"]
        d.qvel[:] = rollout["qvel0"]
        qpos = np.empty_like(rollout["qpos"])
        for k in range(len(rollout["time"])):
            d.ctrl[:] = rollout["ctrl"][k]
            mujoco.mj_step(model, d)
            qpos[k] = d.qpos
        return qpos, d.time

    return replay
