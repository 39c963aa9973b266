"""Steps 6 and 7: the LED controller's identity, on at its lowest current and off."""

from __future__ import annotations

import contextlib
import math
from typing import Any

from benchlab.cli.devices.doctor.base import DoctorBase, _one_line
from benchlab.drivers.errors import DeviceError


class LedSteps(DoctorBase):
    """Steps 6 and 7: the LED controller's identity, on at its lowest current and off."""

    # ---- 6, 7: the LED controller ---------------------------------------------------------
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
