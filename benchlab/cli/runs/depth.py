"""``benchlab benchmark depth``: the depth-of-field sweep against the simulated bench's truth.

(``benchlab run depth`` is the ``run`` command of :mod:`benchlab.cli.runs.procedures`.)
"""

from __future__ import annotations

import argparse
from pathlib import Path

from benchlab.cli import positive_float, positive_int


def benchmark_depth_command(args: argparse.Namespace) -> int:
    """Run the benchmark and print its table."""
    from benchlab.benchmarks.depth import (
        RADIAL_VARIANTS,
        VARIANTS,
        format_benchmark,
        run_benchmark,
    )

    known = [*VARIANTS, *RADIAL_VARIANTS]
    variants = args.variants.split(",") if args.variants else known
    unknown = [v for v in variants if v not in known]
    if unknown:
        from benchlab.cli import UsageError

        raise UsageError(f"--variants: unknown {', '.join(unknown)}; known: "
                         f"{', '.join(known)}")
    seeds = 3 if args.quick else args.seeds
    out = run_benchmark(seeds, variants, Path(args.keep) if args.keep else None,
                        progress=lambda line: print(line, flush=True))
    print(format_benchmark(out))
    return 0


def benchmark_focus_aid_command(args: argparse.Namespace) -> int:
    """Readings per second of the live focus aid, and its accuracy cost."""
    from benchlab.benchmarks.focus_aid import format_benchmark, run_benchmark

    print(format_benchmark(run_benchmark(seconds=args.seconds)))
    return 0


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``benchmark depth`` and ``benchmark focus-aid``."""
    del commands  # no top-level command here
    bd = benchmarks.add_parser(
        "depth", help="depth-of-field sweep figures on the simulated bench",
        description="Run the depth-of-field procedure on the simulated bench for every seed and "
        "lens variant (forward: nominal, sharp, astigmatic, tilted; radial: radial, "
        "radial-astigmatic, radial-curved) and compare best focus and the DOF ends with the "
        "scene's closed-form truth: error, 95 % interval coverage, pass rate (within 0.3 mm, "
        "radial 0.1 mm, or covered); the astigmatic difference's sign; then the wall time and "
        "frames of a default run against a one-frame baseline. Each run is a whole simulated "
        "sweep: about 33 s of CPU (`time benchlab run depth --simulate --yes` on a 2-core "
        "machine, December 2026), so --quick (3 seeds x 7 variants) takes 15-20 minutes.",
    )
    bd.add_argument("--seeds", type=positive_int, default=20, help="seeds per variant (20)")
    bd.add_argument("--variants", help="comma-separated subset of the variants")
    bd.add_argument("--quick", action="store_true", help="3 seeds per variant")
    bd.add_argument("--keep", metavar="DIR", help="keep the sessions in DIR")
    bd.set_defaults(func=benchmark_depth_command)

    bf = benchmarks.add_parser(
        "focus-aid", help="live focus aid: whole-chart readings per second",
        description="Read the whole simulated chart (every found set by a fast estimator, the "
        "slanted edges' MTF50) frame after frame with the pose tracked, at 1280 x 1024 in 8 "
        "and 12 bit; print readings per second and the difference from the full chart reading "
        "of the same frames.",
    )
    bf.add_argument("--seconds", type=positive_float, default=3.0,
                    help="seconds timed per configuration (3)")
    bf.set_defaults(func=benchmark_focus_aid_command)
