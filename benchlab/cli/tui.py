"""``benchlab tui``: the technician's terminal UI (also what ``benchlab`` alone opens)."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from benchlab.cli import PROCEDURES


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add the ``tui`` sub-command."""
    parser = commands.add_parser(
        "tui",
        help="open the terminal UI (the default with no command)",
        description=(
            "Open the technician's terminal UI: devices, live view (with a focus aid), the "
            "procedures (Table 4.10 MTF, section 4.4 radiometry, camera characterisation, depth "
            "of field), and saved sessions."
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
    for procedure in PROCEDURES:
        parser.add_argument(f"--{procedure}-params", type=Path, default=None, metavar="FILE",
                            help=f"{procedure} parameter file (default: the packaged one; the "
                            "Run screen's key f changes it)")
    parser.add_argument("--operator", default="", help="operator name for session.json")
    parser.add_argument(
        "--image", choices=("auto", "kitty", "sixel", "halfblock"), default=None,
        help="how the live view draws the camera: real pixels through Kitty's graphics "
        "protocol or Sixel where the terminal supports them (auto, the default, asks the "
        "terminal; env BENCHLAB_IMAGE), else half-block characters",
    )
    parser.set_defaults(func=run_tui)

    bench = benchmarks.add_parser(
        "tui", help="live-view frames per second by terminal size and drawing method",
        description="Run the live view headless on the simulated bench at 80x24, 120x36 and "
        "200x60 with half-blocks, Sixel and Kitty graphics, and print the frames shown per "
        "second (the display is capped at 20 Hz), the CPU ms per shown frame of the UI thread "
        "and of the whole process, and the rate that CPU cost implies on a quiet machine "
        "(min(20, 1000 / process ms); load on a shared machine lowers the measured rate, "
        "hardly the CPU time), and the camera frames read per frame shown (cam/shown: 1 "
        "when the view takes the newest frame). Then, on the camera simulator running on "
        "wall time like a real camera, the grabs per second of the newest frame (the live "
        "view) and of a fresh frame exposed after the request (measurements).",
    )
    bench.add_argument("--seconds", type=float, default=4.0, help="seconds per case (4)")
    bench.add_argument("--method", action="append", choices=("halfblock", "sixel", "kitty"),
                       help="only this drawing method (repeatable; default all three)")
    bench.set_defaults(func=_benchmark_tui)


def _benchmark_tui(args: argparse.Namespace) -> int:
    from benchlab.tui.bench_rate import main

    return main(args.seconds, tuple(args.method or ("halfblock", "sixel", "kitty")))


def run_tui(args: argparse.Namespace) -> int:
    from benchlab.cli.config import bench_file_in_force, sessions_in_force
    from benchlab.drivers import shutdown
    from benchlab.tui.drawing.pixels import choose_image_protocol

    # Ask the terminal what it can show before Textual takes it over.
    image_protocol = choose_image_protocol(getattr(args, "image", None))
    from benchlab.tui.app import BenchlabApp

    params: dict[str, Path] = {name: path for name in PROCEDURES
              if (path := getattr(args, f"{name}_params")) is not None}
    app = BenchlabApp(
        simulate=args.simulate,
        config=bench_file_in_force(args.config, simulate=args.simulate).value,
        sessions_dir=sessions_in_force(args.sessions, "--sessions").value,
        params_files=params, operator=args.operator, image_protocol=image_protocol,
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
