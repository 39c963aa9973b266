"""``benchlab benchmark startup``: how long ``benchlab --help`` and ``benchlab analyze SESSION``
take as fresh processes (import time included, which is what a user waits for), as medians
with their spread, optionally interleaved with another benchlab install (``--against``).

An installed package has its bytecode (``.pyc``) cached after the first run; a development
shell with ``PYTHONDONTWRITEBYTECODE=1`` recompiles benchlab's sources in every process
(~0.1 s). Both are timed: "cached" runs without ``PYTHONDONTWRITEBYTECODE`` and with
``PYTHONPYCACHEPREFIX`` pointing at a temporary folder filled by one warm-up run (what a user
gets; nothing is written next to the sources); "no .pyc" runs with
``PYTHONDONTWRITEBYTECODE=1`` and no prefix (what this kind of shell gets).

Wall time on a shared machine moves with the other processes' load far more than any change
to benchlab does, so two installs are compared only interleaved: each round runs each command
once per install, alternating which goes first, and the ratio of their medians is printed.
How start-up is kept down: docs/development/startup.md.
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path

from benchlab.cli import UsageError
from benchlab.drivers.errors import BenchlabError

#: Label of this install's runs (the other install's: ``--against-label``).
THIS = "this"


@dataclass
class Timings:
    """Seconds of one command, one bytecode setting and one install, one entry per run."""

    wall: list[float] = field(default_factory=list)
    cpu: list[float] = field(default_factory=list)


def bytecode_environments(pycache: Path) -> dict[str, dict[str, str]]:
    """The child environments: ``cached`` (bytecode written to and read from ``pycache``) and
    ``no .pyc`` (nothing written, benchlab compiled from source in every process)."""
    base = {k: v for k, v in os.environ.items()
            if k not in ("PYTHONDONTWRITEBYTECODE", "PYTHONPYCACHEPREFIX")}
    return {"cached": {**base, "PYTHONPYCACHEPREFIX": str(pycache)},
            "no .pyc": {**base, "PYTHONDONTWRITEBYTECODE": "1"}}


def spread(values: Sequence[float]) -> tuple[float, float, float, float, float]:
    """``(median, first quartile, third quartile, min, max)`` of at least one value (the
    quartiles of one value are that value)."""
    if not values:
        raise ValueError("no values")
    q1, _, q3 = (statistics.quantiles(values, n=4, method="inclusive") if len(values) > 1
                 else (values[0],) * 3)
    return statistics.median(values), q1, q3, min(values), max(values)


def run_once(argv: Sequence[str], out: Timings, fresh_copy_of: Path | None = None,
             env: Mapping[str, str] | None = None) -> None:
    """Run ``argv`` once and append its wall and CPU (user + system of the child) seconds to
    ``out``; with ``fresh_copy_of``, the run gets its own copy of that session folder
    (appended to ``argv``), so every re-analysis starts from the same state."""
    with tempfile.TemporaryDirectory(prefix="benchlab-startup-") as tmp:
        args = list(argv)
        if fresh_copy_of is not None:
            args.append(str(shutil.copytree(fresh_copy_of, Path(tmp) / fresh_copy_of.name)))
            # A saved session is on disk already (acquisition made it durable); without
            # this the command's own syncfs would also flush the copy just made here.
            os.sync()
        before = os.times()
        t0 = time.perf_counter()
        done = subprocess.run(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                              text=True, env=None if env is None else dict(env))
        out.wall.append(time.perf_counter() - t0)
        after = os.times()
        out.cpu.append(after.children_user - before.children_user
                       + after.children_system - before.children_system)
    if done.returncode != 0:
        raise BenchlabError(f"{' '.join(map(str, args))} failed: {done.stderr.strip()}")


def interleaved(programs: Mapping[str, Sequence[str]], session: Path, repeats: int,
                envs: Mapping[str, Mapping[str, str]],
                ) -> dict[tuple[str, str, str], Timings]:
    """``repeats`` rounds; in each, every command (``--help``, ``analyze SESSION``) under
    every environment once per program, the programs' order reversed every other round (so
    neither always runs first, after the other has warmed the disk cache). One warm-up run
    of each (not counted) fills the bytecode cache first. Keyed by (command, environment,
    program)."""
    commands = (("--help", ["--help"], None), ("analyze SESSION", ["analyze"], session))
    times: dict[tuple[str, str, str], Timings] = {}
    names = list(programs)
    for round_ in range(repeats + 1):
        order = names if round_ % 2 == 0 else names[::-1]
        for how, env in envs.items():
            if round_ == 0 and how != "cached":
                continue  # the warm-up fills the bytecode cache only
            for command, words, needs in commands:
                for name in order:
                    slot = Timings() if round_ == 0 else times.setdefault(
                        (command, how, name), Timings())
                    run_once([*programs[name], *words], slot, needs, env)
    return times


def format_timings(times: Mapping[tuple[str, str, str], Timings], repeats: int) -> str:
    """The table: median, quartiles, min and max of wall time, median CPU time; with two
    programs, the ratio of their median wall times per command."""
    lines = [f"{'command':<17}{'bytecode':<9}{'install':<9}{'wall med':>9}{'q1 - q3':>15}"
             f"{'min':>8}{'max':>8}{'cpu med':>9}"]
    for (command, how, name), t in times.items():
        med, q1, q3, lo, hi = spread(t.wall)
        lines.append(f"{command:<17}{how:<9}{name:<9}{med:>8.3f}s{q1:>8.3f}-{q3:.3f}s"
                     f"{lo:>7.3f}s{hi:>7.3f}s{statistics.median(t.cpu):>8.3f}s")
    others = sorted({name for _, _, name in times} - {THIS})
    for other in others:
        for (command, how, name), t in times.items():
            if name != THIS:
                continue
            theirs = times[(command, how, other)]
            ratio = statistics.median(t.wall) / statistics.median(theirs.wall)
            lines.append(f"{command} ({how}): this / {other} median wall = {ratio:.3f}")
    together = ", interleaved" if others else ""
    lines.append(f"{repeats} fresh processes each{together}; load average "
                 f"{os.getloadavg()[0]:.1f} on {os.cpu_count()} CPUs (wall time grows with "
                 "load; CPU time much less). cached: .pyc files cached after one warm-up run, "
                 "as an installed benchlab has them; no .pyc: PYTHONDONTWRITEBYTECODE=1, "
                 "benchlab's sources compiled in every process.")
    return "\n".join(lines)


def this_program() -> list[str]:
    """The command a user types: the ``benchlab`` script beside this interpreter (where pip
    installed it), else ``python -m benchlab.cli.main``."""
    script = Path(sys.executable).parent / "benchlab"
    if script.is_file() and os.access(script, os.X_OK):
        return [str(script)]
    return [sys.executable, "-m", "benchlab.cli.main"]


def _simulated_session(folder: Path) -> Path:
    done = subprocess.run([sys.executable, "-m", "benchlab.cli.main", "run", "mtf", "--simulate",
                           "--yes", "--out", str(folder)], capture_output=True, text=True)
    sessions = sorted(p for p in folder.iterdir() if p.is_dir())
    if done.returncode != 0 or not sessions:
        raise BenchlabError(f"could not simulate a session: {done.stderr.strip()}")
    return sessions[-1]


def _cmd_startup(args: argparse.Namespace) -> int:
    if args.repeats < 1:
        raise UsageError(f"--repeats must be >= 1, got {args.repeats}")
    programs: dict[str, list[str]] = {THIS: this_program()}
    if args.against:
        other = shutil.which(args.against)
        if other is None:
            raise UsageError(f"--against {args.against}: not an executable benchlab command")
        if args.against_label == THIS:
            raise UsageError(f"--against-label: {THIS!r} names this install; choose another")
        programs[args.against_label] = [other]
    with tempfile.TemporaryDirectory(prefix="benchlab-session-") as tmp:
        session = Path(args.session) if args.session else _simulated_session(Path(tmp))
        if not (session / "session.json").is_file():
            raise BenchlabError(f"{session}: not a session folder (no session.json)")
        envs = bytecode_environments(Path(tmp) / "pycache")
        if args.cached_only:
            envs = {"cached": envs["cached"]}
        times = interleaved(programs, session, args.repeats, envs)
    print(format_timings(times, args.repeats))
    return 0


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``benchmark startup``."""
    b = benchmarks.add_parser(
        "startup", help="seconds for `benchlab --help` and `benchlab analyze SESSION`",
        description="Time `benchlab --help` and `benchlab analyze SESSION` as fresh processes "
        "(imports included): median, quartiles, min and max of the wall time and the median "
        "CPU time, both with the bytecode cached (after one warm-up run, as an installed "
        "benchlab has it) and with PYTHONDONTWRITEBYTECODE=1 (sources compiled in every "
        "process). SESSION is copied for each run so every re-analysis starts from the same "
        "state; without SESSION a simulated Table 4.10 MTF session is made first. With "
        "--against, another benchlab command (e.g. an older install's) runs interleaved with "
        "this one and the ratio of the medians is printed.",
    )
    b.add_argument("session", nargs="?", help="session folder (default: simulate one)")
    b.add_argument("--repeats", type=int, default=10, help="runs of each command (default 10)")
    b.add_argument("--against", metavar="BENCHLAB",
                   help="another benchlab command to time interleaved with this one")
    b.add_argument("--against-label", default="other", metavar="NAME",
                   help="its name in the table (default: other)")
    b.add_argument("--cached-only", action="store_true",
                   help="time only the cached-bytecode runs (half the runs)")
    b.set_defaults(func=_cmd_startup)
