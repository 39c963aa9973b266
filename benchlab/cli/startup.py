"""``benchlab benchmark startup``: how long ``benchlab --help`` and ``benchlab analyze SESSION``
take as fresh processes (import time included, which is what a user waits for)."""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Sequence
from pathlib import Path

from benchlab.drivers.errors import BenchlabError

#: The targets from issue 11 (seconds of wall time on an otherwise idle machine).
TARGETS_S = {"--help": 0.15, "analyze SESSION": 0.35}


def _time(argv: Sequence[str], repeats: int, fresh_copy_of: Path | None = None
          ) -> tuple[list[float], list[float]]:
    """Wall and CPU (user + system of the child) seconds of ``repeats`` runs of ``argv``;
    with ``fresh_copy_of``, each run gets its own copy of that session folder (appended)."""
    import time

    wall: list[float] = []
    cpu: list[float] = []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory(prefix="benchlab-startup-") as tmp:
            args = list(argv)
            if fresh_copy_of is not None:
                args.append(str(shutil.copytree(fresh_copy_of, Path(tmp) / fresh_copy_of.name)))
            before = os.times()
            t0 = time.perf_counter()
            done = subprocess.run(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                  text=True)
            wall.append(time.perf_counter() - t0)
            after = os.times()
            cpu.append(after.children_user - before.children_user
                       + after.children_system - before.children_system)
        if done.returncode != 0:
            raise BenchlabError(f"{' '.join(map(str, args))} failed: {done.stderr.strip()}")
    return wall, cpu


def _simulated_session(folder: Path) -> Path:
    done = subprocess.run([sys.executable, "-m", "benchlab.cli.main", "run", "mtf", "--simulate",
                           "--yes", "--out", str(folder)], capture_output=True, text=True)
    sessions = sorted(p for p in folder.iterdir() if p.is_dir())
    if done.returncode != 0 or not sessions:
        raise BenchlabError(f"could not simulate a session: {done.stderr.strip()}")
    return sessions[-1]


def _cmd_startup(args: argparse.Namespace) -> int:
    me = [sys.executable, "-m", "benchlab.cli.main"]
    with tempfile.TemporaryDirectory(prefix="benchlab-session-") as tmp:
        session = Path(args.session) if args.session else _simulated_session(Path(tmp))
        if not (session / "session.json").is_file():
            raise BenchlabError(f"{session}: not a session folder (no session.json)")
        rows = [("--help", *_time([*me, "--help"], args.repeats)),
                ("analyze SESSION", *_time([*me, "analyze"], args.repeats, session))]
    load = os.getloadavg()[0]
    print(f"{'command':<18}{'wall min':>10}{'wall med':>10}{'cpu min':>10}{'cpu med':>10}"
          f"{'target':>9}")
    for name, wall, cpu in rows:
        print(f"{name:<18}{min(wall):>9.3f}s{statistics.median(wall):>9.3f}s{min(cpu):>9.3f}s"
              f"{statistics.median(cpu):>9.3f}s{TARGETS_S[name]:>8.2f}s")
    print(f"{args.repeats} fresh processes each; load average {load:.1f} on {os.cpu_count()} "
          "CPUs (wall time grows with load; CPU time much less)")
    return 0


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``benchmark startup``."""
    b = benchmarks.add_parser(
        "startup", help="seconds for `benchlab --help` and `benchlab analyze SESSION`",
        description="Time `benchlab --help` and `benchlab analyze SESSION` as fresh processes "
        "(imports included): wall and CPU time, min and median. SESSION is copied for each "
        "run so every re-analysis starts from the same state; without SESSION a simulated "
        "Table 4.10 MTF session is made first.",
    )
    b.add_argument("session", nargs="?", help="session folder (default: simulate one)")
    b.add_argument("--repeats", type=int, default=10, help="runs of each command (default 10)")
    b.set_defaults(func=_cmd_startup)
