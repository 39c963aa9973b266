"""One call computed in a forked child process while the caller goes on (start-up of
``benchlab analyze SESSION``, issue 11: the analysis is bound to one core by the GIL, and a
child forked after the imports common to both halves uses the second core without importing
them again).

The child sends its value back pickled through a pipe and ends with :func:`os._exit` (no exit
handlers, no buffered output of the parent flushed twice). Whatever goes wrong in the child -
an exception, a value that does not pickle, the child killed or crashed - makes
:meth:`ForkedCall.result` return None, and the caller computes the value itself: an error then
reaches the user exactly as it does without a child (same exception, message and exit
status), and a child that died is logged as a warning. A child that dies closes its end of the
pipe, so the parent never waits for a dead child; :meth:`ForkedCall.close` (on every exit path)
kills a child still running and reaps it, so no zombie is left. The stop signals are blocked
from the fork until the child is registered, and a child its caller lost (a stop signal
between the fork and the caller's ``finally``) is closed when the interpreter exits, so no
child outlives the command holding its output open.

Forking copies only the calling thread, so :func:`fork_usable` allows it only while the
process has no other Python thread (a lock held by another thread - an import, a logging
handler - would stay held forever in the child), on a POSIX system that reports its CPU
affinity (Linux; macOS forks unsafely once its system frameworks are loaded), and where it
gains: two or more usable CPUs, and a machine not already busy (a 1-minute load average below
its CPU count; on a saturated machine the child's own imports only add CPU time: a
re-analysis measured 0.05-0.1 s slower at load 2-4 on 2 CPUs, ~0.02 s faster when quiet).
``BENCHLAB_SERIAL=1`` computes everything in one process; ``BENCHLAB_SERIAL=0`` forks wherever
it is safe (debugging and tests of the fork path).
"""

from __future__ import annotations

import atexit
import logging
import os
import pickle
import signal
import sys
import threading
import warnings
from collections.abc import Callable
from typing import Any, Generic, TypeVar

#: ``1`` (anything but ``""`` or ``0``): everything in one process; ``0``: fork wherever it is
#: safe; unset: fork where it is safe and gains (:func:`fork_usable`).
SERIAL_ENV = "BENCHLAB_SERIAL"

T = TypeVar("T")
_log = logging.getLogger(__name__)
#: Child exit statuses: the value was sent / the call raised (the parent computes it again,
#: raising the same) / the value did not pickle (a programming error: a warning).
_SENT, _RAISED, _UNPICKLABLE = 0, 3, 4
_STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity mask), 1 where the system does not say."""
    try:
        return len(os.sched_getaffinity(0))
    except (AttributeError, OSError):
        return 1


def fork_usable() -> bool:
    """Whether :func:`start` may fork now (see the module docstring for the conditions)."""
    setting = os.environ.get(SERIAL_ENV, "")
    if setting not in ("", "0"):
        return False
    safe = (hasattr(os, "fork") and hasattr(os, "sched_getaffinity")
            and threading.active_count() == 1)
    return safe and (setting == "0" or (usable_cpus() >= 2 and not machine_busy()))


def machine_busy() -> bool:
    """Whether the 1-minute load average has reached the CPUs this process may use (its
    affinity mask: a container or ``taskset`` limit, not the machine's count) - every usable
    core already taken by other work on average."""
    try:
        return os.getloadavg()[0] >= usable_cpus()
    except (AttributeError, OSError):
        return False


class SharedFlags:
    """Flags shared by this process and the children it forks after making them (an anonymous
    shared mapping): work items the two split between them as they go, each claiming the next
    item not yet claimed. A claim's check and set are not atomic, so both may take the same
    item at the same moment: an item must give the same result in either process (it is then
    done twice, nothing worse)."""

    def __init__(self, size: int) -> None:
        import mmap

        self.size = size
        self._flags = mmap.mmap(-1, size)  # MAP_SHARED | MAP_ANONYMOUS: seen by the children

    def claim(self, index: int) -> bool:
        """Set flag ``index``; whether it was unset (the caller then does item ``index``).
        An index past the flags is always claimed (both processes do that item)."""
        if index >= self.size:
            return True
        if self._flags[index]:
            return False
        self._flags[index] = 1
        return True


class ForkedCall(Generic[T]):
    """A call running in a child process: :meth:`result` once, :meth:`close` always."""

    def __init__(self, pid: int, read_fd: int, what: str) -> None:
        self.pid = pid
        self.what = what
        self._read_fd: int | None = read_fd
        self._reaped = False
        _live.add(self)

    def result(self) -> T | None:
        """The child's value, or None when it raised or died (compute the value here then).
        Waits for the child to send it or to end."""
        fd, self._read_fd = self._read_fd, None
        if fd is None:
            return None  # already taken or closed
        with os.fdopen(fd, "rb") as pipe:
            data = pipe.read()  # until the child closes its end: sent, raised or died
        status = self._reap(kill=False)
        if status == _SENT and data:
            try:
                value: T
                value, caught = pickle.loads(data)
            except Exception as exc:  # any unpickling failure: compute here
                _log.warning("%s: the child's result did not unpickle (%s); computing it here",
                             self.what, exc)
                return None
            _log.debug("%s: computed in child process %d", self.what, self.pid)
            _show_warnings(caught)
            return value
        if status == _UNPICKLABLE:
            _log.warning("%s: the child's result does not pickle; computing it here", self.what)
        elif status != _RAISED:
            _log.warning("%s: the child process %s; computing it here", self.what,
                         _describe(status))
        return None

    def close(self) -> None:
        """Stop the child if it still runs and reap it (idempotent)."""
        fd, self._read_fd = self._read_fd, None
        if fd is not None:
            os.close(fd)
        self._reap(kill=True)

    def _reap(self, *, kill: bool) -> int | None:
        """The child's exit status (``-signal`` when a signal ended it); None if reaped before."""
        if self._reaped:
            return None
        self._reaped = True
        _live.discard(self)
        if kill:
            try:
                os.kill(self.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        while True:
            try:
                _, wait_status = os.waitpid(self.pid, 0)
            except ChildProcessError:
                return None  # reaped by someone else (a SIGCHLD handler)
            except InterruptedError:
                continue
            return os.waitstatus_to_exitcode(wait_status)


#: Children not reaped yet; closed at exit if their caller lost them.
_live: set[ForkedCall[Any]] = set()


@atexit.register
def _close_lost_children() -> None:
    for call in list(_live):
        call.close()


def _describe(status: int | None) -> str:
    if status is None:
        return "was reaped elsewhere"
    if status < 0:
        try:
            name = signal.Signals(-status).name
        except ValueError:
            name = f"signal {-status}"
        return f"was killed by {name}"
    return f"ended with status {status} without a result"


def start(call: Callable[[], T], what: str) -> ForkedCall[T] | None:
    """Run ``call()`` in a forked child; None (nothing started) unless :func:`fork_usable`.
    ``what`` names the computation in warnings."""
    return fork_call(call, what) if fork_usable() else None


def fork_call(call: Callable[[], T], what: str) -> ForkedCall[T] | None:
    """:func:`start` without the checks of :func:`fork_usable`; None if the fork failed."""
    parent = os.getpid()
    read_fd, write_fd = os.pipe()
    # No stop signal between the fork and the child's registration (a handler raising there
    # would lose the child): they wait, blocked, until the child is known.
    mask = signal.pthread_sigmask(signal.SIG_BLOCK, _STOP_SIGNALS)
    job: ForkedCall[T] | None = None
    try:
        try:
            pid = os.fork()
        except OSError as exc:  # no memory or process slots left: compute in this process
            os.close(read_fd)
            os.close(write_fd)
            _log.warning("%s: cannot fork (%s); computing it in this process", what, exc)
        else:
            if pid == 0:  # pragma: no cover - the child (its coverage is not collected)
                _child(call, read_fd, write_fd, mask, parent)
            os.close(write_fd)
            job = ForkedCall(pid, read_fd, what)
    finally:
        try:
            signal.pthread_sigmask(signal.SIG_SETMASK, mask)  # a waiting stop signal acts now
        except BaseException:
            if job is not None:
                job.close()
            raise
    return job


#: Warnings the child caught, as sent to the parent: (message, category, filename, lineno).
_Caught = list[tuple[str, type[Warning], str, int]]


def _show_warnings(caught: _Caught) -> None:
    """Show, in the parent, the warnings the child's call raised: once, and only when the
    child's value is used (when the child failed, the parent's own call raises them again).
    The child already applied the warning filters, so they are shown, not filtered again."""
    for message, category, filename, lineno in caught:
        warnings.showwarning(message, category, filename, lineno)


def _die_with_parent(parent: int) -> None:
    """Linux: the kernel kills this child when its parent dies (PR_SET_PDEATHSIG), so a
    SIGKILLed parent leaves no child computing on; then check the parent did not die before
    that was set (the child was reparented). The kernel acts when the forking *thread* ends:
    :func:`start` forks only from a single-threaded process, whose one thread is the process."""
    if sys.platform.startswith("linux"):
        import ctypes

        try:
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0)
        except (OSError, AttributeError):
            pass  # no prctl: the parent's close() and the broken pipe still end the child
    if os.getppid() != parent:
        os._exit(_RAISED)


_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>


def _child(call: Callable[[], object], read_fd: int, write_fd: int,
           mask: set[int | signal.Signals], parent: int) -> None:
    """Compute, send, and leave with :func:`os._exit` whatever happens: never return into the
    caller's stack (its ``finally`` blocks and exit handlers belong to the parent)."""
    status = _RAISED
    try:
        _die_with_parent(parent)
        os.close(read_fd)
        _live.clear()  # the parent's other children are not this process's
        for sig in _STOP_SIGNALS:
            signal.signal(sig, signal.SIG_DFL)  # a stop signal just ends the child
        signal.pthread_sigmask(signal.SIG_SETMASK, mask)
        data = b""
        # Warnings are recorded (the filters and "once per place" registries as inherited),
        # not printed, and shown by the parent if it uses the value: printed by the child as
        # well, a warning of a call the parent repeats showed twice.
        caught: _Caught = []

        def record(message: Warning | str, category: type[Warning], filename: str,
                   lineno: int, file: object = None, line: str | None = None) -> None:
            caught.append((str(message), category, filename, lineno))

        warnings.showwarning = record
        try:
            value = call()
        except BaseException:  # the parent computes it again and raises (and warns)
            pass
        else:
            try:
                data = pickle.dumps((value, caught), protocol=pickle.HIGHEST_PROTOCOL)
                status = _SENT
            except BaseException:
                status = _UNPICKLABLE
        with os.fdopen(write_fd, "wb") as pipe:
            pipe.write(data)
    except BaseException:  # the parent sees no value: it computes it
        status = _RAISED
    finally:
        os._exit(status)
