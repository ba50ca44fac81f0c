"""The API's heavy work, in compute processes: never on the event loop, always bounded.

Parsing an upload, exporting a motion (JSON clip, glTF, BVH), its plausibility report (MuJoCo
replay) and its plots cost seconds of CPU for a large motion and hold the GIL in C code; in the
API process they would stall every other request (``/health`` included). They run in
:class:`Compute`: ``MOTIONX_COMPUTE_WORKERS`` supervised child processes
(:class:`service.procpool.ProcPool`), each request with a time limit
(``MOTIONX_COMPUTE_TIMEOUT_S``) and each process with a memory cap
(``MOTIONX_COMPUTE_MEMORY_MB``). Results are cached by content (a stored motion is immutable)
and identical concurrent requests share one computation. When the queue is longer than
``MOTIONX_COMPUTE_QUEUE``, a request gets 429 with ``Retry-After``.

The module-level functions below are what runs in the child: plain functions of bytes and
JSON-ready values (pickled to the child, results pickled back).
"""

from __future__ import annotations

import asyncio
import hashlib
import json
import logging
import zlib
from collections.abc import Callable, Hashable
from typing import Any

from cachetools import LRUCache
from fastapi.concurrency import run_in_threadpool

from service.cache import BytesLRU
from service.config import Settings
from service.problems import Problem
from service.procpool import ProcPool, RemoteError, TaskTimeout, WorkerLost

log = logging.getLogger(__name__)

#: imported by each compute process before it takes work (and before its memory cap)
COMPUTE_MODULES = ("numpy", "mujoco", "solver.motion", "solver.export", "mjcf.validate", "service.uploads",
                   "service.plots")


class WorkError(Exception):
    """A refusal decided in the compute process: an HTTP status and a message."""

    def __init__(self, status: int, detail: str) -> None:
        super().__init__(status, detail)
        self.status, self.detail = status, detail


# --- in the compute process ---------------------------------------------------------------

#: the last few stored motions a compute process loaded (it runs one task at a time: no lock)
_MOTIONS: LRUCache[bytes, Any] = LRUCache(maxsize=4)


def _load(data: bytes):
    """A stored motion (zlib-compressed motion file v2); the last few are kept per process."""
    # lazy: runs in a compute process; the API process does not load the solver
    from solver.motion import motion_from_dict

    key = hashlib.sha256(data).digest()
    m = _MOTIONS.get(key)
    if m is None:
        m = _MOTIONS[key] = motion_from_dict(json.loads(zlib.decompress(data)))
    return m


def export(data: bytes, fmt: str, options: dict[str, Any]) -> tuple[bytes, str]:
    try:
        # lazy: runs in a compute process; the API process does not load the solver
        from solver.export import ExportError, export_motion, media_type
    except ImportError as e:
        raise WorkError(501, f"exporters are not available in this build ({e})") from None
    motion = _load(data)
    try:
        out = export_motion(motion, fmt, **options)
        mt = media_type(fmt, **options)
    except ImportError as e:
        raise WorkError(501, f"format {fmt!r} is not available in this build ({e})") from None
    except ExportError as e:
        raise WorkError(422, str(e)[:1000]) from None
    return (out.encode("utf-8") if isinstance(out, str) else out), mt


def library_glb(items: list[tuple[str, bytes]], extras: dict, rig: str = "character",
                world: str = "gravity") -> tuple[bytes, str]:
    """One GLB of a library: (animation name, stored motion) per cell (solver.export.gltf), on the
    motions' own character or (``rig="source"``) on the input's (solver.export.rig_gltf), in
    ``world`` (solver.export.world) with each cell's ground."""
    from solver.export import ExportError  # lazy: runs in a compute process; the API process does not load the solver
    from solver.export.gltf import to_library_glb
    from solver.export.rig_gltf import rig_glb_library

    try:
        clips = [(k, _load(d)) for k, d in items]
        if rig == "source":
            return rig_glb_library(clips, world=world), "model/gltf-binary"
        return to_library_glb(clips, extras=extras, world=world), "model/gltf-binary"
    except ExportError as e:
        raise WorkError(422, str(e)[:1000]) from None


def validation(data: bytes) -> dict | None:
    try:
        from mjcf.validate import validate  # noqa: F401
    except ImportError as e:
        raise WorkError(501, f"the validator is not available in this build ({e})") from None
    # lazy: runs in a compute process; the API process does not load the solver
    from service.jobs import validation_report

    return validation_report(_load(data))


def simulation_check(data: bytes) -> str | None:
    """Why a stored motion cannot be simulated (service.simulation.cannot_simulate), or None."""
    from service.simulation import cannot_simulate  # lazy: runs in a compute process

    return cannot_simulate(_load(data))


def motion_plot(data: bytes, kind: str) -> bytes:
    # lazy: runs in a compute process; the API process does not load the solver
    from service.plots import MOTION_PLOTS, PlotError

    render = MOTION_PLOTS[kind]
    try:
        return render(_load(data))
    except PlotError as e:
        raise WorkError(422, str(e)[:1000]) from None
    except ImportError as e:
        raise WorkError(501, f"{kind} plot not available in this build ({e})") from None


def progress_plot(points: list[dict], target: dict) -> bytes:
    # lazy: runs in a compute process; the API process does not load the solver
    from service.plots import PlotError, progress_png

    try:
        return progress_png(points, target)
    except PlotError as e:
        raise WorkError(422, str(e)[:1000]) from None


# --- in the API process -------------------------------------------------------------------


class Compute:
    """The API's compute processes, a result cache and single flight (see the module doc)."""

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.cache = BytesLRU(settings.export_cache_bytes)
        self._inflight: dict[Hashable, asyncio.Future] = {}
        self.pool: ProcPool | None = None

    def start(self) -> None:
        s = self.settings
        if s.compute_workers > 0:
            self.pool = ProcPool("compute", s.compute_workers, memory_mb=s.compute_memory_mb,
                                 warm=COMPUTE_MODULES).start()

    def close(self) -> None:
        pool, self.pool = self.pool, None
        if pool is not None:
            pool.close(timeout=2.0)

    def pids(self) -> list[int]:
        return self.pool.pids() if self.pool is not None else []

    async def run(self, fn: Callable[..., Any], *args: Any, what: str = "the request") -> Any:
        """``fn(*args)`` in a compute process; refusals and limits become problem details."""
        s = self.settings
        try:
            if self.pool is None:  # MOTIONX_COMPUTE_WORKERS=0: in the API's threads (debugging only)
                return await run_in_threadpool(fn, *args)
            if self.pool.busy() >= s.compute_queue + s.compute_workers:
                raise Problem(429, "the server is busy with other heavy requests (exports, uploads, reports); "
                              "retry in a few seconds", headers={"Retry-After": "5"})
            return await asyncio.wrap_future(self.pool.submit(fn, *args, timeout=s.compute_timeout_s))
        except WorkError as e:
            raise Problem(e.status, e.detail) from None
        except TaskTimeout:
            raise Problem(422, f"{what} needs more than the limit of {s.compute_timeout_s:g} s of computation: "
                          "the input is too large") from None
        except MemoryError:
            raise Problem(422, f"{what} needs more memory than the limit of {s.compute_memory_mb:g} MB: "
                          "the input is too large") from None
        except (WorkerLost, RemoteError) as e:
            log.error("compute process failed on %s: %s", what, e)
            raise Problem(500, "internal error (logged on the server)") from None

    async def cached(self, key: Hashable, fn: Callable[..., tuple[bytes, str]], *args: Any,
                     what: str = "the request") -> tuple[bytes, str]:
        """``fn(*args)`` -> (body, media type), cached by ``key``; concurrent callers share it."""
        hit = self.cache.get(key)
        if hit is not None:
            return hit
        fut = self._inflight.get(key)
        if fut is None:
            fut = self._start(key, fn, args, what)
        body, media_type = await asyncio.shield(fut)
        self.cache.put(key, body, media_type)
        return body, media_type

    async def single(self, key: Hashable, fn: Callable[..., Any], *args: Any, what: str = "the request") -> Any:
        """``fn(*args)`` with concurrent callers of the same ``key`` sharing one computation."""
        fut = self._inflight.get(key)
        if fut is None:
            fut = self._start(key, fn, args, what)
        return await asyncio.shield(fut)

    def _start(self, key: Hashable, fn: Callable[..., Any], args: tuple, what: str) -> asyncio.Future:
        fut = asyncio.ensure_future(self.run(fn, *args, what=what))
        self._inflight[key] = fut

        def done(f: asyncio.Future, k: Hashable = key) -> None:
            self._inflight.pop(k, None)
            if not f.cancelled():
                f.exception()  # retrieved: every waiter that is still there gets it too

        fut.add_done_callback(done)
        return fut
