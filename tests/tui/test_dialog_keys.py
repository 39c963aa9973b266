"""Every dialog button shows the key that presses it, as the terminal shows it at 80x24 (a
label such as "Done [y]" given as markup loses its "[y]": a style tag)."""

from __future__ import annotations

import pytest
from screen_text import screen_text
from textual.app import App
from textual.screen import Screen

from benchlab.tui.dialogs import ConfirmDialog, ErrorDialog, PromptDialog


@pytest.mark.asyncio
@pytest.mark.parametrize(("dialog", "keys"), [
    (lambda: PromptDialog("Step 3", "Mount the chart."), ["[y] Done", "[a] Abort run"]),
    (lambda: ConfirmDialog("Quit?", "A run is active.", yes=("y/q", "Quit"),
                           no=("n", "Keep running")), ["[y/q] Quit", "[n] Keep running"]),
    (lambda: ConfirmDialog("Sure?", "Really."), ["[y] Yes", "[n] No"]),
    (lambda: ErrorDialog("Camera lost", "USB read timed out."), ["[enter] Close"]),
])
async def test_buttons_show_their_keys(dialog: object, keys: list[str]) -> None:
    class Host(App[None]):
        def on_mount(self) -> None:
            self.push_screen(dialog())  # type: ignore[operator]

    app = Host()
    async with app.run_test(size=(80, 24)) as pilot:
        await pilot.pause()
        assert isinstance(app.screen, Screen)
        text = "\n".join(screen_text(app))
        for key in keys:
            assert key in text, text
