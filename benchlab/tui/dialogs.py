"""Modal dialogs: operator prompts for manual steps and plain-words error messages."""

from __future__ import annotations

from textual.app import ComposeResult
from textual.binding import Binding
from textual.containers import Horizontal, Vertical
from textual.content import Content
from textual.screen import ModalScreen
from textual.widgets import Button, Input, Label, Static

DIALOG_CSS = """
PromptDialog, ErrorDialog, InputDialog, ConfirmDialog { align: center middle; }
PromptDialog > Vertical, ErrorDialog > Vertical, InputDialog > Vertical,
ConfirmDialog > Vertical {
    width: 70; max-width: 95%; height: auto; max-height: 90%;
    border: thick $accent; background: $surface; padding: 1 2;
}
ErrorDialog > Vertical { border: thick $error; }
PromptDialog .title, ErrorDialog .title, ConfirmDialog .title {
    text-style: bold; margin-bottom: 1;
}
ConfirmDialog > Vertical { border: thick $warning; }
ConfirmDialog Horizontal { height: auto; margin-top: 1; align-horizontal: right; }
ConfirmDialog Button { margin-left: 2; }
PromptDialog #live-figure { color: $success; text-style: bold; margin-top: 1; }
PromptDialog Horizontal { height: auto; margin-top: 1; align-horizontal: right; }
PromptDialog Button, ErrorDialog Button { margin-left: 2; }
"""


def key_label(keys: str, text: str) -> Content:
    """A button label that shows its key: ``key_label("y", "Done")`` reads ``[y] Done``.

    Plain content, not markup: as a markup string ``"[y]"`` is a style tag and vanishes."""
    return Content(f"[{keys}] {text}")


class PromptDialog(ModalScreen[bool]):
    """A manual step: the operator does something on the bench, then confirms (or aborts).

    Dismisses with ``True`` (done) or ``False`` (abort the run). A live figure may arrive from
    the run's thread at any moment: before the dialog is composed it is kept and shown when it
    is, after the dialog is dismissed it is dropped (:meth:`set_live_figure` never raises).
    """

    DEFAULT_CSS = DIALOG_CSS
    BINDINGS = [
        Binding("y,enter", "confirm", "Done"),
        Binding("escape,a", "cancel", "Abort run"),
    ]

    def __init__(self, title: str, message: str) -> None:
        super().__init__()
        self._title = title
        self._message = message
        #: The latest live figure, shown once the dialog is composed.
        self.live_figure = ""

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self._title, classes="title")
            yield Static(self._message, id="prompt-text", markup=False)
            yield Static(self.live_figure, id="live-figure")
            with Horizontal():
                yield Button(key_label("y", "Done"), variant="primary", id="done")
                yield Button(key_label("a", "Abort run"), variant="error", id="abort")

    def on_mount(self) -> None:
        # a figure set between compose and mount is shown too
        self.set_live_figure(self.live_figure)

    def set_live_figure(self, text: str) -> bool:
        """Show a live number (e.g. the sharpness while adjusting back focus).

        Returns whether it is on screen now: ``False`` before the dialog is composed (it is
        kept and shown then) and after it is dismissed (nobody sees it any more).
        """
        self.live_figure = text
        shown = False
        for figure in self.query("#live-figure").results(Static):
            figure.update(text)
            shown = True
        return shown

    def on_button_pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id == "done")

    def action_confirm(self) -> None:
        self.dismiss(True)

    def action_cancel(self) -> None:
        self.dismiss(False)


class ConfirmDialog(ModalScreen[bool]):
    """A yes/no question; dismisses with ``True`` for yes. ``n`` / Escape answer no."""

    DEFAULT_CSS = DIALOG_CSS
    BINDINGS = [
        Binding("y", "answer(True)", "Yes"),
        Binding("n,escape", "answer(False)", "No"),
    ]

    def __init__(self, title: str, message: str, yes: tuple[str, str] = ("y", "Yes"),
                 no: tuple[str, str] = ("n", "No")) -> None:
        """``yes`` / ``no``: each button's (keys, text), shown as ``[keys] text``."""
        super().__init__()
        self._title, self._message, self._yes, self._no = title, message, yes, no

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self._title, classes="title")
            yield Static(self._message, markup=False)
            with Horizontal():
                yield Button(key_label(*self._yes), variant="error", id="yes")
                yield Button(key_label(*self._no), variant="primary", id="no")

    def on_button_pressed(self, event: Button.Pressed) -> None:
        self.dismiss(event.button.id == "yes")

    def action_answer(self, yes: bool) -> None:
        self.dismiss(yes)


class ErrorDialog(ModalScreen[None]):
    """An error the operator must acknowledge (device lost, bad parameter file, disk full)."""

    DEFAULT_CSS = DIALOG_CSS
    BINDINGS = [Binding("escape,enter,y", "close", "Close")]

    def __init__(self, title: str, message: str) -> None:
        super().__init__()
        self._title = title
        self._message = message

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self._title, classes="title")
            yield Static(self._message, id="error-text", markup=False)
            yield Button(key_label("enter", "Close"), variant="error", id="close")

    def on_button_pressed(self, event: Button.Pressed) -> None:
        self.dismiss(None)

    def action_close(self) -> None:
        self.dismiss(None)


class InputDialog(ModalScreen["str | None"]):
    """Ask for one line of text (a file path); Enter accepts, Escape cancels (``None``)."""

    DEFAULT_CSS = DIALOG_CSS
    BINDINGS = [Binding("escape", "cancel", "Cancel")]

    def __init__(self, title: str, hint: str, value: str = "") -> None:
        super().__init__()
        self._title = title
        self._hint = hint
        self._value = value

    def compose(self) -> ComposeResult:
        with Vertical():
            yield Label(self._title, classes="title")
            yield Static(self._hint)
            yield Input(value=self._value, id="value")

    def on_input_submitted(self, event: Input.Submitted) -> None:
        self.dismiss(event.value.strip())

    def action_cancel(self) -> None:
        self.dismiss(None)
