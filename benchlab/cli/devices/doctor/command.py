"""``benchlab doctor``: the command line, where the report goes, and the run from start to
its report."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from benchlab.cli.devices.doctor.base import SIM_STAGE_TIME_SCALE, _one_line
from benchlab.cli.devices.doctor.injections import INJECTIONS
from benchlab.cli.devices.doctor.record import Outside, read_notes
from benchlab.cli.devices.doctor.report import (
    Check,
    RunSummary,
    report_markdown,
    write_learned,
)
from benchlab.cli.devices.doctor.run import Doctor

# numpy and the drivers load when the command runs: `benchlab --help` builds every parser.
from benchlab.cli.output import add_output_option, check_output, forced
from benchlab.drivers.errors import BenchlabError

if TYPE_CHECKING:
    from benchlab.bench import BenchConfig


def apply_injected_config(config: BenchConfig, inject: tuple[str, ...]) -> BenchConfig:
    """The bench file as an injected fault changes it (``stage-travel-offset``)."""
    if "stage-travel-offset" in inject and config.stage is not None:
        config = replace(config, stage=replace(config.stage, travel_mm=(2.0, 27.0)))
    return config


def report_path(args: argparse.Namespace) -> Path:
    """``--report`` (never a session's file; an existing file only with ``--force``); else the
    bench file's folder; else (the packaged simulated bench) the user's config folder - never
    silently the current folder. The default report is the doctor's own: a new run replaces
    it."""
    if args.report:
        return check_output(args.report, force=forced(args), option="--report")
    if getattr(args, "replay", None):
        cassette = Path(args.replay)
        return cassette.with_name(cassette.name.split(".")[0] + "-replayed.md")
    if args.config:
        return Path(args.config).resolve().parent / "bringup-report.md"
    from benchlab.cli.config import user_bench_file, user_config_dir

    if not args.simulate and user_bench_file().exists():
        return user_config_dir() / "bringup-report.md"
    return user_config_dir() / ("bringup-simulated" if args.simulate else "bringup") / (
        "bringup-report.md")


def _prompts(yes: bool) -> tuple[Callable[[str], bool], Callable[[str], float | None]]:
    def ask(question: str) -> bool:
        if yes:
            print(f"  ? {question} yes (--yes)")
            return True
        return input(f"  ? {question} [y/N] ").strip().lower() in ("y", "yes")

    def measure(question: str) -> float | None:
        if yes:
            print(f"  ? {question} (skipped: --yes)")
            return None
        text = input(f"  ? {question} ").strip()
        try:
            return float(text)
        except ValueError:
            return None

    return ask, measure


def _cmd_doctor(args: argparse.Namespace) -> int:
    from benchlab.bench import BenchConfig
    from benchlab.drivers import shutdown
    from benchlab.drivers.trace import io_trace

    replayed = getattr(args, "replay", None)
    if args.inject and not args.simulate:
        raise BenchlabError("--inject is for the simulated bench: add --simulate")
    report = report_path(args)
    report.parent.mkdir(parents=True, exist_ok=True)
    if replayed:
        notes = read_notes(replayed)
        run = notes.pop(0)["v"]
        simulate, inject = bool(run["simulate"]), tuple(run["inject"])
        import tomllib

        config = BenchConfig.from_dict(tomllib.loads(run["bench_toml"]), run["source"])
        outside = Outside(notes)
        cassette: Path | None = None
    else:
        simulate, inject = bool(args.simulate), tuple(args.inject or ())
        try:
            config = BenchConfig.load(args.config, simulate=simulate)
        except BenchlabError as exc:  # nothing checked, but the report says why
            source = str(args.config or "(packaged simulated bench)")
            report.write_text(report_markdown(
                [Check("0 bench file", "FAIL", _one_line(exc), "fix the named field")],
                RunSummary(source, simulate, {k: INJECTIONS[k] for k in inject}, {}, None)),
                encoding="utf-8")
            print(f"report written to {report}")
            raise
        cassette = Path(args.trace_io) if getattr(args, "trace_io", None) else (
            report.with_name(report.stem + ".cassette.jsonl.gz"))
        if not io_trace.active():
            io_trace.start(cassette)
        bench_toml = Path(config.source).read_text(encoding="utf-8") if Path(
            config.source).is_file() else ""
        outside = Outside()
        outside.get("run", lambda: {"simulate": simulate, "inject": list(inject),
                                    "bench_toml": bench_toml, "source": config.source})
    config = apply_injected_config(config, inject)
    print(f"bring-up of {config.source}{' (simulated)' if simulate else ''}; report: {report}"
          + (f"; recording every device exchange to {cassette}" if cassette else
             f"; replaying {replayed}"))
    ask, measure = _prompts(args.yes)
    doctor = Doctor(config, simulate, ask, measure, inject, outside=outside,
                    stage_time_scale=SIM_STAGE_TIME_SCALE if simulate else 1.0,
                    writes_bench_file=bool(args.config) and not replayed)
    summary = RunSummary(config.source, simulate, {k: INJECTIONS[k] for k in inject},
                         doctor.learned, str(cassette) if cassette else None,
                         replayed_from=replayed)
    t0 = time.monotonic()
    try:
        doctor.run()
    except KeyboardInterrupt as exc:
        summary.interrupted = shutdown.interrupt_reason(exc)
        summary.current_step = doctor.current_step
        raise
    except BenchlabError as exc:  # outside any check (a replay that diverged): say where
        summary.interrupted = f"stopped: {_one_line(exc)}"
        summary.current_step = doctor.current_step
        raise
    finally:
        if not replayed and not getattr(args, "trace_io", None):
            io_trace.stop()
        report.write_text(report_markdown(doctor.checks, summary), encoding="utf-8")
        print(f"report written to {report}" + (f"; send it with {cassette}" if cassette else ""))
    if args.config and doctor.learned and not replayed:
        backup = write_learned(Path(args.config), doctor.learned)
        print(f"wrote what was learned to {args.config} (backup {backup})")
    fails = sum(c.status == "FAIL" for c in doctor.checks)
    print(f"{'bring-up passed' if not fails else f'{fails} check(s) failed'} in "
          f"{time.monotonic() - t0:.1f} s")
    return 1 if fails else 0


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``doctor``."""
    doc = commands.add_parser(
        "doctor", help="guided bring-up of a new bench, one check at a time",
        description="Checks, in order: libusb, udev rule and group, the camera (identity - any "
                    "device of the vendor id is listed with the [camera] pid line to add -, a "
                    "full frame and the trailer order, exposure unit, timestamp unit, region "
                    "of interest and linearity, bit depths), the LED controller (identity, on "
                    "at its lowest current and off) and the stage (identity, homing, a measured "
                    "move from home that settles the counts/mm). Each physical action asks "
                    "first. A failed check is reported and the others still run; the report "
                    "(bringup-report.md) is always written, on Ctrl-C too, next to the bench "
                    "file (or --report PATH), with a recording of every device exchange beside "
                    "it: send both. What it learns goes into the bench file (after a backup). "
                    "Exit status 0: every check ok; 1: something failed.")
    doc.add_argument("--config", metavar="BENCH_TOML", help="the bench file to check and "
                     "update (default: the packaged simulated bench with --simulate)")
    doc.add_argument("--simulate", action="store_true", help="check the simulated bench")
    doc.add_argument("--yes", action="store_true",
                     help="answer yes to every question (scripted runs); measured values "
                          "that need a person are skipped (the stage scale is then not "
                          "measured on a real bench)")
    doc.add_argument("--inject", action="append", choices=sorted(INJECTIONS),
                     help="with --simulate: give a simulated device this fault (repeatable): "
                          + "; ".join(f"{k}: {v}" for k, v in INJECTIONS.items()))
    add_output_option(doc, "--report", metavar="PATH",
                      help="where the bring-up report goes (default: bringup-report.md next to "
                           "the bench file; with the packaged simulated bench, in the user "
                           "config folder); the recording goes beside it "
                           "(NAME.cassette.jsonl.gz)")
    doc.add_argument("--replay", metavar="CASSETTE", default=argparse.SUPPRESS,
                     help="run the bring-up recorded in CASSETTE again, without devices: the "
                          "same exchanges byte for byte, the same answers, the same report "
                          "(default: CASSETTE's folder, NAME-replayed.md)")
    doc.set_defaults(func=_cmd_doctor)
