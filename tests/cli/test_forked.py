"""A call computed in a forked child (:mod:`benchlab.forked`, start-up of ``analyze SESSION``,
issue 11): its value comes back unchanged; an exception, a crash or a kill in the child makes
the caller compute the value itself (a death is logged), never waits for a dead child, and
leaves no zombie; fork only where it is safe and useful."""

from __future__ import annotations

import logging
import os
import signal
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from typing import Any

import numpy as np
import pytest

from benchlab import forked


def _reaped(pid: int) -> bool:
    try:
        os.waitpid(pid, os.WNOHANG)
    except ChildProcessError:
        return True
    return False


def _run(call: Callable[[], Any]) -> tuple[Any, int]:
    job = forked.fork_call(call, "test call")
    assert job is not None
    pid = job.pid
    try:
        return job.result(), pid
    finally:
        job.close()


def test_the_childs_value_comes_back_unchanged_and_the_child_is_reaped(
        caplog: pytest.LogCaptureFixture) -> None:
    parent = os.getpid()
    value = {"pid": 0, "rows": [{"a": 0.1 + 0.2, "b": None, "c": np.float64(1 / 3)}],
             "array": np.linspace(0.0, 1.0, 7), "key": (1.5, "sagittal")}

    def compute() -> dict[str, Any]:
        return {**value, "pid": os.getpid()}

    with caplog.at_level(logging.DEBUG, logger="benchlab.forked"):
        got, pid = _run(compute)
    assert got["pid"] == pid != parent  # computed in the child
    assert got["rows"] == value["rows"] and type(got["rows"][0]["c"]) is np.float64
    assert np.array_equal(got["array"], value["array"]) and got["key"] == value["key"]
    assert _reaped(pid)
    assert f"test call: computed in child process {pid}" in caplog.text


def test_an_exception_in_the_child_gives_no_value_and_no_warning(
        caplog: pytest.LogCaptureFixture) -> None:
    ran = forked.SharedFlags(1)

    def fails() -> int:
        ran.claim(0)
        raise ValueError("bad frame")

    with caplog.at_level(logging.DEBUG, logger="benchlab.forked"):
        got, pid = _run(fails)
    assert got is None and _reaped(pid)
    assert pid != os.getpid() and not ran.claim(0)  # a child existed and ran the call
    assert caplog.records == []  # the caller computes it again and raises the same error


@pytest.mark.parametrize(("die", "said"), [
    (lambda: os.kill(os.getpid(), signal.SIGKILL), "the child process was killed by SIGKILL"),
    (lambda: os.kill(os.getpid(), signal.SIGTERM), "the child process was killed by SIGTERM"),
    (lambda: os._exit(7), "the child process ended with status 7 without a result"),
    (lambda: lambda: None, "the child's result does not pickle"),
])
def test_a_child_that_dies_is_reported_and_not_waited_for(
        caplog: pytest.LogCaptureFixture, die: Callable[[], Any], said: str) -> None:
    ran = forked.SharedFlags(1)
    t0 = time.monotonic()
    with caplog.at_level(logging.WARNING, logger="benchlab.forked"):
        got, pid = _run(lambda: (ran.claim(0), die())[1])
    assert got is None and _reaped(pid)
    assert pid != os.getpid() and not ran.claim(0)  # a child existed and ran the call
    assert time.monotonic() - t0 < 10
    assert [r.getMessage() for r in caplog.records] == [f"test call: {said}; computing it here"]


def test_close_stops_a_running_child_and_reaps_it() -> None:
    job = forked.fork_call(lambda: time.sleep(60), "sleeper")
    assert job is not None
    pid = job.pid
    t0 = time.monotonic()
    job.close()
    job.close()  # idempotent
    assert time.monotonic() - t0 < 10 and _reaped(pid)
    assert job.result() is None  # nothing left to take


def test_the_child_ends_on_a_stop_signal_instead_of_running_the_callers_handler() -> None:
    got, _ = _run(lambda: [signal.getsignal(s) for s in
                           (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)])
    assert got == [signal.SIG_DFL] * 3


def test_fork_only_where_safe_and_useful(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.delenv(forked.SERIAL_ENV, raising=False)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1}, raising=False)
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    load = [0.3]
    monkeypatch.setattr(os, "getloadavg", lambda: (load[0], 1.0, 1.0))
    assert forked.usable_cpus() == 2
    # threads other tests left in this process are not this test's subject
    threads = [1]
    monkeypatch.setattr(threading, "active_count", lambda: threads[0])
    assert forked.fork_usable()
    for value in ("1", "yes"):
        monkeypatch.setenv(forked.SERIAL_ENV, value)
        assert not forked.fork_usable()
        assert forked.start(lambda: 1, "x") is None  # nothing forked
    monkeypatch.delenv(forked.SERIAL_ENV)
    assert forked.fork_usable()
    # one usable CPU (an affinity mask, a container limit): nothing to gain, unless forced
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {3})
    assert not forked.fork_usable()
    monkeypatch.setenv(forked.SERIAL_ENV, "0")
    assert forked.fork_usable()
    monkeypatch.delenv(forked.SERIAL_ENV)
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {0, 1})
    # a machine already busy (load average at its CPU count): the child would only add CPU
    load[0] = 1.9
    assert forked.fork_usable()
    load[0] = 2.0
    assert not forked.fork_usable() and forked.machine_busy()
    # busy for this process: 2 of 8 CPUs usable (affinity mask), load 2 (was os.cpu_count())
    monkeypatch.setattr(os, "cpu_count", lambda: 8)
    assert forked.machine_busy() and not forked.fork_usable()
    load[0] = 1.9
    assert not forked.machine_busy() and forked.fork_usable()
    monkeypatch.setattr(os, "cpu_count", lambda: 2)
    load[0] = 2.0
    monkeypatch.setenv(forked.SERIAL_ENV, "0")
    assert forked.fork_usable()  # forced
    monkeypatch.delenv(forked.SERIAL_ENV)
    load[0] = 0.3
    # another thread: a lock it holds would stay held in the child
    threads[0] = 2
    assert not forked.fork_usable()
    threads[0] = 1
    assert forked.fork_usable()
    # no fork (Windows) or no affinity to ask (macOS): one process, even when forced
    for setting in ("", "0"):
        monkeypatch.setenv(forked.SERIAL_ENV, setting)
        with monkeypatch.context() as m:
            m.delattr(os, "sched_getaffinity")
            assert forked.usable_cpus() == 1 and not forked.fork_usable()
        with monkeypatch.context() as m:
            m.delattr(os, "fork")
            assert not forked.fork_usable()


def test_a_failed_fork_computes_here(monkeypatch: pytest.MonkeyPatch,
                                     caplog: pytest.LogCaptureFixture) -> None:
    def no_fork() -> int:
        raise BlockingIOError(11, "Resource temporarily unavailable")

    monkeypatch.setattr(os, "fork", no_fork)
    fds_before = len(os.listdir("/proc/self/fd"))
    mask_before = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    with caplog.at_level(logging.WARNING, logger="benchlab.forked"):
        assert forked.fork_call(lambda: 1, "test call") is None
    assert "test call: cannot fork" in caplog.text
    assert len(os.listdir("/proc/self/fd")) == fds_before  # the pipe closed again
    assert signal.pthread_sigmask(signal.SIG_BLOCK, []) == mask_before  # signals unblocked


def test_stop_signals_wait_during_the_fork_and_the_child_gets_them(
        monkeypatch: pytest.MonkeyPatch) -> None:
    real_fork = os.fork
    blocked_at_fork: list[set[int]] = []

    def fork() -> int:
        blocked_at_fork.append({int(s) for s in signal.pthread_sigmask(signal.SIG_BLOCK, [])})
        return real_fork()

    monkeypatch.setattr(os, "fork", fork)
    mask_before = signal.pthread_sigmask(signal.SIG_BLOCK, [])
    got, _ = _run(lambda: sorted(int(s) for s in signal.pthread_sigmask(signal.SIG_BLOCK, [])))
    stops = {int(signal.SIGINT), int(signal.SIGTERM), int(signal.SIGHUP)}
    assert blocked_at_fork and stops <= blocked_at_fork[0]
    assert not stops & set(got)  # the child runs with them unblocked (and default)
    assert signal.pthread_sigmask(signal.SIG_BLOCK, []) == mask_before


def test_a_child_its_caller_lost_is_closed_at_exit() -> None:
    job = forked.fork_call(lambda: time.sleep(60), "lost")
    assert job is not None
    pid = job.pid
    del job  # a stop signal between the fork and the caller's finally
    t0 = time.monotonic()
    forked._close_lost_children()  # what the interpreter's exit runs
    assert _reaped(pid) and time.monotonic() - t0 < 10
    assert not forked._live


def test_flags_claimed_in_the_child_are_seen_by_the_parent() -> None:
    flags = forked.SharedFlags(8)
    got, _ = _run(lambda: [flags.claim(i) for i in (0, 2, 2, 5)])
    assert got == [True, True, False, True]
    assert [flags.claim(i) for i in range(8)] == [False, True, False, True, True, False,
                                                  True, True]
    assert not flags.claim(7) and flags.claim(8) and flags.claim(8)  # past the flags: always



_PARENT = """
import os, sys, time
from benchlab import forked
job = forked.fork_call(lambda: time.sleep(60), "orphan")
print(job.pid, flush=True)
time.sleep(60)
"""


def _gone(pid: int) -> bool:
    """No such process, or a zombie (the reaper of orphans has not collected it yet)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().rsplit(")", 1)[1].split()[0] in ("Z", "X")
    except FileNotFoundError:
        return True


def test_the_child_dies_with_a_sigkilled_parent() -> None:
    parent = subprocess.Popen([sys.executable, "-c", _PARENT], stdout=subprocess.PIPE,
                              text=True)
    try:
        assert parent.stdout is not None
        child = int(parent.stdout.readline())
        assert not _gone(child)  # computing
        parent.kill()  # SIGKILL: no finally, no atexit - only the kernel can end the child
        parent.wait(10)
        deadline = time.monotonic() + 5.0
        while not _gone(child) and time.monotonic() < deadline:
            time.sleep(0.01)
        assert _gone(child)  # without PR_SET_PDEATHSIG it slept on for its 60 s
    finally:
        parent.kill()
        parent.wait(10)


_WARNS = """
import os, warnings
from benchlab import forked
parent = os.getpid()

def call():
    warnings.warn("from the call", UserWarning)
    if os.getpid() != parent and {fail}:
        raise ValueError("child fails")
    return 42

if {before}:
    call()  # shown here; the same warning at the same place is not shown again (default)
job = forked.fork_call(call, "warns")
value = job.result()
job.close()
print(value if value is not None else call())
"""


@pytest.mark.parametrize(("fail", "before"), [(False, False), (True, False), (False, True)])
def test_a_warning_of_the_call_is_shown_once(fail: bool, before: bool) -> None:
    out = subprocess.run([sys.executable, "-c", _WARNS.format(fail=fail, before=before)],
                         capture_output=True, text=True, timeout=60, check=True)
    assert out.stdout.strip() == "42"
    # the child's value used: the parent shows the child's warning; the child failed: the
    # parent's own call warns (the child's warning was never printed - it was, twice in all)
    assert out.stderr.count("UserWarning: from the call") == 1, out.stderr
