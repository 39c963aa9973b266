"""``benchlab doctor``: a guided bring-up of a new bench, one check at a time, in order.

1. libusb backend; 2. udev rule and group (Linux); 3. the camera enumerates (VID/PID,
serial, firmware) and answers its queries; 4. exposure: a dark frame, the frame period
against the set exposure (trailer timestamps: the exposure unit) and two exposures whose
signal ratio checks linearity; 5. every bit depth of the camera's profile decodes to
plausible codes (no missing codes or bit pattern); 6. the LED controller: port, identity,
firmware and module type; 7. the LED on at its lowest current and off, read back; 8. the
stage: identity, a short homing and a measured move that settles the counts/mm.

Each physical action (light, motion) waits for a yes (``--yes`` answers yes for scripted
runs). Every failure says what to do. What the doctor learned (the camera profile that
fits, the stage's actuator) is written into the bench file, after a backup, and everything
into a bring-up report. ``--simulate`` runs the same checks on simulated devices; ``--inject``
gives one of them a fault the checks should name (see :data:`INJECTIONS`).
"""

from __future__ import annotations

import argparse
import contextlib
import getpass
import math
import shutil
import sys
import time
import tomllib
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field, replace
from datetime import UTC, datetime
from pathlib import Path
from typing import TYPE_CHECKING, Any

# numpy and the drivers load when the command runs: `benchlab --help` builds every parser.
from benchlab.cli.output import add_output_option, check_output, forced, write_output
from benchlab.drivers.errors import BenchlabError, DeviceError

if TYPE_CHECKING:
    from benchlab.bench import BenchConfig
    from benchlab.drivers.mightex import protocol as p_types

#: Faults ``--simulate --inject NAME`` puts into the simulated bench (what the checks name).
INJECTIONS = {
    "camera-profile": "the camera speaks protocol v1.0.6 (4-byte exposure field)",
    "camera-unit": "the camera counts exposure in 0.1 ms, not 0.05 ms",
    "camera-no-12bit": "the camera has no 12-bit mode",
    "led-lf-cr": "the LED controller ends replies LF CR",
    "led-usb-hid": "the LED controller is plugged in by USB only (HID); its serial port is "
                   "silent",
    "stage-34304": "the actuator has 34304 counts/mm, the bench file assumes 34554.96",
}
EXPOSURE_MS = 100.0  # longer than a full-frame readout (27 ms): the period is the exposure
ROI = 256  # checks read a 256 x 256 frame: fast, and any geometry the models accept
SIM_LED_E_PER_MS_PER_MA = 40.0


@dataclass
class Check:
    step: str
    status: str  # "ok", "FAIL", "warn", "skip"
    detail: str
    todo: str = ""


@dataclass
class Doctor:
    """Runs the checks; ``ask`` gets a yes/no question, ``measure`` a number (None: skip)."""

    config: BenchConfig
    simulate: bool
    ask: Callable[[str], bool]
    measure: Callable[[str], float | None]
    inject: tuple[str, ...] = ()
    say: Callable[[str], None] = print
    checks: list[Check] = field(default_factory=list)
    learned: dict[tuple[str, str], Any] = field(default_factory=dict)
    sims: dict[str, Any] = field(default_factory=dict)
    usb_sysfs: Path | None = None  # where USB devices are listed (default: Linux sysfs)

    def add(self, step: str, status: str, detail: str, todo: str = "") -> None:
        self.checks.append(Check(step, status, detail, todo))
        self.say(f"[{status:>4}] {step}: {detail}" + (f"\n       -> {todo}" if todo else ""))

    @property
    def failed(self) -> bool:
        return any(c.status == "FAIL" for c in self.checks)

    # ---- the run --------------------------------------------------------------------------
    def run(self) -> None:
        with contextlib.ExitStack() as stack:
            if self.simulate:
                self._start_sims(stack)
            self.check_usb_backend()
            self.check_udev()
            cam = self.open_camera(stack)
            led = self.open_led(stack)  # the camera checks need light: the LED gives it
            if cam is not None:
                lit = self._light_on(led)
                try:
                    cam = self.check_exposure(cam, lit, stack)
                    if cam is not None:
                        self.check_depths(cam)
                finally:
                    if led is not None and lit:
                        led.off(self._channel)
            if led is not None:
                self.check_led(led)
            stage = self.open_stage(stack)
            if stage is not None:
                self.check_stage(stage)

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

        mce = p.SPECS["MCE-B013-U"]
        profile = {
            "camera-profile": p.SPECS["MCE-B013-U/v1.0.6"],
            "camera-unit": replace(mce, exposure_unit_ms=0.1),
            "camera-no-12bit": replace(mce, bit_depths=(8, 10)),
        }
        chosen = next((profile[k] for k in self.inject if k in profile), mce)
        cam = SimulatedCamera(light, seed=1, profile=chosen,
                              bench_state=lambda: {"led_ma": slc.channel_output_ma(channel)})
        counts = 34304.0 if "stage-34304" in self.inject else (
            cfg.stage.counts_per_mm if cfg.stage is not None else 34554.96)
        travel = cfg.stage.travel_mm if cfg.stage is not None else (0.0, 50.0)
        stage = SimulatedAptStage(counts_per_mm=counts, travel_mm=travel, time_scale=2000.0,
                                  initial_position_mm=(travel[0] + travel[1]) / 2)
        stage.start()
        stack.callback(stage.stop)
        self.sims = {"camera": cam, "backend": SimCameraBackend([cam]), "led": slc,
                     "stage": stage}

    # ---- 1, 2: USB access -----------------------------------------------------------------
    def check_usb_backend(self) -> None:
        step = "1 libusb backend"
        import usb.backend.libusb1

        if usb.backend.libusb1.get_backend() is not None:
            self.add(step, "ok", "libusb-1.0 found")
        elif self.simulate:
            self.add(step, "skip", "libusb-1.0 not found (not needed on the simulated bench)")
        else:
            self.add(step, "FAIL", "no libusb-1.0: pyusb cannot reach the camera",
                     "sudo apt install libusb-1.0-0  (Fedora: sudo dnf install libusb1)")

    def check_udev(self) -> None:
        step = "2 udev rule and group"
        from benchlab.drivers.mightex.camera import UDEV_RULE, udev_hint

        if not sys.platform.startswith("linux"):
            self.add(step, "skip", "not Linux: no udev rule needed")
            return
        import grp  # Unix only

        rule = Path("/etc/udev/rules.d") / UDEV_RULE
        user = getpass.getuser()
        try:
            in_group = user in grp.getgrnam("plugdev").gr_mem
        except KeyError:
            in_group = False
        if rule.exists() and (in_group or user == "root"):
            self.add(step, "ok", f"{rule} installed, {user} may open the camera")
        else:
            missing = ", ".join(w for w, bad in (
                (f"{rule}", not rule.exists()),
                (f"{user} in group plugdev", not in_group and user != "root")) if bad)
            self.add(step, "skip" if self.simulate else "FAIL", f"missing: {missing}",
                     "" if self.simulate else udev_hint())

    # ---- 3: the camera --------------------------------------------------------------------
    def open_camera(self, stack: contextlib.ExitStack,
                    profile: p_types.CameraSpec | None = None) -> Any:
        from benchlab.drivers.mightex import protocol as p
        from benchlab.drivers.mightex.camera import MightexCamera

        step = "3 camera enumerates and answers"
        cfg = self.config.camera
        try:
            cam = MightexCamera.open(cfg.serial, backend=self.sims.get("backend"),
                                     pid=cfg.pid, model=cfg.model, profile=profile)
        except DeviceError as exc:
            self.add(step, "FAIL", str(exc),
                     "check the cable and power; `benchlab devices` lists what is on the bus; "
                     "a camera with another PID: set [camera] pid")
            return None
        stack.callback(cam.close)
        info = cam.info
        status = cam.buffer_status()
        if profile is None:
            self.add(step, "ok", f"VID 0x{p.VENDOR_ID:04X} PID 0x{info.pid:04X}, {info.model} "
                     f"serial {info.serial}, firmware {info.firmware}, buffer query answered "
                     f"({status.width}x{status.height}); profile {cam.spec.model}")
        cam.configure(width=ROI, height=ROI, bits=8)
        return cam

    # ---- 4: exposure ----------------------------------------------------------------------
    @property
    def _channel(self) -> int:
        return self.config.led.channel if self.config.led is not None else 1

    def _light_on(self, led: Any) -> bool:
        """Light for the camera checks: the LED (after a yes), or room light (real bench)."""
        if led is not None:
            current = max(led.current_step_ma(self._channel), 5.0)
            ceiling = led.ceiling_ma(self._channel)
            if ceiling is not None and current <= ceiling and self.ask(
                    f"switch LED channel {self._channel} on at {current:g} mA for the camera "
                    "checks?"):
                led.on(self._channel, current)
                return True
        if self.simulate:
            return False
        return self.ask("uncover the lens so some room light falls on the sensor; done?")

    def check_exposure(self, cam: Any, lit: bool, stack: contextlib.ExitStack) -> Any:
        from benchlab.drivers.mightex.camera import CameraProfileMismatchError
        from benchlab.drivers.mightex.diagnose import period_finding, ratio_finding

        step = "4 exposure unit and linearity"
        try:
            period = self._period_ms(cam)
        except CameraProfileMismatchError as exc:
            self.add(step, "FAIL", f"profile {cam.spec.model} does not fit: {exc}",
                     self._fitting_profile(cam, stack))
            return None
        finding = period_finding(EXPOSURE_MS, period)
        if finding:
            self.add(step, "FAIL", finding, "the exposure unit of the camera's profile is "
                     "wrong: report the camera model and firmware (issue tracker)")
            return cam
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
                     f"{dark:.1f}, 20/40 ms signal ratio {(long - dark) / (short - dark):.3f}")
        return cam

    def _period_ms(self, cam: Any) -> float:
        """Shortest trailer-timestamp step between consecutive free-running frames."""
        cam.set_exposure_ms(EXPOSURE_MS)
        stamps = [cam.grab().meta.timestamp_ms]
        for _ in range(3):
            stamps.append(cam.grab(fresh=False).meta.timestamp_ms)
        steps = [(b - a) % 65536 for a, b in zip(stamps, stamps[1:], strict=False)]
        return float(min(s for s in steps if s > 0))

    def _mean(self, cam: Any, exposure_ms: float) -> float:
        import numpy as np

        cam.set_exposure_ms(exposure_ms)
        return float(np.mean(cam.grab().pixels))

    def _fitting_profile(self, cam: Any, stack: contextlib.ExitStack) -> str:
        """Try every other known profile; the first whose exposure round-trips is the fix."""
        from benchlab.drivers.mightex import protocol as p
        from benchlab.drivers.mightex.camera import CameraProfileMismatchError
        from benchlab.drivers.mightex.diagnose import period_finding

        tried = cam.spec.model
        cam.close()
        for name, spec in p.SPECS.items():
            if name == tried:
                continue
            other = self.open_camera(stack, profile=spec)
            if other is None:
                continue
            try:
                period = self._period_ms(other)
            except (CameraProfileMismatchError, DeviceError):
                other.close()
                continue
            if period_finding(EXPOSURE_MS, period) is None:
                self.learned[("camera", "model")] = name
                self.add("4 exposure unit and linearity", "ok",
                         f"profile {name} fits (frame period {period:g} ms)")
                return f'set [camera] model = "{name}" (written to the bench file)'
            other.close()
        return "no known profile fits: report the camera model and firmware"

    # ---- 5: bit depths --------------------------------------------------------------------
    def check_depths(self, cam: Any) -> None:
        import numpy as np

        from benchlab.drivers.mightex.diagnose import depth_findings

        step = "5 bit depths decode"
        cam.set_exposure_ms(40.0)
        means: dict[int, float] = {}
        problems: list[str] = []
        for bits in cam.spec.bit_depths:
            try:
                cam.configure(width=ROI, height=ROI, bits=bits)
                pixels = cam.grab().pixels
            except DeviceError as exc:
                problems.append(f"{bits}-bit: {exc}")
                continue
            problems += [f"{bits}-bit: {f}" for f in depth_findings(pixels, bits)]
            means[bits] = float(np.mean(pixels)) * 2 ** (12 - bits)
        cam.configure(width=ROI, height=ROI, bits=8)
        if problems:
            self.add(step, "FAIL", "; ".join(problems),
                     "use a depth that decodes (bench file [camera]) and report the model")
        else:
            scaled = ", ".join(f"{b}-bit {m:.0f}" for b, m in means.items())
            self.add(step, "ok", f"{len(means)} depths plausible (means on the 12-bit scale: "
                     f"{scaled})")

    # ---- 6, 7: the LED controller ---------------------------------------------------------
    def open_led(self, stack: contextlib.ExitStack) -> Any:
        from benchlab.drivers.slc.controller import SlcController

        step = "6 LED controller identity"
        cfg = self.config.led
        if cfg is None:
            self.add(step, "skip", "no [led] section in the bench file")
            return None
        port = self.sims["led"].port if self.simulate else cfg.port
        if not port:
            self.add(step, "FAIL", "no [led] port" + _ports_seen() + self._usb_slcs_seen(),
                     "set [led] port (a path, or hwgrep://VID:PID or hwgrep://SERIAL). A "
                     "USB-only SLC (-U, a HID device) cannot be driven over serial: use its "
                     "RS232 port (-U/S, -X models)")
            return None
        try:
            led = stack.enter_context(SlcController(port, ceilings_ma=cfg.ceilings_ma))
        except DeviceError as exc:
            self.add(step, "FAIL", str(exc) + self._usb_slcs_seen(),
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

        found = usb_slcs(self.usb_sysfs)
        if not found:
            return ""
        return ("; plugged in by USB (HID, which benchlab cannot drive): "
                + ", ".join(d.describe() for d in found))

    def check_led(self, led: Any) -> None:
        step = "7 LED on at its lowest current, off"
        ch = self._channel
        lowest = led.current_step_ma(ch)
        if not self.ask(f"switch LED channel {ch} on at {lowest:g} mA, then off?"):
            self.add(step, "skip", "not switched on (answered no)")
            return
        led.on(ch, lowest)
        on, current = led.is_on(ch), led.current_ma(ch)
        led.off(ch)
        off = not led.is_on(ch)
        if on and off and math.isclose(current, lowest):
            self.add(step, "ok", f"read back on at {current:g} mA, then off")
        else:
            self.add(step, "FAIL", f"read back: on={on} at {current:g} mA, off={off}",
                     "check the channel number and the LED's connection")

    # ---- 8: the stage ---------------------------------------------------------------------
    def open_stage(self, stack: contextlib.ExitStack) -> Any:
        from benchlab.drivers.apt.stage import AptStage

        step = "8 stage identity"
        cfg = self.config.stage
        if cfg is None:
            self.add(step, "skip", "no [stage] section in the bench file")
            return None
        port = self.sims["stage"].port if self.simulate else cfg.port
        if not port:
            self.add(step, "FAIL", "no [stage] port" + _ports_seen(), "set [stage] port (a "
                     "path, or hwgrep://0403:FAF0 or hwgrep://SERIAL for a Thorlabs cube)")
            return None
        try:
            stage = stack.enter_context(AptStage(port, counts_per_mm=cfg.counts_per_mm,
                                                 travel_mm=cfg.travel_mm))
        except DeviceError as exc:
            self.add(step, "FAIL", str(exc), "check the port and the cube's power")
            return None
        info = stage.info
        self.add(step, "ok", f"{info.model} serial {info.serial}, firmware {info.firmware_str}, "
                 f"{cfg.counts_per_mm:g} counts/mm assumed")
        return stage

    def check_stage(self, stage: Any) -> None:
        cfg = self.config.stage
        assert cfg is not None
        if not self.ask("home the stage (it drives to its reverse limit)?"):
            self.add("8 stage homing", "skip", "not homed (answered no)")
            return
        stage.home()
        self.add("8 stage homing", "ok", f"homed at {stage.position_mm:.4f} mm")
        lo, hi = cfg.travel_mm
        distance = min(5.0, (hi - lo) / 2)
        if not self.ask(f"move the stage {distance:g} mm forward, to measure the scale?"):
            self.add("8 stage scale", "skip", "no measured move (answered no)")
            return
        start = self._physical_mm()
        stage.move_to_mm(lo + distance)
        end = self._physical_mm()
        moved = end - start if start is not None and end is not None else self.measure(
            f"how far did the carriage move, measured (dial gauge, mm)? commanded {distance:g}")
        if moved is None or moved <= 0:
            self.add("8 stage scale", "skip", "no measurement given")
            return
        from benchlab.drivers.apt.protocol import ACTUATOR_COUNTS_PER_MM

        counts = round(distance * cfg.counts_per_mm)
        measured = counts / moved
        name, value = min(ACTUATOR_COUNTS_PER_MM.items(),
                          key=lambda kv: abs(kv[1] / measured - 1))
        if abs(value / measured - 1) > 0.002:
            self.add("8 stage scale", "FAIL", f"{measured:.1f} counts/mm measured: no known "
                     "actuator", "set [stage] counts_per_mm to the measured value")
        elif math.isclose(value, cfg.counts_per_mm):
            self.add("8 stage scale", "ok", f"{measured:.1f} counts/mm measured: {name} "
                     f"({value:g}), as the bench file says")
        else:
            self.learned[("stage", "actuator")] = name
            self.add("8 stage scale", "FAIL", f"{measured:.1f} counts/mm measured: this is "
                     f"{name} ({value:g}), the bench file assumes {cfg.counts_per_mm:g}",
                     f'set [stage] actuator = "{name}" (written to the bench file)')

    def _physical_mm(self) -> float | None:
        sim = self.sims.get("stage")
        return float(sim.position_mm) if sim is not None else None


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


# ---- bench file and report -------------------------------------------------------------------
def set_toml_key(text: str, section: str, key: str, value: str | float) -> str:
    """``text`` with ``key = value`` in ``[section]`` (replaced, or added after the header)."""
    literal = f'"{value}"' if isinstance(value, str) else repr(float(value))
    lines = text.splitlines()
    header = f"[{section}]"
    try:
        start = next(i for i, ln in enumerate(lines) if ln.strip() == header)
    except StopIteration:
        return text.rstrip("\n") + f"\n\n{header}\n{key} = {literal}\n"
    end = next((i for i in range(start + 1, len(lines)) if lines[i].lstrip().startswith("[")),
               len(lines))
    for i in range(start + 1, end):
        if lines[i].split("=", 1)[0].strip() == key:
            lines[i] = f"{key} = {literal}"
            break
    else:
        lines.insert(start + 1, f"{key} = {literal}")
    return "\n".join(lines) + "\n"


def write_learned(path: Path, learned: dict[tuple[str, str], Any]) -> Path | None:
    """Write what the doctor learned into the bench file, after a backup; the new text must
    still be a valid bench file, else nothing is written. Returns the backup's path."""
    from benchlab.bench import BenchConfig

    if not learned:
        return None
    text = path.read_text(encoding="utf-8")
    new = text
    for (section, key), value in learned.items():
        new = set_toml_key(new, section, key, value)
        if (section, key) == ("stage", "actuator"):  # the actuator sets the scale
            new = "\n".join(ln for ln in new.splitlines()
                            if ln.split("=", 1)[0].strip() != "counts_per_mm") + "\n"
    BenchConfig.from_dict(tomllib.loads(new), str(path))  # raises: nothing written
    backup = path.with_name(f"{path.name}.bak-{datetime.now(UTC):%Y%m%dT%H%M%S}")
    shutil.copy2(path, backup)
    path.write_text(new, encoding="utf-8")
    return backup


def report_markdown(doctor: Doctor, source: str) -> str:
    out = [f"# Bench bring-up report ({datetime.now(UTC):%Y-%m-%d %H:%M} UTC)", "",
           f"Bench file: {source}{' (simulated bench)' if doctor.simulate else ''}."]
    if doctor.inject:
        out.append("Injected faults: " + "; ".join(f"{k} ({INJECTIONS[k]})"
                                                     for k in doctor.inject) + ".")
    out += ["", "| step | result | detail | what to do |", "|---|---|---|---|"]
    for c in doctor.checks:
        cells = (c.step, c.status, c.detail, c.todo)
        out.append("| " + " | ".join(x.replace("|", "/").replace("\n", " ") for x in cells)
                   + " |")
    if doctor.learned:
        out += ["", "Learned (written to the bench file):", ""]
        out += [f"- [{s}] {k} = {v}" for (s, k), v in doctor.learned.items()]
    return "\n".join(out) + "\n"


@contextlib.contextmanager
def _timer() -> Iterator[list[float]]:
    t0 = time.monotonic()
    elapsed = [0.0]
    yield elapsed
    elapsed[0] = time.monotonic() - t0


def _cmd_doctor(args: argparse.Namespace) -> int:
    if args.inject and not args.simulate:
        raise BenchlabError("--inject is for the simulated bench: add --simulate")
    from benchlab.bench import BenchConfig

    report = check_output(args.report, force=forced(args), option="--report")  # before the bench
    config = BenchConfig.load(args.config, simulate=args.simulate)

    def ask(question: str) -> bool:
        if args.yes:
            print(f"  ? {question} yes (--yes)")
            return True
        return input(f"  ? {question} [y/N] ").strip().lower() in ("y", "yes")

    def measure(question: str) -> float | None:
        if args.yes:
            print(f"  ? {question} (skipped: --yes)")
            return None
        text = input(f"  ? {question} ").strip()
        try:
            return float(text)
        except ValueError:
            return None

    doctor = Doctor(config, args.simulate, ask, measure, tuple(args.inject or ()))
    with _timer() as elapsed:
        doctor.run()
    write_output(report, report_markdown(doctor, config.source), force=forced(args),
                 option="--report")
    if args.config and doctor.learned:
        backup = write_learned(Path(args.config), doctor.learned)
        print(f"wrote what was learned to {args.config} (backup {backup})")
    fails = sum(c.status == "FAIL" for c in doctor.checks)
    print(f"{'bring-up passed' if not fails else f'{fails} check(s) failed'} in "
          f"{elapsed[0]:.1f} s; report {report.absolute()}")
    return 1 if fails else 0


def register(commands: argparse._SubParsersAction, benchmarks: argparse._SubParsersAction) -> None:
    """Add ``doctor``."""
    doc = commands.add_parser(
        "doctor", help="guided bring-up of a new bench, one check at a time",
        description="Checks, in order: libusb, udev rule and group, the camera (identity, "
                    "exposure unit and linearity, bit depths), the LED controller (identity, "
                    "on at its lowest current and off) and the stage (identity, homing, a "
                    "measured move that settles the counts/mm). Each physical action asks "
                    "first. What it learns goes into the bench file (after a backup).")
    doc.add_argument("--config", metavar="BENCH_TOML", help="the bench file to check and "
                     "update (default: the packaged simulated bench with --simulate)")
    doc.add_argument("--simulate", action="store_true", help="check the simulated bench")
    doc.add_argument("--yes", action="store_true",
                     help="answer yes to every question (scripted runs); measured values "
                          "that need a person are skipped")
    doc.add_argument("--inject", action="append", choices=sorted(INJECTIONS),
                     help="with --simulate: give a simulated device this fault (repeatable): "
                          + "; ".join(f"{k}: {v}" for k, v in INJECTIONS.items()))
    add_output_option(doc, "--report", default="bringup-report.md",
                      help="where the bring-up report goes (default ./bringup-report.md)")
    doc.set_defaults(func=_cmd_doctor)
