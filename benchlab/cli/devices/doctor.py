"""``benchlab doctor``: a guided bring-up of a new bench, one check at a time, in order.

1. libusb backend; 2. udev rule (for the camera's ids) and group (active in this login);
3. the camera enumerates (any device of the vendor id is listed when the configured one is
not there), answers its queries, and a full 1280 x 1024 frame settles the trailer order;
4. exposure: the frame period against the set exposure (trailer timestamps, their unit
settled against the host clock), the profile that fits when the exposure field differs, the
region of interest (full frame when refused), a dark frame and two exposures whose signal
ratio checks linearity; 5. every bit depth of the profile decodes to plausible codes (the
frame endpoint is drained after a wrong-size frame); 6. the LED controller: port, identity,
firmware and module type; 7. the LED on at its lowest current and off, read back; 8. the
stage: identity, homing (timeout from its own home velocity) and a measured relative move
from home that settles the counts/mm.

The doctor never stops halfway: a device error inside a check is a FAIL with what it means
on the bench, the checks that depend on it are skipped (saying why), every other check still
runs, and the report is always written - on Ctrl-C or SIGTERM too, with what was done so
far. Every device exchange is recorded in a cassette next to the report; ``benchlab doctor
--replay CASSETTE`` runs the same bring-up again from it, byte for byte, without devices.

Each physical action (light, motion) waits for a yes (``--yes`` answers yes for scripted
runs). What the doctor learned goes into the bench file, after a backup. ``--simulate`` runs
the same checks on simulated devices; ``--inject`` gives one of them a fault the checks
should name (see :data:`INJECTIONS`).
"""

from __future__ import annotations

import argparse
import contextlib
import getpass
import math
import os
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import TYPE_CHECKING, Any, TypeVar

from benchlab.cli.devices.doctor_record import Outside, read_notes
from benchlab.cli.devices.doctor_report import (
    Check,
    RunSummary,
    report_markdown,
    set_toml_key,
    write_learned,
)

# numpy and the drivers load when the command runs: `benchlab --help` builds every parser.
from benchlab.cli.output import add_output_option, check_output, forced
from benchlab.drivers.errors import BenchlabError, DeviceError

if TYPE_CHECKING:
    from benchlab.bench import BenchConfig
    from benchlab.drivers.mightex import protocol as p_types

__all__ = ["INJECTIONS", "Check", "Doctor", "set_toml_key", "write_learned"]

#: Faults ``--simulate --inject NAME`` puts into the simulated bench (what the checks name).
INJECTIONS = {
    "camera-profile": "the camera speaks protocol v1.0.6 (4-byte exposure field)",
    "camera-unit": "the camera counts exposure in 0.1 ms, not 0.05 ms",
    "camera-no-12bit": "the camera has no 12-bit mode",
    "camera-pid": "the camera enumerates with product id 0x0528, not 0x0428",
    "camera-trailer-swapped": "the frame trailer gives the line count before the line length",
    "camera-timestamp-100us": "the trailer timestamps count 0.1 ms, not 1 ms",
    "camera-roi-refused": "the camera takes only the full 1280 x 1024 resolution",
    "camera-grab-timeout": "the camera reports frames in its buffer but never sends one",
    "camera-exposure-4byte-ignored-length": "the firmware reads a 4-byte exposure whatever "
                                            "the length byte says",
    "led-lf-cr": "the LED controller ends replies LF CR",
    "led-usb-hid": "the LED controller is plugged in by USB only (HID); its serial port is "
                   "silent",
    "stage-34304": "the actuator has 34304 counts/mm, the bench file assumes 34554.96",
    "stage-home-timeout": "the stage's reverse limit switch never trips: homing never ends",
    "stage-travel-offset": "the stage's travel is 2..27 mm (a non-zero lower limit)",
    "stage-parks-off": "the stage settles 12 counts off every target",
}
EXPOSURE_MS = 100.0  # longer than a full-frame readout (27 ms): the period is the exposure
ROI = 256  # linearity and depths read a 256 x 256 frame when the camera takes it: fast
SIM_LED_E_PER_MS_PER_MA = 40.0
SIM_STAGE_TIME_SCALE = 2000.0  # the simulated stage moves this much faster than real time
#: Free-running frames timed against the host clock when the timestamp unit is in question.
TIMESTAMP_FRAMES = 5
#: A dial gauge's own error (a 0.01 mm gauge: about +-0.01 mm over the move), mm.
GAUGE_ERROR_MM = 0.01
#: A measured scale is taken as a known actuator's within this fraction.
SCALE_MATCH = 0.004
#: The scale step's longest move: 20 mm on a 25 mm actuator (a gauge's range, and clear of
#: the far limit switch).
SCALE_MOVE_MAX_MM = 20.0
_T = TypeVar("_T")


@dataclass
class Doctor:
    """Runs the checks; ``ask`` gets a yes/no question, ``measure`` a number (None: skip)."""

    config: BenchConfig
    simulate: bool
    ask: Callable[[str], bool]
    measure: Callable[[str], float | None]
    inject: tuple[str, ...] = ()
    say: Callable[[str], None] = print
    outside: Outside = field(default_factory=Outside)
    checks: list[Check] = field(default_factory=list)
    learned: dict[tuple[str, str], Any] = field(default_factory=dict)
    sims: dict[str, Any] = field(default_factory=dict)
    usb_sysfs: Path | None = None  # where USB devices are listed (default: Linux sysfs)
    #: The step running now (the report names it when the run is interrupted).
    current_step: str | None = None
    stage_time_scale: float = 1.0
    #: Whether what is learned goes into a bench file (``--config`` given, not a replay).
    writes_bench_file: bool = False
    #: The camera opened with the profile that fits, when the configured one did not.
    _fitted: Any = field(default=None, init=False, repr=False)

    @property
    def learned_note(self) -> str:
        """How a learned fact reaches the bench file, for the report's "what to do" lines."""
        return ("(written to the bench file)" if self.writes_bench_file
                else "(in your bench file; `benchlab doctor --config FILE` writes it)")

    def add(self, step: str, status: str, detail: str, todo: str = "") -> None:
        self.checks.append(Check(step, status, detail, todo))
        self.say(f"[{status:>4}] {step}: {detail}" + (f"\n       -> {todo}" if todo else ""))

    @property
    def failed(self) -> bool:
        return any(c.status == "FAIL" for c in self.checks)

    @property
    def replaying(self) -> bool:
        return self.outside.replaying

    def attempt(self, step: str, meaning: str, check: Callable[[], _T]) -> _T | None:
        """Run one check; a device error is its FAIL (with what it means on the bench) and
        None, so the run goes on with the checks that do not depend on it."""
        self.current_step = step
        try:
            return check()
        except (BenchlabError, OSError) as exc:
            self.add(step, "FAIL", _replay_reason() or _one_line(exc), meaning)
            return None

    def skip(self, steps: tuple[str, ...], why: str) -> None:
        for step in steps:
            self.add(step, "skip", f"not run: {why}")

    # ---- the run --------------------------------------------------------------------------
    def run(self) -> None:
        stack = contextlib.ExitStack()
        try:
            self._run(stack)
        finally:  # devices closed (LED off, stage stopped); an error there is a check too
            running = self.current_step
            self.attempt("9 devices closed", "switch the LED off and check the stage at their "
                         "controllers", stack.close)
            self.current_step = running

    def _run(self, stack: contextlib.ExitStack) -> None:
        if self.simulate and not self.replaying:
            self._start_sims(stack)
        self.attempt("1 libusb backend", "", self.check_usb_backend)
        self.attempt("2 udev rule and group", "", self.check_udev)
        cam = self.attempt("3 camera enumerates and answers", "check the cable and power; "
                           "`benchlab devices` lists what is on the bus",
                           lambda: self.open_camera(stack))
        if cam is not None and ("camera", "pid") in self.learned:  # the rule for the camera
            self.attempt("2 udev rule and group", "", self.check_udev)  # actually plugged in
        led = self.attempt("6 LED controller identity", "check the port, 9600 8N1 and a "
                           "straight (not null-modem) cable", lambda: self.open_led(stack))
        if cam is not None:
            self._camera_checks(cam, led, stack)
        else:
            self.skip(("4 exposure unit and linearity", "5 bit depths decode"),
                      "no camera (step 3 failed)")
        if led is not None:
            self.attempt("7 LED on at its lowest current, off", "the controller took the "
                         "identity query but not the output commands: check the channel",
                         lambda: self.check_led(led))
        else:
            self.skip(("7 LED on at its lowest current, off",), "no LED controller (step 6)")
        stage = self.attempt("8 stage identity", "check the port and the cube's power",
                             lambda: self.open_stage(stack))
        if stage is not None:
            self.check_stage(stage)
        else:
            self.skip(("8 stage homing", "8 stage scale"), "no stage (step 8 identity)")
        self.current_step = None

    def _camera_checks(self, cam: Any, led: Any, stack: contextlib.ExitStack) -> None:
        lit = bool(self.attempt("4 light for the camera checks", "the LED controller did "
                                "not switch on: the camera checks run without light",
                                lambda: self._light_on(led)))
        try:
            fitted = self.attempt(
                "4 exposure unit and linearity", "the camera answers but no frame with the "
                "set exposure came: see the lines above", lambda: self.check_exposure(cam, lit,
                                                                                    stack))
            if fitted is not None:
                self.attempt("5 bit depths decode", "a bit depth broke the grab: use a depth "
                             "that decodes and report the model", lambda: self.check_depths(
                                 fitted))
            else:
                self.skip(("5 bit depths decode",), "no frame could be read in step 4")
        finally:
            if led is not None and lit:
                self.attempt("4 light for the camera checks", "switch the LED off at the "
                             "controller", lambda: led.off(self._channel))

    # ---- simulated bench ------------------------------------------------------------------
    def _start_sims(self, stack: contextlib.ExitStack) -> None:
        import numpy as np

        from benchlab.drivers.apt.sim import SimulatedAptStage
        from benchlab.drivers.mightex import protocol as p
        from benchlab.drivers.mightex.sim import SimCameraBackend, SimulatedCamera
        from benchlab.drivers.slc.sim import SimulatedSlc

        cfg = self.config
        channel = cfg.led.channel if cfg.led is not None else 1
        slc = SimulatedSlc(reply_end=b"\n\r" if "led-lf-cr" in self.inject else b"\r\n")
        slc.start()
        stack.callback(slc.stop)
        if "led-usb-hid" in self.inject:
            slc.faults.no_reply = 1 << 30  # the configured port reaches no controller...
            self.usb_sysfs = _usb_bus_with_an_slc(stack)  # ...which is on the USB bus

        def light(state: Any) -> Any:
            rate = SIM_LED_E_PER_MS_PER_MA * state.bench.get("led_ma", 0.0)
            return np.full((state.height, state.width), rate)

        chosen = p.SPECS["MCE-B013-U/v1.0.6" if "camera-profile" in self.inject
                         else "MCE-B013-U"]
        facts: dict[str, dict[str, Any]] = {  # what the simulated camera is (they combine)
            "camera-unit": {"exposure_unit_ms": 0.1},
            "camera-no-12bit": {"bit_depths": (8, 10)},
            "camera-trailer-swapped": {"trailer_order": "column_row"},
            "camera-timestamp-100us": {"timestamp_unit_ms": 0.1},
        }
        for name in self.inject:
            chosen = replace(chosen, **facts.get(name, {}))
        cam = SimulatedCamera(light, seed=1, profile=chosen,
                              pid=0x0528 if "camera-pid" in self.inject else p.DEFAULT_PID,
                              bench_state=lambda: {"led_ma": slc.channel_output_ma(channel)})
        cam.faults.refuse_roi = "camera-roi-refused" in self.inject
        cam.faults.frames_never_sent = "camera-grab-timeout" in self.inject
        cam.faults.exposure_reads_4_bytes = "camera-exposure-4byte-ignored-length" in self.inject
        counts = 34304.0 if "stage-34304" in self.inject else (
            cfg.stage.counts_per_mm if cfg.stage is not None else 34554.96)
        travel = cfg.stage.travel_mm if cfg.stage is not None else (0.0, 25.0)
        stage = SimulatedAptStage(counts_per_mm=counts, travel_mm=travel,
                                  time_scale=SIM_STAGE_TIME_SCALE,
                                  initial_position_mm=(travel[0] + travel[1]) / 2)
        stage.faults.home_never = "stage-home-timeout" in self.inject
        stage.faults.park_off_counts = 12 if "stage-parks-off" in self.inject else 0
        stage.start()
        stack.callback(stage.stop)
        self.sims = {"camera": cam, "backend": SimCameraBackend([cam]), "led": slc,
                     "stage": stage}

    # ---- 1, 2: USB access -----------------------------------------------------------------
    def check_usb_backend(self) -> None:
        step = "1 libusb backend"

        def found() -> bool:
            import usb.backend.libusb1

            return usb.backend.libusb1.get_backend() is not None

        if self.outside.get("libusb", found):
            self.add(step, "ok", "libusb-1.0 found")
        elif self.simulate:
            self.add(step, "skip", "libusb-1.0 not found (not needed on the simulated bench)")
        else:
            self.add(step, "FAIL", "no libusb-1.0: pyusb cannot reach the camera",
                     "sudo apt install libusb-1.0-0  (Fedora: sudo dnf install libusb1)")

    def check_udev(self) -> None:
        step = "2 udev rule and group"
        from benchlab.drivers.mightex import protocol as p
        from benchlab.drivers.mightex.camera import udev_hint, udev_rule_line

        pid = self.learned.get(("camera", "pid"), self.config.camera.pid or p.DEFAULT_PID)
        facts = self.outside.get("udev", lambda: _udev_facts(p.VENDOR_ID, pid))
        if facts is None:
            self.add(step, "skip", "not Linux: no udev rule needed")
            return
        user = facts["user"]
        missing = []
        if not facts["rule"]:
            missing.append(f"a udev rule for {p.VENDOR_ID:04x}:{pid:04x} (add: "
                           f"{udev_rule_line(p.VENDOR_ID, pid)})")
        if user != "root" and not facts["member"]:
            missing.append(f"{user} in group plugdev")
        elif user != "root" and not facts["active"]:
            missing.append("plugdev active in this login (log out and in, or `newgrp "
                           "plugdev`)")
        if not missing:
            self.add(step, "ok", f"{facts['rule']} gives {p.VENDOR_ID:04x}:{pid:04x} to "
                     f"plugdev; {user} is in it, active in this login")
        else:
            self.add(step, "skip" if self.simulate else "FAIL", "missing: " + "; ".join(missing),
                     "" if self.simulate else udev_hint())

    # ---- 3: the camera --------------------------------------------------------------------
    def _backend(self) -> Any:
        return self.sims.get("backend")

    def open_camera(self, stack: contextlib.ExitStack,
                    profile: p_types.CameraSpec | None = None, announce: bool = True) -> Any:
        from benchlab.drivers.errors import DeviceNotFoundError
        from benchlab.drivers.mightex import protocol as p
        from benchlab.drivers.mightex.camera import MightexCamera

        step = "3 camera enumerates and answers"
        cfg = self.config.camera
        pid = self.learned.get(("camera", "pid"), cfg.pid)
        profile = profile or self._configured_profile()
        try:
            cam = MightexCamera.open(cfg.serial, backend=self._backend(), pid=pid,
                                     profile=profile)
        except DeviceNotFoundError as exc:
            other = self._camera_elsewhere(step, exc, pid or p.DEFAULT_PID)
            if other is None:
                return None  # its FAIL line is written
            self.learned[("camera", "pid")] = other
            cam = MightexCamera.open(cfg.serial, backend=self._backend(), pid=other,
                                     profile=profile)
        stack.callback(cam.close)
        info = cam.info
        status = cam.buffer_status()
        if announce and ("camera", "pid") not in self.learned:  # else the FAIL line said it
            self.add(step, "ok", f"VID 0x{p.VENDOR_ID:04X} PID 0x{info.pid:04X}, {info.model} "
                     f"serial {info.serial}, firmware {info.firmware}, buffer query answered "
                     f"({status.width}x{status.height}); profile {cam.spec.model}")
        return cam

    def _configured_profile(self) -> p_types.CameraSpec:
        """The bench file's camera profile, with the facts settled so far in this run (all
        of the model's bit depths: step 5 checks each again)."""
        settled = {k: v for (section, k), v in self.learned.items()
                   if section == "camera" and k in ("model", "trailer_order",
                                                    "timestamp_unit_ms")}
        spec: p_types.CameraSpec = replace(self.config.camera, bit_depths=None,
                                           **settled).profile()
        return spec

    def _camera_elsewhere(self, step: str, exc: Exception, pid: int) -> int | None:
        """The camera not found at ``pid``: list every device of the vendor (or naming
        Mightex); one of another product id is taken as the camera. Returns its id."""
        from benchlab.drivers.mightex.camera import udev_rule_line, vendor_devices

        seen = self.outside.get("usb-bus", lambda: [
            d.to_dict() for d in vendor_devices(self._backend())])
        others = [d for d in seen if d["pid"] != pid]
        if not others:
            self.add(step, "FAIL", f"{exc}; no USB device of vendor 0x04B4 or naming Mightex "
                     "is on the bus", "check the cable and power; on Linux `lsusb` should "
                     "list 04b4:xxxx")
            return None
        from benchlab.drivers.mightex.camera import UsbDeviceSeen

        found = [UsbDeviceSeen(**d) for d in others]
        lines = "; ".join(f"{d.describe()}: put `pid = 0x{d.pid:04X}` under [camera] and add "
                          f"the udev rule line `{udev_rule_line(d.vid, d.pid)}`" for d in found)
        if len(found) > 1:
            self.add(step, "FAIL", f"no camera at PID 0x{pid:04X}; on the bus: {lines}",
                     "pick the camera's product id from the list and set [camera] pid")
            return None
        self.add(step, "FAIL", f"no camera at PID 0x{pid:04X}, but this device is on the bus: "
                 f"{found[0].describe()}; the checks go on with it",
                 f"set [camera] pid = 0x{found[0].pid:04X} {self.learned_note} and add "
                 f"the udev rule line {udev_rule_line(found[0].vid, found[0].pid)}")
        return found[0].pid

    # ---- 4: exposure ----------------------------------------------------------------------
    @property
    def _channel(self) -> int:
        return self.config.led.channel if self.config.led is not None else 1

    def _light_on(self, led: Any) -> bool:
        """Light for the camera checks: the LED (after a yes), or room light (real bench)."""
        if led is not None:
            current = max(led.current_step_ma(self._channel), 5.0)
            ceiling = led.ceiling_ma(self._channel)
            if ceiling is not None and current <= ceiling and self._ask(
                    f"switch LED channel {self._channel} on at {current:g} mA for the camera "
                    "checks?"):
                led.on(self._channel, current)
                return True
        if self.simulate:
            return False
        return self._ask("uncover the lens so some room light falls on the sensor; done?")

    def _ask(self, question: str) -> bool:
        return bool(self.outside.get(f"ask: {question}", lambda: self.ask(question)))

    def _measure(self, question: str) -> float | None:
        return self.outside.get("measure", lambda: self.measure(question))

    def _grab(self, cam: Any, fresh: bool = True) -> Any:
        """A grab; a trailer whose geometry is the frame's with its two words swapped
        settles the trailer order (a fact of the profile) and the grab is repeated."""
        from benchlab.drivers.mightex.protocol import TrailerGeometryError

        try:
            return cam.grab(fresh=fresh)
        except TrailerGeometryError as exc:
            if not exc.swapped:
                raise
            w, h = exc.configured
        assumed = cam.spec.trailer_order
        other = "column_row" if assumed == "row_column" else "row_column"
        self.learned[("camera", "trailer_order")] = other
        cam.use_profile(replace(cam.spec, trailer_order=other))
        self.add("3 frame trailer order", "FAIL", f"a full {w}x{h} frame's trailer gives the "
                 f"line count first ({h}, {w}): not the {assumed} order assumed",
                 f'set [camera] trailer_order = "{other}" {self.learned_note}')
        return cam.grab(fresh=fresh)

    def check_exposure(self, cam: Any, lit: bool, stack: contextlib.ExitStack) -> Any:
        """Frame period (full frame), timestamp unit, profile, region of interest and
        linearity; returns the camera to go on with (None when no profile fits)."""
        from benchlab.drivers.errors import DeviceTimeoutError
        from benchlab.drivers.mightex.camera import (
            CameraProfileMismatchError,
            FrameEndpointTimeoutError,
        )
        from benchlab.drivers.mightex.diagnose import period_finding, ratio_finding

        step = "4 exposure unit and linearity"
        spec = cam.spec
        cam.configure(width=spec.max_width, height=spec.max_height, bits=8)
        try:
            period = self._period_ms(cam)
        except FrameEndpointTimeoutError:
            raise  # not a profile question: the frame endpoint delivers nothing
        except (CameraProfileMismatchError, DeviceTimeoutError) as exc:
            self.add(step, "FAIL", f"profile {cam.spec.model} does not fit: {_one_line(exc)}",
                     self._fitting_profile(cam, stack))
            return self._fitted
        self._full_frame_ok(cam)
        finding = period_finding(EXPOSURE_MS, period)
        if finding:
            self.add(step, "FAIL", finding, "the exposure unit of the camera's profile is "
                     "wrong: report the camera model and firmware (issue tracker)")
            return cam
        region = self._region(cam)
        if not lit:
            self.add(step, "warn", f"frame period {period:g} ms at {EXPOSURE_MS:g} ms (unit "
                     "right); linearity not checked (no light)")
            return cam
        dark = self._mean(cam, 0.05)  # the shortest exposure: (almost) dark, lit or not
        short, long = self._mean(cam, 20.0), self._mean(cam, 40.0)
        finding = ratio_finding(dark, short, long, 2.0)
        if finding:
            self.add(step, "FAIL", finding, "check that the light is steady, then the profile")
        else:
            self.add(step, "ok", f"frame period {period:g} ms at a set {EXPOSURE_MS:g} ms; dark "
                     f"{dark:.1f}, 20/40 ms signal ratio {(long - dark) / (short - dark):.3f} "
                     f"({region} frames)")
        return cam

    def _full_frame_ok(self, cam: Any) -> None:
        if not any(c.step == "3 frame trailer order" for c in self.checks):
            s = cam.settings
            self.add("3 frame trailer order", "ok", f"a full {s['width']}x{s['height']} frame "
                     f"read; its trailer gives {s['width']}x{s['height']} "
                     f"({cam.spec.trailer_order} order, as assumed)")

    def _region(self, cam: Any) -> str:
        """Linearity and depths read a 256 x 256 region; a camera that refuses it is read
        at full frame (returns the geometry used, "WxH")."""
        from benchlab.drivers.mightex.camera import CameraRoiRefusedError

        spec = cam.spec
        try:
            cam.configure(width=ROI, height=ROI, bits=8)
            self._grab(cam)
        except CameraRoiRefusedError as exc:
            cam.configure(width=spec.max_width, height=spec.max_height, bits=8)
            self.add("4 region of interest", "FAIL", f"{_one_line(exc)}: the checks go on "
                     "at full frame", "nothing to set in the bench file; procedures that set a "
                     "region of interest fail on this camera: report the model and firmware")
            return f"{spec.max_width}x{spec.max_height}"
        return f"{ROI}x{ROI}"

    def _period_ms(self, cam: Any) -> float:
        """Shortest trailer-timestamp step between consecutive free-running frames, in ms.
        A period near 10x or 0.1x the exposure is a timestamp-unit question, settled here
        against the host clock."""
        unit = cam.spec.timestamp_unit_ms
        cam.set_exposure_ms(EXPOSURE_MS)
        stamps = [self._grab(cam).meta.timestamp_ms]
        for _ in range(3):
            stamps.append(self._grab(cam, fresh=False).meta.timestamp_ms)
        counts = [round(s / unit) for s in stamps]
        steps = [(b - a) % 65536 for a, b in zip(counts, counts[1:], strict=False)]
        period = float(min(s for s in steps if s > 0)) * unit
        ratio = period / EXPOSURE_MS
        if any(abs(ratio / r - 1) < 0.15 for r in (10.0, 0.1)):
            unit = self._settle_timestamp_unit(cam, ratio)
            period = float(min(s for s in steps if s > 0)) * unit
        return period

    def _settle_timestamp_unit(self, cam: Any, ratio: float) -> float:
        """Time :data:`TIMESTAMP_FRAMES` fresh frames by the host clock and by their trailer
        timestamps; the nearer known unit is the camera's."""
        from benchlab.drivers.mightex.profile import TIMESTAMP_UNITS_MS

        step = "4 trailer timestamp unit"
        now = cam.host_time_s
        first = self._grab(cam)
        t0 = self.outside.get("host-clock-s", now)
        last = first
        for _ in range(TIMESTAMP_FRAMES):
            last = self._grab(cam)
        t1 = self.outside.get("host-clock-s", now)
        unit_now = cam.spec.timestamp_unit_ms
        raw = (round(last.meta.timestamp_ms / unit_now)
               - round(first.meta.timestamp_ms / unit_now)) % 65536
        host_ms = (t1 - t0) * 1e3
        measured = host_ms / raw if raw else float("inf")
        unit = min(TIMESTAMP_UNITS_MS, key=lambda u: abs(math.log(measured / u)))
        if unit == unit_now:
            self.add(step, "ok", f"{raw} timestamp steps in {host_ms:.0f} ms of host clock: "
                     f"{unit:g} ms per step, as assumed (the period ratio {ratio:.3g} is not "
                     "the timestamp's)")
            return unit
        self.learned[("camera", "timestamp_unit_ms")] = unit
        cam.use_profile(replace(cam.spec, timestamp_unit_ms=unit))
        self.add(step, "FAIL", f"the frame period read {ratio:.3g} x the exposure, and "
                 f"{raw} timestamp steps took {host_ms:.0f} ms of host clock: the trailer "
                 f"counts {unit:g} ms, not {unit_now:g} ms (the exposure unit is not in "
                 "question)", f"set [camera] timestamp_unit_ms = {unit:g} (written to the "
                 "bench file)")
        return unit

    def _mean(self, cam: Any, exposure_ms: float) -> float:
        import numpy as np

        cam.set_exposure_ms(exposure_ms)
        return float(np.mean(self._grab(cam).pixels))

    def _fitting_profile(self, cam: Any, stack: contextlib.ExitStack) -> str:
        """Try every other known profile; the first whose exposure round-trips is the fix
        (and ``_fitted`` the camera opened with it)."""
        from benchlab.drivers.mightex import protocol as p
        from benchlab.drivers.mightex.camera import FrameEndpointTimeoutError
        from benchlab.drivers.mightex.diagnose import period_finding

        tried = cam.spec.model
        cam.close()
        self._fitted = None
        for name, spec in p.SPECS.items():
            if name == tried:
                continue
            self.current_step = f"4 exposure unit and linearity (profile {name})"
            try:
                other = self.open_camera(stack, profile=replace(
                    spec, trailer_order=cam.spec.trailer_order,
                    timestamp_unit_ms=cam.spec.timestamp_unit_ms), announce=False)
                other.configure(width=spec.max_width, height=spec.max_height, bits=8)
                period = self._period_ms(other)
            except FrameEndpointTimeoutError:
                raise
            except DeviceError:
                with contextlib.suppress(Exception):
                    other.close()
                continue
            if period_finding(EXPOSURE_MS, period) is None:
                self.learned[("camera", "model")] = name
                self._full_frame_ok(other)
                self.add("4 exposure unit and linearity", "ok",
                         f"profile {name} fits (frame period {period:g} ms)")
                self._region(other)
                self._fitted = other
                return f'set [camera] model = "{name}" {self.learned_note}'
            other.close()
        return "no known profile fits: report the camera model and firmware"

    # ---- 5: bit depths --------------------------------------------------------------------
    def check_depths(self, cam: Any) -> None:
        import numpy as np

        from benchlab.drivers.mightex.diagnose import depth_findings

        step = "5 bit depths decode"
        cam.set_exposure_ms(40.0)
        width, height = cam.settings["width"], cam.settings["height"]
        means: dict[int, float] = {}
        problems: list[str] = []
        for bits in (*cam.spec.bit_depths, 8):  # ... and back: 8 must still work after them
            try:
                cam.configure(width=width, height=height, bits=bits)
                pixels = self._grab(cam).pixels
            except DeviceError as exc:
                problems.append(f"{bits}-bit: {_one_line(exc)}")
                continue
            problems += [f"{bits}-bit: {f}" for f in depth_findings(pixels, bits)]
            means[bits] = float(np.mean(pixels)) * 2 ** (12 - bits)
        good = [b for b in cam.spec.bit_depths
                if b in means and not any(x.startswith(f"{b}-bit") for x in problems)]
        configured = self.config.camera.bit_depths or cam.spec.bit_depths
        if good and tuple(good) != tuple(configured):
            self.learned[("camera", "bit_depths")] = good
        elif problems and good:  # the bench file already leaves the others out
            self.add(step, "ok", f"{', '.join(map(str, good))} bits decode; the others do not, "
                     f"as the bench file's bit_depths = {good} says ({'; '.join(problems)})")
            return
        if problems:
            self.add(step, "FAIL", "; ".join(problems), f"set [camera] bit_depths = {good} "
                     f"{self.learned_note}: runs then refuse the others")
        else:
            scaled = ", ".join(f"{b}-bit {means[b]:.0f}" for b in good)
            self.add(step, "ok", f"{len(good)} depths plausible, 8-bit again after them "
                     f"(means on the 12-bit scale: {scaled})")

    # ---- 6, 7: the LED controller ---------------------------------------------------------
    def _serial_port(self, device: str, configured: str | None) -> str | None:
        if self.replaying:
            return configured or f"replay://{device}"  # the replay's pseudo-terminal
        if self.simulate:
            return str(self.sims[device].port)
        return configured

    def open_led(self, stack: contextlib.ExitStack) -> Any:
        from benchlab.drivers.slc.controller import SlcController

        step = "6 LED controller identity"
        cfg = self.config.led
        if cfg is None:
            self.add(step, "skip", "no [led] section in the bench file")
            return None
        port = self._serial_port("led", cfg.port)
        if not port:
            self.add(step, "FAIL", "no [led] port" + self._ports_seen() + self._usb_slcs_seen(),
                     "set [led] port (a path, or hwgrep://VID:PID or hwgrep://SERIAL). A "
                     "USB-only SLC (-U, a HID device) cannot be driven over serial: use its "
                     "RS232 port (-U/S, -X models)")
            return None
        try:
            led = stack.enter_context(SlcController(port, ceilings_ma=cfg.ceilings_ma))
        except DeviceError as exc:
            self.add(step, "FAIL", _one_line(exc) + self._usb_slcs_seen(),
                     "check the port, 9600 8N1, a straight (not null-modem) cable; a -U "
                     "module is USB HID only and has no serial line")
            return None
        info = led.device_info
        self.add(step, "ok", f"{info.module or '(module not reported)'} serial {info.serial}, "
                 f"firmware {info.driver_version}, {led.channel_count} channels, current step "
                 f"{led.current_step_ma(cfg.channel):g} mA")
        return led

    def _usb_slcs_seen(self) -> str:
        """The SLCs plugged in by USB (HID), which no serial port reaches; '' if none."""
        from benchlab.drivers.slc.usb_hid import usb_slcs

        found = self.outside.get("usb-slcs", lambda: [
            d.describe() for d in usb_slcs(self.usb_sysfs)])
        if not found:
            return ""
        return ("; plugged in by USB (HID, which benchlab cannot drive): " + ", ".join(found))

    def _ports_seen(self) -> str:
        return str(self.outside.get("serial-ports", _ports_seen))

    def check_led(self, led: Any) -> bool:
        step = "7 LED on at its lowest current, off"
        ch = self._channel
        lowest = led.current_step_ma(ch)
        if not self._ask(f"switch LED channel {ch} on at {lowest:g} mA, then off?"):
            self.add(step, "skip", "not switched on (answered no)")
            return True
        led.on(ch, lowest)
        on, current = led.is_on(ch), led.current_ma(ch)
        led.off(ch)
        off = not led.is_on(ch)
        if on and off and math.isclose(current, lowest):
            self.add(step, "ok", f"read back on at {current:g} mA, then off")
        else:
            self.add(step, "FAIL", f"read back: on={on} at {current:g} mA, off={off}",
                     "check the channel number and the LED's connection")
        return True

    # ---- 8: the stage ---------------------------------------------------------------------
    def open_stage(self, stack: contextlib.ExitStack) -> Any:
        from benchlab.drivers.apt.stage import AptStage

        step = "8 stage identity"
        cfg = self.config.stage
        if cfg is None:
            self.add(step, "skip", "no [stage] section in the bench file")
            return None
        port = self._serial_port("stage", cfg.port)
        if not port:
            self.add(step, "FAIL", "no [stage] port" + self._ports_seen(), "set [stage] port "
                     "(a path, or hwgrep://0403:FAF0 or hwgrep://SERIAL for a Thorlabs cube)")
            return None
        stage = stack.enter_context(AptStage(
            port, counts_per_mm=cfg.counts_per_mm, travel_mm=cfg.travel_mm,
            completion_tolerance_counts=cfg.tolerance_counts))
        info = stage.info
        self.add(step, "ok", f"{info.model} serial {info.serial}, firmware {info.firmware_str}, "
                 f"{cfg.counts_per_mm:g} counts/mm assumed")
        return stage

    def check_stage(self, stage: Any) -> None:
        homed = self.attempt("8 stage homing", "the stage did not report homed: check that "
                             "the actuator's cable is in and nothing blocks the reverse end",
                             lambda: self.check_homing(stage))
        if not homed:
            self.skip(("8 stage scale",), "the stage is not homed (step 8 homing)")
            return
        self.attempt("8 stage scale", "the measured move did not end as commanded",
                     lambda: self.check_scale(stage))

    def check_homing(self, stage: Any) -> bool:
        if not self._ask("home the stage (it drives to its reverse limit)?"):
            self.add("8 stage homing", "skip", "not homed (answered no)")
            return False
        from benchlab.drivers.errors import DeviceTimeoutError

        home = stage.get_home_params()
        timeout_s = stage.home_timeout_s(home) / self.stage_time_scale + stage.timeout_s
        try:
            stage.home(timeout_s=timeout_s)
        except DeviceTimeoutError as exc:
            lo, hi = stage.travel_mm
            fast = (f"; simulated time runs {self.stage_time_scale:g}x fast"
                    if self.stage_time_scale != 1 else "")
            raise DeviceTimeoutError(
                f"the controller never reported homed within {timeout_s:.3g} s, the time "
                f"homing from anywhere in {hi - lo:g} mm takes at its home velocity of "
                f"{home.velocity_mm_s:g} mm/s (read from it){fast}; the stage was stopped "
                f"({_one_line(exc)})") from exc
        self.add("8 stage homing", "ok", f"homed at {stage.position_mm:.4f} mm (home velocity "
                 f"{home.velocity_mm_s:g} mm/s read from the controller)")
        return True

    def check_scale(self, stage: Any) -> bool:
        """A relative move from home, measured (a zeroed dial gauge; the simulator's carriage
        on the simulated bench): the counts/mm of the actuator."""
        from benchlab.drivers.apt.protocol import ACTUATOR_COUNTS_PER_MM

        cfg = self.config.stage
        assert cfg is not None
        step = "8 stage scale"
        lo, hi = cfg.travel_mm
        start_mm = stage.position_mm
        distance = round(min(SCALE_MOVE_MAX_MM, 0.8 * (hi - lo), hi - start_mm), 3)
        if distance <= 0:
            self.add(step, "skip", f"the scale was NOT measured: home ({start_mm:g} mm) is not "
                     f"below the travel's upper end ({hi:g} mm)", "check [stage] travel_mm")
            return True
        gauge = self.sims.get("stage") is not None or (
            self.replaying and self.simulate)
        if not gauge and not self._ask("zero the dial gauge against the carriage now; done?"):
            self.add(step, "skip", "the scale was NOT measured (no zeroed dial gauge)")
            return True
        if not self._ask(f"move the stage {distance:g} mm forward from home, to measure the "
                         "scale?"):
            self.add(step, "skip", "the scale was NOT measured (no measured move: answered no)")
            return True
        start = self._physical_mm()
        stage.move_by_mm(distance)
        end = self._physical_mm()
        self._landing(stage, start_mm + distance)
        moved = end - start if start is not None and end is not None else self._measure(
            f"dial gauge reading now, mm (commanded {distance:g} mm)?")
        if moved is None or moved <= 0:
            self.add(step, "skip", "the scale was NOT measured (no dial gauge reading given)")
            return True
        counts = round(distance * cfg.counts_per_mm)
        measured = counts / moved
        name, value = min(ACTUATOR_COUNTS_PER_MM.items(),
                          key=lambda kv: abs(kv[1] / measured - 1))
        off = abs(value / measured - 1)
        moved_how = (f"a relative move of {distance:g} mm from home (travel {lo:g}..{hi:g} "
                     "mm)")
        how_sure = (f"a {GAUGE_ERROR_MM:g} mm gauge error over {moved:.3f} mm is "
                    f"{100 * GAUGE_ERROR_MM / moved:.2f} %; the known scales are 0.73 % apart"
                    if start is None else "measured by the simulator's carriage")
        if off > SCALE_MATCH:
            self.add(step, "FAIL", f"{measured:.1f} counts/mm measured over {moved:.3f} mm: no "
                     f"known actuator within {100 * SCALE_MATCH:g} % ({how_sure})",
                     "set [stage] counts_per_mm to the measured value")
        elif math.isclose(value, cfg.counts_per_mm):
            self.add(step, "ok", f"{measured:.1f} counts/mm measured over {moved:.3f} mm by "
                     f"{moved_how}: {name} ({value:g}, {100 * off:.2f} % off), as the bench "
                     f"file says ({how_sure})")
        else:
            self.learned[("stage", "actuator")] = name
            self.add(step, "FAIL", f"{measured:.1f} counts/mm measured: this is "
                     f"{name} ({value:g}), the bench file assumes {cfg.counts_per_mm:g} "
                     f"({how_sure})", f'set [stage] actuator = "{name}" (written to the '
                     "bench file)")
        return True

    def _landing(self, stage: Any, target_mm: float) -> None:
        """How far from its target the carriage settled (counts), against the tolerance."""
        cfg = self.config.stage
        assert cfg is not None
        off = round((stage.position_mm - target_mm) * cfg.counts_per_mm)
        if abs(off) > 5:  # more than a servo's usual settling: worth a line
            self.add("8 stage landing", "warn", f"the move settled {off:+d} counts off its "
                     f"target (within the bench file's tolerance of {cfg.tolerance_counts} "
                     "counts)", f"fine as it is; to refuse such moves set [stage] "
                     f"tolerance_counts below {abs(off)}")

    def _physical_mm(self) -> float | None:
        sim = self.sims.get("stage")
        if sim is None and not (self.replaying and self.simulate):
            return None
        return self.outside.get("carriage-mm", lambda: float(sim.position_mm))  # type: ignore[union-attr]


def _replay_reason() -> str | None:
    """While a cassette is replayed, why a serial device dropped the line (it diverged)."""
    from benchlab.drivers.trace import replay

    return replay.divergence() if replay.active() else None


def _one_line(exc: BaseException) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


def _udev_facts(vid: int, pid: int) -> dict[str, Any] | None:
    """Whether a udev rule gives ``vid:pid`` to plugdev, the user is in plugdev, and the
    membership is active in this login (None: not Linux)."""
    if not sys.platform.startswith("linux"):
        return None
    import grp  # Unix only

    user = getpass.getuser()
    try:
        group = grp.getgrnam("plugdev")
        member, active = user in group.gr_mem, group.gr_gid in os.getgroups()
    except KeyError:
        member = active = False
    rule = ""
    for folder in (Path("/etc/udev/rules.d"), Path("/lib/udev/rules.d"),
                   Path("/usr/lib/udev/rules.d")):
        for path in sorted(folder.glob("*.rules")) if folder.is_dir() else ():
            with contextlib.suppress(OSError):
                text = path.read_text(encoding="utf-8", errors="replace").lower()
                if (f'"{vid:04x}"' in text and f'"{pid:04x}"' in text) and not rule:
                    rule = str(path)
    return {"user": user, "member": member, "active": active, "rule": rule}


def _usb_bus_with_an_slc(stack: contextlib.ExitStack) -> Path:
    """A folder laid out like Linux's /sys/bus/usb/devices: a root hub, a USB-only SLC and its
    HID interface (interfaces carry no product string)."""
    import tempfile

    root = Path(stack.enter_context(tempfile.TemporaryDirectory(prefix="benchlab-sysfs-")))
    entries = {
        "usb1": {"manufacturer": "Linux xhci-hcd", "product": "xHCI Host Controller",
                 "idVendor": "1d6b", "idProduct": "0002"},
        "1-2": {"manufacturer": "Mightex", "product": "SLC-MA04-U", "serial": "04-251013-021",
                "idVendor": "ffff", "idProduct": "0001"},  # made-up ids: none is public
        "1-2:1.0": {"bInterfaceClass": "03"},
    }
    for name, attributes in entries.items():
        (root / name).mkdir()
        for key, value in attributes.items():
            (root / name / key).write_text(value + "\n")
    return root


def _ports_seen() -> str:
    """USB serial ports on this machine, as hwgrep URLs that find them again after a reboot."""
    from serial.tools import list_ports

    seen = [f"{q.device} ({q.description}; port = \"hwgrep://{q.serial_number}\")"
            if q.serial_number else f"{q.device} ({q.description})"
            for q in sorted(list_ports.comports(), key=lambda q: q.device) if q.vid is not None]
    return "; USB serial ports seen: " + ", ".join(seen) if seen else "; no USB serial port seen"


# ---- the command ------------------------------------------------------------------------------
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
