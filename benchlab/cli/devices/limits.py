"""The bench file's safety limits for the one-device commands (``led``, ``stage``).

``run``, ``resume``, ``doctor`` and the TUI open the bench through the bench file, so its LED
ceilings and stage travel bound every byte they send. ``led`` and ``stage`` talk to one device
directly; this module gives them the same bench file (``--config``, else the user's bench.toml,
else the packaged simulated bench with ``--simulate``) and the same limits. An option may
narrow a limit, never widen it: a wider one is a usage error naming both values.
"""

from __future__ import annotations

import argparse
from dataclasses import dataclass
from typing import TYPE_CHECKING

from benchlab.drivers.apt.protocol import COMPLETION_TOLERANCE_COUNTS, Z8_COUNTS_PER_MM
from benchlab.drivers.errors import UsageError

if TYPE_CHECKING:  # bench imports numpy: loaded only when a device command runs
    from benchlab.bench import BenchConfig

#: Travel used by ``stage`` when no bench file says (a Z825 actuator's).
DEFAULT_TRAVEL_MM = (0.0, 25.0)


@dataclass(frozen=True)
class LedLimits:
    """What ``led`` may do: the port, the channel and its current ceiling (None: no ceiling
    known, so the channel is never lit)."""

    port: str | None
    channel: int
    ceiling_ma: float | None


@dataclass(frozen=True)
class StageLimits:
    """What ``stage`` may do: the port, the travel and scale, and the bench's velocity
    (None: the controller's own)."""

    port: str | None
    travel_mm: tuple[float, float]
    counts_per_mm: float
    velocity_mm_s: float | None
    tolerance_counts: int


def _bench_config(args: argparse.Namespace) -> tuple[BenchConfig, str]:
    """The bench configuration in force for ``args`` and a name for it in messages."""
    from benchlab.bench import BenchConfig
    from benchlab.cli.config import bench_file_in_force

    bench_file = bench_file_in_force(args.config, simulate=args.simulate)
    cfg = BenchConfig.load(bench_file.value, simulate=args.simulate)
    # the file read (the packaged one with --simulate), else why there is none
    where = (cfg.source if bench_file.value is not None or args.simulate
             else f"no bench file ({bench_file.source})")
    return cfg, where


def led_limits(args: argparse.Namespace) -> LedLimits:
    """The LED port, channel and ceiling ``led`` uses; :class:`UsageError` when ``--on`` would
    need a ceiling the bench file does not give or ``--ceiling-ma`` is above the bench file's."""
    from benchlab.bench import BenchConfig

    cfg, where = _bench_config(args)
    led = cfg.led
    channel = args.channel if args.channel is not None else (led.channel if led else 1)
    port = args.port or (led.port if led is not None else None)
    asked = args.ceiling_ma
    if asked is not None and not asked >= 0.0:
        raise UsageError(f"--ceiling-ma must be >= 0 mA, got {asked:g}")
    if led is None:  # no bench file, or one without [led]: only an explicit ceiling
        if args.on and asked is None:
            why = where if cfg.source == BenchConfig().source else f"{where} has no [led]"
            raise UsageError(f"led --on needs a current ceiling and there is none ({why}): "
                             "give --config bench.toml with [led.ceiling_ma] (`benchlab config "
                             "init` writes one), or --ceiling-ma")
        return LedLimits(port, channel, asked)
    configured = led.ceilings_ma.get(channel)
    if configured is None:
        if args.on:
            raise UsageError(f"{where}: LED channel {channel} has no ceiling in "
                             "[led.ceiling_ma]; a channel without a ceiling is never lit")
        return LedLimits(port, channel, None)
    if asked is not None and asked > configured:
        raise UsageError(f"--ceiling-ma {asked:g} mA is above the bench file's ceiling "
                         f"{configured:g} mA for LED channel {channel} ({where}); give a "
                         "lower one or change [led.ceiling_ma] there")
    return LedLimits(port, channel, configured if asked is None else asked)


def stage_limits(args: argparse.Namespace) -> StageLimits:
    """The stage port, travel, scale and velocity ``stage`` uses; :class:`UsageError` when
    ``--travel-mm`` reaches beyond the bench file's travel or ``--counts-per-mm`` contradicts
    its scale."""
    cfg, where = _bench_config(args)
    st = cfg.stage
    asked = tuple(args.travel_mm) if args.travel_mm is not None else None
    if asked is not None and not asked[0] < asked[1]:
        raise UsageError(f"--travel-mm: LOW must be below HIGH, got {asked[0]:g} {asked[1]:g}")
    if st is None:  # no bench file, or one without [stage]: the options, else a Z825
        travel = asked or DEFAULT_TRAVEL_MM
        return StageLimits(args.port, (travel[0], travel[1]),
                           args.counts_per_mm or Z8_COUNTS_PER_MM, None,
                           COMPLETION_TOLERANCE_COUNTS)
    lo, hi = st.travel_mm
    if asked is not None and (asked[0] < lo or asked[1] > hi):
        raise UsageError(f"--travel-mm {asked[0]:g} {asked[1]:g} reaches beyond the bench "
                         f"file's travel {lo:g} .. {hi:g} mm ({where}); give a travel inside "
                         "it or change [stage] travel_mm there")
    if args.counts_per_mm is not None and args.counts_per_mm != st.counts_per_mm:
        raise UsageError(f"--counts-per-mm {args.counts_per_mm} contradicts the bench file's "
                         f"{st.counts_per_mm} counts/mm ({where}): every position in mm "
                         "would be wrong; leave it out or change [stage] there")
    travel = asked or st.travel_mm
    return StageLimits(args.port or st.port, (travel[0], travel[1]), st.counts_per_mm,
                       st.velocity_mm_s, st.tolerance_counts)
