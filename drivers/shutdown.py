"""One way for every benchlab program to stop on a signal: SIGINT, SIGTERM and SIGHUP alike.

``systemctl stop`` sends SIGTERM, a closed terminal or a dropped SSH session SIGHUP, Ctrl-C
SIGINT. Python only turns SIGINT into an exception; the other two kill the process where it
stands, so no ``finally``, no context exit and no ``atexit`` hook runs and an LED stays lit.
Here all three are handled the same way:

1. every instrument registered with :func:`watch` gets its ``_on_stop_signal()`` called at
   once (the LED controller switches off right away when it is between commands);
2. then either the program's own ``on_signal`` callback runs (the terminal UI schedules its
   orderly quit), or :class:`Stopped` - a :class:`KeyboardInterrupt` - is raised, so every
   ``except KeyboardInterrupt`` / ``finally`` / ``with`` already written for Ctrl-C runs:
   LEDs off, stage stopped, the session journalled as interrupted.

A repeated signal within :data:`REPEAT_GRACE_S` of the one being handled is ignored (and said
so on stderr), so a double Ctrl-C cannot cut short the clean-up the first one started. Later
ones act again: Python can lose an exception raised while a finaliser or a garbage-collector
callback runs, and a stop signal must never be swallowed for good. SIGKILL stays the hard stop.
The exit status is ``128 + signal number`` (130, 143, 129), as shells report it.

Python runs signal handlers in the main thread only, so :func:`install` is a no-op elsewhere.
"""

from __future__ import annotations

import contextlib
import math
import signal
import sys
import threading
import time
import weakref
from collections.abc import Callable, Iterator
from types import FrameType
from typing import Protocol

#: The signals that stop a benchlab program cleanly.
STOP_SIGNALS: tuple[signal.Signals, ...] = (signal.SIGINT, signal.SIGTERM, signal.SIGHUP)
#: Seconds after a stop signal during which a repeated one is ignored (clean-up time).
REPEAT_GRACE_S = 5.0


class Stopped(KeyboardInterrupt):
    """Raised in the main thread when a stop signal arrives; it is a KeyboardInterrupt, so
    every Ctrl-C path handles it."""

    def __init__(self, signum: int) -> None:
        self.signum = int(signum)
        super().__init__(f"stopped by {signal_name(signum)}")

    @property
    def signal_name(self) -> str:
        """``"SIGTERM"`` etc."""
        return signal_name(self.signum)

    @property
    def exit_status(self) -> int:
        """``128 + signal number``."""
        return 128 + self.signum


class _Watched(Protocol):
    def _on_stop_signal(self) -> None: ...


def signal_name(signum: int) -> str:
    """``"SIGTERM"`` for 15 (the number as text when unknown)."""
    try:
        return signal.Signals(signum).name
    except ValueError:
        return f"signal {signum}"


def exit_status(exc: BaseException) -> int:
    """Exit status for an interrupt: ``128 + signal`` for :class:`Stopped`, 130 for a bare
    KeyboardInterrupt (Ctrl-C raised by Python's own handler)."""
    if isinstance(exc, Stopped):
        return exc.exit_status
    return 128 + int(signal.SIGINT)


def interrupt_reason(exc: BaseException) -> str:
    """What to journal for an interrupt: the signal name, or ``KeyboardInterrupt``."""
    return exc.signal_name if isinstance(exc, Stopped) else "KeyboardInterrupt"


class _State:
    def __init__(self) -> None:
        self.lock = threading.Lock()
        self.watched: weakref.WeakSet[_Watched] = weakref.WeakSet()
        self.on_signal: Callable[[int], None] | None = None
        self.previous: dict[int, object] = {}
        self.received: int | None = None
        self.acted_at = -math.inf  # time.monotonic() of the last signal acted on
        self.depth = 0
        #: Signals whose handler :func:`install_default` set (restored when nothing is watched).
        self.defaulted: set[int] = set()


_state = _State()


def watch(instrument: _Watched) -> None:
    """Call ``instrument._on_stop_signal()`` on a stop signal (weakly held), and make sure
    the stop signals are handled at all (see :func:`install_default`)."""
    with _state.lock:
        _state.watched.add(instrument)
    install_default()


def unwatch(instrument: _Watched) -> None:
    """Forget an instrument (it was closed); with none left, handlers that
    :func:`install_default` set are restored to Python's defaults."""
    with _state.lock:
        _state.watched.discard(instrument)
        idle = len(_state.watched) == 0
    if idle and _state.depth == 0 and _in_main_thread():
        _state.acted_at = -math.inf
        for signum in sorted(_state.defaulted):
            if signal.getsignal(signum) is _handle:
                signal.signal(signum, signal.default_int_handler if signum == signal.SIGINT
                              else signal.SIG_DFL)
        _state.defaulted.clear()
        _state.received = None


def received() -> int | None:
    """The stop signal received since the handlers were installed, if any."""
    return _state.received


def _handle(signum: int, frame: FrameType | None) -> None:
    now = time.monotonic()
    repeat = _state.received is not None and now - _state.acted_at < REPEAT_GRACE_S
    _state.received = _state.received or signum
    for instrument in list(_state.watched):
        try:
            instrument._on_stop_signal()
        except Exception:  # noqa: BLE001 - the unwinding below closes it properly
            pass
    if repeat:
        print(f"benchlab: {signal_name(signum)} ignored: already stopping, making the bench "
              "safe", file=sys.stderr, flush=True)
        return
    _state.acted_at = now
    if _state.on_signal is not None:
        _state.on_signal(signum)
        return
    raise Stopped(signum)


def _in_main_thread() -> bool:
    return threading.current_thread() is threading.main_thread()


def _is_default(signum: int, handler: object) -> bool:
    if signum == signal.SIGINT:
        return handler is signal.default_int_handler
    return handler in (signal.SIG_DFL, None)


def install_default() -> None:
    """Install the handlers where no program has set its own (a script using a driver
    directly); a no-op outside the main thread or when already installed."""
    if not _in_main_thread():
        return
    for sig in STOP_SIGNALS:
        current = signal.getsignal(sig)
        if current is _handle:
            continue
        if _is_default(sig, current):
            signal.signal(sig, _handle)
            _state.defaulted.add(int(sig))


@contextlib.contextmanager
def handling_signals(on_signal: Callable[[int], None] | None = None) -> Iterator[None]:
    """Handle the stop signals inside the block; restore the previous handlers after.

    ``on_signal(signum)``, when given, replaces raising :class:`Stopped` (for an event loop
    that must stop itself in order); it runs in the main thread inside the signal handler, so
    it should only schedule work.
    """
    if not _in_main_thread():
        yield
        return
    previous = {int(sig): signal.getsignal(sig) for sig in STOP_SIGNALS}
    outer_callback = _state.on_signal
    if _state.depth == 0:
        _state.received = None
        _state.acted_at = -math.inf
    _state.depth += 1
    _state.on_signal = on_signal
    for sig in STOP_SIGNALS:
        signal.signal(sig, _handle)
    try:
        yield
    finally:
        _state.depth -= 1
        _state.on_signal = outer_callback
        for signum, handler in previous.items():
            signal.signal(signum, handler if handler is not None else signal.SIG_DFL)  # type: ignore[arg-type]
