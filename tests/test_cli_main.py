"""The benchlab entry point: help, version, error reporting."""

from __future__ import annotations

import subprocess
import sys

import pytest

from benchlab import __version__
from benchlab.cli.main import build_parser, main


def test_version(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--version"])
    assert exc.value.code == 0
    assert capsys.readouterr().out.strip() == f"benchlab {__version__}"


def test_every_documented_command_is_registered() -> None:
    parser = build_parser()
    sub = next(a for a in parser._actions if a.dest == "command")
    commands = set(sub.choices)  # type: ignore[arg-type]
    expected = {"devices", "snap", "led", "stage", "simulate", "analyze", "run", "resume",
                "report", "tui", "benchmark"}
    assert expected <= commands, f"missing: {expected - commands}"


def test_console_script_help_runs() -> None:
    out = subprocess.run(
        [sys.executable, "-m", "benchlab.cli.main", "--help"],
        capture_output=True, text=True, timeout=60, check=True,
    ).stdout
    text = " ".join(out.split())  # argparse re-wraps the description
    assert "Table 4.10 MTF test" in text and "--simulate" in text
