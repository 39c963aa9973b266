"""``benchlab tui``: the technician's terminal UI (also what ``benchlab`` alone opens)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add the ``tui`` sub-command."""
    parser = commands.add_parser(
        "tui",
        help="open the terminal UI (the default with no command)",
        description=(
            "Open the technician's terminal UI: devices, live view, the Table 4.10 MTF and "
            "radiometry procedures, and saved sessions."
        ),
    )
    parser.add_argument("--simulate", action="store_true", help="use the simulated bench")
    parser.add_argument("--config", type=Path, default=None,
                        help="bench configuration (TOML; default: the user's, see "
                        "`benchlab config show`)")
    parser.add_argument(
        "--sessions", type=Path, default=None,
        help="folder of saved sessions (default: [paths] sessions of the user's bench.toml, "
        "else ./sessions)",
    )
    parser.add_argument("--mtf-params", type=Path, default=None, help="MTF parameter file")
    parser.add_argument(
        "--radiometry-params", type=Path, default=None, help="radiometry parameter file"
    )
    parser.add_argument("--operator", default="", help="operator name for session.json")
    parser.set_defaults(func=run_tui)


def run_tui(args: argparse.Namespace) -> int:
    from benchlab.cli.config import bench_file_in_force, sessions_in_force
    from benchlab.tui.app import BenchlabApp

    params = {
        name: path
        for name, path in (("mtf", args.mtf_params), ("radiometry", args.radiometry_params))
        if path is not None
    }
    app = BenchlabApp(
        simulate=args.simulate,
        config=bench_file_in_force(args.config, simulate=args.simulate).value,
        sessions_dir=sessions_in_force(args.sessions, "--sessions").value,
        params_files=params, operator=args.operator,
    )
    app.run()
    if app.close_error is not None:
        from benchlab.tui.services import plain_error

        print(f"benchlab: error while closing the bench: {plain_error(app.close_error)}",
              file=sys.stderr)
        return 1
    return int(app.return_code or 0)
