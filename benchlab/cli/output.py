"""One rule for every file a command writes at the user's request (issue 38).

Every option that names an output file (``report --out``, ``certificate --out``, ``sessions
list --csv``, ``sessions trend --plot``, ``find-chart --plot``, ``--trace-io`` ...) is added
with :func:`add_output_option` and written with :func:`write_output` (or checked with
:func:`check_output` when a lower layer writes it). The rule:

* never inside a session's managed parts - ``frames/``, ``results/``, ``verdicts/``,
  ``session.json``, ``events.jsonl``, the owner lock - nor over a sessions folder's catalogue:
  those change only through the session's own API. Refused even with ``--force``.
* an existing file is replaced only with ``--force``; otherwise a usage error (exit 2) names
  the file and nothing is written.
* written to a temporary file in the same folder and renamed into place
  (:func:`benchlab.storage.atomic_write_bytes`), so a crash or a full disk never leaves half
  a file, and without ``--force`` the final link refuses a file that appeared meanwhile.

``tests/cli/test_output_policy.py`` walks every parser and fails on an option that looks like
an output file but was not added here.

What a command prints on stdout as its result - a table, or one JSON document with ``--json`` -
and the exit code its outcome gives go through :func:`print_outcome`.
"""

from __future__ import annotations

import argparse
import json
from collections.abc import Callable
from pathlib import Path
from typing import Any

from benchlab.drivers.errors import UsageError

#: Help text every output option ends with.
FORCE_NOTE = "an existing file is replaced only with --force"
#: The top-level ``benchlab --force`` (for ``--trace-io``) lands here, so that a
#: sub-command's own ``--force`` default cannot hide it.
GLOBAL_FORCE_DEST = "force_global"


class OutputFile(argparse.Action):
    """An option naming a file the command writes; marks it for the policy test."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        setattr(namespace, self.dest, values)


def add_output_option(parser: argparse.ArgumentParser, *flags: str, help: str,  # noqa: A002
                      **kwargs: Any) -> argparse.Action:
    """Add an output-file option (and the parser's ``--force`` once)."""
    add_force_option(parser)
    return parser.add_argument(*flags, action=OutputFile, help=f"{help}; {FORCE_NOTE}",
                               **kwargs)


def add_force_option(parser: argparse.ArgumentParser) -> None:
    """``--force``: replace existing output files (never a session's own files)."""
    if "--force" not in parser._option_string_actions:
        parser.add_argument("--force", action="store_true",
                            help="replace output files that already exist (never a session's "
                                 "frames, results, verdicts, session file or journal)")


def forced(args: argparse.Namespace) -> bool:
    """Whether ``--force`` was given, to the sub-command or to ``benchlab`` itself."""
    return bool(getattr(args, "force", False) or getattr(args, GLOBAL_FORCE_DEST, False))


def session_part(path: str | Path) -> str | None:
    """Why ``path`` belongs to a session or a catalogue (``frames/ of session S``), or None.

    Symbolic links are followed, so a link pointing into ``frames/`` is caught as well.
    """
    from benchlab.catalog.index import CATALOG_FILE
    from benchlab.session import (
        EVENTS_FILE,
        FRAMES_DIR,
        OWNER_FILE,
        RESULTS_DIR,
        SESSION_FILE,
        VERDICTS_DIR,
    )

    target = Path(path).resolve()
    if target.name.startswith(CATALOG_FILE):  # catalog.sqlite and its -wal / -journal files
        return f"the sessions catalogue of {target.parent}"
    for folder in target.parents:
        if not (folder / SESSION_FILE).is_file():
            continue
        first = target.relative_to(folder).parts[0]
        if first in (FRAMES_DIR, RESULTS_DIR, VERDICTS_DIR):
            return f"{first}/ of session {folder}"
        if first in (SESSION_FILE, EVENTS_FILE, OWNER_FILE) and target.parent == folder:
            return f"the {first} of session {folder}"
        return None  # elsewhere in a session folder (report.html, a certificate)
    return None


def check_output(path: str | Path, *, force: bool, option: str) -> Path:
    """``path`` if the policy lets the command write it; else :class:`UsageError` naming it.

    Parameters
    ----------
    path
        The file the option names.
    force
        ``--force`` was given: an existing file (outside a session's own parts) may go.
    option
        The option's name for the message (``--out``), or the command's default.
    """
    target = Path(path)
    part = session_part(target)
    if part is not None:
        raise UsageError(f"{option} {target}: is part of {part}, which only benchlab's session "
                         "commands write; nothing written (name a file outside it)")
    if target.is_dir():
        raise UsageError(f"{option} {target}: is a folder; name a file")
    if (target.exists() or target.is_symlink()) and not force:
        raise UsageError(f"{option} {target}: already exists; nothing written (add --force to "
                         "replace it)")
    return target


def write_output(path: str | Path, data: bytes | str, *, force: bool, option: str) -> Path:
    """Check ``path`` (:func:`check_output`) and write ``data`` atomically (temporary file
    in the same folder, then rename); returns the path written."""
    from benchlab.storage import atomic_write_bytes

    target = check_output(path, force=force, option=option)
    raw = data.encode("utf-8") if isinstance(data, str) else data
    try:
        return atomic_write_bytes(target, raw, overwrite=force)
    except FileExistsError:  # created meanwhile: the link refused it
        raise UsageError(f"{option} {target}: already exists; nothing written (add --force to "
                         "replace it)") from None


def print_outcome(as_json: bool, payload: Callable[[], Any], text: Callable[[], str | None], *,
                  status: int = 0, **json_options: Any) -> int:
    """Print a command's result and return its exit code.

    Parameters
    ----------
    as_json
        ``--json`` was given: ``payload()`` is printed as one JSON document
        (``json.dumps(payload(), **json_options)``), nothing else.
    payload, text
        The result as data, and as text for a person: ``text()`` returns what to print, or
        prints several parts itself and returns None. Only the one asked for is computed.
    status
        The exit code the outcome gives (0 ok; a check that failed: 1, ...).
    """
    if as_json:
        print(json.dumps(payload(), **json_options))
    else:
        shown = text()
        if shown is not None:
            print(shown)
    return status

