"""Steps 1 and 2: the libusb backend, the udev rule and the group."""

from __future__ import annotations

import contextlib
import getpass
import os
import sys
from pathlib import Path
from typing import Any

from benchlab.cli.devices.doctor.base import DoctorBase


class HostSteps(DoctorBase):
    """Steps 1 and 2: the libusb backend, the udev rule and the group."""

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
