"""`benchlab.cli.output.print_outcome`: a command's result as a table or one JSON document,
and the exit code its outcome gives (issue 42: one helper instead of a copy per command)."""

from __future__ import annotations

import ast
import json
from pathlib import Path

import pytest

import benchlab.cli
from benchlab.cli.output import print_outcome


def _never() -> object:
    raise AssertionError("only the form asked for is computed")


def test_json_prints_the_payload_alone_with_the_options_given(
        capsys: pytest.CaptureFixture[str]) -> None:
    status = print_outcome(True, lambda: {"b": 1.5, "a": [1]}, _never, status=3, indent=2)  # type: ignore[arg-type]
    out = capsys.readouterr().out
    assert status == 3
    assert out == json.dumps({"b": 1.5, "a": [1]}, indent=2) + "\n"


def test_text_prints_what_text_returns_or_what_it_printed_itself(
        capsys: pytest.CaptureFixture[str]) -> None:
    assert print_outcome(False, _never, lambda: "a table") == 0
    assert capsys.readouterr().out == "a table\n"

    def printed() -> None:
        print("part 1")
        print("part 2")

    assert print_outcome(False, _never, printed, status=1) == 1
    assert capsys.readouterr().out == "part 1\npart 2\n"


def test_json_options_reach_json_dumps(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(ValueError, match="Out of range float"):
        print_outcome(True, lambda: {"x": float("nan")}, _never, allow_nan=False)  # type: ignore[arg-type]
    assert capsys.readouterr().out == ""


def _json_prints(source: str) -> list[int]:
    """Lines of ``source`` where a result is printed as JSON by hand: ``print(json.dumps(...))``."""
    lines = []
    for node in ast.walk(ast.parse(source)):
        if (isinstance(node, ast.Call) and isinstance(node.func, ast.Name)
                and node.func.id == "print" and node.args
                and isinstance(first := node.args[0], ast.Call)
                and isinstance(first.func, ast.Attribute) and first.func.attr == "dumps"
                and isinstance(first.func.value, ast.Name) and first.func.value.id == "json"):
            lines.append(node.lineno)
    return lines


def test_no_command_prints_its_json_result_by_hand() -> None:
    """Every ``--json`` result goes through print_outcome; a copy of the block is named."""
    assert _json_prints("import json\nprint(json.dumps({}), end='')\n") == [2]  # the finder finds
    cli = Path(benchlab.cli.__file__).parent
    by_hand = {str(p.relative_to(cli)): found for p in sorted(cli.rglob("*.py"))
               if p.name != "output.py" and (found := _json_prints(p.read_text("utf-8")))}
    assert by_hand == {}
