"""The docs site's generated parts and the README's promises (issue 26 items 4 and 6)."""

from __future__ import annotations

import importlib.util
import re
from pathlib import Path
from types import ModuleType
from typing import Any

ROOT = Path(__file__).resolve().parents[1]


def _hooks() -> ModuleType:
    spec = importlib.util.spec_from_file_location("docs_hooks", ROOT / "tools" / "docs_hooks.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_cli_reference_holds_every_command_and_its_help() -> None:
    from benchlab.cli.main import COMMAND_OWNERS, build_parser

    page = _hooks().cli_reference()
    for command in COMMAND_OWNERS:
        assert f"## `benchlab {command}`" in page, command
    # sub-commands at any depth, read from the parser itself: a new one needs no docs edit
    parser = build_parser()
    (bench,) = [a for a in parser._actions if a.dest == "command"]
    benchmarks = bench.choices["benchmark"]._actions[-1].choices  # type: ignore[attr-defined]
    assert {"analysis", "sfr", "chart", "characterise"} <= set(benchmarks)
    for name in benchmarks:
        assert f"### `benchlab benchmark {name}`" in page, name
    assert "#### `benchlab sessions trend`" not in page and "`benchlab sessions trend`" in page
    # each section is the command's own --help
    assert bench.choices["sfr"].format_help().splitlines()[0] in page


def test_a_page_missing_from_nav_joins_its_folders_section(tmp_path: Path) -> None:
    docs = tmp_path / "docs"
    for page in ("index.md", "analysis/bars.md", "analysis/new.md", "hardware.md",
                 "hardware/camera.md", "development/startup.md", "loose.md"):
        (docs / page).parent.mkdir(parents=True, exist_ok=True)
        (docs / page).write_text("# x\n")
    nav: list[Any] = [{"Home": "index.md"}, {"Analysis": [{"Bars": "analysis/bars.md"}]},
                      {"Bench": [{"Hardware": "hardware.md"}]}]
    config = _hooks().on_config({"nav": nav, "docs_dir": str(docs)})
    assert config["nav"] == [
        {"Home": "index.md"},
        {"Analysis": [{"Bars": "analysis/bars.md"}, "analysis/new.md"]},
        {"Bench": [{"Hardware": "hardware.md"}, "hardware/camera.md"]},
        {"Development": ["development/startup.md"]},
        "loose.md",
    ]


def test_readme_fits_and_gives_the_test_command_ci_runs() -> None:
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 250
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    (pytest_line,) = [line for line in ci.splitlines() if "-m pytest" in line]
    command = re.sub(r"^(\w+=\S*\s+)*", "", pytest_line.split("#")[0].strip())
    assert command == "python -m pytest -n 2 -q"
    assert f"    {command}\n" in readme
    assert "mkdocs build --strict" in ci and "mkdocs serve" in readme
