"""Every worker-to-UI call in the TUI goes through :func:`benchlab.tui.ui_calls.call_ui`, which
passes keyword arguments and never raises (issue 30: a display that is not there must never
fail the thread that reported to it)."""

from __future__ import annotations

import ast
from pathlib import Path
from typing import Any

import pytest
from textual.app import App

from benchlab.tui.ui_calls import call_ui

TUI = Path(__file__).resolve().parents[2] / "benchlab" / "tui"


def _raw_calls(path: Path) -> list[int]:
    """Lines calling ``call_from_thread`` with a non-lambda callback (a lambda is a read that
    needs the returned value, which call_ui does not give)."""
    lines = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Attribute)
                and node.func.attr == "call_from_thread"
                and not (node.args and isinstance(node.args[0], ast.Lambda))):
            lines.append(node.lineno)
    return lines


def test_workers_reach_the_ui_only_through_call_ui() -> None:
    found = {p.name: _raw_calls(p) for p in TUI.rglob("*.py") if p.name != "ui_calls.py"}
    assert {name: lines for name, lines in found.items() if lines} == {}


@pytest.mark.asyncio
async def test_call_ui_passes_keywords_and_survives_a_failing_callback() -> None:
    import asyncio

    got: list[Any] = []

    def show(text: str, *, severity: str) -> None:
        got.append((text, severity))

    def broken() -> None:
        raise LookupError("no such widget")

    app: App[None] = App()
    async with app.run_test():
        results = await asyncio.to_thread(
            lambda: (call_ui(app, show, "hello", severity="warning"), call_ui(app, broken)))
    assert results == (True, False)
    assert got == [("hello", "warning")]
    assert call_ui(app, show, "late", severity="x") is False  # the app no longer runs
    assert got == [("hello", "warning")]
