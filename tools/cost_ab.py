"""Issue 39's costs, this checkout against another, interleaved, with the results compared.

Usage::

    python tools/cost_ab.py --against /path/to/previous/checkout [--against-python PY]
                            [--rounds 5] [--sessions 64]

This checkout runs with this interpreter, the other with ``--against-python`` (its own
environment: a dependency added since, such as ``imagecodecs``, would otherwise speed up the
other checkout too), both through ``PYTHONPATH``. Each round runs every job once per
checkout, the order reversed every other round (neither always runs first on a warm disk
cache), and prints the medians and their ratio:

* **batch**: ``benchlab analyze --all`` over N copies of one simulated MTF session (frames
  hard-linked, as ``benchlab benchmark batch`` makes them), the CPU of the whole process tree
  (the command, the pool's forkserver and workers: user + system time read from ``/proc`` every
  20 ms, the command's own from ``wait4``), per session;
* **depth**: ``benchlab run depth --simulate --yes``, the CPU of the process.

Every re-analysis of the batch must reuse the sessions' first results version (a version is
reused only when every results file is byte-identical) and every depth run must write the same
CSV files as the other checkout's: the script stops with the first file that differs.
"""

from __future__ import annotations

import argparse
import filecmp
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent.parent
CLI = "import sys; from benchlab.cli.main import main; sys.exit(main())"
TICKS = os.sysconf("SC_CLK_TCK")


def _tree_cpu_s(python: str, argv: list[str], env: dict[str, str]) -> float:
    """CPU seconds of ``argv`` and every process it starts (its own session)."""
    proc = subprocess.Popen([python, "-c", CLI, *argv], env=env, cwd="/tmp",
                            stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            start_new_session=True)
    seen: dict[int, float] = {}
    while True:
        for stat in Path("/proc").glob("[0-9]*/stat"):
            try:
                fields = stat.read_text().rsplit(")", 1)[1].split()
            except (OSError, IndexError):
                continue
            pid = int(stat.parent.name)
            if int(fields[3]) == proc.pid and pid != proc.pid:  # session id
                seen[pid] = (int(fields[11]) + int(fields[12])) / TICKS
        _, status, usage = os.wait4(proc.pid, os.WNOHANG)
        if status or _:
            break
        time.sleep(0.02)
    err = proc.stderr.read().decode() if proc.stderr else ""
    if os.waitstatus_to_exitcode(status) != 0:
        raise SystemExit(f"{' '.join(argv)} failed:\n{err[-2000:]}")
    return usage.ru_utime + usage.ru_stime + sum(seen.values())


def _env(checkout: Path) -> dict[str, str]:
    return {**os.environ, "PYTHONPATH": str(checkout)}


def _session(python: str, root: Path, env: dict[str, str], kind: str) -> Path:
    subprocess.run([python, "-c", CLI, "run", kind, "--simulate", "--yes", "--out",
                    str(root)], env=env, check=True, capture_output=True, cwd="/tmp")
    return sorted(p for p in root.iterdir() if p.is_dir())[-1]


def _same_csvs(a: Path, b: Path) -> None:
    """Stop at the first CSV that differs between two results versions."""
    names = sorted(p.name for p in a.glob("*.csv"))
    if names != sorted(p.name for p in b.glob("*.csv")):
        raise SystemExit(f"{a} and {b} hold different CSV files")
    for name in names:
        if not filecmp.cmp(a / name, b / name, shallow=False):
            raise SystemExit(f"{a / name} and {b / name} differ")


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--against", required=True, type=Path, help="the other checkout")
    p.add_argument("--against-python", default=sys.executable,
                   help="the other checkout's interpreter (default: this one)")
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--sessions", type=int, default=64, help="copies re-analysed per batch")
    p.add_argument("--jobs", type=int, default=2)
    p.add_argument("--skip", choices=("batch", "depth"), action="append", default=[])
    args = p.parse_args()
    sys.path.insert(0, str(HERE))
    from benchlab.benchmarks.batch import fabricate

    checkouts = {"this": HERE, "other": args.against.resolve()}
    pythons = {"this": sys.executable, "other": args.against_python}
    cpu: dict[tuple[str, str], list[float]] = {}
    with tempfile.TemporaryDirectory(prefix="cost-ab-") as tmp:
        root = Path(tmp)
        source = _session(pythons["other"], root / "source", _env(checkouts["other"]), "mtf")
        copies = fabricate(source, root / "batch", args.sessions)
        depth_results: dict[str, Path] = {}
        for round_ in range(args.rounds):
            order = list(checkouts) if round_ % 2 == 0 else list(checkouts)[::-1]
            for name in order:
                env = _env(checkouts[name])
                if "batch" not in args.skip:
                    s = _tree_cpu_s(pythons[name], ["analyze", "--all", str(root / "batch"),
                                                    "--jobs", str(args.jobs)], env)
                    cpu.setdefault(("batch, CPU s per session", name), []).append(
                        s / args.sessions)
                    grown = [c for c in copies if (c / "results" / "v2").exists()]
                    if grown:
                        raise SystemExit(f"{name}: {grown[0]} got a second results version: "
                                         "its results differ from the first")
                if "depth" not in args.skip:
                    out = root / f"depth-{name}-{round_}"
                    s = _tree_cpu_s(pythons[name], ["run", "depth", "--simulate", "--yes",
                                                    "--out", str(out)], env)
                    cpu.setdefault(("run depth, CPU s", name), []).append(s)
                    results = next(out.glob("*/results/v1"))
                    if name in depth_results:
                        _same_csvs(depth_results[name], results)
                    depth_results[name] = results
                    shutil.rmtree(out.parent / f"depth-{name}-{round_ - 2}",
                                  ignore_errors=True)
            if len(depth_results) == 2:
                _same_csvs(depth_results["this"], depth_results["other"])
            print(f"round {round_ + 1}: " + ", ".join(
                f"{job} {name} {values[-1]:.3f}" for (job, name), values in cpu.items()),
                flush=True)
    for job in dict.fromkeys(job for job, _ in cpu):
        this, other = cpu[(job, "this")], cpu[(job, "other")]
        pairs = [a / b for a, b in zip(this, other, strict=True)]
        print(f"{job}: this {statistics.median(this):.3f}, other {statistics.median(other):.3f}, "
              f"ratio {statistics.median(this) / statistics.median(other):.3f} "
              f"(pairs {min(pairs):.2f}-{max(pairs):.2f}, {len(pairs)} rounds)")
    print(f"results identical: {args.sessions} batch sessions kept results v1 in every round; "
          "depth CSVs equal across checkouts and rounds")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
