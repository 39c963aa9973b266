"""Entry point of the ``benchlab`` command.

Each command group lives in its own module, in ``devices/`` (the instruments), ``runs/``
(procedures, sessions, verdicts) or ``frames/`` (analysis of saved frames), or beside this one
(``tui``, ``config``, ``startup``). A module exposes ``register(commands, benchmarks)``:
``commands`` is the top-level sub-parser collection, ``benchmarks`` the one under
``benchlab benchmark``. A registered parser sets ``func=handler`` where
``handler(args) -> int`` returns the exit status.
"""

from __future__ import annotations

import argparse
import codecs
import contextlib
import errno
import importlib
import io
import os
import sys
from collections.abc import Iterator, Sequence

from benchlab.cli import UsageError
from benchlab.cli.output import FORCE_NOTE, GLOBAL_FORCE_DEST, OutputFile, check_output, forced
from benchlab.drivers import shutdown
from benchlab.drivers.errors import BenchlabError

COMMAND_MODULES = (
    "benchlab.cli.devices.camera",  # devices, snap, benchmark camera
    "benchlab.cli.devices.serial",  # led, stage, simulate
    "benchlab.cli.frames.analysis",  # analyze IMAGE, benchmark analysis
    "benchlab.cli.frames.chart",  # find-chart, benchmark chart (analyze --chart usaf)
    "benchlab.cli.frames.sfr",  # sfr IMAGE (slanted-edge MTF), benchmark sfr
    "benchlab.cli.runs.procedures",  # run, resume, analyze SESSION, report
    "benchlab.cli.runs.batch",  # benchmark batch (analyze SESSION... is in cli.analysis)
    "benchlab.cli.runs.sessions",  # sessions reindex|list|show|trend, benchmark catalog
    "benchlab.cli.frames.viewsynth",  # unwrap, perspective, viewpoint, calibrate radial
    "benchlab.cli.tui",  # tui (and the no-argument default)
    "benchlab.cli.config",  # config init, config show
    "benchlab.cli.startup",  # benchmark startup
    "benchlab.cli.devices.soak",  # benchmark soak
    "benchlab.cli.runs.verify",  # verify, units, unit, lot, certificate (acceptance per unit)
    "benchlab.cli.devices.doctor",  # doctor (guided bring-up)
    "benchlab.cli.runs.depth",  # benchmark depth (run depth is in cli.procedures)
    "benchlab.cli.runs.fov",  # benchmark fov (run fov is in cli.procedures)
)
#: Top-level command -> the module (of COMMAND_MODULES) that registers it. A command line
#: naming one of these builds only that module's parsers: the full parser (every module
#: imported, ~45 sub-parsers) costs 50-100 ms of start-up. tests/test_cli_main.py checks
#: this table against what the modules register.
COMMAND_OWNERS = {
    "devices": "benchlab.cli.devices.camera", "snap": "benchlab.cli.devices.camera",
    "led": "benchlab.cli.devices.serial", "stage": "benchlab.cli.devices.serial",
    "simulate": "benchlab.cli.devices.serial",
    "analyze": "benchlab.cli.frames.analysis",
    "find-chart": "benchlab.cli.frames.chart",
    "sfr": "benchlab.cli.frames.sfr",
    "run": "benchlab.cli.runs.procedures", "resume": "benchlab.cli.runs.procedures",
    "report": "benchlab.cli.runs.procedures",
    "sessions": "benchlab.cli.runs.sessions",
    "unwrap": "benchlab.cli.frames.viewsynth", "perspective": "benchlab.cli.frames.viewsynth",
    "viewpoint": "benchlab.cli.frames.viewsynth", "calibrate": "benchlab.cli.frames.viewsynth",
    "tui": "benchlab.cli.tui",
    "config": "benchlab.cli.config",
    "verify": "benchlab.cli.runs.verify", "units": "benchlab.cli.runs.verify",
    "unit": "benchlab.cli.runs.verify", "lot": "benchlab.cli.runs.verify",
    "certificate": "benchlab.cli.runs.verify",
    "doctor": "benchlab.cli.devices.doctor",
}
LOG_LEVELS = ("debug", "info", "warning", "error")
#: Set to 1 for ``analyze`` (issue 11): numpy's OpenBLAS starts a worker per core at import
#: and they spin waiting for work (~90 ms of CPU during the import, ~15 ms per 50 ms after),
#: taking a core from the frame loads and the forward view's thread; the analysis's linear
#: algebra is a few dozen points (least squares), which gains nothing from them.
ONE_BLAS_THREAD = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
#: Where ``benchlab --append`` (for ``--trace-io``) lands.
APPEND_TRACE_DEST = "append_trace"
#: Top-level options that take a value as the next word (``--log-level info``).
_OPTIONS_WITH_VALUE = ("--log-level", "--trace-io", "--replay")


class _VersionAction(argparse.Action):
    """``--version``, looking the version up only when asked (start-up time)."""

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: object, option_string: str | None = None) -> None:
        from benchlab import __version__

        print(f"benchlab {__version__}")
        parser.exit()


def command_of(argv: Sequence[str]) -> str | None:
    """The top-level command word of a command line (after the global options), if any."""
    words = iter(argv)
    for word in words:
        if word in _OPTIONS_WITH_VALUE:
            next(words, None)
        elif not word.startswith("-"):
            return word
    return None


def build_parser(command: str | None = None) -> argparse.ArgumentParser:
    """The ``benchlab`` parser; with a ``command`` of :data:`COMMAND_OWNERS`, only that
    command's module is registered (everything else parses the same)."""
    parser = argparse.ArgumentParser(
        prog="benchlab",
        description=(
            "Run the endoscope optical test bench: camera, LED controller, stage, the Table 4.10 "
            "MTF test, the section 4.4 radiometry, camera characterisation and depth of field, "
            "with offline analysis and acceptance per unit. Every command that uses the bench "
            "takes --simulate to use the built-in simulated bench. With no command, opens the "
            "terminal UI."
        ),
    )
    parser.add_argument("--version", action=_VersionAction, nargs=0,
                        help="print the version and exit")
    parser.add_argument("--log-level", choices=LOG_LEVELS, default="warning",
                        help="log messages from this level up to stderr (default warning)")
    parser.add_argument("--trace-io", metavar="FILE", action=OutputFile,
                        help="record every device exchange to FILE, a cassette (.gz: "
                             f"compressed) that --replay plays back; {FORCE_NOTE}, and added "
                             "to only with --append")
    parser.add_argument("--force", action="store_true", dest=GLOBAL_FORCE_DEST,
                        help="let --trace-io replace an existing file (sub-commands that "
                             "write files take their own --force)")
    parser.add_argument("--append", action="store_true", dest=APPEND_TRACE_DEST,
                        help="let --trace-io add this command's exchanges to the end of an "
                             "existing cassette (same format: .gz or not); any other file "
                             "is refused")
    parser.add_argument("--replay", metavar="FILE",
                        help="answer the drivers with the bytes recorded in the cassette FILE "
                             "instead of devices (no hardware, no simulator)")
    commands = parser.add_subparsers(dest="command", metavar="COMMAND")
    bench = commands.add_parser(
        "benchmark", help="measure speed and accuracy and print a table",
        description="Measure speed and accuracy and print a table.",
    )
    benchmarks = bench.add_subparsers(dest="benchmark", metavar="WHAT", required=True)
    owner = COMMAND_OWNERS.get(command or "")
    for name in (owner,) if owner else COMMAND_MODULES:
        importlib.import_module(name).register(commands, benchmarks)
    return parser


def plain_os_error(exc: OSError) -> str:
    """``/data/x: permission denied (read-only?)`` rather than a traceback."""
    what = exc.strerror or str(exc) or type(exc).__name__
    hint = {errno.EACCES: " (no permission to write there?)",
            errno.EROFS: " (read-only file system)",
            errno.EEXIST: " (already exists; nothing was overwritten)",
            errno.ENOSPC: " (disk full)",
            errno.EFBIG: " (over the file size limit: ulimit -f)"}.get(exc.errno or 0, "")
    name = exc.filename if exc.filename is not None else ""
    return f"{name}: {what.lower()}{hint}" if name else f"{what}{hint}"


#: Options that belong to ``benchlab`` itself, not to the terminal UI.
_TOP_LEVEL_OPTIONS = {"-h", "--help", "--version", "--log-level", "--trace-io", "--replay",
                      "--force", "--append"}


def main(argv: Sequence[str] | None = None) -> int:
    """Run one command; exit status 0, 1 (runtime error), 2 (usage error) or 128 + signal.

    SIGINT, SIGTERM and SIGHUP all stop the command the same way (:mod:`benchlab.drivers.
    shutdown`): LEDs off, stage stopped, a running session journalled as interrupted.

    Called as the program (``argv`` None), the objects left when the command is done are
    frozen (:func:`gc.freeze`): the process ends next, and the cycle collections of the
    interpreter's exit over every object of numpy and benchlab took 20-60 ms of a 0.4 s
    ``benchlab analyze SESSION`` (issue 11). Exit handlers and buffered output are unchanged.
    ``analyze`` (one image or a re-analysis: short, few reference cycles) also runs without
    cycle collection: ~60 passes over the objects of the imports cost it 10-15 ms, and with
    one BLAS thread (:data:`ONE_BLAS_THREAD`, unless the user set them).
    """
    import gc

    program = argv is None
    if program and command_of(sys.argv[1:]) == "analyze":
        gc.disable()  # not enabled again: the process ends with the command
        for name in ONE_BLAS_THREAD:  # before numpy is imported (nothing above imports it)
            os.environ.setdefault(name, "1")
    status = _main(argv)
    if program:
        gc.freeze()
    return status


#: The error handler of the command's output: a character the terminal's encoding cannot
#: take (a folder name's byte that is not UTF-8) is printed escaped, never a traceback.
PRINTABLE_ERRORS = "benchlab.printable"


def _escape_unencodable(exc: UnicodeError) -> tuple[str, int]:
    """A file name's undecodable byte (Python's surrogate escape U+DC80-U+DCFF) as ``\\xNN``,
    as :func:`benchlab.storage.printable_name` shows it; anything else as ``\\uNNNN``."""
    if not isinstance(exc, UnicodeEncodeError):
        raise exc
    text = exc.object[exc.start:exc.end]
    return "".join(f"\\x{ord(c) - 0xDC00:02x}" if 0xDC80 <= ord(c) <= 0xDCFF
                   else c.encode("ascii", "backslashreplace").decode("ascii")
                   for c in text), exc.end


codecs.register_error(PRINTABLE_ERRORS, _escape_unencodable)


@contextlib.contextmanager
def _printable_output() -> Iterator[None]:
    """stdout and stderr escape what they cannot encode while a command runs (the streams
    are restored after: tests capture them)."""
    changed = []
    for stream in (sys.stdout, sys.stderr):
        if isinstance(stream, io.TextIOWrapper) and stream.errors in ("strict",
                                                                       "backslashreplace"):
            changed.append((stream, stream.errors))
            stream.reconfigure(errors=PRINTABLE_ERRORS)
    try:
        yield
    finally:
        for stream, errors in changed:
            stream.reconfigure(errors=errors)


def _main(argv: Sequence[str] | None) -> int:
    with _printable_output():
        return _run(argv)


def _run(argv: Sequence[str] | None) -> int:
    args_list = with_tui(list(sys.argv[1:] if argv is None else argv))
    parser = build_parser(command_of(args_list))
    args = parser.parse_args(args_list)
    func = getattr(args, "func", None)
    if func is None:
        parser.print_help()
        return 2
    _setup_logging(args.log_level)
    if args.trace_io or getattr(args, APPEND_TRACE_DEST):
        from benchlab.drivers.trace import io_trace

        try:
            after = _trace_io_target(args)
        except UsageError as exc:
            print(f"benchlab: error: {exc}", file=sys.stderr)
            return 2
        io_trace.start(args.trace_io, after=after)
    if args.replay:
        from benchlab.drivers.trace import replay

        try:
            replay.start(args.replay)
        except BenchlabError as exc:
            print(f"benchlab: error: {exc}", file=sys.stderr)
            return 1
    with shutdown.handling_signals():
        try:
            return int(func(args) or 0)
        except UsageError as exc:
            print(f"benchlab: error: {exc}", file=sys.stderr)
            return 2
        except BenchlabError as exc:
            print(f"benchlab: error: {_replay_reason(exc) or exc}", file=sys.stderr)
            return 1
        except BrokenPipeError:  # `benchlab ... | head`: the reader left; nothing to say
            os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())
            return 1
        except OSError as exc:  # a file the command was pointed at: say which, plainly
            print(f"benchlab: error: {plain_os_error(exc)}", file=sys.stderr)
            return 1
        except KeyboardInterrupt as exc:
            print(f"benchlab: interrupted ({shutdown.interrupt_reason(exc)}); bench left safe",
                  file=sys.stderr)
            return shutdown.exit_status(exc)
        finally:
            if args.trace_io:
                from benchlab.drivers.trace import io_trace

                io_trace.stop()
            if args.replay:
                from benchlab.drivers.trace import replay

                replay.stop()


def _trace_io_target(args: argparse.Namespace) -> int | None:
    """Check ``--trace-io FILE`` against the output policy: None to write a new cassette, or
    (``--append`` onto an existing cassette) the number of its last event.

    Raises
    ------
    UsageError
        ``--append`` without ``--trace-io`` or with ``--force``; a file inside a session; an
        existing file without ``--append`` / ``--force``; ``--append`` onto a file that is not a
        whole cassette of the same format (named, with what is wrong with it).
    """
    from benchlab.drivers.trace.cassette import CassetteError, last_event_number

    append = bool(getattr(args, APPEND_TRACE_DEST))
    if not args.trace_io:
        raise UsageError("--append adds to the cassette of --trace-io FILE; give --trace-io")
    if append and forced(args):
        raise UsageError("--append and --force: give one (--append adds to the cassette, "
                         "--force replaces it)")
    target = check_output(args.trace_io, force=forced(args) or append, option="--trace-io")
    if not append or not target.exists():
        return None
    try:
        return last_event_number(target)
    except CassetteError as exc:
        why = str(exc).removeprefix(f"{target}: ")
        raise UsageError(f"--trace-io {target}: not a cassette of this format ({why}); "
                         "--append adds only to a cassette recorded by --trace-io under a "
                         "name of the same kind (.gz or not); nothing written") from None


def with_tui(argv: list[str]) -> list[str]:
    """``argv`` with the ``tui`` command where the terminal UI is meant: no command, or an
    option of the UI's right after ``benchlab``'s own (``benchlab --simulate``, ``benchlab
    --append --trace-io bench.jsonl --simulate``)."""
    i = 0
    while i < len(argv) and (name := argv[i].split("=", 1)[0]) in _TOP_LEVEL_OPTIONS:
        i += 2 if name in _OPTIONS_WITH_VALUE and "=" not in argv[i] else 1
    rest = argv[i:]
    if not argv or (rest and rest[0].startswith("-")):
        return [*argv[:i], "tui", *rest]
    return argv


def _replay_reason(exc: BaseException) -> str | None:
    """While a cassette is replayed: the divergence behind ``exc``, if any."""
    from benchlab.drivers.trace import replay

    return replay.divergence_behind(exc)


def _setup_logging(level: str) -> None:
    """One handler on the ``benchlab`` logger: ``benchlab.<module>: LEVEL: message``."""
    import logging

    class StderrHandler(logging.StreamHandler):  # type: ignore[type-arg]
        """Writes to the sys.stderr of the moment (tests and the TUI swap it)."""

        @property  # type: ignore[override]
        def stream(self) -> object:
            return sys.stderr

        @stream.setter
        def stream(self, value: object) -> None:
            pass

    root = logging.getLogger("benchlab")
    root.setLevel(level.upper())
    if not any(type(h).__name__ == "StderrHandler" for h in root.handlers):
        handler = StderrHandler()
        handler.setFormatter(logging.Formatter("%(asctime)s %(name)s: %(levelname)s: %(message)s",
                                               "%H:%M:%S"))
        root.addHandler(handler)


if __name__ == "__main__":
    sys.exit(main())
