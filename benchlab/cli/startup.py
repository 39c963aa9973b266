"""``benchlab benchmark startup``: how long ``benchlab --help`` and ``benchlab analyze SESSION``
take as fresh processes (import time included, which is what a user waits for).

An installed package has its bytecode (``.pyc``) cached after the first run; a development
shell with ``PYTHONDONTWRITEBYTECODE=1`` recompiles benchlab's sources in every process
(~0.1 s). Both are timed: "cached" runs without ``PYTHONDONTWRITEBYTECODE`` and with
``PYTHONPYCACHEPREFIX`` pointing at a temporary folder filled by one warm-up run (what a user
gets; the targets apply to it, and nothing is written next to the sources); "no .pyc" runs with
``PYTHONDONTWRITEBYTECODE=1`` and no prefix (what this kind of shell gets).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path

from benchlab.cli import UsageError
from benchlab.drivers.errors import BenchlabError

#: The targets from issue 11 (seconds of wall time on an otherwise idle machine).
TARGETS_S = {"--help": 0.15, "analyze SESSION": 0.35}


def bytecode_environments(pycache: Path) -> dict[str, dict[str, str]]:
    """The child environments: ``cached`` (bytecode written to and read from ``pycache``) and
    ``no .pyc`` (nothing written, benchlab compiled from source in every process)."""
    base = {k: v for k, v in os.environ.items()
            if k not in ("PYTHONDONTWRITEBYTECODE", "PYTHONPYCACHEPREFIX")}
    return {"cached": {**base, "PYTHONPYCACHEPREFIX": str(pycache)},
            "no .pyc": {**base, "PYTHONDONTWRITEBYTECODE": "1"}}


def _time(argv: Sequence[str], repeats: int, fresh_copy_of: Path | None = None,
          env: Mapping[str, str] | None = None,
          forks: list[bool] | None = None) -> tuple[list[float], list[float]]:
    """Wall and CPU (user + system of the child) seconds of ``repeats`` runs of ``argv``;
    with ``fresh_copy_of``, each run gets its own copy of that session folder (appended).
    ``forks`` collects, per run, whether ``analyze SESSION`` would fork its child then
    (:func:`benchlab.forked.fork_usable` asked here just before the run: the same
    ``BENCHLAB_SERIAL``, CPUs and load average)."""
    import time

    from benchlab.forked import fork_usable

    wall: list[float] = []
    cpu: list[float] = []
    for _ in range(repeats):
        with tempfile.TemporaryDirectory(prefix="benchlab-startup-") as tmp:
            args = list(argv)
            if fresh_copy_of is not None:
                args.append(str(shutil.copytree(fresh_copy_of, Path(tmp) / fresh_copy_of.name)))
                # A saved session is on disk already (acquisition made it durable); without
                # this the command's own syncfs would also flush the copy just made here.
                os.sync()
            if forks is not None:
                forks.append(fork_usable())
            before = os.times()
            t0 = time.perf_counter()
            done = subprocess.run(args, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                  text=True, env=None if env is None else dict(env))
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
    from benchlab.forked import usable_cpus

    if args.repeats < 1:
        raise UsageError(f"--repeats must be >= 1, got {args.repeats}")
    me = [sys.executable, "-m", "benchlab.cli.main"]
    commands = [("--help", [*me, "--help"], False), ("analyze SESSION", [*me, "analyze"], True)]
    rows = []
    forks: list[bool] = []
    with tempfile.TemporaryDirectory(prefix="benchlab-session-") as tmp:
        session = Path(args.session) if args.session else _simulated_session(Path(tmp))
        if not (session / "session.json").is_file():
            raise BenchlabError(f"{session}: not a session folder (no session.json)")
        envs = bytecode_environments(Path(tmp) / "pycache")
        for _name, argv, needs_session in commands:  # the warm-up run fills the bytecode cache
            _time(argv, 1, session if needs_session else None, envs["cached"])
        for how, env in envs.items():
            for name, argv, needs_session in commands:
                wall, cpu = _time(argv, args.repeats, session if needs_session else None, env,
                                  forks if needs_session else None)
                rows.append((name, how, wall, cpu))
    load = os.getloadavg()[0]
    print(f"{'command':<18}{'bytecode':<10}{'wall min':>10}{'wall med':>10}{'cpu min':>10}"
          f"{'cpu med':>10}{'target':>9}")
    for name, how, wall, cpu in rows:
        target = f"{TARGETS_S[name]:>8.2f}s" if how == "cached" else f"{'-':>9}"
        print(f"{name:<18}{how:<10}{min(wall):>9.3f}s{statistics.median(wall):>9.3f}s"
              f"{min(cpu):>9.3f}s{statistics.median(cpu):>9.3f}s{target}")
    print(f"{args.repeats} fresh processes each; load average {load:.1f} on {os.cpu_count()} "
          "CPUs (wall time grows with load; CPU time much less).\n"
          "cached: .pyc files cached after one warm-up run, as an installed benchlab has them "
          "(the targets apply here); no .pyc: PYTHONDONTWRITEBYTECODE=1, benchlab's sources "
          "compiled in every process.\n"
          f"analyze SESSION had its second process (benchlab.forked) in {sum(forks)} of "
          f"{len(forks)} runs: it forks with two usable CPUs ({usable_cpus()} here) unless "
          "the 1-minute load average is at the CPU count or BENCHLAB_SERIAL=1 is set "
          "(BENCHLAB_SERIAL=0: always).")
    return 0


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``benchmark startup``."""
    b = benchmarks.add_parser(
        "startup", help="seconds for `benchlab --help` and `benchlab analyze SESSION`",
        description="Time `benchlab --help` and `benchlab analyze SESSION` as fresh processes "
        "(imports included): wall and CPU time, min and median, both with the bytecode cached "
        "(after one warm-up run, as an installed benchlab has it; the targets apply) and with "
        "PYTHONDONTWRITEBYTECODE=1 (sources compiled in every process). SESSION is copied for "
        "each run so every re-analysis starts from the same state; without SESSION a "
        "simulated Table 4.10 MTF session is made first.",
    )
    b.add_argument("session", nargs="?", help="session folder (default: simulate one)")
    b.add_argument("--repeats", type=int, default=10, help="runs of each command (default 10)")
    b.set_defaults(func=_cmd_startup)
