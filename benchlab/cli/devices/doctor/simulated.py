"""The simulated bench of ``--simulate`` and the faults ``--inject`` gives it."""

from __future__ import annotations

import contextlib
from dataclasses import replace
from pathlib import Path
from typing import Any

from benchlab.cli.devices.doctor.base import (
    SIM_LED_E_PER_MS_PER_MA,
    SIM_STAGE_TIME_SCALE,
    DoctorBase,
)


class SimulatedBench(DoctorBase):
    """The simulated bench of ``--simulate`` and the faults ``--inject`` gives it."""

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
