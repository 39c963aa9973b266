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
    parser.add_argument("--config", type=Path, default=None, help="bench configuration (TOML)")
    parser.add_argument(
        "--sessions", type=Path, default=Path("sessions"),
        help="folder of saved sessions (default: ./sessions)",
    )
    parser.add_argument("--mtf-params", type=Path, default=None, help="MTF parameter file")
    parser.add_argument(
        "--radiometry-params", type=Path, default=None, help="radiometry parameter file"
    )
    parser.add_argument("--operator", default="", help="operator name for session.json")
    parser.set_defaults(func=run_tui)


def run_tui(args: argparse.Namespace) -> int:
    from benchlab.drivers import shutdown
    from benchlab.tui.app import BenchlabApp

    params = {
        name: path
        for name, path in (("mtf", args.mtf_params), ("radiometry", args.radiometry_params))
        if path is not None
    }
    app = BenchlabApp(
        simulate=args.simulate, config=args.config, sessions_dir=args.sessions,
        params_files=params, operator=args.operator,
    )
    with shutdown.handling_signals(on_signal=app.stop_from_signal):
        app.run()
    if app.close_error is not None:
        from benchlab.tui.services import plain_error

        print(f"benchlab: error while closing the bench: {plain_error(app.close_error)}",
              file=sys.stderr)
        return 1
    if app.stop_signal is not None:
        print(f"benchlab: stopped by {shutdown.signal_name(app.stop_signal)}; bench left safe",
              file=sys.stderr)
        return 128 + app.stop_signal
    return int(app.return_code or 0)
