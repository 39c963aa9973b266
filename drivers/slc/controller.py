"""Driver for the Mightex SLC (Sirius) LED controller over RS232 ASCII (pyserial).

Protocol facts: shared/docs/device-protocols.md section B. Line settings 9600 8N1, commands
end in LF CR, replies are ``payload + " \\r\\n"``. Every exchange resets the input buffer first
and drains stray bytes after the reply, the recipe that made the bench unit reliable. The
line carries no sequence numbers, so after a command goes unanswered (timeout, cut-off line,
Ctrl-C) the next exchange first waits for and discards its late reply, and if that still has
not come, refuses a reply that a second line follows (the first may be the late one).

Echo (ECHOON, B.4): a controller left echoing by a previous program, or switched to echo
mid-session, sends each command line back before its reply. Opening sends ECHOOFF and checks
with DEVICEINFO that the reply comes without echo (ECHOOFF once more if not, then
:class:`SlcEchoError` naming the bytes). Mid-session, an echo is stripped only when it is
exactly the command line just sent; the reply behind it is used, and ECHOOFF is sent (and
checked) before the next command.

Safety: per-channel current ceilings are checked before anything is sent; every channel is
switched off (``MODE ch 0``, read back with ``?MODE``) on close, on any exception inside the
``with`` block, on Ctrl-C and at interpreter exit. Closing the port alone does not switch an
SLC off, so this driver never relies on it.
"""

from __future__ import annotations

import logging
import math
import re
import threading
import time
from collections.abc import Mapping

import serial

from benchlab.drivers.errors import (
    DeviceError,
    DeviceLostError,
    SettingOutOfRangeError,
)
from benchlab.drivers.interfaces import DeviceIdentity, LightSource
from benchlab.drivers.serial_port import IO_ERRORS, open_serial
from benchlab.drivers.slc.protocol import (
    ACK,
    ARGUMENT_ERROR,
    BAUD,
    COMMAND_END,
    CURRENT_STEP_MA,
    EXECUTION_ERROR,
    REPLY_END,
    UNDEFINED,
    SlcAckInsteadOfDataError,
    SlcArgumentError,
    SlcBadReplyError,
    SlcCommandError,
    SlcDeviceInfo,
    SlcEchoError,
    SlcExecutionError,
    SlcMode,
    SlcNoReplyError,
    SlcUnknownCommandError,
    current_unit_ma,
    module_family,
    normal_max_ma,
    parse_current_reply,
    parse_device_info,
    split_echo,
)

log = logging.getLogger(__name__)

__all__ = [  # the protocol names are re-exported: callers keep importing them from here
    "SlcAckInsteadOfDataError", "SlcArgumentError", "SlcBadReplyError", "SlcCommandError",
    "SlcController", "SlcDeviceInfo", "SlcEchoError", "SlcExecutionError", "SlcMode",
    "SlcNoReplyError", "SlcUnknownCommandError", "parse_current_reply", "parse_device_info",
]

ECHOOFF_SETTLE_S = 0.1  # how long to wait for an (optional) ECHOOFF acknowledgement
ECHOOFF_ATTEMPTS = 2  # ECHOOFF sent this often before a still-echoing controller is refused
# After an unanswered command: the line counts as clear once it stayed silent this long.
LATE_REPLY_QUIET_S = 0.08


_DEFAULT_NORMAL_MAX_MA = 1000.0
_MAX_PROBE_CHANNELS = 16
_MAX_STALE_ACKS = 2


def read_reply_line(ser: serial.Serial, command: str | None = None) -> bytes:
    """One reply line ending in CR LF (documented) or LF CR (some vendor examples), returned
    ending in CR LF either way; what came before a timeout otherwise.

    Reads to the LF; an LF with a CR after it ends the line too - unless that line is the
    echo of ``command`` (ECHOON sends the command back with its LF CR), then the reply that
    follows the echo is read and returned after it, as received.
    """
    raw: bytes = ser.read_until(b"\n")
    if not raw.endswith(b"\n") or raw.endswith(REPLY_END):
        return raw
    cr = ser.read(1)
    if cr != b"\r":
        return raw + cr  # a lone LF: not a line end; the caller sees an unterminated line
    if command is not None and raw.lstrip(b">") == command.encode("ascii") + b"\n":
        return raw + cr + read_reply_line(ser)
    return raw[:-1] + REPLY_END


def _is_ack(raw: bytes) -> bool:
    """An acknowledgement line (``## \\r\\n``; ``>##`` with echo on)."""
    return raw.strip().lstrip(b">") == ACK.encode()


class SlcController(LightSource):
    """One SLC controller on a serial port. Channels are 1-based, as on the wire."""

    SAFE_ACTION = "switching the LEDs off"
    NAME = "LED controller"
    CHANNEL_NAME = "LED channel"

    def __init__(
        self, port: str, *, ceilings_ma: Mapping[int, float], timeout_s: float = 1.0
    ) -> None:
        for ch, limit in ceilings_ma.items():
            if not (isinstance(limit, int | float) and math.isfinite(limit) and limit >= 0):
                raise SettingOutOfRangeError(f"ceiling for channel {ch} must be >= 0 mA: {limit}")
        self.port = port
        self._ceilings_ma: dict[int, float] = {int(k): float(v) for k, v in ceilings_ma.items()}
        self.timeout_s = timeout_s
        self._ser: serial.Serial | None = None
        self._info: SlcDeviceInfo | None = None
        self._channel_count = 0
        self._unit_ma = 1.0
        self._step_wire = 1  # wire units per hardware current step (5 on CA modules)
        self._normal_max_ma = _DEFAULT_NORMAL_MAX_MA
        self._io_lock = threading.RLock()
        self._busy = False
        #: A command went out but its reply did not (fully) arrive: timeout, unterminated line,
        #: Ctrl-C / SIGTERM. Its late reply must be read before the next command's, or it
        #: would be taken for that one.
        self._late_reply = False
        #: The last reply line that came with an echo of its command (b"": none since the
        #: last check); set, it makes the next exchange switch echo off first.
        self._echoed_line = b""
        self._echo_off_running = False
        self._echo_stuck = False  # echo could not be switched off mid-session: strip only

    # ---- lifecycle -------------------------------------------------------------------------
    def open(self) -> SlcController:
        try:
            self._ser = open_serial(
                self.port, BAUD, device="led", bytesize=8, parity="N", stopbits=1,
                timeout=self.timeout_s, write_timeout=self.timeout_s,
            )
        except IO_ERRORS as exc:
            raise DeviceLostError(f"LED controller: cannot open {self.port}: {exc}") from exc
        try:
            echo_error: SlcEchoError | None = None
            try:
                info_text = self._switch_echo_off()
            except SlcEchoError as exc:
                # Still echoing: refuse the controller, but first switch its LEDs off (each
                # reply is still read, behind the exact echo of its command).
                echo_error, info_text, self._echo_stuck = exc, exc.reply_text, True
            self._info = parse_device_info(info_text)
            self._configure_family(self._info.module)
            self._channel_count = self._count_channels()
            self._register_atexit()  # and SIGINT/SIGTERM/SIGHUP: _on_stop_signal
            self.all_off()  # opening the driver must never leave light on from a previous user
            if echo_error is not None:
                raise echo_error
            log.info("LED controller %s serial %s on %s: %d channels, all off",
                     self._info.module, self._info.serial, self.port, self._channel_count)
        except BaseException:
            self._unregister_atexit()
            self._close_port()
            raise
        return self

    def close(self) -> None:
        """Switch every channel off (verified), then close the port."""
        if self._ser is None:
            return
        try:
            self.all_off()
        finally:
            self._unregister_atexit()
            self._close_port()

    @property
    def is_open(self) -> bool:
        return self._ser is not None

    @property
    def device_info(self) -> SlcDeviceInfo:
        if self._info is None:
            raise DeviceError("LED controller is not open")
        return self._info

    @property
    def identity(self) -> DeviceIdentity:
        info = self.device_info
        return DeviceIdentity(info.module, info.serial, info.driver_version, self.port)

    @property
    def channel_count(self) -> int:
        return self._channel_count

    @property
    def ceilings_ma(self) -> Mapping[int, float]:
        return self._ceilings_ma

    def ceiling_ma(self, ch: int) -> float | None:
        """The configured ceiling, capped by what the controller family can drive."""
        ceiling = self._ceilings_ma.get(ch)
        return None if ceiling is None else min(ceiling, self._normal_max_ma)

    def current_step_ma(self, ch: int) -> float:
        """The module family's current step (B.7): 1 mA, 0.1 mA on FA/FV/XA/XV, 5 mA on CA."""
        if self._ser is None:
            raise DeviceError("LED controller is not open")
        return round(self._step_wire * self._unit_ma, 9)

    # ---- channel commands ------------------------------------------------------------------
    def set_mode(self, ch: int, mode: SlcMode | int) -> None:
        """Select a channel's mode. NORMAL is only entered after its currents are verified."""
        self._check_channel(ch)
        mode = SlcMode(mode)
        if mode in (SlcMode.STROBE, SlcMode.TRIGGER):
            raise SettingOutOfRangeError(
                f"LED channel {ch}: {mode.name} mode is not supported by this driver"
            )
        if mode is SlcMode.NORMAL:
            # The controller may hold NORMAL currents set by someone else: check before lighting.
            imax_ma, iset_ma = self.get_current(ch)
            self._check_current(ch, max(imax_ma, iset_ma))
        self._command(f"MODE {ch} {int(mode)}")

    def get_mode(self, ch: int) -> SlcMode:
        self._check_channel(ch)
        cmd = f"?MODE {ch}"
        payload = self._query_data(cmd)
        try:
            return SlcMode(int(payload))
        except ValueError:
            raise SlcBadReplyError(cmd, f"unknown mode {payload!r}") from None

    def set_normal(self, ch: int, imax_ma: float, iset_ma: float) -> None:
        """Store NORMAL-mode ceiling and working current (both checked against the ceiling).

        Iset must be a whole number of current steps (:meth:`current_step_ma`); Imax, a limit,
        is rounded down to the step.
        """
        self._check_channel(ch)
        self._check_current(ch, imax_ma)
        self._check_current(ch, iset_ma)
        self._check_step(ch, iset_ma)
        if iset_ma > imax_ma:
            raise SettingOutOfRangeError(
                f"LED channel {ch}: Iset {iset_ma} mA above Imax {imax_ma} mA; nothing sent"
            )
        self._command(f"NORMAL {ch} {self._wire_limit(imax_ma)} {self._wire(iset_ma)}")

    def set_current(self, ch: int, iset_ma: float) -> None:
        """Change the working current live (takes effect only in NORMAL mode); a whole number
        of current steps."""
        self._check_channel(ch)
        self._check_current(ch, iset_ma)
        self._check_step(ch, iset_ma)
        self._command(f"CURRENT {ch} {self._wire(iset_ma)}")

    def get_current(self, ch: int) -> tuple[float, float]:
        """(Imax, Iset) of the NORMAL parameter set, in mA."""
        self._check_channel(ch)
        cmd = f"?CURRENT {ch}"
        imax, iset = parse_current_reply(cmd, self._query_data(cmd))
        return imax * self._unit_ma, iset * self._unit_ma

    def _do_on(self, ch: int, current_ma: float) -> None:
        """NORMAL mode at ``current_ma``, Imax = the configured ceiling."""
        log.debug("LED channel %d on at %g mA", ch, current_ma)
        ceiling_ma = self.ceiling_ma(ch)
        assert ceiling_ma is not None  # checked by on()
        self.set_normal(ch, ceiling_ma, current_ma)
        self._command(f"MODE {ch} {int(SlcMode.NORMAL)}")

    def _do_off(self, ch: int) -> None:
        self._command(f"MODE {ch} {int(SlcMode.DISABLE)}")

    def _do_is_on(self, ch: int) -> bool:
        return self.get_mode(ch) is not SlcMode.DISABLE

    def _do_current_ma(self, ch: int) -> float:
        return self.get_current(ch)[1]

    def all_off(self) -> None:
        """Disable every channel and read the modes back; raise if any channel may still be lit."""
        failures: list[str] = []
        with self._io_lock:
            for ch in range(1, self._channel_count + 1):
                try:
                    self.off(ch)
                    if self.get_mode(ch) is not SlcMode.DISABLE:
                        failures.append(f"channel {ch} did not report DISABLE")
                except DeviceLostError:
                    raise DeviceLostError(
                        "LED controller lost while switching off: outputs may still be lit; "
                        "switch them off at the controller"
                    ) from None
                except DeviceError as exc:
                    failures.append(f"channel {ch}: {exc}")
        if failures:
            raise DeviceError("LED controller: could not confirm all off: " + "; ".join(failures))

    # ---- checks (channel and ceiling: LightSource) ------------------------------------------
    def _wire(self, current_ma: float) -> int:
        """A working current in wire units; already checked to be on the current step."""
        return round(current_ma / self._unit_ma)

    def _wire_limit(self, current_ma: float) -> int:
        # A limit (Imax) rounds down - to the hardware's current step too - so neither our
        # rounding nor the controller's quantisation can push it above its checked ceiling.
        wire = math.floor(current_ma / self._unit_ma + 1e-9)
        return wire - wire % self._step_wire

    # ---- open helpers ----------------------------------------------------------------------
    def _echo_off(self) -> None:
        ser = self._port_or_raise()
        try:
            ser.reset_input_buffer()
            ser.write(b"ECHOOFF" + COMMAND_END)
            ser.timeout = min(self.timeout_s, ECHOOFF_SETTLE_S)
            read_reply_line(ser, "ECHOOFF")  # an ack may or may not come; either is fine
            ser.timeout = self.timeout_s
            ser.reset_input_buffer()
        except IO_ERRORS as exc:
            raise DeviceLostError(f"LED controller lost (command 'ECHOOFF'): {exc}") from exc

    def _switch_echo_off(self) -> str:
        """ECHOOFF, then DEVICEINFO, whose reply shows whether echo is off; ECHOOFF again
        while it is not. Returns the DEVICEINFO text; :class:`SlcEchoError` (naming the
        bytes) if the controller still echoes after ECHOOFF_ATTEMPTS tries."""
        echoed = b""
        self._echo_off_running = True
        try:
            for _ in range(ECHOOFF_ATTEMPTS):
                self._echo_off()
                self._echoed_line = b""
                text = self._device_info_text()
                echoed, self._echoed_line = self._echoed_line, b""
                if not echoed:
                    return text
                log.warning("LED controller echoes commands (ECHOON): %r; sending ECHOOFF",
                            echoed)
        finally:
            self._echo_off_running = False
        raise SlcEchoError("DEVICEINFO", f"still echoes commands after ECHOOFF sent "
                           f"{ECHOOFF_ATTEMPTS} times: got {echoed!r}", text)

    def _device_info_text(self) -> str:
        """DEVICEINFO right after ECHOOFF, robust to ECHOOFF's optional ack coming late: an
        ack line before the reply is skipped; an ack so late that DEVICEINFO timed out is
        drained (with the reply behind it) by the late-reply rule and DEVICEINFO asked again."""
        try:
            return self._query_text("DEVICEINFO", skip_acks=True)
        except SlcNoReplyError:
            log.debug("LED controller: no DEVICEINFO reply at open; resynchronising once")
            return self._query_text("DEVICEINFO", skip_acks=True)

    def _configure_family(self, module: str) -> None:
        family = module_family(module)
        self._unit_ma = current_unit_ma(module)
        self._step_wire = round(CURRENT_STEP_MA.get(family, 0) / self._unit_ma) or 1
        self._normal_max_ma = normal_max_ma(module)

    def _count_channels(self) -> int:
        m = re.match(r"SLC-[A-Z]{2}(\d\d)", self._info.module.upper() if self._info else "")
        if m and int(m.group(1)) > 0:
            return int(m.group(1))
        count = 0  # no module number: probe ?MODE n until the controller says "#?"
        for ch in range(1, _MAX_PROBE_CHANNELS + 1):
            try:
                self._query_data(f"?MODE {ch}")
            except SlcArgumentError:
                break
            count = ch
        if count == 0:
            raise SlcBadReplyError("?MODE 1", "controller reports no channels")
        return count

    # ---- wire ------------------------------------------------------------------------------
    def _port_or_raise(self) -> serial.Serial:
        if self._ser is None:
            raise DeviceError("LED controller is not open")
        return self._ser

    def _exchange(self, command: str, *, skip_acks: bool = False) -> str:
        """Send one command, return the reply payload (stripped), with buffer hygiene.

        ``skip_acks``: the command never answers ``##`` (DEVICEINFO), so up to
        ``_MAX_STALE_ACKS`` ``##`` lines before its reply are the late ack of an earlier
        command (ECHOOFF at open) and are discarded - the line is back in step.
        """
        ser = self._port_or_raise()
        with self._io_lock:
            if self._echoed_line and not self._echo_off_running and not self._echo_stuck:
                self._echo_off_mid_session()
            self._busy = True
            try:
                # A late reply that did not turn up may still come, during this exchange.
                still_due = self._late_reply and not self._drain_late_reply(ser)
                self._late_reply = False
                ser.reset_input_buffer()
                ser.write(command.encode("ascii") + COMMAND_END)
                raw = read_reply_line(ser, command)
                for _ in range(_MAX_STALE_ACKS if skip_acks else 0):
                    if not (raw.endswith(REPLY_END) and _is_ack(raw)):
                        break
                    log.debug("LED controller: discarded a late %r before %r", raw, command)
                    raw = read_reply_line(ser, command)
                two_replies = False
                echo, reply = split_echo(command, raw)
                if echo:
                    log.debug("LED controller: stripped the echo %r of %r", echo, command)
                    self._echoed_line = raw
                if not raw.endswith(REPLY_END):
                    self._late_reply = True  # silence or a cut-off line: the rest may follow
                elif still_due:
                    two_replies = self._another_line_follows(ser)  # reads the second, if any
                elif ser.in_waiting:
                    ser.read(ser.in_waiting)  # drain strays after the terminator
            except IO_ERRORS as exc:
                raise DeviceLostError(f"LED controller lost (command {command!r}): {exc}") from exc
            except KeyboardInterrupt:
                self._late_reply = True  # its reply comes later: read it before the next
                raise
            finally:
                self._busy = False
        if two_replies:
            raise SlcBadReplyError(command, f"two replies, the first {raw!r} may answer an "
                                   "earlier command that timed out")
        if not raw:
            raise SlcNoReplyError(command, self.timeout_s)
        if not raw.endswith(REPLY_END):
            raise SlcBadReplyError(command, f"unterminated reply {raw!r}")
        try:
            text = reply.decode("ascii").strip()
        except UnicodeDecodeError:
            raise SlcBadReplyError(command, f"non-ASCII reply {raw!r}") from None
        if UNDEFINED in text:
            raise SlcUnknownCommandError(command, f"unknown command ({text})")
        if text.startswith(EXECUTION_ERROR):
            raise SlcExecutionError(command, "controller reported an execution error (#!)")
        if text.startswith(ARGUMENT_ERROR):
            raise SlcArgumentError(command, "argument out of range (#?)")
        return text

    def _echo_off_mid_session(self) -> None:
        """Echo came on mid-session (another program on the line, a power glitch): switch it
        off before the next command. If it stays on, say so once (SlcEchoError) and from then
        on only strip echoes, so switching the LEDs off still works."""
        echoed, self._echoed_line = self._echoed_line, b""
        log.warning("LED controller started echoing commands: %r; sending ECHOOFF", echoed)
        try:
            self._switch_echo_off()
        except SlcEchoError:
            self._echo_stuck = True
            raise

    def _drain_late_reply(self, ser: serial.Serial) -> bool:
        """Discard the reply of an earlier unanswered command; False if none came.

        Waits up to ``timeout_s`` for its line end, then reads until the line has stayed quiet
        for LATE_REPLY_QUIET_S (the doc's "sleep, drain in_waiting" recipe, made robust to a
        reply that is still on its way). Bounded by twice the timeout even if bytes keep coming.
        """
        deadline = time.monotonic() + 2 * self.timeout_s
        try:
            ser.timeout = self.timeout_s
            stale = read_reply_line(ser)
            ser.timeout = LATE_REPLY_QUIET_S
            while time.monotonic() < deadline:
                more = ser.read(max(1, ser.in_waiting))
                if not more:
                    break
                stale += more
        finally:
            ser.timeout = self.timeout_s
        if stale:
            log.debug("LED controller: discarded late reply %r", stale)
        return bool(stale)

    def _another_line_follows(self, ser: serial.Serial) -> bool:
        """After a reply read while a late one was still due: does a second line follow
        within LATE_REPLY_QUIET_S? Then the first may have been the late one."""
        try:
            ser.timeout = LATE_REPLY_QUIET_S
            extra = read_reply_line(ser)
        finally:
            ser.timeout = self.timeout_s
        return extra.endswith(REPLY_END)

    def _command(self, command: str) -> None:
        text = self._exchange(command)
        if text != ACK:
            raise SlcBadReplyError(command, f"expected {ACK!r}, got {text!r}")

    def _query_data(self, command: str) -> str:
        text = self._exchange(command)
        if text == ACK:
            raise SlcAckInsteadOfDataError(command, "acknowledged (##) but no data returned")
        if not text.startswith("#") or len(text) < 2:
            raise SlcBadReplyError(command, f"expected '#<data>', got {text!r}")
        return text[1:].strip()

    def _query_text(self, command: str, *, skip_acks: bool = False) -> str:
        text = self._exchange(command, skip_acks=skip_acks)
        if text.startswith("#"):
            raise SlcBadReplyError(command, f"expected a bare text line, got {text!r}")
        return text

    def _close_port(self) -> None:
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except IO_ERRORS:
                pass

    # ---- stop signals (Ctrl-C, SIGTERM, SIGHUP) ----------------------------------------------
    def _on_stop_signal(self) -> None:
        # Between commands: switch off now. Mid-command (the port is busy): the interrupted
        # exchange unwinds to the context exit / close(), which switches every channel off.
        if self._ser is not None and not self._busy:
            try:
                self.all_off()
            except DeviceError:
                pass
