"""[beyond] MUMPS on an optimized BLAS: IPOPT's linear solver without CasADi's generic kernels.

CasADi's wheels ship IPOPT and MUMPS linked to their own OpenBLAS
(``libcasadi-tp-openblas.so.0``), built for the ``CORE2`` target: SSE3 kernels on every CPU.
MUMPS spends most of its factorization time in dense BLAS (``dgemm_``, ``dtrsm_``) on the KKT
fronts (up to ~620 rows for the full body), so the kernel matters: with OpenBLAS's kernel for
the CPU it runs on (``scipy-openblas32``, the SciPy project's build, kernel chosen at run
time) an IPOPT iteration costs 22–43 % less on a spacetime problem (measured in
docs/spacetime.md, "Optimized BLAS").

How: a tiny library whose soname is CasADi's OpenBLAS' and whose every BLAS/LAPACK entry point
the CasADi libraries import jumps to the same routine of ``scipy-openblas32`` (its symbols carry
a ``scipy_`` prefix; 32-bit integers, like CasADi's). Loaded before CasADi loads its IPOPT
plugin, it satisfies MUMPS' and IPOPT's dependency on that soname, so the dynamic loader binds
them to it (``tests/test_blas.py`` checks the binding). It is built once with the C compiler
into the compiled-derivatives cache, under a hash of both libraries' versions.

Off unless ``enable(cache_dir)`` is called (the service's jobs and the CLI do, from
``Settings.optimized_blas``). It must run before the process' first IPOPT solve; later, MUMPS
is already bound and it leaves things as they are. Any failure (no compiler, no ``nm``, the
package missing, a symbol missing) leaves CasADi's OpenBLAS in charge with a warning, never an
error. Results are the same optimum; iteration counts can differ by rounding, as they do between
CPUs (bench/machine.py).
"""

from __future__ import annotations

import ctypes
import hashlib
import logging
import os
import shutil
import subprocess
import threading
from pathlib import Path
from typing import Any

import casadi as ca

log = logging.getLogger(__name__)

SONAME = "libcasadi-tp-openblas.so.0"
PREFIX = "scipy_"
#: BLAS threads of the optimized library (workers run one job per core; two threads gained
#: ~5 % on the full body)
THREADS = 1

_state: dict[str, Any] = {"loaded": None, "tried": False}
_lock = threading.Lock()  # the in-process runner starts jobs on threads


def loaded() -> Path | None:
    """The shim library this process loaded, if any."""
    return _state["loaded"]


def enable(cache_dir: str | os.PathLike[str] | None, compiler: str | None = None) -> bool:
    """Bind MUMPS to the optimized BLAS in this process (once; ``None``: do nothing). Returns
    whether it is in use."""
    with _lock:
        if _state["loaded"] is not None:
            return True
        if cache_dir is None or _state["tried"]:
            return False
        _state["tried"] = True
        return _enable(Path(cache_dir).expanduser(), compiler)


def _enable(cache_dir: Path, compiler: str | None) -> bool:
    try:
        if _mumps_loaded():
            log.info("optimized BLAS not loaded: this process already runs IPOPT on CasADi's OpenBLAS")
            return False
        target = _target()
        cc = shutil.which(compiler or os.environ.get("CC") or "cc")
        if cc is None:
            raise RuntimeError("no C compiler")
        shim = _build(cache_dir, target, cc)
        ctypes.CDLL(str(shim))
        lib = ctypes.CDLL(str(target))
        lib[f"{PREFIX}openblas_set_num_threads"](ctypes.c_int(THREADS))
        _state["loaded"] = shim
        log.info("MUMPS runs on %s (%s kernels)", target.name, corename())
        return True
    except Exception as e:  # costs speed, never a result
        log.warning("optimized BLAS unavailable (%s): MUMPS keeps CasADi's OpenBLAS", e)
        return False


def corename(library: Path | None = None) -> str | None:
    """The kernel an OpenBLAS runs (None when it cannot be asked): the optimized one by default, or
    the OpenBLAS at ``library`` (unprefixed symbols, e.g. CasADi's own)."""
    try:
        if library is None:
            fn = ctypes.CDLL(str(_target()))[f"{PREFIX}openblas_get_corename"]
        else:
            fn = ctypes.CDLL(str(library)).openblas_get_corename
        fn.restype = ctypes.c_char_p
        return fn().decode()
    except Exception:
        return None


def _target() -> Path:
    import scipy_openblas32

    return Path(scipy_openblas32.get_lib_dir()) / f"lib{scipy_openblas32.get_library()}.so"


def _mumps_loaded() -> bool:
    """Whether this process has loaded CasADi's MUMPS (asked of the dynamic loader by soname)."""
    try:
        ctypes.CDLL("libcoinmumps.so.3", mode=os.RTLD_NOLOAD)
        return True
    except OSError:
        return False


def _key(target: Path) -> str:
    from importlib.metadata import version

    h = hashlib.sha256()
    for part in (version("casadi"), Path(ca.__file__).parent.as_posix(), version("scipy-openblas32"),
                 target.as_posix(), Path(__file__).read_text()):
        h.update(part.encode())
        h.update(b"\0")
    return h.hexdigest()[:24]


def _build(cache: Path, target: Path, cc: str) -> Path:
    shim = cache / f"blas-{_key(target)}.so"
    if shim.exists():
        return shim
    symbols = _symbols(target)
    cache.mkdir(parents=True, exist_ok=True)
    asm = [".text"]
    for s in symbols:  # a jump: any signature, arguments untouched
        asm += [f".globl {s}", f".type {s},@function", f"{s}: jmp {PREFIX}{s}@PLT"]
    asm.append('.section .note.GNU-stack,"",@progbits')
    src = shim.with_suffix(f".{os.getpid()}.s")
    tmp = shim.with_suffix(f".{os.getpid()}.tmp")
    src.write_text("\n".join(asm) + "\n")
    try:
        subprocess.run([cc, "-shared", "-o", str(tmp), str(src), f"-L{target.parent}",
                        f"-l:{target.name}", f"-Wl,-rpath,{target.parent}", f"-Wl,-soname,{SONAME}"],
                       check=True, capture_output=True, timeout=120)
        tmp.replace(shim)
    finally:
        src.unlink(missing_ok=True)
        tmp.unlink(missing_ok=True)
    return shim


def _symbols(target: Path) -> list[str]:
    """Every function CasADi's OpenBLAS exports that some CasADi library imports; each must exist
    in the optimized library (else the shim would leave a plugin unresolved: refuse)."""
    casadi_dir = Path(ca.__file__).parent
    nm = shutil.which("nm")
    if nm is None:
        raise RuntimeError("no nm (binutils)")

    def dynsyms(path: Path, flag: str, kinds: str | None = None) -> set[str]:
        out = subprocess.run([nm, "-D", flag, str(path)], check=True, capture_output=True, text=True).stdout
        rows = [line.split() for line in out.splitlines() if line.split()]
        return {r[-1] for r in rows if kinds is None or (len(r) >= 2 and r[-2] in kinds)}

    exported = dynsyms(casadi_dir / SONAME, "--defined-only", kinds="TWi")  # functions only
    imported: set[str] = set()
    for lib in casadi_dir.glob("*.so*"):
        if lib.is_file() and not lib.name.startswith("libcasadi-tp-openblas"):
            imported |= dynsyms(lib, "--undefined-only")
    wanted = sorted(exported & imported)
    if not wanted:
        raise RuntimeError("found no BLAS symbols imported by CasADi's libraries")
    optimized = ctypes.CDLL(str(target))
    missing = [s for s in wanted if not hasattr(optimized, PREFIX + s)]
    if missing:
        raise RuntimeError(f"{target.name} lacks {', '.join(missing[:5])}")
    return wanted
