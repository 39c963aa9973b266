"""The bring-up in order: which step runs, which is skipped when another failed."""

from __future__ import annotations

import contextlib
from typing import Any

from benchlab.cli.devices.doctor.camera import CameraSteps
from benchlab.cli.devices.doctor.host import HostSteps
from benchlab.cli.devices.doctor.led import LedSteps
from benchlab.cli.devices.doctor.simulated import SimulatedBench
from benchlab.cli.devices.doctor.stage import StageSteps


class Doctor(HostSteps, CameraSteps, LedSteps, StageSteps, SimulatedBench):
    """Runs the checks in order (see the package docstring); ``ask`` gets a yes/no question,
    ``measure`` a number (None: skip)."""

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
