"""``benchlab benchmark fov``: the field-of-view procedure against the simulated bench's truth.

(``benchlab run fov`` is the ``run`` command of :mod:`benchlab.cli.runs.procedures`.)
"""

from __future__ import annotations

import argparse
from pathlib import Path

from benchlab.cli import positive_int


def benchmark_fov_command(args: argparse.Namespace) -> int:
    """Run the benchmark and print its table."""
    from benchlab.benchmarks.fov import VARIANTS, format_benchmark, run_benchmark

    variants = args.variants.split(",") if args.variants else list(VARIANTS)
    unknown = [v for v in variants if v not in VARIANTS]
    if unknown:
        from benchlab.cli import UsageError

        raise UsageError(f"--variants: unknown {', '.join(unknown)}; known: "
                         f"{', '.join(VARIANTS)}")
    seeds = 3 if args.quick else args.seeds
    out = run_benchmark(seeds, variants, Path(args.keep) if args.keep else None,
                        progress=lambda line: print(line, flush=True))
    print(format_benchmark(out))
    return 0


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``benchmark fov``."""
    del commands  # no top-level command here
    bf = benchmarks.add_parser(
        "fov", help="field-of-view figures on the simulated bench",
        description="Run the field-of-view procedure on the simulated bench for every seed and "
        "lens variant (nominal, no-distortion, strong-barrel, tilted, shifted-pupil) and compare "
        "the full field of view, direction of view, entrance pupil, focal length, image height "
        "and local distortion, and the radial view's field start and end on the wall, field "
        "of view and image heights, with the simulator's exact mappings: bias, RMSE, largest "
        "error against the issue's targets, and 95 % interval coverage. Each variant takes its "
        "own seeds, so the radial view (the same in every variant) is scored over seeds x "
        "variants independent runs. Each run takes 10-20 s, so the default 20 seeds x 5 "
        "variants take 20-35 minutes; --quick 3 seeds.",
    )
    bf.add_argument("--seeds", type=positive_int, default=20, help="seeds per variant (20)")
    bf.add_argument("--variants", help="comma-separated subset of the variants")
    bf.add_argument("--quick", action="store_true", help="3 seeds per variant")
    bf.add_argument("--keep", metavar="DIR", help="keep the sessions in DIR")
    bf.set_defaults(func=benchmark_fov_command)
