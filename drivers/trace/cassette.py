"""Reading a cassette (:mod:`benchlab.drivers.trace.io_trace` writes them) and the one error a
replay raises when the driver does something else than what was recorded."""

from __future__ import annotations

import base64
import json
import zlib
from dataclasses import dataclass
from pathlib import Path

from benchlab.drivers.errors import DeviceError
from benchlab.drivers.trace.io_trace import CASSETTE_VERSION, open_text

#: Shown of a transfer in a divergence message.
_SHOWN_BYTES = 24


class CassetteError(DeviceError):
    """A cassette file that cannot be read (names the file and the line)."""


class ReplayDivergedError(DeviceError):
    """The driver sent (or read) something else than the cassette recorded at this point."""


@dataclass(frozen=True)
class Exchange:
    """One recorded event of one device: a transfer, a timed-out read, or an open."""

    n: int  # exchange number in the cassette (1-based, all devices counted)
    device: str
    direction: str  # ">" to the device, "<" from it, "open"
    data: bytes = b""
    ep: int | None = None
    timeout: bool = False
    opened: dict[str, object] | None = None

    def describe(self) -> str:
        if self.direction == "open":
            return f"open {self.opened}"
        if self.timeout:
            return f"a read that timed out{_ep(self.ep)}"
        if self.direction == ">":
            return f"{show(self.data)}{_ep(self.ep)}"
        return f"a reply {show(self.data)}{_ep(self.ep)}"


def _ep(ep: int | None) -> str:
    return "" if ep is None else f" on EP 0x{ep:02X}"


def show(data: bytes) -> str:
    """Bytes for a message: hex, cut after a few, with the length."""
    more = f" ... ({len(data)} bytes)" if len(data) > _SHOWN_BYTES else ""
    return (data[:_SHOWN_BYTES].hex(" ") or "(nothing)") + more


def load(path: str | Path) -> list[Exchange]:
    """Every exchange of a cassette, in order; :class:`CassetteError` names a bad line."""
    return _read(path)[0]


def last_event_number(path: str | Path) -> int:
    """The number of the last event (exchange or note) of the cassette ``path``, after
    checking every line of it as :func:`load` does: what ``--append`` numbers on from.

    Raises
    ------
    CassetteError
        Naming the file when it is not a whole cassette (a frame, a session file, a
        truncated gzip, a cassette of another version).
    """
    return _read(path)[1]


def _read(path: str | Path) -> tuple[list[Exchange], int]:
    """Every exchange of a cassette and the number of its last event (0: none)."""
    out: list[Exchange] = []
    last = 0
    try:
        with open_text(path, "r") as fh:
            lines = fh.read().splitlines()
    except FileNotFoundError:
        raise CassetteError(f"{path}: no such cassette") from None
    except EOFError:  # a .gz file cut short (a copy that did not finish, a full disk)
        raise CassetteError(f"{path}: damaged cassette: the compressed data ends early "
                            "(truncated file)") from None
    except (OSError, zlib.error) as exc:  # gzip.BadGzipFile is an OSError
        raise CassetteError(f"{path}: cannot read the cassette: "
                            f"{getattr(exc, 'strerror', None) or exc}") from None
    except UnicodeDecodeError as exc:
        raise CassetteError(f"{path}: damaged cassette: byte 0x{exc.object[exc.start]:02x} at "
                            f"offset {exc.start} is not text (cassettes are ASCII JSON "
                            "lines)") from None
    if not lines:
        raise CassetteError(f"{path}: empty file, not a cassette")
    for i, text in enumerate(lines, 1):
        try:
            item = json.loads(text)
        except json.JSONDecodeError as exc:
            raise CassetteError(f"{path}: line {i} is not JSON: {exc}") from None
        if not isinstance(item, dict):
            raise CassetteError(f"{path}: line {i} is not a JSON object")
        if i == 1:
            if item.get("cassette") != CASSETTE_VERSION:
                raise CassetteError(f"{path}: line 1 is not a version-{CASSETTE_VERSION} "
                                    "cassette header (record one with --trace-io)")
            continue
        if "note" in item:
            last = max(last, _number(item))
            continue
        try:
            n, device = int(item["n"]), str(item["dev"])
            last = max(last, n)
            if "open" in item:
                out.append(Exchange(n, device, "open", opened=dict(item["open"])))
                continue
            direction = item["dir"]
            if direction not in (">", "<"):
                raise ValueError(f"dir {direction!r}")
            ep = item.get("ep")
            if item.get("timeout"):
                out.append(Exchange(n, device, direction, ep=ep, timeout=True))
                continue
            data = (bytes.fromhex(item["hex"]) if "hex" in item
                    else base64.b64decode(item["b64"], validate=True))
            if len(data) != int(item["len"]):
                raise ValueError(f"len {item['len']} but {len(data)} bytes")
        except (KeyError, ValueError, TypeError) as exc:
            raise CassetteError(f"{path}: line {i}: bad exchange ({exc})") from None
        out.append(Exchange(n, device, direction, data, ep))
    return out, last


def _number(item: dict[str, object]) -> int:
    """A note line's event number (0 when it has none: notes are free text)."""
    n = item.get("n")
    return n if isinstance(n, int) and not isinstance(n, bool) else 0
