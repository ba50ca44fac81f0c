"""Native code for the solver: compiled NLP derivatives and MUMPS on an optimized BLAS.

Both give the same optima faster (``solver.spacetime.compiled``: the derivative functions in
machine code, cached per character; ``solver.spacetime.blas``: IPOPT's linear solver on BLAS
kernels for this CPU). Both need a C compiler; without one they stay off with a warning.

On by default: ``make_tutor``, ``extrapolate`` and ``solve_library`` call :func:`ensure` before
they solve, which turns both on unless this process already chose with :func:`enable` (the
command line and the service do, from their settings). The environment variables the service's
settings read give the default here too: ``MOTIONX_COMPILED_DERIVATIVES=0`` or
``MOTIONX_OPTIMIZED_BLAS=0`` turn one off, ``MOTIONX_COMPILED_DIR`` moves the cache. The
optimized BLAS can only be bound before the process' first IPOPT solve.
"""

from __future__ import annotations

import os
import threading
from pathlib import Path

_state: dict[str, bool] = {"chosen": False}
_lock = threading.Lock()
_OFF = ("0", "false", "no", "off")


def default_cache_dir() -> Path:
    """``$XDG_CACHE_HOME/motionx/compiled`` (``~/.cache/motionx/compiled``): a cache, not state."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "motionx" / "compiled"


def enable(compiled: bool = True, blas: bool = True, cache_dir: str | os.PathLike[str] | None = None) -> dict:
    """Turn compiled derivatives and the optimized BLAS on (or off) in this process. Returns
    which are in use: ``{"compiled": bool, "blas": bool}``."""
    from solver.spacetime import blas as blas_module
    from solver.spacetime import compiled as compiled_module

    with _lock:
        _state["chosen"] = True
    where = Path(cache_dir) if cache_dir is not None else default_cache_dir()
    on_c = compiled_module.enable(where if compiled else None)
    on_b = blas_module.enable(where) if blas else blas_module.loaded() is not None
    return {"compiled": bool(on_c), "blas": bool(on_b)}


def ensure() -> None:
    """Native code as the environment says (on by default), unless this process already chose."""
    with _lock:
        if _state["chosen"]:
            return
    env = os.environ
    enable(compiled=env.get("MOTIONX_COMPILED_DERIVATIVES", "1").strip().lower() not in _OFF,
           blas=env.get("MOTIONX_OPTIMIZED_BLAS", "1").strip().lower() not in _OFF,
           cache_dir=env.get("MOTIONX_COMPILED_DIR") or None)
