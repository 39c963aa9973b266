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

The package, one job per module: :mod:`.base` (the doctor's state, recording a check, a device
error as that check's FAIL), :mod:`.host` (steps 1-2), :mod:`.camera` (3-5), :mod:`.led` (6-7),
:mod:`.stage` (8), :mod:`.simulated` (the simulated bench and its faults, :mod:`.injections`),
:mod:`.run` (the steps in order: :class:`Doctor`), :mod:`.command` (the command line and the
report's path), :mod:`.record` (answers and facts kept for a replay) and :mod:`.report` (the
report and the bench-file update).
"""

from __future__ import annotations

from benchlab.cli.devices.doctor.command import apply_injected_config, register, report_path
from benchlab.cli.devices.doctor.injections import INJECTIONS
from benchlab.cli.devices.doctor.report import Check, set_toml_key, write_learned
from benchlab.cli.devices.doctor.run import Doctor

__all__ = ["INJECTIONS", "Check", "Doctor", "apply_injected_config", "register", "report_path",
           "set_toml_key", "write_learned"]
