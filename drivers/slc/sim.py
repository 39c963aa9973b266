"""Simulated Mightex SLC LED controller (fw 3.1.8 behaviour) on a pseudo-terminal.

Speaks the RS232 ASCII protocol byte for byte (device-protocols.md section B): commands end in
LF CR (CR LF and bare CR/LF are accepted too), every reply is ``payload + " \\r\\n"``.
Quirks reproduced: ECHOOFF is not acknowledged (``echooff_ack=True`` gives the fw 3.1.8 ``##``),
echo mode (B.4, SDK "Echo Mode": after ECHOON each command line is echoed back as received,
then a ``>`` prompt for its CR, then the reply, then another ``>`` prompt; the echo setting
lives in the simulator instance, so it persists across host opens until ECHOOFF or RESET),
``?CURRENT`` answers with 12 fields (10 calibration values, then Imax and Iset), unknown verbs
answer ``    VERB is not defined``, and output keeps running when the host closes the port.
"""

from __future__ import annotations

import re
import time
from dataclasses import dataclass, field, replace

from benchlab.drivers.simulation.dispatch import CommandTable
from benchlab.drivers.simulation.pty_device import Clock, PtyDevice
from benchlab.drivers.slc.protocol import (
    ACK,
    ARGUMENT_ERROR,
    CURRENT_STEP_MA,
    EXECUTION_ERROR,
    NO_TRIGGER_FAMILIES,
    REPLY_SUFFIX,
    UNDEFINED,
    SlcMode,
    current_unit_ma,
    module_family,
)
from benchlab.drivers.slc.protocol import normal_max_ma as normal_max_ma_of

_LINE_SPLIT = re.compile(rb"\n\r|\r\n|\r|\n")
# Ten leading calibration fields as seen on a bench unit (one negative); drivers must skip them.
_CAL_FIELDS = "5 81 480 972 1468 1964 8 -72 8000 0"


@dataclass
class SimChannel:
    mode: SlcMode = SlcMode.DISABLE
    normal_imax: int = 20  # factory defaults (SDK): NORMAL Imax 20 / Iset 10
    normal_iset: int = 10
    strobe_imax: int = 20
    strobe_repeat: int = 0
    trigger_imax: int = 10
    trigger_polarity: int = 0
    # Profiles: step -> (Iset mA, Tset us); bench default after RESTOREDEF for TRIGGER.
    strobe_profile: dict[int, tuple[int, int]] = field(default_factory=dict)
    trigger_profile: dict[int, tuple[int, int]] = field(
        default_factory=lambda: {0: (10, 20), 1: (0, 0)})


@dataclass
class SlcFaults:
    """One-shot fault injection; each counter is decremented as it fires."""

    no_reply: int = 0  # ignore the next N commands entirely (silence)
    # The next N commands execute at once but are answered late_reply_s (wall seconds, like
    # the host's timeout) later; the firmware is busy meanwhile, so commands arriving in
    # between wait in the UART buffer and are answered after it, in order.
    late_reply: int = 0
    late_reply_s: float = 0.0
    # ECHOOFF is acknowledged ("##", whatever ``echooff_ack``) this many wall seconds late,
    # after the host stopped waiting for it (fw 3.1.8 acks it; older firmware does not).
    late_echooff_ack_s: float = 0.0
    garbage: bytes | None = None  # answer the next command with these bytes instead
    drop_on_command: str | None = None  # drop the link when this verb arrives (before acting)
    out_of_range: int = 0  # next N queries answer with impossible values
    exec_error: int = 0  # next N commands execute but answer "#!"
    undefined: set[str] = field(default_factory=set)  # verbs this "firmware" does not know
    # Echo switches on when this verb arrives (before the line is echoed and acted on), as if
    # a terminal program on the same line had sent ECHOON mid-session.
    echo_on_at: str | None = None
    # The next N ECHOOFF commands are answered as usual but leave echo on (a controller that
    # cannot be brought out of echo mode).
    echooff_ignored: int = 0


@dataclass
class _Stored:
    channels: list[SimChannel] = field(default_factory=list)


def _copy(c: SimChannel) -> SimChannel:
    return replace(c, strobe_profile=dict(c.strobe_profile),
                   trigger_profile=dict(c.trigger_profile))


MAX_PROFILE_STEP = 127
MAX_TSET_US = 99_999_999


class SimulatedSlc(PtyDevice):
    """An SLC-xx0N controller: per-channel mode plus NORMAL / STROBE / TRIGGER parameter sets."""

    name = "slc-sim"
    #: Verb (``?VERB`` for queries) -> handler taking the integer arguments.
    commands: CommandTable[str] = CommandTable()

    def __init__(
        self,
        *,
        channels: int = 4,
        module: str | None = None,
        serial: str = "04-251013-011",
        firmware: str = "3.1.8",
        clock: Clock | None = None,
        normal_max_ma: int | None = None,
        pulsed_max_ma: int = 3500,
        echooff_ack: bool = False,
        echo: bool = False,
        reply_end: bytes = b"\r\n",
    ) -> None:
        super().__init__(clock=clock)
        #: How reply lines end: CR LF as documented, or LF CR as some vendor examples show.
        self.reply_end = reply_end
        self.channel_count = channels
        # Default module number matches the channel count ("SLC-SA04-U/S" for 4 channels).
        self.module = module if module is not None else f"SLC-SA{channels:02d}-U/S"
        self.serial = serial
        self.firmware = firmware
        # NORMAL maximum in wire units (B.7: 1000 mA, 2000 on HA/HV, 100.0 on FA/FV/XA/XV,
        # 1200 on MA/CA -MU) unless given.
        self.normal_max_ma = (normal_max_ma if normal_max_ma is not None else round(
            normal_max_ma_of(self.module) / current_unit_ma(self.module)))
        # CA modules drive currents in 5 mA steps, to the nearest step (B.7: 123-127 -> 125).
        self.current_step_ma = CURRENT_STEP_MA.get(module_family(self.module), 1)
        self.pulsed_max_ma = pulsed_max_ma
        self.echooff_ack = echooff_ack
        self.faults = SlcFaults()
        #: Echo mode (ECHOON): kept across host opens, like the firmware keeps it across
        #: port closes; ``echo=True`` is a controller a previous program left echoing.
        self.echo = echo
        self.channels = [SimChannel() for _ in range(channels)]
        self._stored = _Stored([SimChannel() for _ in range(channels)])
        self._rx = b""
        self._late_out: bytearray | None = None  # reply of the command being answered late
        self._late: tuple[float, bytes] | None = None  # (send at, monotonic s; bytes) pending

    # ---- physical state for scenes and tests ----------------------------------------------
    def channel_output_ma(self, ch: int) -> float:
        """Actual LED current on channel ``ch`` (1-based): Iset while in NORMAL, else 0."""
        with self.lock:
            c = self.channels[ch - 1]
            return float(c.normal_iset) if c.mode == SlcMode.NORMAL else 0.0

    def host_lines(self) -> list[bytes]:
        """Every command line the host sent, terminators included."""
        return [b for who, b in self.transcript if who == "host"]

    # ---- protocol --------------------------------------------------------------------------
    def on_bytes(self, data: bytes) -> None:
        self._rx += data
        while self._late is None:  # busy with a late reply: later lines wait their turn
            m = _LINE_SPLIT.search(self._rx)
            if m is None:
                return
            line, raw = self._rx[: m.start()], self._rx[: m.end()]
            self._rx = self._rx[m.end() :]
            if not line.strip():
                continue  # the second half of a split terminator, or a blank line
            self.transcript.append(("host", raw))
            if not self.connected:
                return
            text = line.decode("ascii", errors="replace").strip()
            self._echo_line(text, raw)
            self._handle_line(text)

    def _echo_line(self, text: str, raw: bytes) -> None:
        """Echo mode: the line comes back as received (backspaces excepted), then the ``>``
        prompt for its CR - at once, even when the reply itself is late."""
        at = self.faults.echo_on_at
        if at is not None and text.split()[0].upper() == at.upper():
            self.faults.echo_on_at = None
            self.echo = True
        if self.echo:
            self.write(raw.replace(b"\x08", b"") + (b">" if b"\r" in raw else b""))

    def on_tick(self, now_s: float) -> None:
        late = self._late
        if late is not None and time.monotonic() >= late[0]:
            self._late = None
            if late[1]:
                self.write(late[1])
            self.on_bytes(b"")  # now answer what arrived meanwhile

    def _reply(self, payload: str) -> None:
        body = payload.encode("ascii").replace(b" \r\n", b" " + self.reply_end)
        self._out(body + b" " + self.reply_end)

    def _out(self, data: bytes) -> None:
        if self._late_out is not None:
            self._late_out += data
        else:
            self.write(data)

    def _handle_line(self, line: str) -> None:
        f = self.faults
        if f.late_echooff_ack_s > 0 and line.split()[0].upper() == "ECHOOFF":
            self.echo = False
            self._late = (time.monotonic() + f.late_echooff_ack_s, ACK.encode() + REPLY_SUFFIX)
            f.late_echooff_ack_s = 0.0
            return
        if f.late_reply > 0 and f.drop_on_command is None and f.no_reply == 0:
            f.late_reply -= 1
            self._late_out = bytearray()
            try:
                self._answer(line)
            finally:
                out, self._late_out = bytes(self._late_out), None
                self._late = (time.monotonic() + f.late_reply_s, out)
            return
        self._answer(line)

    def _answer(self, line: str) -> None:
        self._execute(line)
        if self.echo and self.connected:
            self._out(b">")  # echo mode: the SDK's "additional prompt" after the response

    def _execute(self, line: str) -> None:
        words = line.split()
        verb = words[0].upper()
        f = self.faults
        if f.drop_on_command is not None and verb == f.drop_on_command.upper():
            f.drop_on_command = None
            self.drop_connection()
            return
        if f.no_reply > 0:
            f.no_reply -= 1
            return
        if f.garbage is not None:
            junk, f.garbage = f.garbage, None
            self._out(junk)
            return
        handler = self.commands.handler(self, verb)
        if (handler is None or verb in {v.upper() for v in f.undefined}
                or (verb.lstrip("?") in ("TRIGGER", "TRIGP")
                    and module_family(self.module) in NO_TRIGGER_FAMILIES)):
            self._reply(f"    {words[0]} {UNDEFINED}")
            return
        try:
            args = [int(w) for w in words[1:]]
        except ValueError:
            self._reply(ARGUMENT_ERROR)
            return
        reply = handler(args)
        if reply == ACK and f.exec_error > 0:
            f.exec_error -= 1
            reply = EXECUTION_ERROR
        if reply is not None:
            self._reply(reply)

    def _quantised(self, current: int) -> int:
        step = self.current_step_ma
        return step * round(current / step)

    def _chan(self, args: list[int], nargs: int) -> SimChannel | None:
        if len(args) != nargs or not 1 <= args[0] <= self.channel_count:
            return None
        return self.channels[args[0] - 1]

    def _take_out_of_range(self) -> bool:
        if self.faults.out_of_range > 0:
            self.faults.out_of_range -= 1
            return True
        return False

    @commands.handles("ECHOOFF")
    def _cmd_ECHOOFF(self, args: list[int]) -> str | None:
        if self.faults.echooff_ignored > 0:
            self.faults.echooff_ignored -= 1
        else:
            self.echo = False
        return ACK if self.echooff_ack else None

    @commands.handles("ECHOON")
    def _cmd_ECHOON(self, args: list[int]) -> str | None:
        self.echo = True
        return ACK

    @commands.handles("DEVICEINFO")
    def _cmd_DEVICEINFO(self, args: list[int]) -> str:
        module = f"Device Module No.:{self.module} " if self.module else ""  # old fw: absent
        return f"Mightex LED Driver:{self.firmware} {module}Device Serial No.:{self.serial}"

    @commands.handles("MODE")
    def _cmd_MODE(self, args: list[int]) -> str:
        c = self._chan(args, 2)
        if c is None or args[1] not in SlcMode._value2member_map_:
            return ARGUMENT_ERROR
        c.mode = SlcMode(args[1])
        return ACK

    @commands.handles("?MODE")
    def _cmd_Q_MODE(self, args: list[int]) -> str:
        c = self._chan(args, 1)
        if c is None:
            return ARGUMENT_ERROR
        return "#7" if self._take_out_of_range() else f"#{int(c.mode)}"

    @commands.handles("NORMAL")
    def _cmd_NORMAL(self, args: list[int]) -> str:
        c = self._chan(args, 3)
        if c is None:
            return ARGUMENT_ERROR
        imax, iset = self._quantised(args[1]), self._quantised(args[2])
        # Iset > Imax is undocumented on hardware; the simulator rejects it as out of range.
        if not (0 <= imax <= self.normal_max_ma and 0 <= iset <= imax):
            return ARGUMENT_ERROR
        c.normal_imax, c.normal_iset = imax, iset
        return ACK

    @commands.handles("CURRENT")
    def _cmd_CURRENT(self, args: list[int]) -> str:
        c = self._chan(args, 2)
        if c is None or not 0 <= self._quantised(args[1]) <= c.normal_imax:
            return ARGUMENT_ERROR
        c.normal_iset = self._quantised(args[1])
        return ACK

    @commands.handles("?CURRENT")
    def _cmd_Q_CURRENT(self, args: list[int]) -> str:
        c = self._chan(args, 1)
        if c is None:
            return ARGUMENT_ERROR
        if self._take_out_of_range():
            return f"#{_CAL_FIELDS} 1000 4000"  # Iset above Imax: impossible
        return f"#{_CAL_FIELDS} {c.normal_imax} {c.normal_iset}"

    @commands.handles("STROBE")
    def _cmd_STROBE(self, args: list[int]) -> str:
        c = self._chan(args, 3)
        if c is None or not 0 <= args[1] <= self.pulsed_max_ma or not 0 <= args[2] <= 99_999_999:
            return ARGUMENT_ERROR
        c.strobe_imax, c.strobe_repeat = args[1], args[2]
        return ACK

    @commands.handles("?STROBE")
    def _cmd_Q_STROBE(self, args: list[int]) -> str:
        c = self._chan(args, 1)
        return ARGUMENT_ERROR if c is None else f"#{c.strobe_imax} {c.strobe_repeat}"

    @commands.handles("TRIGGER")
    def _cmd_TRIGGER(self, args: list[int]) -> str:
        c = self._chan(args, 3)
        if c is None:
            return ARGUMENT_ERROR
        # Bench quirk: never rejected; Imax clamped to the pulsed ceiling, polarity stored verbatim.
        c.trigger_imax, c.trigger_polarity = min(args[1], self.pulsed_max_ma), args[2]
        return ACK

    @commands.handles("?TRIGGER")
    def _cmd_Q_TRIGGER(self, args: list[int]) -> str:
        c = self._chan(args, 1)
        return ARGUMENT_ERROR if c is None else f"#{c.trigger_imax} {c.trigger_polarity}"

    @commands.handles("STORE")
    def _cmd_STORE(self, args: list[int]) -> str:
        self._stored.channels = [_copy(c) for c in self.channels]
        return ACK

    @commands.handles("RESET")
    def _cmd_RESET(self, args: list[int]) -> str:
        # Soft reset: back to the stored state, each channel resuming its stored mode; echo off.
        self.channels = [_copy(c) for c in self._stored.channels]
        self.echo = False
        return ACK

    @commands.handles("RESTOREDEF")
    def _cmd_RESTOREDEF(self, args: list[int]) -> str:
        self.channels = [SimChannel() for _ in self.channels]  # volatile settings only
        return ACK

    def _profile_reply(self, profile: dict[int, tuple[int, int]]) -> str:
        # Multi-line: "#I0 T0 \r\n", "I1 T1 \r\n", ... up to and including the first "0 0".
        lines: list[str] = []
        for step in sorted(profile):
            i_ma, t_us = profile[step]
            lines.append(f"{i_ma} {t_us}")
            if (i_ma, t_us) == (0, 0):
                break
        if not lines or lines[-1] != "0 0":
            lines.append("0 0")
        return "#" + " \r\n".join(lines)

    @commands.handles("STRP")
    def _cmd_STRP(self, args: list[int]) -> str:
        c = self._chan(args, 4)
        if c is None or not 0 <= args[1] <= MAX_PROFILE_STEP or not 0 <= args[2] <= c.strobe_imax:
            return ARGUMENT_ERROR
        if not 0 <= args[3] <= MAX_TSET_US:
            return ARGUMENT_ERROR
        c.strobe_profile[args[1]] = (args[2], args[3])
        return ACK

    @commands.handles("?STRP")
    def _cmd_Q_STRP(self, args: list[int]) -> str:
        c = self._chan(args, 1)
        return ARGUMENT_ERROR if c is None else self._profile_reply(c.strobe_profile)

    @commands.handles("TRIGP")
    def _cmd_TRIGP(self, args: list[int]) -> str:
        c = self._chan(args, 4)
        if c is None:
            return ARGUMENT_ERROR
        # Bench quirk: never rejected; step current clamped to the TRIGGER Imax at write time.
        c.trigger_profile[args[1]] = (min(args[2], c.trigger_imax), args[3])
        return ACK

    @commands.handles("?TRIGP")
    def _cmd_Q_TRIGP(self, args: list[int]) -> str:
        c = self._chan(args, 1)
        return ARGUMENT_ERROR if c is None else self._profile_reply(c.trigger_profile)
