"""Entry point of the ``benchlab`` command.

Each command group lives in its own module exposing ``register(commands, benchmarks)``:
``commands`` is the top-level sub-parser collection, ``benchmarks`` the one under
``benchlab benchmark``. A registered parser sets ``func=handler`` where
``handler(args) -> int`` returns the exit status.
"""

from __future__ import annotations

import argparse
import importlib
import sys
from collections.abc import Sequence

from benchlab import __version__
from benchlab.drivers.errors import BenchlabError

COMMAND_MODULES = (
    "benchlab.cli.camera",  # devices, snap, benchmark camera
    "benchlab.cli.serial",  # led, stage, simulate
    "benchlab.cli.analysis",  # analyze IMAGE, benchmark analysis
    "benchlab.cli.sfr",  # sfr IMAGE (slanted-edge MTF), benchmark sfr
    "benchlab.cli.procedures",  # run, resume, analyze SESSION, report
    "benchlab.cli.batch",  # benchmark batch (analyze SESSION... is in cli.analysis)
    "benchlab.cli.sessions",  # sessions reindex|list|show|trend, benchmark catalog
    "benchlab.cli.viewsynth",  # unwrap, perspective, viewpoint, calibrate radial
    "benchlab.cli.tui",  # tui (and the no-argument default)
)


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="benchlab",
        description=(
            "Run the endoscope optical test bench: camera, LED controller, stage, the Table 4.10 "
            "MTF test and the section 4.4 radiometry, with offline analysis. Every command "
            "takes --simulate to use the built-in simulated bench. With no command, opens the "
            "terminal UI."
        ),
    )
    parser.add_argument("--version", action="version", version=f"benchlab {__version__}")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    bench = commands.add_parser(
        "benchmark", help="measure speed and accuracy and print a table",
        description="Measure speed and accuracy and print a table.",
    )
    benchmarks = bench.add_subparsers(dest="benchmark", metavar="WHAT", required=True)
    for name in COMMAND_MODULES:
        importlib.import_module(name).register(commands, benchmarks)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args_list = list(sys.argv[1:] if argv is None else argv)
    parser = build_parser()
    if not args_list or args_list == ["--simulate"]:
        args_list = ["tui", *args_list]
    args = parser.parse_args(args_list)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return 2
    try:
        return int(func(args) or 0)
    except BenchlabError as exc:
        print(f"benchlab: error: {exc}", file=sys.stderr)
        return 1
    except KeyboardInterrupt:
        print("benchlab: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
