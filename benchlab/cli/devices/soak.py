"""``benchlab benchmark soak``: the camera driver under injected USB faults, with figures."""

from __future__ import annotations

import argparse


def soak_command(args: argparse.Namespace) -> int:
    from benchlab.cli import UsageError
    from benchlab.drivers.mightex.soak import run_soak

    if args.frames < 1:
        raise UsageError(f"--frames must be >= 1, got {args.frames}")
    if not 0.0 <= args.fault_rate <= 1.0:
        raise UsageError(f"--fault-rate must be in [0, 1], got {args.fault_rate:g}")
    report = run_soak(args.frames, fault_rate=args.fault_rate, seed=args.seed)
    print(report.format())
    return 0 if report.ok else 1


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``benchmark soak``."""
    soak = benchmarks.add_parser(
        "soak", help="grab frames through injected USB faults: lost/duplicated/corrupted",
        description="Grab frames from the simulated camera through the real driver while "
        "injecting USB faults (reply timeouts, garbage replies, short frames, unplug "
        "mid-frame, stale frames) at a stated rate, reconnecting as a procedure does. Prints "
        "frames lost, duplicated and corrupted - judged by the simulator's own frame counter "
        "and pixel hashes - and the recovery time per fault kind. Exit 1 unless all are 0.")
    soak.add_argument("--frames", type=int, default=10_000, help="frames to deliver "
                      "(default 10000)")
    soak.add_argument("--fault-rate", type=float, default=0.05,
                      help="probability of a fault per grab (default 0.05)")
    soak.add_argument("--seed", type=int, default=0, help="random seed (faults, noise)")
    soak.set_defaults(func=soak_command)
