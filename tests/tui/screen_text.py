"""The text a terminal shows of a running Textual app (no tests here): what a user reads."""

from __future__ import annotations

from textual.app import App


def screen_text(app: App[object]) -> list[str]:
    """The visible lines of ``app``'s current screen, as rendered at the app's size."""
    return [strip.text for strip in app.screen._compositor.render_strips()]
