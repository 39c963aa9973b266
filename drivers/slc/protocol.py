"""Wire facts of the Mightex SLC (Sirius) LED controller's RS232 ASCII protocol.

No I/O here: the driver (:mod:`benchlab.drivers.slc.controller`) and the simulator
(:mod:`benchlab.drivers.slc.sim`) both build on it. Facts: shared/docs/device-protocols.md
section B. Line settings 9600 8N1; commands end in LF CR; every reply is the payload, one
space, then CR LF. Replies: ``##`` acknowledges, ``#<data>`` answers a query, ``#!`` is an
execution error, ``#?`` an argument out of range, ``VERB is not defined`` an unknown command.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import IntEnum

from benchlab.drivers.errors import DeviceTimeoutError, ProtocolError

BAUD = 9600
COMMAND_END = b"\n\r"  # LF then CR - the order the SLC expects
REPLY_END = b"\r\n"  # a reply line ends here ...
REPLY_SUFFIX = b" \r\n"  # ... and the firmware always puts a space before it
ACK = "##"
EXECUTION_ERROR = "#!"
ARGUMENT_ERROR = "#?"
UNDEFINED = "is not defined"
#: Families whose hardware sets currents in coarser steps than the wire unit (section B.7):
#: CA drives the nearest 5 mA step (123-127 -> 125), so a value sent can come out higher.
CURRENT_STEP_MA: dict[str, int] = {"CA": 5}
#: Families without the TRIGGER mode (B.7).
NO_TRIGGER_FAMILIES = ("MA", "CA")
_NORMAL_MAX_MA = {"HA": 2000.0, "HV": 2000.0, "FA": 100.0, "FV": 100.0, "XA": 100.0,
                  "XV": 100.0}


def current_unit_ma(module: str) -> float:
    """What one wire unit of current is (B.7): 0.1 mA on FA / FV / XA / XV, else 1 mA."""
    return 0.1 if module_family(module) in ("FA", "FV", "XA", "XV") else 1.0


def normal_max_ma(module: str) -> float:
    """The NORMAL-mode maximum current of a module (B.7): 1000 mA unless its family says
    otherwise; MA / CA modules with the -MU suffix drive 1200 mA."""
    family = module_family(module)
    if family in ("MA", "CA") and module.upper().split("/")[0].endswith("-MU"):
        return 1200.0
    return _NORMAL_MAX_MA.get(family, 1000.0)


def module_family(module: str) -> str:
    """Two-letter family of a module number ("SLC-CA04-MU" -> "CA"); "" when not recognised."""
    m = re.match(r"SLC-([A-Z]{2})\d\d", module.upper())
    return m.group(1) if m else ""


class SlcMode(IntEnum):
    """Channel modes (``MODE ch n`` / ``?MODE ch``)."""

    DISABLE = 0
    NORMAL = 1
    STROBE = 2
    TRIGGER = 3


# ---- exceptions: one per failure the wire can express, each naming the command -------------
class SlcCommandError(ProtocolError):
    """Base of SLC reply errors; ``command`` is the line that caused it."""

    def __init__(self, command: str, message: str) -> None:
        super().__init__(f"LED controller: {message} (command {command!r})")
        self.command = command


class SlcAckInsteadOfDataError(SlcCommandError):
    """``##``: a query was acknowledged but no data came back."""


class SlcExecutionError(SlcCommandError):
    """``#!``: valid command, executed, but the controller reported an error."""


class SlcArgumentError(SlcCommandError):
    """``#?``: valid command, argument out of range (channel, mode or current)."""


class SlcUnknownCommandError(SlcCommandError):
    """``XXXX is not defined``: the firmware does not know this command."""


class SlcBadReplyError(SlcCommandError):
    """A reply that is garbled or carries impossible values."""


class SlcEchoError(SlcCommandError):
    """The controller keeps echoing commands (ECHOON) although ECHOOFF was sent;
    ``reply_text`` is the reply found behind the echo."""

    def __init__(self, command: str, message: str, reply_text: str = "") -> None:
        super().__init__(command, message)
        self.reply_text = reply_text


def split_echo(command: str, raw: bytes) -> tuple[bytes, bytes]:
    """Split a reply line read with echo on into ``(echo, reply)`` (B.4, SDK "Echo Mode").

    With ECHOON the controller sends the command line back as received, a ``>`` prompt for
    its CR, the reply, then another ``>`` prompt (which can lead the next line if it came
    after the drain). ``echo`` is the exact command line (``command`` + LF CR) when ``raw``
    starts with it - a line that only looks similar is not an echo and stays in ``reply``
    for the caller to refuse - else ``b""``. Leading prompts are dropped from ``reply``: no
    reply starts with ``>``.
    """
    line = command.encode("ascii") + COMMAND_END
    body = raw.lstrip(b">")
    if body.startswith(line):
        return line, body[len(line):].lstrip(b">")
    return b"", body


class SlcNoReplyError(DeviceTimeoutError):
    """Silence: nothing came back within the timeout."""

    def __init__(self, command: str, timeout_s: float) -> None:
        super().__init__(f"LED controller: no reply within {timeout_s:g} s (command {command!r})")
        self.command = command


@dataclass(frozen=True)
class SlcDeviceInfo:
    driver_version: str  # firmware ("Mightex LED Driver:3.1.8")
    module: str  # e.g. "SLC-SA04-U/S"; "" when the firmware does not report it
    serial: str


def parse_device_info(text: str) -> SlcDeviceInfo:
    """Parse a DEVICEINFO line by keyword (field order and presence vary by firmware)."""

    def field(key: str) -> str:
        m = re.search(re.escape(key) + r"\s*(\S+)", text)
        return m.group(1) if m else ""

    info = SlcDeviceInfo(field("Driver:"), field("Module No.:"), field("Serial No.:"))
    if not info.driver_version or not info.serial:
        raise SlcBadReplyError("DEVICEINFO", f"unrecognised device info {text!r}")
    return info


def parse_current_reply(command: str, payload: str) -> tuple[int, int]:
    """``?CURRENT`` payload -> (Imax, Iset) in wire units: the last two fields, whatever precede."""
    tokens = payload.split()
    try:
        imax, iset = int(tokens[-2]), int(tokens[-1])
    except (IndexError, ValueError):
        raise SlcBadReplyError(command, f"cannot read currents from {payload!r}") from None
    if imax < 0 or iset < 0 or iset > imax:
        raise SlcBadReplyError(command, f"impossible currents Imax={imax} Iset={iset}")
    return imax, iset
