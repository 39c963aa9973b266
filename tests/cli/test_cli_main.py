"""The benchlab entry point: help, version, error reporting."""

from __future__ import annotations

import argparse
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from benchlab import __version__
from benchlab.cli.main import COMMAND_OWNERS, build_parser, command_of, main


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


def _top_level(parser: argparse.ArgumentParser) -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in parser._actions if a.dest == "command")
    return dict(sub.choices)  # type: ignore[arg-type]


def test_each_command_builds_only_its_module_and_parses_the_same() -> None:
    """COMMAND_OWNERS names the module registering each command: a command line builds only
    that module's parsers (start-up), with the same options and defaults as the full one."""
    full = _top_level(build_parser())
    assert set(full) - {"benchmark"} == set(COMMAND_OWNERS)
    for command, module in COMMAND_OWNERS.items():
        partial = _top_level(build_parser(command))
        assert command in partial, command
        # only the owner's commands (and the benchmark group) are there
        assert all(COMMAND_OWNERS.get(c, module) == module for c in partial), command
        for a, b in zip(full[command]._actions, partial[command]._actions, strict=True):
            assert (a.dest, a.option_strings, a.default, a.nargs) == \
                (b.dest, b.option_strings, b.default, b.nargs), command
    args = ["analyze", "frame.tiff", "--roi", "1,2,3,4", "--freq", "6"]
    assert vars(build_parser("analyze").parse_args(args)) == vars(build_parser().parse_args(args))


@pytest.mark.parametrize(("argv", "command"), [
    (["analyze", "x"], "analyze"), (["--log-level", "info", "run", "mtf"], "run"),
    (["--log-level=debug", "--trace-io", "t.txt", "snap"], "snap"), (["--help"], None),
    ([], None), (["--trace-io", "analyze", "sessions"], "sessions"),
])
def test_command_word_after_the_global_options(argv: list[str], command: str | None) -> None:
    assert command_of(argv) == command


def test_unknown_command_still_lists_every_command(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["no-such-command"])
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert "invalid choice: 'no-such-command'" in err and "find-chart" in err and "tui" in err


def _all_parsers(parser: argparse.ArgumentParser, path: str = "benchlab"
                 ) -> list[tuple[str, argparse.ArgumentParser]]:
    out = [(path, parser)]
    for action in parser._actions:
        if isinstance(action, argparse._SubParsersAction):
            for name, sub in action.choices.items():
                out += _all_parsers(sub, f"{path} {name}")
    return out


def test_every_help_text_reads_as_printed() -> None:
    """argparse %-formats argument help but not descriptions: a ``%%`` (or an unexpanded
    ``%(default)s``) in a description prints as written."""
    from benchlab.cli.main import build_parser

    parsers = _all_parsers(build_parser())
    assert len(parsers) > 40
    bad = {path: [line for line in p.format_help().splitlines() if "%%" in line or "%(" in line]
           for path, p in parsers}
    assert {path: lines for path, lines in bad.items() if lines} == {}


def test_the_command_line_offers_every_procedure() -> None:
    """The parser offers the registry's procedures, and the TUI launcher takes a parameter
    file for each."""
    from benchlab.cli.main import build_parser
    from benchlab.procedures import PROCEDURES as DEFINED

    assert DEFINED == ("mtf", "radiometry", "characterise", "depth", "fov")
    parsers = dict(_all_parsers(build_parser()))
    tui_help = parsers["benchlab tui"].format_help()
    run_help = parsers["benchlab run"].format_help()
    for name in DEFINED:
        assert f"--{name}-params FILE" in tui_help
        assert f"{name}:" in run_help  # what each procedure is


def test_tui_hands_every_procedure_s_parameter_file_to_the_app(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    seen: dict[str, Any] = {}

    class App:  # the launcher's side of BenchlabApp, recording what it was given
        close_error = stop_signal = None
        return_code = 0

        def __init__(self, **kwargs: Any) -> None:
            seen.update(kwargs)

        def run(self) -> None:
            seen["ran"] = True

        def stop_from_signal(self, signum: int) -> None:
            raise AssertionError("no signal in this test")

    monkeypatch.setattr("benchlab.tui.app.BenchlabApp", App)
    args = ["tui", "--simulate", "--image", "halfblock", "--sessions", str(tmp_path)]
    for name in ("mtf", "radiometry", "characterise", "depth"):
        args += [f"--{name}-params", str(tmp_path / f"{name}.toml")]
    assert main(args) == 0
    assert seen["ran"] and seen["params_files"] == {
        name: tmp_path / f"{name}.toml" for name in ("mtf", "radiometry", "characterise", "depth")}
