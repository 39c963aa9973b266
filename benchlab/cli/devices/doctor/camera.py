"""Steps 3-5: the camera enumerates and answers, exposure unit and linearity (the profile
that fits), bit depths."""

from __future__ import annotations

import contextlib
import math
from dataclasses import replace
from typing import TYPE_CHECKING, Any

from benchlab.cli.devices.doctor.base import (
    EXPOSURE_MS,
    ROI,
    TIMESTAMP_FRAMES,
    DoctorBase,
    _one_line,
)
from benchlab.drivers.errors import DeviceError

if TYPE_CHECKING:
    from benchlab.drivers.mightex import protocol as p_types

class CameraSteps(DoctorBase):
    """Steps 3-5: the camera enumerates and answers, exposure unit and linearity (the
    profile that fits), bit depths."""

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
