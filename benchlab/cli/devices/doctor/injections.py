"""Faults ``benchlab doctor --simulate --inject NAME`` puts into the simulated bench."""

from __future__ import annotations

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
