"""What every instrument that can hurt the bench shares: it is made safe on every exit path.

:class:`SafeInstrument` gives a driver the context-manager protocol (``close()`` - which makes
the instrument safe before releasing it - runs on normal exit and on any exception, keeping
the original error and noting a failed safe-state) and an interpreter-exit hook that closes
an instrument still open. The hook holds only a weak reference, so it never keeps a driver
alive; ``__del__`` is deliberately not used for shutdown.

An open instrument is also watched by :mod:`benchlab.drivers.shutdown`, so SIGTERM and SIGHUP
(``systemctl stop``, a closed terminal) unwind like Ctrl-C and ``close()`` runs; an instrument
that can act at once from the signal handler overrides :meth:`_on_stop_signal`.
"""

from __future__ import annotations

import atexit
import weakref
from abc import ABC, abstractmethod
from collections.abc import Callable
from types import TracebackType
from typing import Self

from benchlab.drivers import shutdown
from benchlab.drivers.errors import DeviceError


class SafeInstrument(ABC):
    """Base class: context manager + atexit safety for one instrument."""

    #: Says what ``close()`` does to make the instrument safe, for error notes.
    SAFE_ACTION = "making the instrument safe"

    _atexit_cb: Callable[[], None] | None = None

    @abstractmethod
    def open(self) -> Self:
        """Open the connection and bring the instrument to a known, safe state."""

    @abstractmethod
    def close(self) -> None:
        """Make the instrument safe, then release the connection."""

    @property
    @abstractmethod
    def is_open(self) -> bool:
        """Whether the connection is open."""

    def __enter__(self) -> Self:
        return self if self.is_open else self.open()

    def __exit__(
        self, exc_type: type[BaseException] | None, exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        if exc is None:
            self.close()
            return
        try:
            self.close()
        except DeviceError as safe_exc:  # keep the original error; record the failed safe-state
            exc.add_note(f"{self.SAFE_ACTION} also failed: {safe_exc}")

    def _on_stop_signal(self) -> None:
        """Called from the signal handler (main thread) on SIGINT/SIGTERM/SIGHUP, before the
        program unwinds; default: nothing, ``close()`` on the way out makes it safe."""
        return None

    def _register_atexit(self) -> None:
        """Close this instrument at interpreter exit if it is still open, and watch it for
        stop signals."""
        ref = weakref.ref(self)

        def at_exit() -> None:
            obj = ref()
            if obj is not None and obj.is_open:
                try:
                    obj.close()
                except DeviceError:
                    pass  # nothing left to report to at interpreter exit

        self._unregister_atexit()
        self._atexit_cb = at_exit
        atexit.register(at_exit)
        shutdown.watch(self)

    def _unregister_atexit(self) -> None:
        if self._atexit_cb is not None:
            atexit.unregister(self._atexit_cb)
            self._atexit_cb = None
        shutdown.unwatch(self)
