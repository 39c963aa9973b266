"""Exception hierarchy shared by every driver.

Every driver raises subclasses of :class:`DeviceError`; callers can catch one family
without knowing which instrument failed.
"""

from __future__ import annotations


class BenchlabError(Exception):
    """Base of every error benchlab raises on purpose."""


class UsageError(BenchlabError):
    """A value on the command line (or in a call) that cannot be right: an unknown name, a
    malformed ``--roi``, a count below 1. The command line reports it as ``benchlab: error:
    ...`` with exit status 2, like argparse's own usage errors."""


class DeviceError(BenchlabError):
    """Something went wrong talking to an instrument."""


class DeviceNotFoundError(DeviceError):
    """No instrument matched the requested identity (VID/PID, serial number, port)."""


class DeviceLostError(DeviceError):
    """The instrument disappeared (unplugged, port closed) while in use."""


class DeviceTimeoutError(DeviceError):
    """The instrument did not answer within the allowed time."""


class ProtocolError(DeviceError):
    """A reply was short, garbled or inconsistent with the configuration."""


class SettingOutOfRangeError(DeviceError, ValueError):
    """A requested setting is outside the valid range; nothing was sent."""


class SafetyLimitError(DeviceError, ValueError):
    """A command would exceed a configured safety limit; nothing was sent."""
