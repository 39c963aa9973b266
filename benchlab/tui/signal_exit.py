"""The terminal UI ends with its terminal: a stop signal (SIGHUP, SIGTERM, SIGINT) always ends
the process within :data:`EXIT_DEADLINE_S`, bench safe first.

The orderly path (:meth:`benchlab.tui.app.BenchlabApp.stop_from_signal`) aborts the runner,
leaves the bench safe, closes the devices and lets Textual restore the terminal. That last
part can hang for good once the terminal is gone (``tmux kill-session``, a closed window):
Textual's output thread writes into a hung-up pseudo-terminal, and its shutdown blocks on a
full output queue (issue 38: a process still alive 55 s later, ignoring SIGTERM). So the
first signal also starts a watchdog thread; if the process is still running after
:data:`ORDERLY_EXIT_S` - in the app, or after it, in the interpreter's exit waiting for a
worker thread - the watchdog stops every worker, makes the bench safe itself (LEDs
off, stage stopped, devices closed: the runner has journalled the interruption by then, or
does so while the watchdog waits for it) and ends the process with ``128 + signal``.

On SIGHUP the terminal is gone: the standard streams are taken off it at once
(:func:`detach_from_terminal`), so nothing blocks or fails writing to it, and nothing spins
reading it.
"""

from __future__ import annotations

import os
import signal
import threading
import time
from typing import Protocol

#: Seconds the orderly quit gets before the watchdog takes over.
ORDERLY_EXIT_S = 3.0
#: Seconds the watchdog waits for device threads (the runner journalling the interruption).
DEVICE_THREADS_S = 1.0
#: Seconds it waits for the device lock before closing the bench without it.
DEVICE_LOCK_S = 0.5
#: The process is gone within this many seconds of the first stop signal (the three waits
#: above add up to 4.5 s).
EXIT_DEADLINE_S = 5.0


class _App(Protocol):
    abort_event: threading.Event
    device_stop: threading.Event

    def wait_for_device_threads(self, timeout_s: float = ...) -> bool: ...

    def force_close_bench(self, lock_timeout_s: float) -> BaseException | None: ...


class SignalExit:
    """Starts (once) the watchdog that ends the process if the orderly quit does not."""

    def __init__(self, app: _App) -> None:
        self._app = app
        self._started = False

    def on_signal(self, signum: int) -> None:
        """Called in the signal handler, for every stop signal: only quick work here."""
        if signum == signal.SIGHUP:
            detach_from_terminal()
        if self._started:
            return
        self._started = True
        threading.Thread(target=self._watch, args=(signum,), name="benchlab-signal-exit",
                         daemon=True).start()

    def _watch(self, signum: int) -> None:
        time.sleep(ORDERLY_EXIT_S)  # a process that ended in order took this thread with it
        app = self._app
        app.abort_event.set()
        app.device_stop.set()
        app.wait_for_device_threads(DEVICE_THREADS_S)
        error = app.force_close_bench(DEVICE_LOCK_S)
        _say(f"benchlab: stopped by {signal.Signals(signum).name}; "
             + ("bench left safe" if error is None
                else f"closing the bench failed: {error}") + "\n")
        os._exit(128 + signum)


def detach_from_terminal() -> None:
    """Point stdout and stderr at /dev/null and stdin at an empty non-blocking pipe (the
    terminal is gone: writing to it can block or fail; reading a hung-up terminal - or
    /dev/null - returns end-of-file at once, forever, and Textual's input thread would spin
    on it, starving the orderly quit; a blocking empty pipe would hold that thread, and with
    it the interpreter's exit, for good: a non-blocking one ends it)."""
    try:
        null = os.open(os.devnull, os.O_WRONLY)
        quiet, _keep_open = os.pipe()  # the write end stays open: no EOF, never readable
        os.set_blocking(quiet, False)  # a read already under way fails instead of waiting
    except OSError:
        return
    for fd, target in ((0, quiet), (1, null), (2, null)):
        try:
            os.dup2(target, fd)
        except OSError:
            pass
    os.close(null)
    os.close(quiet)


def _say(text: str) -> None:
    """One line to stderr without blocking (a terminal nobody reads must not hold the exit)."""
    try:
        os.set_blocking(2, False)
        os.write(2, text.encode("utf-8", "replace"))
    except OSError:
        pass

