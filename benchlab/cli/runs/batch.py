"""``benchlab analyze SESSION SESSION...`` / ``analyze --all ROOT``: many sessions at once.

:mod:`benchlab.cli.frames.analysis` hands the command here when more than one session (or ``--all``)
is given; one session keeps the single-session path and output.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import TYPE_CHECKING, Any, TextIO

from benchlab.cli import UsageError, non_negative_int, positive_int
from benchlab.cli.output import print_outcome

if TYPE_CHECKING:  # the batch (and its executors) is imported when a batch runs
    from benchlab.protocols.batch import BatchReport

#: Above this many sessions the summary lists only the skipped and failed ones (--json: all).
MAX_LISTED_ANALYSED = 50
#: Image-only options of ``analyze``; a batch of sessions takes only --estimator.
_IMAGE_OPTIONS = ("roi", "peaks", "freq", "orientation", "bootstrap", "linearise", "chart")


def add_batch_arguments(p: argparse.ArgumentParser) -> None:
    """The batch options of ``benchlab analyze``."""
    p.add_argument("--all", dest="all_root", metavar="ROOT",
                   help="re-analyse every session folder under ROOT (in parallel)")
    p.add_argument("--jobs", type=positive_int, metavar="N",
                   help="worker processes for several sessions (default: every core)")
    p.add_argument("--scheduler", metavar="ADDRESS",
                   help="run the sessions on a dask cluster (tcp://host:8786) instead of "
                   "local processes; needs the dask extra and workers that see the folders")


def batch_requested(args: argparse.Namespace) -> bool:
    targets = args.target if isinstance(args.target, list) else [args.target]
    return args.all_root is not None or len(targets) > 1


class _Bar:
    """A progress bar on a terminal; a line every 10 % otherwise."""

    def __init__(self, stream: TextIO, width: int = 30) -> None:
        self.stream = stream
        self.tty = stream.isatty()
        self.width = width
        self._last_tenth = -1

    def __call__(self, done: int, total: int, item: Any) -> None:
        failed = "" if item.outcome != "failed" else f"  failed: {Path(item.session).name}"
        if self.tty:
            filled = int(self.width * done / max(total, 1))
            bar = "#" * filled + "-" * (self.width - filled)
            self.stream.write(f"\r[{bar}] {done}/{total} {Path(item.session).name[:40]:<40}")
            if failed:
                self.stream.write(f"\n{failed.strip()}\n")
            if done == total:
                self.stream.write("\n")
        else:
            tenth = 10 * done // max(total, 1)
            if tenth != self._last_tenth or failed:
                self.stream.write(f"[{done}/{total}]{failed}\n")
                self._last_tenth = tenth
        self.stream.flush()


def batch_command(args: argparse.Namespace) -> int:
    """Re-analyse several sessions; exit 1 if any failed."""
    import gc

    gc.enable()  # a batch runs long: collect cycles (the analyze program starts without)
    from benchlab.protocols.batch import find_sessions, run_batch

    used = [f"--{o}" for o in _IMAGE_OPTIONS if getattr(args, o, None) is not None]
    if getattr(args, "all_estimators", False):
        used.append("--all-estimators")
    if used:  # an option that cannot be meant for sessions: a usage error, before any work
        raise UsageError(f"{', '.join(used)}: for one image only; only --estimator applies "
                         "to sessions")
    targets = [Path(t) for t in (args.target or [])]
    if args.all_root is not None:
        targets += find_sessions(args.all_root)
    report = run_batch(targets, estimator=args.estimator, jobs=args.jobs,
                       scheduler=args.scheduler, progress=_Bar(sys.stderr))
    return print_outcome(args.json, lambda: {
        "seconds": report.seconds, "jobs": report.jobs, "executor": report.executor,
        "analysed": report.count("analysed"), "skipped": report.count("skipped"),
        "failed": report.count("failed"),
        "sessions": [vars(i) for i in report.items],
    }, lambda: _summary_text(report), status=1 if report.failed else 0)


def _summary_text(report: BatchReport) -> str:
    """The batch for a person: a line per session (beyond :data:`MAX_LISTED_ANALYSED`
    sessions only those skipped or failed), then the counts and the time."""
    from benchlab.protocols.batch import summary_rows

    rows = list(summary_rows(report))
    n = len(report.items)
    if n > MAX_LISTED_ANALYSED:  # every failure and skip, but not 10,000 "analysed" lines
        rows = [r for r in rows if r[1] != "analysed"]
    lines: list[str] = []
    if rows:
        width = max(len(r[0]) for r in rows)
        lines.append(f"{'session':<{width}}  {'outcome':<8}  detail")
        lines += [f"{name:<{width}}  {outcome:<8}  {detail}" for name, outcome, detail in rows]
    analysed = report.count("analysed")
    # Only what is true: the frames of the sessions analysed were verified; a failed one may
    # have failed precisely because its frames changed.
    verified = ("" if not analysed else " (frames of the session analysed verified unchanged)"
                if analysed == 1 else f" (frames of the {analysed} analysed verified unchanged)")
    lines.append(f"\n{n} sessions: {analysed} analysed, {report.count('skipped')} "
                 f"skipped, {report.count('failed')} failed; {report.seconds:.1f} s on "
                 f"{report.executor}{verified}")
    return "\n".join(lines)


def benchmark_batch_command(args: argparse.Namespace) -> int:
    """``benchlab benchmark batch``: N fabricated sessions re-analysed on every core."""
    from benchlab.benchmarks.batch import run_batch_benchmark

    def say(text: str) -> None:
        print(text, file=sys.stderr, flush=True)

    print(run_batch_benchmark(n_sessions=args.sessions, jobs=args.jobs, source=args.source,
                              workdir=args.workdir, link_frames=not args.copy_frames,
                              fsync_repeats=args.fsync_repeats, say=say))
    return 0


def benchmark_journal_command(args: argparse.Namespace) -> int:
    """``benchlab benchmark journal``: time per saved frame as one session grows."""
    from benchlab.benchmarks.journal import format_journal_benchmark, run_journal_benchmark

    if args.frames < args.block:
        raise UsageError(f"--frames {args.frames} is less than one block (--block {args.block})")
    print(format_journal_benchmark(run_journal_benchmark(args.frames, block=args.block)))
    return 0


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``benchmark batch`` and ``benchmark journal`` (the batch options of ``analyze`` are
    added with them)."""
    b = benchmarks.add_parser(
        "batch", help="batch re-analysis of many sessions: time, per-session cost, memory",
        description="Fabricate N sessions by copying one real simulated MTF run (or --source), "
        "rebuild their catalogue, re-analyse them all on a process pool, and compare the "
        "results fsync policies; prints wall time, per-session cost, the extrapolation to "
        "10,000 sessions and the workers' peak memory across the batch.",
    )
    b.add_argument("--sessions", type=positive_int, default=200, help="sessions to fabricate (200)")
    b.add_argument("--jobs", type=positive_int, metavar="N",
                   help="worker processes (default: all cores)")
    b.add_argument("--source", metavar="SESSION", help="session folder to copy (default: one "
                   "simulated MTF run made for the benchmark)")
    b.add_argument("--workdir", metavar="DIR", help="where to fabricate (default: temp folder)")
    b.add_argument("--copy-frames", action="store_true",
                   help="copy the frames instead of hard-linking them")
    b.add_argument("--fsync-repeats", type=non_negative_int, default=20, metavar="N",
                   help="re-analyses per fsync policy for the comparison (0: skip)")
    b.set_defaults(func=benchmark_batch_command)

    j = benchmarks.add_parser(
        "journal", help="time per saved frame as one session grows to 10,000 frames",
        description="Save small simulated frames into one new session (in a temporary folder) "
        "as a procedure does, four per step, and print the time per frame for each block. The "
        "session's bookkeeping is linear in its frames when the last block costs what the first "
        "does. The default (10,000 frames) takes about 40 s on one core.",
    )
    j.add_argument("--frames", type=positive_int, default=10_000, help="how many frames (10000)")
    j.add_argument("--block", type=positive_int, default=1000, help="frames per timed block (1000)")
    j.set_defaults(func=benchmark_journal_command)
