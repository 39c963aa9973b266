"""The base of benchlab's screens: ``self.app`` typed as the benchlab app, so a screen's use
of the bench, its locks and its state is checked by mypy like any other call."""

from __future__ import annotations

from typing import TYPE_CHECKING

from textual.screen import Screen

if TYPE_CHECKING:
    from benchlab.tui.app import BenchlabApp


class BenchScreen(Screen[None]):
    """A full screen of the benchlab app (Live, Run, Sessions, Devices)."""

    if TYPE_CHECKING:  # Textual types ``app`` as any App; ours is always a BenchlabApp
        app: BenchlabApp
