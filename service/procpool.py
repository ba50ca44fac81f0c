"""Supervised worker processes, for everything heavy the API causes.

The LocalRunner's jobs and the API's heavy requests (parsing uploads, exports, validation,
plots) run in child processes of a :class:`ProcPool`, never on the API's event loop or in its
threads. Each *slot* is one child (``python -m service.procpool``) running one task at a time,
talking to the pool over two pipes (pickled messages; the child's stdout stays free for the
libraries that print, such as IPOPT's banner).

- **Bounded.** A task has a time limit: past it, its process is killed (SIGKILL) and the task
  fails with :class:`TaskTimeout`. A child may have an address-space limit (``RLIMIT_AS``):
  past it allocations fail (``MemoryError``) and the child exits after answering, so the next
  task gets a fresh process.
- **Isolated.** A child that dies (killed, crashed, out of memory) fails only its own task
  (:class:`WorkerLost`); the slot gets a new process.
- **No orphans.** A child dies with its parent: ``PR_SET_PDEATHSIG(SIGKILL)`` on Linux (the
  children are started by the pool's supervisor thread, which lives as long as the pool), and a
  watchdog thread that exits when the parent's pid changes (every platform). No
  ``multiprocessing`` machinery is used, so no resource-tracker process is started either.
  ``close()`` stops the children (SIGTERM, then SIGKILL).
"""

from __future__ import annotations

import collections
import ctypes
import itertools
import logging
import os
import resource
import selectors
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import Future
from dataclasses import dataclass, field
from multiprocessing.connection import Connection
from typing import Any

log = logging.getLogger(__name__)

#: exit status of a child that exits on purpose after a MemoryError (so the slot starts afresh)
EXIT_AFTER_MEMORY_ERROR = 75


class WorkerLost(RuntimeError):
    """The task's process died before answering (killed, crashed, or over its memory limit)."""


class TaskTimeout(WorkerLost):
    """The task ran past its time limit; its process was killed."""


class RemoteError(RuntimeError):
    """An exception of the child that could not be sent back as itself (type and message kept)."""


class Abandoned(RuntimeError):
    """The task was cancelled by its caller (:meth:`ProcPool.cancel`): dropped from the queue, or its
    process killed while it ran."""


# --- the child ------------------------------------------------------------------------------


def die_with_parent(parent_pid: int, *, pdeathsig: bool = True, interval: float = 1.0) -> None:
    """Make this process exit when ``parent_pid`` does.

    ``PR_SET_PDEATHSIG`` (Linux) delivers SIGKILL when the *thread* that started us ends, so it
    is only safe when that thread lives as long as the parent (``pdeathsig=False`` otherwise);
    the watchdog thread compares ``getppid()`` with ``parent_pid`` every ``interval`` seconds.
    """
    if pdeathsig and sys.platform.startswith("linux"):
        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG = 1
        except (OSError, AttributeError):  # not fatal: the watchdog below still works
            log.debug("prctl(PR_SET_PDEATHSIG) unavailable", exc_info=True)
    if os.getppid() != parent_pid:  # the parent died before we got here
        os._exit(0)

    def watch() -> None:
        while True:
            time.sleep(interval)
            if os.getppid() != parent_pid:
                os._exit(0)

    threading.Thread(target=watch, name="parent-watchdog", daemon=True).start()


def limit_memory(memory_mb: float | None) -> None:
    """Cap this process's address space (``RLIMIT_AS``): allocations beyond fail with MemoryError."""
    if not memory_mb:
        return
    limit = int(memory_mb * 1024 * 1024)
    soft, hard = resource.getrlimit(resource.RLIMIT_AS)
    if hard != resource.RLIM_INFINITY:
        limit = min(limit, hard)
    resource.setrlimit(resource.RLIMIT_AS, (limit, hard))


def _child_main(argv: Sequence[str]) -> int:
    rfd, wfd, parent = int(argv[0]), int(argv[1]), int(argv[2])
    memory_mb = float(argv[3]) if argv[3] != "-" else None
    warm = [m for m in argv[4].split(",") if m] if len(argv) > 4 else []
    die_with_parent(parent)
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # Ctrl-C reaches the parent, which stops us
    logging.basicConfig(level=os.environ.get("MOTIONX_PROC_LOGLEVEL", "WARNING"),
                        format="%(asctime)s %(levelname)s [%(process)d] %(name)s: %(message)s")
    for m in warm:  # import before the memory cap: the cap is for the work, not for the libraries
        __import__(m)
    limit_memory(memory_mb)
    conn_in, conn_out = Connection(rfd, writable=False), Connection(wfd, readable=False)
    conn_out.send(("ready", os.getpid()))
    while True:
        try:
            task_id, fn, args, kwargs = conn_in.recv()
        except EOFError:
            return 0
        memory_error = False
        try:
            reply = (task_id, "ok", fn(*args, **kwargs))
        except MemoryError:
            memory_error = True
            limit = f" (limit {memory_mb:g} MB)" if memory_mb else ""
            reply = (task_id, "err", MemoryError(f"out of memory{limit}"))
        except BaseException as e:  # the task's failure is the caller's to judge
            reply = (task_id, "err", e)
        reply = (*reply, memory_error)  # the last field: this process exits after the reply
        try:
            conn_out.send(reply)
        except MemoryError:
            memory_error = True
            conn_out.send((task_id, "err", MemoryError("out of memory while sending the result"), True))
        except Exception as e:  # an unpicklable result or exception: send what can be sent
            conn_out.send((task_id, "err", RemoteError(f"{type(reply[2]).__name__}: {reply[2]}"[:2000]
                                                       if reply[1] == "err" else f"unpicklable result: {e}"),
                           memory_error))
        del reply
        if memory_error:
            return EXIT_AFTER_MEMORY_ERROR


# --- the pool -------------------------------------------------------------------------------


@dataclass
class _Task:
    id: int
    fn: Callable[..., Any]
    args: tuple
    kwargs: dict
    timeout: float | None
    future: Future
    lane: str = ""
    deadline: float | None = None
    abandoned: bool = False


@dataclass
class _Slot:
    index: int
    proc: subprocess.Popen | None = None
    conn_in: Connection | None = None  # we write tasks
    conn_out: Connection | None = None  # we read results
    ready: bool = False
    task: _Task | None = None
    started: float = 0.0
    pid: int | None = None

    def alive(self) -> bool:
        return self.proc is not None and self.proc.poll() is None


@dataclass
class ProcPool:
    """``size`` supervised child processes. ``submit(fn, *args, timeout=..., lane=...)`` returns a
    :class:`concurrent.futures.Future`; ``fn`` must be importable (pickled by reference).

    **Lanes.** Each task belongs to a lane (the API uses one per API key). Waiting tasks are
    handed to free processes round-robin over the lanes, never more than ``lane_limit`` of one
    lane at a time: a lane with many long tasks cannot take every process, and a task of another
    lane starts at the next free process however long the first lane's queue is.
    :meth:`cancel` drops a waiting task or kills the process of a running one (its caller went
    away)."""

    name: str
    size: int
    memory_mb: float | None = None
    warm: Sequence[str] = ()
    env: dict[str, str] | None = None
    lane_limit: int | None = None
    _slots: list[_Slot] = field(default_factory=list, repr=False)
    _lanes: dict[str, collections.deque] = field(default_factory=dict, repr=False)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)
    _thread: threading.Thread | None = field(default=None, repr=False)
    _stop: bool = field(default=False, repr=False)
    _ids: Any = field(default_factory=itertools.count, repr=False)
    _close_timeout: float = field(default=5.0, repr=False)

    def __post_init__(self) -> None:
        if self.size < 1:
            raise ValueError("a pool needs at least one process")
        self._wake_r, self._wake_w = os.pipe()
        os.set_blocking(self._wake_w, False)
        self._slots = [_Slot(i) for i in range(self.size)]
        self.restarts = 0

    # --- public ----------------------------------------------------------------------------
    def start(self) -> ProcPool:
        self._thread = threading.Thread(target=self._supervise, name=f"procpool-{self.name}", daemon=True)
        self._thread.start()
        return self

    def submit(self, fn: Callable[..., Any], *args: Any, timeout: float | None = None, lane: str = "",
               **kwargs: Any) -> Future:
        fut: Future = Future()
        with self._lock:
            if self._stop:
                raise RuntimeError(f"pool {self.name!r} is closed")
            self._lanes.setdefault(lane, collections.deque()).append(
                _Task(next(self._ids), fn, args, kwargs, timeout, fut, lane))
        self._wake()
        return fut

    def cancel(self, fut: Future) -> bool:
        """Cancel the task of ``fut``: a waiting one leaves the queue, a running one has its process
        killed (the slot gets a new one). Returns False when the task had already ended."""
        with self._lock:
            for lane, q in self._lanes.items():
                for t in q:
                    if t.future is fut:
                        q.remove(t)
                        if not q:
                            del self._lanes[lane]
                        fut.cancel()
                        return True
            for s in self._slots:
                if s.task is not None and s.task.future is fut and not fut.done():
                    s.task.abandoned = True
                    break
            else:
                return False
        self._wake()
        return True

    def stats(self) -> dict[str, Any]:
        """Processes, tasks running and waiting, and per lane (running, waiting)."""
        with self._lock:
            lanes: dict[str, list[int]] = {k: [0, len(q)] for k, q in self._lanes.items()}
            for s in self._slots:
                if s.task is not None:
                    lanes.setdefault(s.task.lane, [0, 0])[0] += 1
            return {"processes": self.size, "running": sum(v[0] for v in lanes.values()),
                    "waiting": sum(v[1] for v in lanes.values()), "lanes": {k: tuple(v) for k, v in lanes.items()}}

    def pids(self) -> list[int]:
        with self._lock:
            return [s.pid for s in self._slots if s.pid is not None and s.alive()]

    def busy(self) -> int:
        with self._lock:
            return sum(1 for s in self._slots if s.task is not None) + sum(len(q) for q in self._lanes.values())

    def healthy(self) -> bool:
        return self._thread is not None and self._thread.is_alive() and not self._stop

    def close(self, timeout: float = 5.0) -> None:
        """Stop every child (SIGTERM, then SIGKILL after ``timeout``); queued tasks fail.

        The supervisor thread stops the children itself before it ends: it is the thread they
        watch with PR_SET_PDEATHSIG."""
        with self._lock:
            self._stop = True
            self._close_timeout = timeout
        self._wake()
        if self._thread is not None:
            self._thread.join(timeout + 10.0)
        self._terminate_all(timeout)  # if the thread never started (or did not stop)
        for fd in (self._wake_r, self._wake_w):
            try:
                os.close(fd)
            except OSError:
                pass

    # --- supervisor thread --------------------------------------------------------------------
    def _wake(self) -> None:
        try:
            os.write(self._wake_w, b"x")
        except (BlockingIOError, OSError):  # the pipe is full (a wake-up is pending) or closed
            pass

    def _spawn(self, slot: _Slot) -> None:
        r_task, w_task = os.pipe()  # parent -> child
        r_res, w_res = os.pipe()  # child -> parent
        args = [sys.executable, "-m", "service.procpool", str(r_task), str(w_res), str(os.getpid()),
                f"{self.memory_mb:g}" if self.memory_mb else "-", ",".join(self.warm)]
        env = dict(os.environ)
        env.update(self.env or {})
        try:
            slot.proc = subprocess.Popen(args, pass_fds=(r_task, w_res), stdin=subprocess.DEVNULL, env=env,
                                         close_fds=True)
        finally:
            os.close(r_task)
            os.close(w_res)
        slot.conn_in, slot.conn_out = Connection(w_task, readable=False), Connection(r_res, writable=False)
        slot.ready, slot.task, slot.pid, slot.started = False, None, slot.proc.pid, time.monotonic()

    def _reap(self, slot: _Slot, why: Exception | None) -> None:
        """The slot's child is gone (or must go): fail its task, close the pipes."""
        if slot.proc is not None and slot.proc.poll() is None:
            slot.proc.kill()
        if slot.proc is not None:
            try:
                slot.proc.wait(5)
            except subprocess.TimeoutExpired:
                log.error("pool %s: process %s did not exit after SIGKILL", self.name, slot.pid)
        task, slot.task = slot.task, None
        if task is not None and not task.future.done():
            code = slot.proc.returncode if slot.proc is not None else None
            err = why or WorkerLost(f"the {self.name} process {slot.pid} died (exit status {code}) while running "
                                    "the task")
            task.future.set_exception(err)
        for c in (slot.conn_in, slot.conn_out):
            if c is not None:
                c.close()
        slot.proc, slot.conn_in, slot.conn_out, slot.ready = None, None, None, False
        if not self._stop:
            self.restarts += 1

    def _supervise(self) -> None:
        sel = selectors.DefaultSelector()
        sel.register(self._wake_r, selectors.EVENT_READ, None)
        try:
            while True:
                with self._lock:
                    stopping = self._stop
                if stopping:
                    break
                self._tick(sel)
        except Exception:  # pragma: no cover - a bug here must not leave callers waiting forever
            log.exception("pool %s: supervisor failed", self.name)
        finally:
            with self._lock:
                self._stop = True
                queued = [t for q in self._lanes.values() for t in q]
                self._lanes.clear()
            for t in queued:
                if not t.future.done():
                    t.future.set_exception(RuntimeError(f"pool {self.name!r} closed"))
            self._terminate_all(self._close_timeout)
            sel.close()

    def _tick(self, sel: selectors.BaseSelector) -> None:
        # (re)start the children that are missing: from this thread only (see die_with_parent)
        for slot in self._slots:
            if slot.proc is None:
                try:
                    self._spawn(slot)
                except OSError:
                    log.exception("pool %s: could not start a process", self.name)
                    continue
                sel.register(slot.conn_out.fileno(), selectors.EVENT_READ, slot)
        # hand queued tasks to idle children, round-robin over the lanes
        for slot in self._slots:
            if slot.ready and slot.task is None:
                with self._lock:
                    task = self._next_task()
                if task is None:
                    break
                if not task.future.set_running_or_notify_cancel():
                    continue
                task.deadline = time.monotonic() + task.timeout if task.timeout else None
                slot.task = task
                try:
                    slot.conn_in.send((task.id, task.fn, task.args, task.kwargs))
                except (OSError, EOFError):
                    self._forget(sel, slot, None)
                except Exception as e:  # the task itself cannot be pickled: its caller's error
                    slot.task = None
                    task.future.set_exception(e)
        now = time.monotonic()
        deadlines = [s.task.deadline for s in self._slots if s.task is not None and s.task.deadline is not None]
        wait = max(0.0, min([1.0, *(d - now for d in deadlines)]))
        for key, _ in sel.select(wait):
            slot = key.data
            if slot is None:
                try:
                    os.read(self._wake_r, 4096)
                except BlockingIOError:
                    pass
                continue
            try:
                msg = slot.conn_out.recv()
            except (EOFError, OSError):
                self._forget(sel, slot, None)
                continue
            except Exception as e:  # the result could not be unpickled in this process
                task, slot.task = slot.task, None
                if task is not None and not task.future.done():
                    task.future.set_exception(RemoteError(f"could not read the result: {e}"))
                continue
            if msg[0] == "ready":
                slot.ready = True
                continue
            task_id, kind, value, exiting = msg
            if exiting:  # no new task for it: it ends, and the slot gets a new process
                slot.ready = False
            task, slot.task = slot.task, None
            if task is None or task.id != task_id or task.future.done():
                continue
            if kind == "ok":
                task.future.set_result(value)
            else:
                task.future.set_exception(value)
        # time limits, and children that died without closing their pipe yet
        now = time.monotonic()
        for slot in self._slots:
            if slot.proc is None:
                continue
            t = slot.task
            if t is not None and t.abandoned:
                log.info("pool %s: task cancelled by its caller; stopping process %s", self.name, slot.pid)
                self._forget(sel, slot, Abandoned("the task was cancelled by its caller"))
            elif t is not None and t.deadline is not None and now > t.deadline:
                log.warning("pool %s: task ran past its %g s limit; killing process %s", self.name, t.timeout,
                            slot.pid)
                self._forget(sel, slot, TaskTimeout(f"the task ran past its time limit of {t.timeout:g} s"))
            elif slot.proc.poll() is not None:
                self._forget(sel, slot, None)

    def _next_task(self) -> _Task | None:
        """The next task to run (under the lock): the first lane in turn with a task waiting and
        fewer than ``lane_limit`` running; that lane then goes to the back of the turn."""
        running: collections.Counter[str] = collections.Counter(s.task.lane for s in self._slots if s.task is not None)
        for lane in list(self._lanes):
            if self.lane_limit is not None and running[lane] >= self.lane_limit:
                continue
            q = self._lanes.pop(lane)
            task = q.popleft()
            if q:
                self._lanes[lane] = q  # re-inserted: the back of the turn
            return task
        return None

    def _forget(self, sel: selectors.BaseSelector, slot: _Slot, why: Exception | None) -> None:
        if slot.conn_out is not None:
            try:
                sel.unregister(slot.conn_out.fileno())
            except (KeyError, ValueError):
                pass
        self._reap(slot, why)

    def _terminate_all(self, timeout: float) -> None:
        procs = [s.proc for s in self._slots if s.proc is not None]
        for p in procs:
            if p.poll() is None:
                p.terminate()
        deadline = time.monotonic() + timeout
        for p in procs:
            try:
                p.wait(max(0.0, deadline - time.monotonic()))
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait(5)
        for s in self._slots:
            if s.task is not None and not s.task.future.done():
                s.task.future.set_exception(WorkerLost(f"pool {self.name!r} closed while the task ran"))
            for c in (s.conn_in, s.conn_out):
                if c is not None:
                    c.close()
            s.proc, s.conn_in, s.conn_out, s.task = None, None, None, None


if __name__ == "__main__":
    sys.exit(_child_main(sys.argv[1:]))
