"""Calls from a worker thread into the UI that can never raise into the caller.

A procedure runs in a worker thread and tells the UI what happens (a step started, a partial
result, a live figure for a prompt). The UI may not be ready for it: a dialog not composed
yet, dismissed a moment ago, the app closing. Such a failure is the display's, not the
measurement's, so it is logged and dropped here instead of failing the step that reported it
(issue 30: a live figure sent to a dismissed prompt dialog failed the back-focus step).
"""

from __future__ import annotations

import concurrent.futures
import logging
from collections.abc import Callable
from typing import Any

from textual.app import App

log = logging.getLogger(__name__)


def call_ui(app: App[Any], callback: Callable[..., object], *args: Any, **kwargs: Any) -> bool:
    """Run ``callback(*args)`` in the app's thread and wait for it; never raise.

    Parameters
    ----------
    app : App
        The running app whose event loop runs the callback.
    callback : callable
        UI work: it may query widgets, update them, push screens.
    *args, **kwargs
        Passed to ``callback``.

    Returns
    -------
    bool
        ``True`` when the callback ran to its end; ``False`` when it raised or the app no
        longer runs (the reason is logged, nothing is raised).
    """
    name = getattr(callback, "__qualname__", repr(callback))

    def guarded() -> bool:
        try:
            callback(*args, **kwargs)
        except Exception as exc:  # noqa: BLE001 - a display problem, never the caller's
            log.warning("UI update %s dropped: %r", name, exc)
            app.log.warning(f"UI update {name} dropped: {exc!r}")
            return False
        return True

    try:
        return bool(app.call_from_thread(guarded))
    except (RuntimeError, concurrent.futures.CancelledError) as exc:  # the app has stopped
        log.warning("UI update %s dropped: %r", name, exc)
        return False
