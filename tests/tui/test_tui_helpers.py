"""Shared helpers of the TUI tests (collected by pytest, but holds no tests)."""

from __future__ import annotations

import time
from collections.abc import Callable
from pathlib import Path

from textual.pilot import Pilot
from textual.widgets import Static

from benchlab.tui.app import BenchlabApp
from benchlab.tui.dialogs import ErrorDialog, PromptDialog
from benchlab.tui.live import LiveScreen

MTF_PARAMS = """\
procedure = "mtf"
[focus]
frames = 1
[forward]
elements = ["G2E1", "G2E4"]
[radial]
frequencies_lp_per_mm = [1, 4]
"""

RADIOMETRY_PARAMS = """\
procedure = "radiometry"
[positions]
field_mm = [15, 25]
[analysis]
simulated_irradiance_mw_per_mm2 = [22.48, 14.34]
"""


def make_app(tmp_path: Path, **params: str) -> BenchlabApp:
    """A simulated-bench app with small parameter files written under ``tmp_path``."""
    files = {}
    for name, text in params.items():
        path = tmp_path / f"{name}.toml"
        path.write_text(text, encoding="utf-8")
        files[name] = path
    return BenchlabApp(simulate=True, sessions_dir=tmp_path / "sessions", params_files=files)


async def wait_until(
    pilot: Pilot[None],
    condition: Callable[[], bool],
    *,
    timeout_s: float = 90.0,
    answer_prompts: bool = False,
    what: str = "condition",
) -> int:
    """Pause the pilot until ``condition()``; optionally confirm manual-step prompts.

    Returns how many prompts were confirmed. The timeout is only a guard against hangs.
    Each prompt dialog is answered once: on a loaded CPU the dialog can still be on screen
    after the key press returned (its key not handled yet), and a second "y" would be
    counted for a prompt that was not there.
    """
    answered = 0
    last: PromptDialog | None = None
    deadline = time.monotonic() + timeout_s
    while not condition():
        screen = pilot.app.screen
        if answer_prompts and isinstance(screen, PromptDialog) and screen is not last:
            await pilot.press("y")
            last = screen
            answered += 1
        await pilot.pause(0.05)
        if time.monotonic() > deadline:
            raise AssertionError(f"timed out waiting for {what}")
    return answered


async def connected(pilot: Pilot[None]) -> None:
    """Wait for the simulated bench; fail at once, with its text, if connecting failed."""
    app = pilot.app

    def ready() -> bool:
        if isinstance(app.screen, ErrorDialog):
            text = app.screen.query_one("#error-text", Static).render()
            raise AssertionError(f"the bench did not connect: {text}")
        return app.bench is not None  # type: ignore[attr-defined]

    await wait_until(pilot, ready, what="bench connected")


async def open_live(pilot: Pilot[None], frames: int) -> LiveScreen:
    """Connect, open the Live screen (key 2) and wait until it has shown ``frames`` frames."""
    await connected(pilot)
    await pilot.press("2")
    live = pilot.app.screen
    assert isinstance(live, LiveScreen)
    await wait_until(pilot, lambda: live.frames_displayed >= frames, what="frames")
    return live
