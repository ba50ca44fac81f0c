"""service.procpool: the supervised processes that run jobs (LocalRunner) and the API's heavy
requests. Real child processes, stdlib functions as tasks (importable in the child)."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import pytest
from svc_util import alive, wait_gone

from service.procpool import ProcPool, TaskTimeout, WorkerLost

REPO = Path(__file__).resolve().parents[2]


@pytest.fixture
def pool():
    p = ProcPool("test", 2, memory_mb=700).start()
    yield p
    p.close()


def test_results_and_exceptions_come_back(pool):
    pid = pool.submit(os.getpid).result(30)
    assert pid != os.getpid() and pid in pool.pids()
    err = pool.submit(int, "not a number").exception(30)
    assert isinstance(err, ValueError) and "not a number" in str(err)


def test_time_limit_kills_only_that_task_and_the_slot_is_replaced(pool):
    slow = pool.submit(time.sleep, 30, timeout=0.5)
    other = pool.submit(time.sleep, 1.0)  # on the other slot, unaffected
    err = slow.exception(30)  # a 30 s task: only its 0.5 s limit ends it before this wait does
    assert isinstance(err, TaskTimeout) and "time limit of 0.5 s" in str(err), err
    assert other.result(30) is None
    assert pool.submit(os.getpid).result(30) in pool.pids()  # the pool works on
    assert pool.restarts >= 1


def test_memory_limit_fails_the_task_and_the_process_starts_afresh(pool):
    pool.submit(os.getpid).result(30)
    before = set(pool.pids())
    assert len(before) == 2
    err = pool.submit(bytearray, 3 * 1024**3).exception(30)  # 3 GB under a 700 MB cap
    assert isinstance(err, MemoryError) and "700 MB" in str(err)
    for _ in range(4):  # never handed to the process that is ending
        assert pool.submit(len, b"abc").result(30) == 3
    deadline = time.monotonic() + 10
    while len(set(pool.pids()) - before) != 1 and time.monotonic() < deadline:
        time.sleep(0.05)
    assert len(set(pool.pids()) - before) == 1 and len(pool.pids()) == 2  # the one over the cap was replaced


def test_a_dying_process_fails_only_its_own_task(pool):
    long = pool.submit(time.sleep, 2.0)
    time.sleep(0.3)
    crash = pool.submit(os._exit, 3)
    assert isinstance(crash.exception(30), WorkerLost)
    assert long.result(30) is None
    assert pool.submit(os.getpid).result(30)


def test_close_stops_every_child(pool):
    pool.submit(time.sleep, 30)
    pool.submit(os.getpid).result(30)
    pids = pool.pids()
    assert len(pids) == 2
    pool.close(timeout=2)
    assert wait_gone(pids) == []


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGTERM])
def test_children_die_with_their_parent(tmp_path, sig):
    """The API process killed (SIGKILL: no cleanup at all): its children do not outlive it
    (PR_SET_PDEATHSIG, and the parent watchdog), and no resource tracker is left either."""
    script = tmp_path / "parent.py"
    script.write_text(textwrap.dedent("""
        import os, sys, time
        from service.procpool import ProcPool
        pool = ProcPool("t", 2).start()
        busy = pool.submit(time.sleep, 60)
        pool.submit(os.getpid).result(30)
        print(" ".join(map(str, pool.pids())), flush=True)
        time.sleep(60)
    """))
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True, cwd=REPO)
    try:
        kids = [int(p) for p in proc.stdout.readline().split()]
        assert len(kids) == 2 and all(alive(k) for k in kids)
        os.kill(proc.pid, sig)
        proc.wait(10)
        assert wait_gone(kids, timeout=3.0) == []
    finally:
        if proc.poll() is None:
            proc.kill()
