"""The API's heavy work, in compute processes: never on the event loop, always bounded.

Parsing an upload, exporting a motion (JSON clip, glTF, BVH), its plausibility report (MuJoCo
replay) and its plots cost seconds of CPU for a large motion and hold the GIL in C code; in the
API process they would stall every other request (``/health`` included). They run in
:class:`Compute`: ``MOTIONX_COMPUTE_WORKERS`` supervised child processes
(:class:`service.procpool.ProcPool`), each request with a time limit
(``MOTIONX_COMPUTE_TIMEOUT_S``) and each process with a memory cap
(``MOTIONX_COMPUTE_MEMORY_MB``). Results are cached by content (a stored motion is immutable)
and identical concurrent requests share one computation. Each API key has its own lane
(:class:`Compute`): a key's requests cannot take every process, a key past its quota of
heavy requests in flight gets 429 with ``Retry-After``, the work of a client that went away is
cancelled, and a failure of an input is remembered.

The module-level functions below are what runs in the child: plain functions of bytes and
JSON-ready values (pickled to the child, results pickled back).
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import hashlib
import json
import logging
import zlib
from collections.abc import Callable, Hashable
from typing import Any

from cachetools import LRUCache, TTLCache
from fastapi import Request
from fastapi.concurrency import run_in_threadpool

from service.cache import BytesLRU
from service.config import Settings
from service.problems import ClientGone, Problem
from service.procpool import Abandoned, ProcPool, RemoteError, TaskTimeout, WorkerLost

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

#: how often a request waiting for a compute process checks whether its client is still there
DISCONNECT_POLL_S = 0.5


def busy(detail: str, quota: str, retry_after: int) -> Problem:
    """429 for the caller's key alone: ``quota`` names the limit (also in the body), ``Retry-After``
    says when to try again."""
    return Problem(429, detail, headers={"Retry-After": str(retry_after)}, type=QUOTA_TYPE, quota=quota)


QUOTA_TYPE = "https://motionx.dev/problems/quota"


def unavailable(detail: str, retry_after: int = 2) -> Problem:
    """503 with ``Retry-After``: an infrastructure fault (a compute process restarted, the database
    out of reach), not the request's."""
    return Problem(503, detail, headers={"Retry-After": str(retry_after)})


class Compute:
    """The API's compute processes: one lane per API key, a result cache, single flight, and a
    memory of failures (see the module doc).

    - **Lanes.** A key has at most ``compute_lane_running`` requests computed at once (one process
      fewer than the pool: another key always finds one free) and at most
      ``quota_heavy_requests`` in flight (computed or waiting): beyond, *that key* gets 429
      (quota ``heavy_requests``) while the others are served.
    - **Client gone.** A request whose client closed the connection stops waiting; its
      computation is cancelled when nobody else waits for it (dropped from the queue, or its
      process killed and replaced).
    - **Failures remembered.** A request refused for its input (422: past the time or memory
      limit, or refused by the computation) is answered the same way for ``failure_memo_s``
      without computing it again (key: the stored content, or the upload's bytes and options).
    """

    def __init__(self, settings: Settings) -> None:
        self.settings = settings
        self.cache = BytesLRU(settings.export_cache_bytes)
        self.failures: TTLCache[Hashable, tuple[int, str]] = TTLCache(maxsize=4096, ttl=settings.failure_memo_s)
        self._inflight: dict[Hashable, asyncio.Future] = {}
        self._waiters: collections.Counter[Hashable] = collections.Counter()
        self._held: collections.Counter[str] = collections.Counter()
        self.pool: ProcPool | None = None

    def start(self) -> None:
        s = self.settings
        if s.compute_workers > 0:
            self.pool = ProcPool("compute", s.compute_workers, memory_mb=s.compute_memory_mb,
                                 warm=COMPUTE_MODULES + s.check_module_names, lane_limit=s.lane_running).start()

    def close(self) -> None:
        pool, self.pool = self.pool, None
        if pool is not None:
            pool.close(timeout=2.0)

    def pids(self) -> list[int]:
        return self.pool.pids() if self.pool is not None else []

    def saturation(self) -> dict[str, Any]:
        """What /health reports: processes, requests running and waiting, keys with requests."""
        if self.pool is None:
            return {"processes": 0, "running": 0, "waiting": 0, "keys": len(self._held)}
        st = self.pool.stats()
        return {"processes": st["processes"], "running": st["running"], "waiting": st["waiting"],
                "keys": len(self._held)}

    @contextlib.contextmanager
    def _admit(self, owner: str):
        """Count one heavy request of ``owner`` in flight; 429 (for that key only) past its quota."""
        s = self.settings
        if self._held[owner] >= s.quota_heavy_requests:
            raise busy(f"quota heavy_requests: this API key already has {self._held[owner]} heavy requests "
                       f"(exports, uploads, reports, plots) in flight, the limit is {s.quota_heavy_requests}; "
                       "retry when one has been answered", "heavy_requests", 5)
        if self.pool is not None and self.pool.busy() >= s.compute_queue + s.compute_workers:
            raise busy("the server is busy with heavy requests of many keys; retry in a few seconds",
                       "server_heavy_requests", 5)
        self._held[owner] += 1
        try:
            yield
        finally:
            self._held[owner] -= 1
            if self._held[owner] <= 0:
                del self._held[owner]

    def _remembered(self, key: Hashable | None) -> None:
        if key is None:
            return
        hit = self.failures.get(key)
        if hit is not None:
            raise Problem(hit[0], hit[1] + " (a known failure: this input failed the same way before)")

    async def _compute(self, fn: Callable[..., Any], args: tuple, what: str, lane: str,
                       memo: Hashable | None) -> Any:
        """``fn(*args)`` in a compute process of ``lane``; refusals and limits become problem details
        (an input's failure remembered under ``memo``); cancelled with the task that awaits it."""
        s = self.settings
        try:
            if self.pool is None:  # MOTIONX_COMPUTE_WORKERS=0: in the API's threads (debugging only)
                return await run_in_threadpool(fn, *args)
            try:
                fut = self.pool.submit(fn, *args, timeout=s.compute_timeout_s, lane=lane)
            except RuntimeError:  # the pool is closing
                raise unavailable("the compute processes are restarting; retry in a few seconds") from None
            try:
                return await asyncio.wrap_future(fut)
            except asyncio.CancelledError:
                self.pool.cancel(fut)
                raise
        except WorkError as e:
            raise self._failed(memo, e.status, e.detail) from None
        except TaskTimeout:
            raise self._failed(memo, 422, f"{what} needs more than the limit of {s.compute_timeout_s:g} s of "
                               "computation: the input is too large") from None
        except MemoryError:
            raise self._failed(memo, 422, f"{what} needs more memory than the limit of {s.compute_memory_mb:g} "
                               "MB: the input is too large") from None
        except Abandoned:
            raise ClientGone() from None
        except (WorkerLost, RemoteError) as e:
            log.error("compute process failed on %s: %s", what, e)
            raise unavailable(f"the compute process working on {what} stopped and was restarted; retry") from None

    def _failed(self, memo: Hashable | None, status: int, detail: str) -> Problem:
        if memo is not None and status == 422:
            self.failures[memo] = (status, detail)
        return Problem(status, detail)

    async def _wait(self, fut: asyncio.Future, request: Request | None) -> Any:
        """``fut``'s result, or :class:`ClientGone` as soon as the request's client has gone."""
        while True:
            done, _ = await asyncio.wait({fut}, timeout=DISCONNECT_POLL_S)
            if done:
                return fut.result()
            if request is not None and await request.is_disconnected():
                raise ClientGone()

    async def run(self, fn: Callable[..., Any], *args: Any, owner: str, what: str = "the request",
                  request: Request | None = None, memo: Hashable | None = None) -> Any:
        """``fn(*args)`` in a compute process of ``owner``'s lane (``memo``: remember a failure)."""
        self._remembered(memo)
        with self._admit(owner):
            task = asyncio.ensure_future(self._compute(fn, args, what, owner, memo))
            try:
                return await self._wait(task, request)
            finally:
                if not task.done():
                    task.cancel()

    async def cached(self, key: Hashable, fn: Callable[..., tuple[bytes, str]], *args: Any, owner: str,
                     what: str = "the request", request: Request | None = None) -> tuple[bytes, str]:
        """``fn(*args)`` -> (body, media type), cached by ``key``; concurrent callers share it."""
        hit = self.cache.get(key)
        if hit is not None:
            return hit
        body, media_type = await self.single(key, fn, *args, owner=owner, what=what, request=request)
        self.cache.put(key, body, media_type)
        return body, media_type

    async def single(self, key: Hashable, fn: Callable[..., Any], *args: Any, owner: str,
                     what: str = "the request", request: Request | None = None) -> Any:
        """``fn(*args)`` with concurrent callers of the same ``key`` sharing one computation, which
        is cancelled when the last of them has gone."""
        self._remembered(key)
        with self._admit(owner):
            fut = self._inflight.get(key)
            if fut is None:
                fut = self._start(key, fn, args, what, owner)
            self._waiters[key] += 1
            try:
                return await self._wait(fut, request)
            finally:
                self._waiters[key] -= 1
                if self._waiters[key] <= 0:
                    del self._waiters[key]
                    if not fut.done():  # nobody waits for it any more: cancelled, and not handed to anyone
                        if self._inflight.get(key) is fut:
                            del self._inflight[key]
                        fut.cancel()

    def _start(self, key: Hashable, fn: Callable[..., Any], args: tuple, what: str, lane: str) -> asyncio.Future:
        fut = asyncio.ensure_future(self._compute(fn, args, what, lane, key))
        self._inflight[key] = fut

        def done(f: asyncio.Future, k: Hashable = key) -> None:
            if self._inflight.get(k) is f:
                del self._inflight[k]
            if not f.cancelled():
                f.exception()  # retrieved: every waiter that is still there gets it too

        fut.add_done_callback(done)
        return fut
