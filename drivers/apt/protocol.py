"""Pure pack / unpack for the Thorlabs APT binary protocol (subset for DC servo cubes).

No I/O here: the driver (:mod:`benchlab.drivers.apt.stage`) and the simulator
(:mod:`benchlab.drivers.apt.sim`) both build on it. Facts: shared/docs/device-protocols.md
section C. Header: 6 bytes, message id u16 LE, then either param1/param2 (short form) or a
u16 LE data length (long form, flagged by bit 7 of the destination byte), then dest, source.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable
from dataclasses import dataclass
from enum import IntEnum, IntFlag

HOST = 0x01
UNIT = 0x50  # generic USB unit: single-channel cubes (KDC101, TDC001)
LONG_FLAG = 0x80
CHAN1 = 0x01
HEADER_LEN = 6
MAX_DATA_LEN = 255  # the length field is 16-bit but no APT packet exceeds 255 bytes

# DC servo time base: velocity and acceleration scale with T = 2048 / 6 MHz (section C.6).
T_S = 2048 / 6_000_000
#: Z8-series encoder counts per mm, as in Thorlabs' unit-conversion table (67.49:1 gearhead,
#: Kinesis configurations). The same document's POTPARAMS example, pyLabLib and pyAPT use
#: 34304 (512 counts/rev x 67:1, 1 mm pitch): 0.73 % apart. The bench file's
#: ``stage.actuator`` picks one; ``benchlab doctor`` settles it with a measured move.
Z8_COUNTS_PER_MM = 34554.96
Z8_ALT_COUNTS_PER_MM = 34304.0
#: Encoder counts per mm by actuator name (``stage.actuator`` in the bench file).
ACTUATOR_COUNTS_PER_MM: dict[str, float] = {
    "Z8": Z8_COUNTS_PER_MM,
    "Z8-34304": Z8_ALT_COUNTS_PER_MM,
    "Z6": 24600.0,
}
#: Travel of each actuator, mm: a stage section without ``travel_mm`` gets (0, this). The Z8
#: default is the Z825's 25 mm (a Z812 has 12 mm: give travel_mm); the Z606 has 6 mm.
ACTUATOR_TRAVEL_MM: dict[str, float] = {"Z8": 25.0, "Z8-34304": 25.0, "Z6": 6.0}
#: A completed move must end this close to its target, counts (about 0.9 um on a Z8): a
#: servo can park a few tens of counts off inside its own window. No source gives a number;
#: the bench file's ``stage.tolerance_counts`` overrides it.
COMPLETION_TOLERANCE_COUNTS = 30


def actuator_counts_per_mm(actuator: str) -> float:
    """Counts per mm of a named actuator; ``ValueError`` lists the known names."""
    try:
        return ACTUATOR_COUNTS_PER_MM[actuator]
    except KeyError:
        raise ValueError(f"unknown actuator {actuator!r}: known are "
                         f"{', '.join(ACTUATOR_COUNTS_PER_MM)}") from None


class Msg(IntEnum):
    HW_DISCONNECT = 0x0002
    HW_REQ_INFO = 0x0005
    HW_GET_INFO = 0x0006
    HW_START_UPDATEMSGS = 0x0011
    HW_STOP_UPDATEMSGS = 0x0012
    HW_NO_FLASH_PROGRAMMING = 0x0018
    HW_RESPONSE = 0x0080
    HW_RICHRESPONSE = 0x0081
    MOD_SET_CHANENABLESTATE = 0x0210
    MOD_REQ_CHANENABLESTATE = 0x0211
    MOD_GET_CHANENABLESTATE = 0x0212
    MOD_IDENTIFY = 0x0223
    MOT_SET_POSCOUNTER = 0x0410
    MOT_REQ_POSCOUNTER = 0x0411
    MOT_GET_POSCOUNTER = 0x0412
    MOT_SET_VELPARAMS = 0x0413
    MOT_REQ_VELPARAMS = 0x0414
    MOT_GET_VELPARAMS = 0x0415
    MOT_REQ_STATUSBITS = 0x0429
    MOT_GET_STATUSBITS = 0x042A
    MOT_REQ_HOMEPARAMS = 0x0441
    MOT_GET_HOMEPARAMS = 0x0442
    MOT_MOVE_HOME = 0x0443
    MOT_MOVE_HOMED = 0x0444
    MOT_MOVE_RELATIVE = 0x0448
    MOT_MOVE_ABSOLUTE = 0x0453
    MOT_MOVE_COMPLETED = 0x0464
    MOT_MOVE_STOP = 0x0465
    MOT_MOVE_STOPPED = 0x0466
    MOT_REQ_DCSTATUSUPDATE = 0x0490
    MOT_GET_DCSTATUSUPDATE = 0x0491
    MOT_ACK_DCSTATUSUPDATE = 0x0492


# Data length of every long-form message in this subset; a header announcing any other length
# for these ids is garbage, which is how the reader resynchronises.
LONG_LEN: dict[int, int] = {
    Msg.HW_GET_INFO: 84,
    Msg.HW_RICHRESPONSE: 68,
    Msg.MOT_SET_POSCOUNTER: 6,
    Msg.MOT_GET_POSCOUNTER: 6,
    Msg.MOT_SET_VELPARAMS: 14,
    Msg.MOT_GET_VELPARAMS: 14,
    Msg.MOT_GET_HOMEPARAMS: 14,
    Msg.MOT_GET_STATUSBITS: 6,
    Msg.MOT_MOVE_RELATIVE: 6,
    Msg.MOT_MOVE_ABSOLUTE: 6,
    Msg.MOT_MOVE_COMPLETED: 14,
    Msg.MOT_MOVE_STOPPED: 14,
    Msg.MOT_GET_DCSTATUSUPDATE: 14,
}
# Messages that only exist in long form (the two moves also have a short form).
LONG_ONLY = frozenset(LONG_LEN) - {Msg.MOT_MOVE_RELATIVE, Msg.MOT_MOVE_ABSOLUTE}

STOP_IMMEDIATE = 0x01
STOP_PROFILED = 0x02
ENABLE = 0x01
DISABLE = 0x02


class StatusBits(IntFlag):
    """P_MOT_SB_* status bits (section C.4); "forward" = increasing position counts."""

    FWD_HW_LIMIT = 0x00000001
    REV_HW_LIMIT = 0x00000002
    FWD_SW_LIMIT = 0x00000004
    REV_SW_LIMIT = 0x00000008
    MOVING_FWD = 0x00000010
    MOVING_REV = 0x00000020
    JOGGING_FWD = 0x00000040
    JOGGING_REV = 0x00000080
    MOTOR_CONNECTED = 0x00000100
    HOMING = 0x00000200
    HOMED = 0x00000400
    INITIALIZING = 0x00000800
    TRACKING = 0x00001000
    SETTLED = 0x00002000
    POSITION_ERROR = 0x00004000
    INSTRUMENT_ERROR = 0x00008000
    INTERLOCK = 0x00010000
    OVER_TEMPERATURE = 0x00020000
    BUS_VOLTAGE_FAULT = 0x00040000
    COMMUTATION_ERROR = 0x00080000
    DIGITAL_IN_1 = 0x00100000
    DIGITAL_IN_2 = 0x00200000
    DIGITAL_IN_3 = 0x00400000
    DIGITAL_IN_4 = 0x00800000
    OVERLOAD = 0x01000000
    ENCODER_FAULT = 0x02000000
    OVER_CURRENT = 0x04000000
    BUS_CURRENT_FAULT = 0x08000000
    POWER_OK = 0x10000000
    ACTIVE = 0x20000000
    ERROR = 0x40000000
    ENABLED = 0x80000000


MOVING_BITS = StatusBits.MOVING_FWD | StatusBits.MOVING_REV | StatusBits.HOMING
LIMIT_BITS = StatusBits.FWD_HW_LIMIT | StatusBits.REV_HW_LIMIT
#: Bits that mean the controller or motor reported a fault (section C.4).
FAULT_BITS = (StatusBits.POSITION_ERROR | StatusBits.INSTRUMENT_ERROR | StatusBits.INTERLOCK
              | StatusBits.OVER_TEMPERATURE | StatusBits.BUS_VOLTAGE_FAULT
              | StatusBits.COMMUTATION_ERROR | StatusBits.OVERLOAD | StatusBits.ENCODER_FAULT
              | StatusBits.OVER_CURRENT | StatusBits.BUS_CURRENT_FAULT | StatusBits.ERROR)


@dataclass(frozen=True)
class Message:
    """One APT message. ``data`` is None for the 6-byte short form."""

    msg_id: int
    param1: int = 0
    param2: int = 0
    data: bytes | None = None
    dest: int = UNIT
    source: int = HOST

    def pack(self) -> bytes:
        if self.data is None:
            return struct.pack("<HBBBB", self.msg_id, self.param1, self.param2,
                               self.dest, self.source)
        return struct.pack("<HHBB", self.msg_id, len(self.data), self.dest | LONG_FLAG,
                           self.source) + self.data

    @property
    def name(self) -> str:
        try:
            return Msg(self.msg_id).name
        except ValueError:
            return f"0x{self.msg_id:04X}"


def short(msg_id: int, param1: int = 0, param2: int = 0, *, dest: int = UNIT,
          source: int = HOST) -> Message:
    return Message(msg_id, param1, param2, None, dest, source)


def long(msg_id: int, data: bytes, *, dest: int = UNIT, source: int = HOST) -> Message:
    return Message(msg_id, 0, 0, data, dest, source)


class FrameReader:
    """Incremental parser: bytes in, whole messages out, resynchronising after garbage.

    A header is accepted only if its id is in the catalogue, the addresses are the expected
    ones and a long form announces the catalogue length; otherwise one byte is dropped and
    parsing retries (the approach of the public APT unpackers).
    """

    def __init__(self, *, dests: Iterable[int], sources: Iterable[int]) -> None:
        self._dests = frozenset(dests)
        self._sources = frozenset(sources)
        self._buf = bytearray()
        self.dropped_bytes = 0

    def feed(self, data: bytes) -> list[Message]:
        self._buf += data
        out: list[Message] = []
        while len(self._buf) >= HEADER_LEN:
            msg_id, p1, p2, dest, source = struct.unpack_from("<HBBBB", self._buf)
            is_long = bool(dest & LONG_FLAG)
            length = p1 | (p2 << 8)
            if not self._header_ok(msg_id, is_long, length, dest & ~LONG_FLAG, source):
                del self._buf[0]
                self.dropped_bytes += 1
                continue
            if not is_long:
                out.append(Message(msg_id, p1, p2, None, dest, source))
                del self._buf[:HEADER_LEN]
                continue
            if len(self._buf) < HEADER_LEN + length:
                break  # wait for the rest of the packet
            payload = bytes(self._buf[HEADER_LEN : HEADER_LEN + length])
            out.append(Message(msg_id, 0, 0, payload, dest & ~LONG_FLAG, source))
            del self._buf[: HEADER_LEN + length]
        return out

    def _header_ok(self, msg_id: int, is_long: bool, length: int, dest: int, source: int) -> bool:
        if msg_id not in Msg._value2member_map_ or dest not in self._dests:
            return False
        if source not in self._sources:
            return False
        if is_long:
            # Only ids that have a long form, at their one length (a short-only id such as
            # MOVE_HOMED with bit 7 of byte 4 set is stray bytes, not a message).
            return 0 < length <= MAX_DATA_LEN and LONG_LEN.get(msg_id) == length
        return msg_id not in LONG_ONLY


# ---- payload structures ----------------------------------------------------------------------
_DC_STATUS = struct.Struct("<HiHhI")
_VELPARAMS = struct.Struct("<Hiii")
_POSITION = struct.Struct("<Hi")
_STATUSBITS = struct.Struct("<HI")
_HWINFO = struct.Struct("<I8sH4B48s12sHHH")


@dataclass(frozen=True)
class DcStatus:
    """DC servo status structure (0x0491 / 0x0464 / 0x0466), 14 bytes."""

    position_counts: int
    velocity_raw: int
    motor_current_ma: int
    bits: StatusBits
    chan: int = CHAN1

    def pack(self) -> bytes:
        return _DC_STATUS.pack(self.chan, self.position_counts, self.velocity_raw,
                               self.motor_current_ma, int(self.bits))

    @classmethod
    def unpack(cls, data: bytes) -> DcStatus:
        chan, pos, vel, cur, bits = _DC_STATUS.unpack(data[: _DC_STATUS.size])
        return cls(pos, vel, cur, StatusBits(bits), chan)


@dataclass(frozen=True)
class VelParamsRaw:
    accel_raw: int
    max_vel_raw: int
    min_vel_raw: int = 0
    chan: int = CHAN1

    def pack(self) -> bytes:
        return _VELPARAMS.pack(self.chan, self.min_vel_raw, self.accel_raw, self.max_vel_raw)

    @classmethod
    def unpack(cls, data: bytes) -> VelParamsRaw:
        chan, vmin, acc, vmax = _VELPARAMS.unpack(data[: _VELPARAMS.size])
        return cls(acc, vmax, vmin, chan)


_HOMEPARAMS = struct.Struct("<HHHii")


@dataclass(frozen=True)
class HomeParamsRaw:
    """MOT_GET_HOMEPARAMS (0x0442): direction, limit switch, home velocity (velocity units
    as in VELPARAMS) and offset distance (counts) of the controller's homing move."""

    direction: int
    limit_switch: int
    velocity_raw: int
    offset_counts: int
    chan: int = CHAN1

    def pack(self) -> bytes:
        return _HOMEPARAMS.pack(self.chan, self.direction, self.limit_switch,
                                self.velocity_raw, self.offset_counts)

    @classmethod
    def unpack(cls, data: bytes) -> HomeParamsRaw:
        chan, direction, switch, vel, offset = _HOMEPARAMS.unpack(data[: _HOMEPARAMS.size])
        return cls(direction, switch, vel, offset, chan)


def pack_position(counts: int, chan: int = CHAN1) -> bytes:
    """chan u16 + i32: POSCOUNTER, MOVE_ABSOLUTE / MOVE_RELATIVE long-form payloads."""
    return _POSITION.pack(chan, counts)


def unpack_position(data: bytes) -> tuple[int, int]:
    return _POSITION.unpack(data[: _POSITION.size])


def pack_statusbits(bits: StatusBits, chan: int = CHAN1) -> bytes:
    return _STATUSBITS.pack(chan, int(bits))


def unpack_statusbits(data: bytes) -> StatusBits:
    return StatusBits(_STATUSBITS.unpack(data[: _STATUSBITS.size])[1])


@dataclass(frozen=True)
class HwInfo:
    serial: int
    model: str
    hw_type: int
    firmware: tuple[int, int, int]  # (major, interim, minor)
    hw_version: int
    mod_state: int
    channels: int
    stage_id: int = 0  # KDC101/TDC001 stage id at bytes 76..77 (8 = MTS50-Z8)

    @property
    def firmware_str(self) -> str:
        return ".".join(str(v) for v in self.firmware)

    def pack(self) -> bytes:
        major, interim, minor = self.firmware
        tail = bytes(10) + struct.pack("<H", self.stage_id)
        return _HWINFO.pack(self.serial, self.model.encode("ascii"), self.hw_type, minor,
                            interim, major, 0, bytes(48), tail, self.hw_version,
                            self.mod_state, self.channels)

    @classmethod
    def unpack(cls, data: bytes) -> HwInfo:
        if len(data) != _HWINFO.size:
            raise ValueError(f"HW_GET_INFO payload is {len(data)} bytes, expected {_HWINFO.size}")
        (serial, model, hw_type, minor, interim, major, _unused, _notes, tail, hw_ver, mod,
         nchan) = _HWINFO.unpack(data)
        return cls(serial, model.rstrip(b"\x00 ").decode("ascii", errors="replace"), hw_type,
                   (major, interim, minor), hw_ver, mod, nchan,
                   struct.unpack_from("<H", tail, 10)[0])


# ---- unit conversion (DC servo, section C.6) --------------------------------------------------
@dataclass(frozen=True)
class Units:
    counts_per_mm: float = Z8_COUNTS_PER_MM

    def counts(self, mm: float) -> int:
        return round(mm * self.counts_per_mm)

    def mm(self, counts: int) -> float:
        return counts / self.counts_per_mm

    def vel_raw(self, mm_s: float) -> int:
        return round(mm_s * self.counts_per_mm * T_S * 65536)

    def vel_mm_s(self, raw: int) -> float:
        return raw / (self.counts_per_mm * T_S * 65536)

    def acc_raw(self, mm_s2: float) -> int:
        return round(mm_s2 * self.counts_per_mm * T_S * T_S * 65536)

    def acc_mm_s2(self, raw: int) -> float:
        return raw / (self.counts_per_mm * T_S * T_S * 65536)
