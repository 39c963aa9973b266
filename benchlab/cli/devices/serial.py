"""Serial bench devices on the command line: ``led``, ``stage``, ``simulate``.

``--simulate`` starts a simulator on a pseudo-terminal inside the command and talks to it
through the real driver, so the same code path runs as on the bench. ``benchlab simulate``
keeps both simulators up for other programs until Ctrl-C.
"""

from __future__ import annotations

import argparse
import contextlib
import signal
import statistics
import sys
import time
from collections.abc import Iterator
from typing import Any

from benchlab.cli import UsageError, positive_float, positive_int
from benchlab.cli.devices.limits import StageLimits, led_limits, stage_limits
from benchlab.drivers import shutdown
from benchlab.drivers.apt.protocol import Z8_COUNTS_PER_MM
from benchlab.drivers.errors import BenchlabError, DeviceError

CLI_SIM_TIME_SCALE = 20.0  # one-shot --simulate commands should not make people wait
APT_USB_IDS = {(0x0403, 0xFAF0)}  # Thorlabs APT cubes (FTDI with Thorlabs PID)


# ---- helpers ---------------------------------------------------------------------------------
@contextlib.contextmanager
def _port_for(args: argparse.Namespace, kind: str, port: str | None,
              stage: StageLimits | None = None) -> Iterator[str]:
    """Yield the port to use: a fresh simulator's pty with --simulate, else ``port`` (--port,
    else the bench file's)."""
    from benchlab.drivers.apt.sim import SimulatedAptStage
    from benchlab.drivers.slc.sim import SimulatedSlc
    if not args.simulate:
        if not port:
            raise BenchlabError(f"{kind}: give --port PATH, a bench file with [{kind}] port "
                                "(--config), or --simulate")
        yield port
        return
    sim: SimulatedSlc | SimulatedAptStage
    if stage is None:
        sim = SimulatedSlc()
    else:
        sim = SimulatedAptStage(travel_mm=stage.travel_mm, counts_per_mm=stage.counts_per_mm,
                                time_scale=CLI_SIM_TIME_SCALE, homed=True)
    sim_port = sim.start()
    print(f"(simulated {kind} on {sim_port})", file=sys.stderr)
    try:
        yield sim_port
    finally:
        sim.stop()


def _wait_for_interrupt(hold_s: float | None) -> None:
    """Hold for ``hold_s`` (None: until a stop signal). Ctrl-C is the documented way to end a
    hold and returns; SIGTERM / SIGHUP propagate, so the command exits 143 / 129."""
    deadline = None if hold_s is None else time.monotonic() + hold_s
    try:
        while deadline is None or time.monotonic() < deadline:
            time.sleep(0.1 if deadline is None
                       else max(0.0, min(0.1, deadline - time.monotonic())))
    except shutdown.Stopped as exc:
        if exc.signum != signal.SIGINT:
            raise
    except KeyboardInterrupt:
        pass


# ---- led -------------------------------------------------------------------------------------
def _cmd_led(args: argparse.Namespace) -> int:
    from benchlab.drivers.slc.controller import SlcController
    if args.on and args.current_ma is None:  # before the controller is opened
        raise UsageError("led --on needs --current-ma")
    limits = led_limits(args)  # the bench file's ceiling, before anything is sent
    channel = limits.channel
    ceilings = {} if limits.ceiling_ma is None else {channel: limits.ceiling_ma}
    with (_port_for(args, "led", limits.port) as port,
          SlcController(port, ceilings_ma=ceilings) as slc):
        if args.off:
            slc.off(channel)
            print(f"led channel {channel} off")
            return 0
        slc.on(channel, args.current_ma)
        imax_ma, iset_ma = slc.get_current(channel)
        held = "until Ctrl-C" if args.for_s is None else f"for {args.for_s:g} s"
        try:  # the stop-signal hook switches off at once; close() verifies
            print(f"led channel {channel} on at {iset_ma:g} mA (ceiling {imax_ma:g} mA), "
                  f"held {held}; all channels switch off on exit", flush=True)
            _wait_for_interrupt(args.for_s)
        except shutdown.Stopped as exc:
            if exc.signum != signal.SIGINT:  # Ctrl-C ends the hold; TERM / HUP stop the command
                raise
    print(f"led channel {channel} off")
    return 0


# ---- stage -----------------------------------------------------------------------------------
def _cmd_stage(args: argparse.Namespace) -> int:
    from benchlab.drivers.apt.stage import AptStage
    if args.action == "move" and args.position_mm is None:  # before the stage is opened
        raise UsageError("stage move needs a position in mm")
    limits = stage_limits(args)  # the bench file's travel, before anything is sent
    with _port_for(args, "stage", limits.port, limits) as port, AptStage(
        port, counts_per_mm=limits.counts_per_mm, travel_mm=limits.travel_mm,
        allow_unhomed=args.allow_unhomed, completion_tolerance_counts=limits.tolerance_counts,
    ) as stage:
        if limits.velocity_mm_s is not None and args.action in ("home", "move"):
            stage.set_velocity_mm_s(limits.velocity_mm_s)
        if args.action == "home":
            stage.home()
        elif args.action == "move":
            if args.relative:
                stage.move_by_mm(args.position_mm)
            else:
                stage.move_to_mm(args.position_mm)
        elif args.action == "identify":
            stage.identify()
        status = stage.status
        info = stage.info
        print(f"stage {info.model} {info.serial}: position {status.position_mm:.4f} mm, "
              f"homed {'yes' if status.is_homed else 'no'}")
    return 0


# ---- simulate --------------------------------------------------------------------------------
def _cmd_simulate(args: argparse.Namespace) -> int:
    from benchlab.drivers.apt.sim import SimulatedAptStage
    from benchlab.drivers.slc.sim import SimulatedSlc
    lo, hi = args.travel_mm
    if not lo < hi:
        raise UsageError(f"--travel-mm: LOW must be below HIGH, got {lo:g} {hi:g}")
    if not lo <= args.initial_position_mm <= hi:
        raise UsageError(f"--initial-position-mm {args.initial_position_mm:g} is outside the "
                         f"travel {lo:g} .. {hi:g} mm")
    led = SimulatedSlc(channels=args.channels, echo=args.led_echo)
    stage = SimulatedAptStage(travel_mm=(lo, hi), time_scale=args.time_scale, homed=args.homed,
                              counts_per_mm=args.counts_per_mm,
                              initial_position_mm=args.initial_position_mm)
    try:
        print(f"led {led.start()}")
        print(f"stage {stage.start()}", flush=True)
        _wait_for_interrupt(args.for_s)
    finally:
        led.stop()
        stage.stop()
    return 0


# ---- device listing (used by `benchlab devices`) ----------------------------------------------
def list_serial_devices(simulate: bool) -> list[dict[str, Any]]:
    """Serial bench devices as dicts with keys kind, model, serial, firmware, port.

    ``simulate=True`` starts both simulators on pseudo-terminals and identifies them through
    the real drivers (the ports are gone once this returns). On hardware, APT cubes are found
    by USB id and asked for HW_GET_INFO only; other USB-serial ports are listed as
    ``kind="serial"`` without probing, since writing to an unknown instrument is unsafe. An SLC
    plugged in by USB (HID) is listed with the reason benchlab cannot drive it.
    """
    from benchlab.drivers.apt.stage import query_info
    if simulate:
        return _list_simulated()
    from serial.tools import list_ports

    out: list[dict[str, Any]] = []
    for p in sorted(list_ports.comports(), key=lambda p: p.device):
        if p.vid is None:
            continue
        entry: dict[str, Any] = {"kind": "serial", "model": p.description or "",
                                 "serial": p.serial_number or "", "firmware": "",
                                 "port": p.device}
        if (p.vid, p.pid) in APT_USB_IDS:
            try:
                info = query_info(p.device)
                entry.update(kind="stage", model=info.model, serial=str(info.serial),
                             firmware=info.firmware_str)
            except DeviceError:
                entry["kind"] = "stage"
        out.append(entry)
    from benchlab.drivers.slc.usb_hid import usb_slcs

    out += [{"kind": "led", "model": d.product, "serial": d.serial, "firmware": "",
             "port": f"usb {d.where} {d.vendor_id:04x}:{d.product_id:04x}",
             "error": "USB HID: benchlab drives the SLC over RS232 only"} for d in usb_slcs()]
    return out


def _list_simulated() -> list[dict[str, Any]]:
    from benchlab.drivers.apt.sim import SimulatedAptStage
    from benchlab.drivers.apt.stage import AptStage
    from benchlab.drivers.slc.controller import SlcController
    from benchlab.drivers.slc.sim import SimulatedSlc
    led, stage = SimulatedSlc(), SimulatedAptStage(travel_mm=(0.0, 50.0))
    try:
        led_port, stage_port = led.start(), stage.start()
        with SlcController(led_port, ceilings_ma={}) as slc:
            li = slc.device_info
        with AptStage(stage_port, travel_mm=(0.0, 50.0), updates=False) as apt:
            si = apt.info
    finally:
        led.stop()
        stage.stop()
    return [
        {"kind": "led", "model": li.module, "serial": li.serial, "firmware": li.driver_version,
         "port": led_port},
        {"kind": "stage", "model": si.model, "serial": str(si.serial),
         "firmware": si.firmware_str, "port": stage_port},
    ]


# ---- benchmark -------------------------------------------------------------------------------
def _cmd_benchmark(args: argparse.Namespace) -> int:
    from benchlab.drivers.apt.sim import SimulatedAptStage
    from benchlab.drivers.apt.stage import AptStage
    from benchlab.drivers.slc.controller import SlcController
    from benchlab.drivers.slc.sim import SimulatedSlc
    n = args.repeat
    rows: list[tuple[str, list[float]]] = []
    led, stage = SimulatedSlc(), SimulatedAptStage(travel_mm=(0.0, 50.0), homed=True,
                                                    time_scale=100.0)
    try:
        with SlcController(led.start(), ceilings_ma={1: 100.0}) as slc:
            rows.append(("SLC ?CURRENT round trip", _timed(lambda: slc.get_current(1), n)))
            rows.append(("SLC on() NORMAL+MODE", _timed(lambda: slc.on(1, 50.0), n)))
        with AptStage(stage.start(), travel_mm=(0.0, 50.0)) as apt:
            rows.append(("APT position request", _timed(lambda: apt.position_mm, n)))
            targets = iter([15.0, 32.0] * n)
            rows.append(("APT 17 mm move, x100 time",
                         _timed(lambda: apt.move_to_mm(next(targets)), min(n, 10))))
    finally:
        led.stop()
        stage.stop()
    print(f"{'operation':30s} {'n':>5s} {'median ms':>10s} {'max ms':>10s}")
    for name, times in rows:
        print(f"{name:30s} {len(times):5d} {statistics.median(times) * 1e3:10.3f} "
              f"{max(times) * 1e3:10.3f}")
    return 0


def _timed(fn: Any, n: int) -> list[float]:
    out = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        out.append(time.perf_counter() - t0)
    return out


# ---- registration ----------------------------------------------------------------------------
def _add_stage_geometry(p: argparse.ArgumentParser, default_hi: float) -> None:
    p.add_argument("--travel-mm", nargs=2, type=float, metavar=("LOW", "HIGH"),
                   default=(0.0, default_hi), help=f"soft travel limits (default 0 {default_hi:g})")
    p.add_argument("--counts-per-mm", type=float, default=Z8_COUNTS_PER_MM,
                   help=f"encoder counts per mm (Z8: {Z8_COUNTS_PER_MM}; alternative 34304)")


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``led``, ``stage``, ``simulate`` and ``benchmark serial``."""
    led = commands.add_parser(
        "led", help="switch an LED channel of the Mightex SLC on or off",
        description="Switch one SLC channel on (held until Ctrl-C or --for-s, then every "
                    "channel is switched off) or off. The current is checked against the bench "
                    "file's ceiling for the channel before anything is sent; a channel without "
                    "a ceiling is never lit.")
    led.add_argument("--port", help="serial port of the SLC (default: the bench file's "
                     "[led] port), e.g. /dev/ttyUSB0")
    led.add_argument("--simulate", action="store_true", help="use a built-in simulated SLC")
    led.add_argument("--config", help="bench file whose [led.ceiling_ma] bounds the current "
                     "(default: the user's bench.toml; with --simulate the simulated bench's)")
    led.add_argument("--channel", type=int, default=None,
                     help="channel, 1-based (default: the bench file's [led] channel, else 1)")
    led.add_argument("--current-ma", type=float, help="working current in mA (with --on)")
    led.add_argument("--ceiling-ma", type=float, default=None,
                     help="refuse currents above this; default the bench file's ceiling for "
                     "the channel, and never above it (needed when no bench file gives one)")
    led.add_argument("--for-s", type=float, help="with --on: hold this long, then switch off")
    onoff = led.add_mutually_exclusive_group(required=True)
    onoff.add_argument("--on", action="store_true", help="switch on at --current-ma")
    onoff.add_argument("--off", action="store_true", help="switch off")
    led.set_defaults(func=_cmd_led)

    stage = commands.add_parser(
        "stage", help="home, move or read the Thorlabs APT stage",
        description="Home, move (absolute, or --relative) or read the position of a "
                    "KDC101/TDC001 stage with a Z8 actuator. Prints the final position.")
    stage.add_argument("action", choices=["home", "move", "where", "identify"])
    stage.add_argument("position_mm", nargs="?", type=float, help="target for move, in mm")
    stage.add_argument("--port", help="serial port of the cube (default: the bench file's "
                       "[stage] port), e.g. /dev/ttyUSB1")
    stage.add_argument("--simulate", action="store_true",
                       help="use a built-in simulated stage (starts homed)")
    stage.add_argument("--relative", action="store_true", help="move by MM instead of to MM")
    stage.add_argument("--allow-unhomed", action="store_true", help="allow moves before homing")
    stage.add_argument("--config", help="bench file whose [stage] travel, scale and velocity "
                       "apply (default: the user's bench.toml; with --simulate the simulated "
                       "bench's)")
    stage.add_argument("--travel-mm", nargs=2, type=float, metavar=("LOW", "HIGH"),
                       default=None, help="soft travel limits, inside the bench file's "
                       "(default: the bench file's, else 0 25)")
    stage.add_argument("--counts-per-mm", type=float, default=None,
                       help=f"encoder counts per mm (default: the bench file's, else Z8: "
                       f"{Z8_COUNTS_PER_MM}; alternative 34304)")
    stage.set_defaults(func=_cmd_stage)

    sim = commands.add_parser(
        "simulate", help="serve a simulated LED controller and stage on pseudo-terminals",
        description="Start the simulated SLC and APT stage, print 'led PATH' and "
                    "'stage PATH', and serve until Ctrl-C.")
    sim.add_argument("--time-scale", type=positive_float, default=1.0,
                     help="simulated seconds per wall second for stage motion (default 1)")
    sim.add_argument("--channels", type=positive_int, default=4, help="LED channels (default 4)")
    sim.add_argument("--homed", action="store_true", help="start the stage already homed")
    sim.add_argument("--led-echo", action="store_true",
                     help="start the LED controller echoing commands (ECHOON), as a previous "
                     "program may leave it; the driver switches echo off when it opens")
    sim.add_argument("--initial-position-mm", type=float, default=0.0)
    sim.add_argument("--for-s", type=positive_float, help="serve this long instead of until Ctrl-C")
    _add_stage_geometry(sim, 50.0)
    sim.set_defaults(func=_cmd_simulate)

    bench = benchmarks.add_parser(
        "serial", help="round-trip times of the serial drivers against their simulators",
        description="Time SLC and APT exchanges over pseudo-terminals and print a table.")
    bench.add_argument("--repeat", type=positive_int, default=100)
    bench.set_defaults(func=_cmd_benchmark)
