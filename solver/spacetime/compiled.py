"""[beyond] The NLP's derivative functions compiled to machine code, cached on disk.

CasADi evaluates the per-term Hessian and Jacobian blocks (``derivatives.py``) in its virtual
machine. Compiled by a C compiler (CasADi's code generator, ``cc -O0``) they give the same
values with fewer instructions per evaluation: the same IPOPT iterations, 1.3–1.6× faster
HalfBoy solves, 1.14–1.23× full-body ones (docs/spacetime.md, "Compiled derivatives").

The expressions hold the character's constants (segment lengths, masses, axes), so a library
is per character. It is cached in a directory under a hash of the character's functions and
the code that derives them, so each character is compiled once, by whichever process first
needs it, and reused by every later process (workers, the CLI). Compiling takes seconds to
minutes (HalfBoy ~14 s, the full body ~66–75 s on a 2-core machine), so a background thread
starts a detached compiler and loads its library when it appears: problems built before that
use the virtual machine; ``solver.pipeline.problem_for`` rebuilds a cached problem
once its character's compiled functions are ready. Off unless ``enable(cache_dir)`` is called
(the service and the CLI do it from their settings); without a C compiler it stays off with a
warning. Every library is checked against the virtual machine on a random input before use.
"""

from __future__ import annotations

import hashlib
import inspect
import logging
import os
import shutil
import subprocess
import threading
import time
from pathlib import Path
from typing import Any

import casadi as ca
import numpy as np

from solver.spacetime import derivatives as derivatives_module

log = logging.getLogger(__name__)

FLAGS = ("-O0",)  # -O1 evaluates ~5 % faster but compiles 4× longer (HalfBoy 61 s instead of 15 s)
COMPILE_TIMEOUT_S = 1800.0
#: the cache keeps the most recently used libraries within this size (HalfBoy ~5 MB, full body ~18 MB)
MAX_CACHE_BYTES = 2 * 1024**3
CHECK_RTOL = 1e-9

_state: dict[str, Any] = {"dir": None, "compiler": None, "missing": None}
_lock = threading.Lock()
_building: set[int] = set()


def enable(cache_dir: str | os.PathLike[str] | None, compiler: str | None = None) -> bool:
    """Compile derivative functions into ``cache_dir`` from now on (``None``: off). Returns
    whether compiling is available (a C compiler was found)."""
    if cache_dir is None:
        _state.update(dir=None, compiler=None)
        return False
    name = compiler or os.environ.get("CC") or "cc"
    cc = shutil.which(name)
    if cc is None:
        if _state.get("missing") != name:  # once per process (jobs call enable every time)
            log.warning("no C compiler (%s): the NLP derivatives stay in CasADi's virtual machine", name)
        _state.update(dir=None, compiler=None, missing=name)
        return False
    _state.update(dir=Path(cache_dir).expanduser(), compiler=cc)
    return True


def enabled() -> bool:
    return _state["dir"] is not None


def start(ff: Any, *, wait: bool = False) -> threading.Thread | None:
    """Give ``ff`` compiled derivative functions: at once when its library is in the cache,
    else compiled in a background thread (``wait``: join it). ``ff.derivatives`` is replaced
    by the compiled functions in one assignment."""
    cache, cc = _state["dir"], _state["compiler"]
    if cache is None or getattr(ff, "compiled", False):
        return None
    try:
        lib = cache / f"derivatives-{_key(ff)}.so"
        if lib.exists():
            os.utime(lib)  # recently used: pruned last
            _load(ff, lib)
            return None
    except Exception as e:  # a failed load costs speed, never a result
        log.warning("compiled NLP derivatives unavailable (%s): CasADi's virtual machine evaluates them", e)
        return None
    with _lock:
        if id(ff) in _building:
            return None
        _building.add(id(ff))
    th = threading.Thread(target=_build, args=(ff, lib, cc), name="motionx-compile", daemon=True)
    th.start()
    if wait:
        th.join()
    return th


def _key(ff: Any) -> str:
    """The library's name: the character's functions (their serialized expressions hold every
    constant), the code that derives them, CasADi's version and the compiler flags."""
    h = hashlib.sha256()
    for name, f in sorted(ff.functions().items()):
        h.update(name.encode())
        h.update(f.serialize().encode())
    for source in (inspect.getfile(type(ff)), inspect.getfile(derivatives_module)):  # frame.py, derivatives.py
        h.update(Path(source).read_bytes())
    h.update("\0".join([str(getattr(ca, "__version__", "")), *FLAGS]).encode())
    return h.hexdigest()[:24]


def _build(ff: Any, lib: Path, cc: str) -> None:
    """Generate the C source here, compile it in a detached process (it finishes even if this
    process ends first: the next process finds the library), load it when it appears."""
    try:
        failed, building = lib.with_suffix(".failed"), lib.with_suffix(".building")
        if failed.exists():
            raise RuntimeError(f"an earlier compile failed ({failed})")
        if _claim(building):
            cg = ca.CodeGenerator("motionx_derivatives.c")
            for f in _functions(ff.derivatives).values():
                cg.add(f)
            c_file = lib.with_suffix(f".{os.getpid()}.c")
            c_file.write_text(cg.dump())
            # the job's address-space cap (a soft limit) is for the job, not its compiler
            # (the full body's library takes gcc ~2.7 GB)
            script = ('ulimit -S -v unlimited 2>/dev/null; '
                      '"$CC" $FLAGS -fPIC -shared "$SRC" -o "$OUT.tmp" -lm 2>"$FAILED.tmp" '
                      '&& mv "$OUT.tmp" "$OUT" && rm -f "$FAILED.tmp" || mv "$FAILED.tmp" "$FAILED"; '
                      'rm -f "$SRC" "$OUT.tmp" "$BUILDING"')
            env = dict(os.environ, CC=cc, FLAGS=" ".join(FLAGS), SRC=str(c_file), OUT=str(lib),
                       FAILED=str(failed), BUILDING=str(building))
            subprocess.Popen(["sh", "-c", script], env=env, start_new_session=True, stdin=subprocess.DEVNULL,
                             stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        deadline = time.monotonic() + COMPILE_TIMEOUT_S
        while time.monotonic() < deadline:
            if lib.exists():
                _load(ff, lib)
                prune(lib.parent, keep=lib)
                return
            if failed.exists():
                raise RuntimeError(f"the compile failed ({failed})")
            time.sleep(0.5)
        raise TimeoutError(f"no library after {COMPILE_TIMEOUT_S:g} s")
    except Exception as e:  # a failed compile costs speed, never a result
        log.warning("compiled NLP derivatives unavailable (%s): CasADi's virtual machine evaluates them", e)
    finally:
        with _lock:
            _building.discard(id(ff))


def prune(cache: Path, keep: Path | None = None, max_bytes: int = MAX_CACHE_BYTES) -> list[Path]:
    """Delete the least recently used libraries beyond ``max_bytes`` (a process that has one
    loaded keeps its mapping). Returns the deleted paths."""
    libs = sorted(cache.glob("derivatives-*.so"), key=lambda p: (p == keep, p.stat().st_mtime), reverse=True)
    total, gone = 0, []
    for lib in libs:
        total += lib.stat().st_size
        if total > max_bytes and lib != keep:
            lib.unlink(missing_ok=True)
            gone.append(lib)
    return gone


def _claim(building: Path) -> bool:
    """This process compiles the library unless another one is doing it (a marker younger than
    the compile timeout)."""
    building.parent.mkdir(parents=True, exist_ok=True)
    for _ in range(2):
        try:
            os.close(os.open(building, os.O_CREAT | os.O_EXCL | os.O_WRONLY))
            return True
        except FileExistsError:
            try:
                if time.time() - building.stat().st_mtime < COMPILE_TIMEOUT_S:
                    return False
                building.unlink()  # left by a compile that died
            except FileNotFoundError:
                pass
    return False


def _functions(derivs: dict) -> dict[str, ca.Function]:
    """Every Hessian and Jacobian function of a character, by name."""
    return {f.name(): f for pair in derivs.values() for f in pair}


def _load(ff: Any, lib: Path) -> None:
    derivs = ff.derivatives
    fns = _functions(derivs)
    ext = {name: ca.external(name, str(lib)) for name in fns}
    for name, f in fns.items():
        _check(f, ext[name])
        ext[name].vm_instructions = f.n_instructions()  # type: ignore[attr-defined]  # derivatives.mapped
    ff.derivatives = {name: (ext[h.name()], ext[j.name()]) for name, (h, j) in derivs.items()}
    ff.compiled = True
    log.info("compiled NLP derivatives loaded from %s", lib)


def _check(vm: ca.Function, ext: ca.Function) -> None:
    """The compiled function gives the virtual machine's values on a random input."""
    rng = np.random.default_rng(0)
    args = [ca.DM(vm.sparsity_in(i), rng.uniform(0.1, 0.9, vm.sparsity_in(i).nnz())) for i in range(vm.n_in())]
    for a, b in zip(vm.call(args), ext.call(args), strict=True):
        x, y = np.asarray(ca.DM(a).nonzeros()), np.asarray(ca.DM(b).nonzeros())
        atol = CHECK_RTOL * (1 + np.abs(x).max(initial=0))
        if x.shape != y.shape or not np.allclose(x, y, rtol=CHECK_RTOL, atol=atol):
            raise RuntimeError(f"compiled {vm.name()} disagrees with the virtual machine")
