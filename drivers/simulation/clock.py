"""The one test clock every simulator accepts: time moves only when the test says so."""

from __future__ import annotations

import threading


class ManualClock:
    """Simulated time that only moves when a test calls :meth:`advance`.

    It fits both clock interfaces the simulators take: call it (``clock() -> seconds``, the
    serial simulators on a pseudo-terminal) or ask :meth:`now` / :meth:`wait_until` (the
    camera firmware, which may not jump ahead on its own under this clock).
    """

    def __init__(self, start_s: float = 0.0) -> None:
        self._now_s = float(start_s)
        self._lock = threading.Lock()

    def __call__(self) -> float:
        return self.now()

    def now(self) -> float:
        with self._lock:
            return self._now_s

    def advance(self, dt_s: float) -> None:
        if dt_s < 0:
            raise ValueError("time only moves forward")
        with self._lock:
            self._now_s += dt_s

    def wait_until(self, t_s: float) -> bool:
        """Never jumps: frames become ready only when the test advances time."""
        return False
