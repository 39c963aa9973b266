"""MkDocs hooks for the benchlab docs site (listed under ``hooks:`` in mkdocs.yml).

- ``on_config``: a page under ``docs/`` that ``nav`` does not list is added to the section
  holding its folder's other pages (or to a new section named after the folder), so a page
  another engineer adds shows up without an edit to mkdocs.yml.
- ``on_files``: ``reference/cli.md`` is written from the ``benchlab`` argparse parser
  (:func:`benchlab.cli.main.build_parser`) on every build: every command and sub-command with its
  ``--help``, so a new command is documented the moment it is registered.
"""

from __future__ import annotations

import argparse
import os
from collections.abc import Iterator
from pathlib import Path
from typing import Any

CLI_PAGE = "reference/cli.md"
#: Help text is wrapped at this width whatever terminal runs the build (a stable page).
HELP_COLUMNS = "100"


def _nav_pages(nav: Any) -> Iterator[str]:
    """Every page path a ``nav`` entry lists, at any depth."""
    if isinstance(nav, str):
        yield nav
    elif isinstance(nav, list):
        for item in nav:
            yield from _nav_pages(item)
    elif isinstance(nav, dict):
        for value in nav.values():
            yield from _nav_pages(value)


def _section_for(nav: list[Any], folder: str) -> list[Any] | None:
    """The top-level section list whose pages live in ``folder`` (or are ``folder.md``)."""
    for item in nav:
        if isinstance(item, dict):
            for value in item.values():
                if isinstance(value, list) and any(
                    page.startswith(folder + "/") or page == folder + ".md"
                    for page in _nav_pages(value)
                ):
                    return value
    return None


def on_config(config: Any) -> Any:
    nav = config.get("nav")
    if not nav:
        return config  # no explicit nav: MkDocs lists every page itself
    docs = Path(config["docs_dir"])
    listed = set(_nav_pages(nav)) | {CLI_PAGE}
    for path in sorted(docs.rglob("*.md")):
        page = path.relative_to(docs).as_posix()
        if page in listed:
            continue
        folder = page.rsplit("/", 1)[0] if "/" in page else ""
        section = _section_for(nav, folder) if folder else None
        if section is None and folder:
            section = []
            nav.append({folder.replace("-", " ").capitalize(): section})
        (section if section is not None else nav).append(page)
    return config


Command = tuple[tuple[str, ...], str, argparse.ArgumentParser]


def _commands(parser: argparse.ArgumentParser, words: tuple[str, ...] = ()) -> Iterator[Command]:
    """(command words, one-line help, parser) for ``parser`` and every sub-command below it."""
    for action in parser._actions:
        if not isinstance(action, argparse._SubParsersAction):
            continue
        helps = {choice.dest: choice.help or "" for choice in action._choices_actions}
        seen: set[int] = set()
        for name, sub in action.choices.items():
            if id(sub) in seen:  # an alias of a command already listed
                continue
            seen.add(id(sub))
            yield (*words, name), helps.get(name, ""), sub
            yield from _commands(sub, (*words, name))


def cli_reference() -> str:
    """The CLI reference page, in Markdown."""
    from benchlab.cli.main import build_parser

    before = os.environ.get("COLUMNS")
    os.environ["COLUMNS"] = HELP_COLUMNS
    try:
        parser = build_parser()
        lines = [
            "# Command-line reference",
            "",
            "Generated from the `benchlab` argument parser each time the site is built: it is "
            "exactly what `benchlab ... --help` prints. Global options (`--log-level`, "
            "`--trace-io`) go before the command.",
            "",
            "| command | what it does |",
            "|---|---|",
        ]
        commands = list(_commands(parser))
        for words, summary, _ in commands:
            anchor = "benchlab-" + "-".join(words)
            lines.append(f"| [`benchlab {' '.join(words)}`](#{anchor}) | {summary} |")
        lines += ["", "## `benchlab`", "", "```text", parser.format_help().rstrip(), "```", ""]
        for words, _, sub in commands:
            anchor = "benchlab-" + "-".join(words)
            level = "#" * min(2 + len(words) - 1, 4)
            lines += [f"{level} `benchlab {' '.join(words)}` {{#{anchor}}}", "",
                      "```text", sub.format_help().rstrip(), "```", ""]
        return "\n".join(lines)
    finally:
        if before is None:
            os.environ.pop("COLUMNS", None)
        else:
            os.environ["COLUMNS"] = before


def on_files(files: Any, config: Any) -> Any:
    from mkdocs.structure.files import File

    files.append(File.generated(config, CLI_PAGE, content=cli_reference()))
    return files
