"""A simulated serial instrument served on a real pseudo-terminal.

The simulator owns the master side of ``os.openpty()``; a driver (or any serial program)
opens the slave path exactly as it would open ``/dev/ttyUSB0``. One daemon thread reads the
master, hands bytes to :meth:`PtyDevice.on_bytes` and calls :meth:`PtyDevice.on_tick` every
few milliseconds so time-driven behaviour (move completion, status updates) can happen.

Time is injectable: ``clock`` is any ``() -> float`` seconds callable. Tests pass a
:class:`ManualClock` and advance it explicitly; interactive use takes :class:`ScaledClock`
(``time_scale`` simulated seconds per wall second, 1.0 = real time).
"""

from __future__ import annotations

import contextlib
import os
import select
import threading
import time
import tty
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Self

from benchlab.drivers.simulation.clock import ManualClock

__all__ = ["Clock", "ManualClock", "PtyDevice", "ScaledClock"]

Clock = Callable[[], float]


class ScaledClock:
    """Wall time multiplied by ``time_scale`` (simulated seconds per wall second)."""

    def __init__(self, time_scale: float = 1.0) -> None:
        if not time_scale > 0:
            raise ValueError(f"time_scale must be > 0, got {time_scale}")
        self.time_scale = time_scale
        self._t0 = time.monotonic()

    def __call__(self) -> float:
        return (time.monotonic() - self._t0) * self.time_scale


class PtyDevice(ABC):
    """Base class: serve a byte protocol on a pseudo-terminal from a background thread."""

    poll_interval_s = 0.005  # tick period and read-poll granularity (wall time)
    write_stall_s = 0.5  # drop output the host has not read for this long (wall time)
    name = "pty-device"

    def __init__(self, *, clock: Clock | None = None, time_scale: float = 1.0) -> None:
        self.clock: Clock = clock if clock is not None else ScaledClock(time_scale)
        self.lock = threading.RLock()  # guards simulator state against readers in other threads
        self.transcript: list[tuple[str, bytes]] = []  # ("host"|"dev", one framed unit)
        self._master_fd: int | None = None
        self._slave_fd: int | None = None
        self._port: str | None = None
        self._thread: threading.Thread | None = None
        self._stop_event = threading.Event()
        self.connected = False

    # ---- lifecycle -------------------------------------------------------------------------
    @property
    def port(self) -> str:
        if self._port is None:
            raise RuntimeError(f"{self.name} is not started")
        return self._port

    def start(self) -> str:
        """Open the pseudo-terminal, start serving, return the slave path (``/dev/pts/N``)."""
        if self._thread is not None:
            return self.port
        master, slave = os.openpty()
        # Raw line discipline: no echo, no CR/LF translation - bytes pass exactly as sent.
        tty.setraw(slave)
        tty.setraw(master)
        os.set_blocking(master, False)
        self._master_fd, self._slave_fd = master, slave
        self._port = os.ttyname(slave)  # we keep the slave open so re-opens never see EIO
        self.connected = True
        self._stop_event.clear()
        self._thread = threading.Thread(target=self._serve, name=self.name, daemon=True)
        self._thread.start()
        return self._port

    def stop(self) -> None:
        """Stop serving and close the pseudo-terminal."""
        self._stop_event.set()
        if self._thread is not None and self._thread is not threading.current_thread():
            self._thread.join(timeout=2.0)
        self._thread = None
        self._close_fds()

    def drop_connection(self) -> None:
        """Fault: the link vanishes (cable pulled). The driver's next read/write fails."""
        with self.lock:
            self.connected = False
        self._stop_event.set()
        self._close_fds()

    def __enter__(self) -> Self:
        self.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.stop()

    def _close_fds(self) -> None:
        for attr in ("_master_fd", "_slave_fd"):
            fd = getattr(self, attr)
            setattr(self, attr, None)
            if fd is not None:
                with contextlib.suppress(OSError):
                    os.close(fd)

    # ---- I/O ------------------------------------------------------------------------------
    def write(self, data: bytes, *, log: bool = True) -> None:
        """Send bytes to the host (all of them, or nothing if the link is down)."""
        if log:
            self.transcript.append(("dev", data))
        view = memoryview(data)
        give_up = time.monotonic() + self.write_stall_s
        while view:
            fd = self._master_fd
            if fd is None:
                return
            try:
                n = os.write(fd, view)
            except BlockingIOError:
                # Nobody is reading: like a UART FIFO, overflow is lost rather than blocking.
                if time.monotonic() > give_up:
                    return
                select.select([], [fd], [], self.poll_interval_s)
                continue
            except OSError:
                return  # host gone; a device does not care
            view = view[n:]

    def _serve(self) -> None:
        while not self._stop_event.is_set():
            fd = self._master_fd
            if fd is None:
                return
            try:
                ready, _, _ = select.select([fd], [], [], self.poll_interval_s)
                data = os.read(fd, 4096) if ready else b""
            except (BlockingIOError, InterruptedError):
                data = b""
            except OSError:
                # EIO while no host has the slave open is normal on Linux; keep serving.
                data = b""
                time.sleep(self.poll_interval_s)
            with self.lock:
                if data:
                    self.on_bytes(data)
                self.on_tick(self.clock())

    # ---- subclass hooks -------------------------------------------------------------------
    @abstractmethod
    def on_bytes(self, data: bytes) -> None:
        """Handle bytes the host wrote (each simulator parses its own protocol here)."""

    def on_tick(self, now_s: float) -> None:  # noqa: B027 - optional hook, no-op by default
        """Called every poll interval with the simulated time in seconds."""
