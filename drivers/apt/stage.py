"""Driver for a Thorlabs KDC101 / TDC001 DC servo cube with a Z8-series actuator (APT protocol).

Protocol facts: shared/docs/device-protocols.md section C; pure framing lives in
:mod:`benchlab.drivers.apt.protocol`. A background reader thread owns the input side: it
parses frames (resynchronising after garbage), routes unsolicited messages (status updates,
move completed / stopped, homed) into a log that requests and waits search, and sends the
USB keep-alive (0x0492) while status updates flow. Writes are serialised by a lock.

Safety: travel limits from configuration are checked (in encoder counts, after rounding)
before a move is sent; moves are refused before homing unless ``allow_unhomed=True``; the
stage is stopped on close, on any exception inside the ``with`` block, when a wait is
interrupted (timeout, Ctrl-C) and at interpreter exit.
"""

from __future__ import annotations

import collections
import contextlib
import logging
import math
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass

import serial

from benchlab.drivers.apt.protocol import (
    CHAN1,
    COMPLETION_TOLERANCE_COUNTS,
    DISABLE,
    ENABLE,
    FAULT_BITS,
    HOST,
    STOP_IMMEDIATE,
    STOP_PROFILED,
    UNIT,
    Z8_COUNTS_PER_MM,
    DcStatus,
    FrameReader,
    HomeParamsRaw,
    HwInfo,
    Message,
    Msg,
    StatusBits,
    Units,
    VelParamsRaw,
    long,
    pack_position,
    short,
    unpack_position,
    unpack_statusbits,
)
from benchlab.drivers.errors import (
    DeviceError,
    DeviceLostError,
    DeviceTimeoutError,
    ProtocolError,
    SafetyLimitError,
    SettingOutOfRangeError,
)
from benchlab.drivers.interfaces import DeviceIdentity, LinearStage
from benchlab.drivers.serial_port import IO_ERRORS, open_serial

log = logging.getLogger(__name__)

BAUD = 115200
READ_POLL_S = 0.02  # reader thread's serial read timeout
#: The cube (USB) wants 0x0492 at least once a second, else it stops sending unsolicited
#: messages - status updates and move completions alike - after ~50 of them. Sent on a timer
#: from open to close, so it also restarts a cube that stalled.
KEEPALIVE_PERIOD_S = 0.9
#: A completed move ends this close to its target by default (protocol's
#: COMPLETION_TOLERANCE_COUNTS; the ``completion_tolerance_counts`` argument overrides it).
#: Clients re-read the position after settling, and so does this driver:
SETTLE_READS = 5  # position re-reads after a MOVE_COMPLETED off target ...
SETTLE_WAIT_S = 0.05  # ... this far apart
#: The vendor's open routine: wait, purge both buffers, wait, with an RTS pulse around it.
OPEN_PAUSE_S = 0.05
Z8_MAX_VELOCITY_MM_S = 2.6
Z8_MAX_ACCELERATION_MM_S2 = 4.0
_STATUS_IDS = (Msg.MOT_GET_DCSTATUSUPDATE, Msg.MOT_MOVE_COMPLETED, Msg.MOT_MOVE_STOPPED)
_END_OF_MOVE_IDS = (Msg.MOT_MOVE_COMPLETED, Msg.MOT_MOVE_STOPPED, Msg.MOT_MOVE_HOMED)


class AptNoReplyError(DeviceTimeoutError):
    """No reply (or no completion message) within the timeout; names the request."""


class AptBadReplyError(ProtocolError):
    """A reply with an impossible value (position far outside travel, bad payload)."""


class AptLimitSwitchError(DeviceError):
    """A hardware limit switch stopped the move before the target."""


class AptMoveInterruptedError(DeviceError):
    """The move ended in MOVE_STOPPED (a stop request, a disable) instead of completing."""


class AptMoveFaultError(DeviceError):
    """MOVE_COMPLETED arrived, but with a fault bit, an unexpected limit switch, or the
    carriage away from the target."""


class AptNotHomedError(SafetyLimitError):
    """A move was requested before homing; nothing was sent."""


@dataclass(frozen=True)
class AptStatus:
    position_mm: float
    velocity_raw: int  # status-word velocity; device units are undocumented
    bits: StatusBits

    @property
    def is_homed(self) -> bool:
        return bool(self.bits & StatusBits.HOMED)

    @property
    def is_moving(self) -> bool:
        return bool(self.bits & (StatusBits.MOVING_FWD | StatusBits.MOVING_REV | StatusBits.HOMING))

    @property
    def at_forward_limit(self) -> bool:
        return bool(self.bits & StatusBits.FWD_HW_LIMIT)

    @property
    def at_reverse_limit(self) -> bool:
        return bool(self.bits & StatusBits.REV_HW_LIMIT)


@dataclass(frozen=True)
class HomeParams:
    """The controller's homing move: velocity, offset from the switch, direction, switch."""

    velocity_mm_s: float
    offset_mm: float
    direction: int
    limit_switch: int


@dataclass(frozen=True)
class VelocityParams:
    max_velocity_mm_s: float
    acceleration_mm_s2: float


def reset_line(ser: serial.Serial) -> None:
    """The vendor's (and pyLabLib's) open routine: RTS high, wait, purge input and output,
    wait, RTS low. A pseudo-terminal (the simulator) has no modem lines: the pulse is skipped
    there, the purge is not."""
    with contextlib.suppress(OSError):
        ser.rts = True
    time.sleep(OPEN_PAUSE_S)
    ser.reset_input_buffer()
    ser.reset_output_buffer()
    time.sleep(OPEN_PAUSE_S)
    with contextlib.suppress(OSError):
        ser.rts = False


def query_info(port: str, *, timeout_s: float = 1.0) -> HwInfo:
    """Ask a cube for HW_GET_INFO only (no enable, no updates): safe for device listings."""
    frames = FrameReader(dests={HOST}, sources={UNIT, 0x11, *range(0x21, 0x2B)})
    try:
        with open_serial(port, BAUD, device="stage", rtscts=True, timeout=READ_POLL_S,
                         write_timeout=timeout_s) as ser:
            reset_line(ser)
            ser.write(short(Msg.HW_REQ_INFO).pack())
            deadline = time.monotonic() + timeout_s
            while time.monotonic() < deadline:
                for msg in frames.feed(ser.read(max(1, ser.in_waiting))):
                    if msg.msg_id == Msg.HW_GET_INFO and msg.data:
                        return HwInfo.unpack(msg.data)
    except IO_ERRORS as exc:
        raise DeviceLostError(f"stage: cannot query {port}: {exc}") from exc
    except ValueError as exc:
        raise AptBadReplyError(f"stage: bad HW_GET_INFO reply from {port}: {exc}") from None
    raise AptNoReplyError(f"stage: no HW_GET_INFO reply from {port} within {timeout_s:g} s")


class AptStage(LinearStage):
    """One single-axis APT stage on a serial port; positions in mm, limits from configuration."""

    SAFE_ACTION = "stopping the stage"

    def __init__(
        self,
        port: str,
        *,
        counts_per_mm: float = Z8_COUNTS_PER_MM,
        travel_mm: tuple[float, float] = (0.0, 25.0),
        timeout_s: float = 2.0,
        allow_unhomed: bool = False,
        updates: bool = True,
        max_velocity_mm_s: float = Z8_MAX_VELOCITY_MM_S,
        max_acceleration_mm_s2: float = Z8_MAX_ACCELERATION_MM_S2,
        completion_tolerance_counts: int = COMPLETION_TOLERANCE_COUNTS,
    ) -> None:
        lo, hi = float(travel_mm[0]), float(travel_mm[1])
        if not (math.isfinite(lo) and math.isfinite(hi) and lo < hi):
            raise SettingOutOfRangeError(f"travel_mm must be (low, high), low < high: {travel_mm}")
        if not counts_per_mm > 0:
            raise SettingOutOfRangeError(f"counts_per_mm must be > 0: {counts_per_mm}")
        self.port = port
        self.units = Units(counts_per_mm)
        self._travel_mm = (lo, hi)
        # Limits in counts, rounded inwards, so rounding can never step outside the travel.
        self._lo_counts = math.ceil(lo * counts_per_mm - 1e-6)
        self._hi_counts = math.floor(hi * counts_per_mm + 1e-6)
        self.timeout_s = timeout_s
        self.allow_unhomed = allow_unhomed
        self.updates = updates
        self.max_velocity_mm_s = max_velocity_mm_s
        self.max_acceleration_mm_s2 = max_acceleration_mm_s2
        #: A completed move must end this close to its target (else AptMoveFaultError).
        self.completion_tolerance_counts = int(completion_tolerance_counts)
        self._ser: serial.Serial | None = None
        self._write_lock = threading.RLock()
        self._cond = threading.Condition()
        self._log: collections.deque[tuple[int, Message]] = collections.deque(maxlen=2048)
        self._seq = 0
        self._frames = FrameReader(dests={HOST}, sources={UNIT, 0x11, *range(0x21, 0x2B)})
        self._reader: threading.Thread | None = None
        self._closing = threading.Event()
        self._lost: BaseException | None = None
        self._keepalive: threading.Thread | None = None
        self.keepalive_period_s = KEEPALIVE_PERIOD_S
        self._updates_started = False
        self._info: HwInfo | None = None
        self._bits = StatusBits(0)
        self._vel = VelocityParams(2.0, 1.5)
        self._move_seq: int | None = None  # seq before the outstanding move/home was sent
        # A stop was sent and nobody waited for its MOVE_STOPPED: it may still be on its way,
        # and must not be taken for the end of the next move (see _settle).
        self._stop_unconfirmed = False
        # Reply id -> (log seq of a request that timed out, until when its reply may come).
        self._owed: dict[int, tuple[int, float]] = {}
        self._move_target_mm: float | None = None
        self.device_errors: list[Message] = []  # HW_RESPONSE / HW_RICHRESPONSE seen

    # ---- lifecycle --------------------------------------------------------------------------
    def open(self) -> AptStage:
        try:
            self._ser = open_serial(self.port, BAUD, device="stage", bytesize=8, parity="N",
                                    stopbits=1, rtscts=True, timeout=READ_POLL_S,
                                    write_timeout=self.timeout_s)
            reset_line(self._ser)
        except IO_ERRORS as exc:
            self._ser = None
            raise DeviceLostError(f"stage: cannot open {self.port}: {exc}") from exc
        self._closing.clear()
        self._lost = None
        self._updates_started = False
        self._reader = threading.Thread(target=self._read_loop, name="apt-reader", daemon=True)
        self._reader.start()
        self._keepalive = threading.Thread(target=self._keepalive_loop, name="apt-keepalive",
                                           daemon=True)
        self._keepalive.start()
        try:
            self._send(short(Msg.HW_NO_FLASH_PROGRAMMING))
            reply = self._request(short(Msg.HW_REQ_INFO), Msg.HW_GET_INFO)
            try:
                self._info = HwInfo.unpack(reply.data or b"")
            except ValueError as exc:
                raise AptBadReplyError(f"stage: bad HW_GET_INFO reply: {exc}") from None
            self.enable(True)
            self._vel = self.get_velocity_params()
            if self.updates:
                self._send(short(Msg.HW_START_UPDATEMSGS))
                self._updates_started = True
            self.status  # noqa: B018 - reads homed state into the cache
            self._register_atexit()
            log.info("stage %s serial %s on %s (homed: %s)", self._info.model, self._info.serial,
                     self.port, self.is_homed)
        except BaseException:
            self._shutdown_port()
            raise
        return self

    def close(self) -> None:
        """Stop the stage, stop update messages, disconnect, close the port."""
        if self._ser is None:
            return
        try:
            if self._lost is None:
                self.stop(immediate=True)
                self._send(short(Msg.HW_STOP_UPDATEMSGS))
                self._updates_started = False
                self._send(short(Msg.HW_DISCONNECT))
        finally:
            self._unregister_atexit()
            self._shutdown_port()
        if self._lost is not None:
            raise DeviceLostError(f"stage: connection lost ({self._lost}); it could not be stopped")

    @property
    def is_open(self) -> bool:
        return self._ser is not None

    def _shutdown_port(self) -> None:
        self._closing.set()
        for thread in (self._reader, self._keepalive):
            if thread is not None and thread is not threading.current_thread():
                thread.join(timeout=1.0)
        self._reader = self._keepalive = None
        ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.close()
            except IO_ERRORS:
                pass

    # ---- identity and state -----------------------------------------------------------------
    @property
    def info(self) -> HwInfo:
        if self._info is None:
            raise DeviceError("stage is not open")
        return self._info

    @property
    def identity(self) -> DeviceIdentity:
        info = self.info
        return DeviceIdentity(info.model, str(info.serial), info.firmware_str, self.port)

    @property
    def travel_mm(self) -> tuple[float, float]:
        return self._travel_mm

    @property
    def is_moving(self) -> bool:
        return self.status.is_moving

    @property
    def velocity_mm_s(self) -> float:
        return self._vel.max_velocity_mm_s

    @property
    def dropped_bytes(self) -> int:
        """Garbage bytes skipped while resynchronising."""
        return self._frames.dropped_bytes

    def identify(self) -> None:
        """Flash the cube's front-panel LED."""
        self._send(short(Msg.MOD_IDENTIFY, CHAN1))

    def enable(self, enabled: bool = True) -> None:
        self._send(short(Msg.MOD_SET_CHANENABLESTATE, CHAN1, ENABLE if enabled else DISABLE))

    def is_enabled(self) -> bool:
        reply = self._request(short(Msg.MOD_REQ_CHANENABLESTATE, CHAN1),
                              Msg.MOD_GET_CHANENABLESTATE)
        return reply.param2 == ENABLE

    @property
    def position_mm(self) -> float:
        """Position counter in mm (fresh from the device)."""
        reply = self._request(short(Msg.MOT_REQ_POSCOUNTER, CHAN1), Msg.MOT_GET_POSCOUNTER)
        return self._mm_checked(unpack_position(reply.data or bytes(6))[1], "MOT_GET_POSCOUNTER")

    @property
    def status(self) -> AptStatus:
        """Position, velocity word and status bits (fresh from the device)."""
        reply = self._request(short(Msg.MOT_REQ_DCSTATUSUPDATE, CHAN1),
                              Msg.MOT_GET_DCSTATUSUPDATE)
        return self._status_from(reply)

    @property
    def status_bits(self) -> StatusBits:
        reply = self._request(short(Msg.MOT_REQ_STATUSBITS, CHAN1), Msg.MOT_GET_STATUSBITS)
        return unpack_statusbits(reply.data or bytes(6))

    @property
    def is_homed(self) -> bool:
        """Homed flag from the latest status the cube sent (updates keep it current)."""
        return bool(self._bits & StatusBits.HOMED)

    def get_velocity_params(self) -> VelocityParams:
        reply = self._request(short(Msg.MOT_REQ_VELPARAMS, CHAN1), Msg.MOT_GET_VELPARAMS)
        raw = VelParamsRaw.unpack(reply.data or bytes(14))
        if raw.max_vel_raw <= 0 or raw.accel_raw <= 0:
            raise AptBadReplyError(f"stage: impossible velocity parameters {raw}")
        self._vel = VelocityParams(self.units.vel_mm_s(raw.max_vel_raw),
                                   self.units.acc_mm_s2(raw.accel_raw))
        return self._vel

    def set_velocity_params(self, max_velocity_mm_s: float, acceleration_mm_s2: float) -> None:
        if not 0 < max_velocity_mm_s <= self.max_velocity_mm_s:
            raise SettingOutOfRangeError(
                f"stage velocity {max_velocity_mm_s} mm/s outside (0, {self.max_velocity_mm_s}]")
        if not 0 < acceleration_mm_s2 <= self.max_acceleration_mm_s2:
            raise SettingOutOfRangeError(f"stage acceleration {acceleration_mm_s2} mm/s^2 "
                                         f"outside (0, {self.max_acceleration_mm_s2}]")
        raw = VelParamsRaw(self.units.acc_raw(acceleration_mm_s2),
                           self.units.vel_raw(max_velocity_mm_s))
        self._send(long(Msg.MOT_SET_VELPARAMS, raw.pack()))
        self._vel = VelocityParams(max_velocity_mm_s, acceleration_mm_s2)

    def _do_set_velocity_mm_s(self, velocity_mm_s: float) -> None:
        """Keeps the controller's acceleration."""
        self.set_velocity_params(velocity_mm_s, self.get_velocity_params().acceleration_mm_s2)

    # ---- motion -----------------------------------------------------------------------------
    def get_home_params(self) -> HomeParams:
        """The controller's homing move (MOT_REQ_HOMEPARAMS): its velocity and offset."""
        reply = self._request(short(Msg.MOT_REQ_HOMEPARAMS, CHAN1), Msg.MOT_GET_HOMEPARAMS)
        raw = HomeParamsRaw.unpack(reply.data or bytes(14))
        if raw.velocity_raw <= 0:
            raise AptBadReplyError(f"stage: impossible home parameters {raw}")
        return HomeParams(self.units.vel_mm_s(raw.velocity_raw),
                          self.units.mm(raw.offset_counts), raw.direction, raw.limit_switch)

    def home_timeout_s(self, home: HomeParams) -> float:
        """Seconds homing may take at the controller's own home velocity: unhomed, the
        carriage may be anywhere, so two spans (out, and back off the switch), plus half."""
        span = self.travel_mm[1] - self.travel_mm[0]
        v, a = home.velocity_mm_s, self._vel.acceleration_mm_s2
        return 1.5 * ((2 * span + abs(home.offset_mm)) / max(v, 1e-9) + v / max(a, 1e-9))

    def _do_home(self, timeout_s: float | None) -> None:
        """Home (drive to the reverse limit and zero the counter) and wait until homed; the
        default timeout follows the controller's home velocity, read first."""
        if timeout_s is None:
            timeout_s = self.home_timeout_s(self.get_home_params()) + self.timeout_s
        self._settle()
        seq = self._send(short(Msg.MOT_MOVE_HOME, CHAN1))
        self._move_seq, self._move_target_mm = seq, self.travel_mm[0]
        self.wait_for_move(timeout_s)

    def _do_move_to_mm(self, position_mm: float, *, wait: bool,
                       timeout_s: float | None) -> None:
        """Absolute move; limits (in counts, after rounding) and homing checked first."""
        log.debug("stage: move to %.4f mm", position_mm)
        counts = self._target_counts(position_mm)
        self._check_homed()
        self._settle()
        seq = self._send(long(Msg.MOT_MOVE_ABSOLUTE, pack_position(counts)))
        self._move_seq, self._move_target_mm = seq, position_mm
        if wait:
            # Default timeout assumes the longest possible move: the start may be unknown.
            self.wait_for_move(timeout_s)

    def move_by_mm(self, distance_mm: float, *, wait: bool = True,
                   timeout_s: float | None = None) -> None:
        """Relative move from the current position; the end point is limit-checked first."""
        if not (isinstance(distance_mm, int | float) and math.isfinite(distance_mm)):
            raise SettingOutOfRangeError(f"stage: distance {distance_mm!r} is not finite")
        if self._move_seq is not None:
            raise DeviceError("stage: a move is still in progress; wait for it or stop first")
        self._check_homed()
        self._settle()
        reply = self._request(short(Msg.MOT_REQ_POSCOUNTER, CHAN1), Msg.MOT_GET_POSCOUNTER)
        start_counts = unpack_position(reply.data or bytes(6))[1]
        self._mm_checked(start_counts, "MOT_GET_POSCOUNTER")
        delta_counts = self.units.counts(distance_mm)
        self._check_counts(start_counts + delta_counts, self.units.mm(start_counts) + distance_mm)
        seq = self._send(long(Msg.MOT_MOVE_RELATIVE, pack_position(delta_counts)))
        self._move_seq = seq
        self._move_target_mm = self.units.mm(start_counts + delta_counts)
        if wait:
            self.wait_for_move(timeout_s)

    def wait_for_move(self, timeout_s: float | None = None) -> AptStatus | None:
        """Wait for the outstanding move/home to end; raise unless it completed normally."""
        seq = self._move_seq
        if seq is None:
            return None
        timeout = timeout_s if timeout_s is not None else self._travel_timeout(
            self.travel_mm[1] - self.travel_mm[0])
        try:
            msg = self._wait_for(lambda m: m.msg_id in _END_OF_MOVE_IDS, seq, timeout,
                                 "move/home completion")
        except DeviceLostError as exc:
            # Unplugged mid-move: no stop can reach the controller, which (on its own supply)
            # finishes the move. Say so, and where it is going.
            self._move_seq = None
            target = self._move_target_mm
            to = "its target" if target is None else f"{target:g} mm"
            raise DeviceLostError(
                f"stage lost mid-move to {to} ({self._lost}): it could not be stopped and may "
                "still be moving; stop it at its controller") from exc
        except BaseException:
            # Timeout, Ctrl-C: never leave the actuator running.
            self._move_seq = None
            self._safe_stop()
            raise
        self._move_seq = None
        if msg.msg_id == Msg.MOT_MOVE_HOMED:
            self._bits |= StatusBits.HOMED
            return None
        status = self._status_from(msg)
        if msg.msg_id == Msg.MOT_MOVE_STOPPED:
            if status.bits & (StatusBits.FWD_HW_LIMIT | StatusBits.REV_HW_LIMIT):
                raise AptLimitSwitchError(
                    f"stage: limit switch hit at {status.position_mm:.4f} mm before reaching "
                    f"{self._move_target_mm} mm (status {status.bits!r})")
            raise AptMoveInterruptedError(
                f"stage: move stopped at {status.position_mm:.4f} mm before reaching "
                f"{self._move_target_mm} mm")
        status = self._settled(status)
        self._check_completed(status)
        return status

    def _settled(self, status: AptStatus) -> AptStatus:
        """A MOVE_COMPLETED off target (no fault bit) may come while the servo still settles:
        re-read the position up to :data:`SETTLE_READS` times before calling it a fault."""
        target_mm = self._move_target_mm
        if target_mm is None or status.bits & FAULT_BITS:
            return status
        for _ in range(SETTLE_READS):
            off = self.units.counts(status.position_mm) - self.units.counts(target_mm)
            if abs(off) <= self.completion_tolerance_counts:
                break
            time.sleep(SETTLE_WAIT_S)
            status = AptStatus(self.position_mm, status.velocity_raw, status.bits)
        return status

    def _check_completed(self, status: AptStatus) -> None:
        """A MOVE_COMPLETED is success only if it says so: no fault bit and the carriage
        within a few counts of the target. A limit switch pressed is named when the carriage
        is also off target (a real switch is pressed over a zone at each end of travel, so a
        move to near the end may finish on target with it pressed)."""
        target_mm = self._move_target_mm
        problems: list[str] = []
        faults = status.bits & FAULT_BITS
        if faults:
            problems.append(f"fault {faults.name}")
        if target_mm is not None:
            off = self.units.counts(status.position_mm) - self.units.counts(target_mm)
            if abs(off) > self.completion_tolerance_counts:
                problems.append(f"{off:+d} counts from the target after {SETTLE_READS} position "
                                f"re-reads over {SETTLE_READS * SETTLE_WAIT_S:g} s")
                if status.at_forward_limit:
                    problems.append("forward limit switch engaged")
                if status.at_reverse_limit:
                    problems.append("reverse limit switch engaged")
        if problems:
            raise AptMoveFaultError(
                f"stage: move to {target_mm} mm reported complete at {status.position_mm:.4f} mm "
                f"but {', '.join(problems)} (status {status.bits!r})")

    def _do_stop(self, *, immediate: bool, wait: bool, timeout_s: float | None) -> None:
        """Stop (immediate, or profiled at the configured deceleration); wait for MOVE_STOPPED."""
        self._stop_unconfirmed = True
        seq = self._send(short(Msg.MOT_MOVE_STOP, CHAN1,
                               STOP_IMMEDIATE if immediate else STOP_PROFILED))
        self._move_seq = None  # a waiter in another thread still sees MOVE_STOPPED and raises
        if not wait:
            return
        try:
            self._wait_for(lambda m: m.msg_id == Msg.MOT_MOVE_STOPPED, seq,
                           timeout_s if timeout_s is not None else self._stop_timeout_s(),
                           "MOT_MOVE_STOP")
        except AptNoReplyError:
            # Firmware may stay silent when told to stop while idle: trust the status bits.
            if self.status.is_moving:
                raise
        self._stop_unconfirmed = False

    def _stop_timeout_s(self) -> float:
        """Seconds a stop may take: a reply, and twice a full deceleration."""
        decel_s = self._vel.max_velocity_mm_s / max(self._vel.acceleration_mm_s2, 1e-9)
        return self.timeout_s + 2 * decel_s

    def _settle(self) -> None:
        """Before a move or homing: after a stop nobody waited for, wait until the stage
        stands still. The cube answers in order, so its MOVE_STOPPED (if it sends one) is
        then logged before the next command is sent and is never taken for that command's
        end (it used to end the next move at once, leaving the carriage running)."""
        if not self._stop_unconfirmed:
            return
        deadline = time.monotonic() + self._stop_timeout_s()
        while self.status.is_moving:  # a round trip each: answers come after earlier news
            if time.monotonic() > deadline:
                raise AptMoveInterruptedError("stage: still moving after a stop; not sending "
                                              "the next move")
            time.sleep(0.02)
        self._stop_unconfirmed = False

    def _safe_stop(self) -> None:
        """Best-effort immediate stop that never raises (used on error paths)."""
        try:
            if self._ser is not None and self._lost is None:
                self._stop_unconfirmed = True
                self._send(short(Msg.MOT_MOVE_STOP, CHAN1, STOP_IMMEDIATE))
        except DeviceError:
            pass

    # ---- checks -----------------------------------------------------------------------------
    def _target_counts(self, position_mm: float) -> int:
        if not (isinstance(position_mm, int | float) and math.isfinite(position_mm)):
            raise SettingOutOfRangeError(f"stage: target {position_mm!r} is not finite")
        counts = self.units.counts(position_mm)
        self._check_counts(counts, position_mm)
        return counts

    def _check_counts(self, counts: int, position_mm: float) -> None:
        if not self._lo_counts <= counts <= self._hi_counts:
            lo, hi = self.travel_mm
            raise SafetyLimitError(
                f"stage: target {position_mm:.4f} mm outside travel [{lo}, {hi}] mm; nothing sent")

    def _check_homed(self) -> None:
        if self._ser is None:
            raise DeviceError("stage is not open")
        if not self.allow_unhomed and not self.is_homed:
            raise AptNotHomedError("stage: not homed; home it first (or allow_unhomed=True); "
                                   "nothing sent")

    def _mm_checked(self, counts: int, what: str) -> float:
        lo, hi = self.travel_mm
        span = hi - lo
        mm = self.units.mm(counts)
        # The counter is relative to the power-up position until homing, so allow one span.
        if not lo - span <= mm <= hi + span:
            raise AptBadReplyError(f"stage: {what} reports {counts} counts ({mm:.3f} mm), "
                                   f"impossible for travel [{lo}, {hi}] mm")
        return mm

    def _status_from(self, msg: Message) -> AptStatus:
        try:
            st = DcStatus.unpack(msg.data or b"")
        except Exception:  # struct.error on a short payload
            raise AptBadReplyError(f"stage: short status payload in {msg.name}") from None
        return AptStatus(self._mm_checked(st.position_counts, msg.name), st.velocity_raw,
                         st.bits)

    def _travel_timeout(self, distance_mm: float) -> float:
        v, a = self._vel.max_velocity_mm_s, self._vel.acceleration_mm_s2
        travel_s = distance_mm / max(v, 1e-9) + v / max(a, 1e-9)
        return 1.5 * travel_s + self.timeout_s

    # ---- wire -------------------------------------------------------------------------------
    def _send(self, msg: Message) -> int:
        """Write one message; return the log sequence number current at send time."""
        ser = self._ser
        if ser is None:
            raise DeviceError("stage is not open")
        if self._lost is not None:
            raise DeviceLostError(f"stage: connection lost ({self._lost})")
        with self._cond:
            seq = self._seq
        with self._write_lock:
            try:
                ser.write(msg.pack())
            except IO_ERRORS as exc:
                raise DeviceLostError(f"stage lost while sending {msg.name}: {exc}") from exc
        return seq

    def _request(self, msg: Message, reply_id: int) -> Message:
        owed = self._owed.pop(reply_id, None)
        if owed is not None:
            # A request of this kind timed out lately: its reply may still come, and must
            # not be taken for this one's - so it is waited for (until a timeout after the
            # first) before this request is sent.
            after_seq, until = owed
            with contextlib.suppress(AptNoReplyError):
                self._wait_for(lambda m: m.msg_id == reply_id, after_seq,
                               max(until - time.monotonic(), 0.0), f"a late {msg.name} reply")
        seq = self._send(msg)
        try:
            return self._wait_for(lambda m: m.msg_id == reply_id, seq, self.timeout_s,
                                  msg.name)
        except AptNoReplyError:
            self._owed[reply_id] = (seq, time.monotonic() + self.timeout_s)
            raise

    def _wait_for(self, match: Callable[[Message], bool], after_seq: int, timeout_s: float,
                  what: str) -> Message:
        deadline = time.monotonic() + timeout_s
        with self._cond:
            while True:
                for seq, msg in self._log:
                    if seq > after_seq and match(msg):
                        return msg
                if self._lost is not None:
                    raise DeviceLostError(f"stage lost while waiting for {what}: {self._lost}")
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise AptNoReplyError(f"stage: no reply to {what} within {timeout_s:.3g} s")
                self._cond.wait(min(remaining, 0.1))

    def _read_loop(self) -> None:
        ser = self._ser
        while ser is not None and not self._closing.is_set():
            try:
                data = ser.read(max(1, ser.in_waiting))
            except (*IO_ERRORS, TypeError, AttributeError) as exc:
                if not self._closing.is_set():
                    with self._cond:
                        self._lost = exc
                        self._cond.notify_all()
                return
            if data:
                for msg in self._frames.feed(data):
                    self._dispatch(msg)

    def _dispatch(self, msg: Message) -> None:
        with self._cond:
            self._seq += 1
            self._log.append((self._seq, msg))
            if msg.msg_id in _STATUS_IDS and msg.data and len(msg.data) >= 14:
                self._bits = DcStatus.unpack(msg.data).bits
            elif msg.msg_id == Msg.MOT_MOVE_HOMED:
                self._bits |= StatusBits.HOMED
            elif msg.msg_id in (Msg.HW_RESPONSE, Msg.HW_RICHRESPONSE):
                self.device_errors.append(msg)
            self._cond.notify_all()

    def _keepalive_loop(self) -> None:
        """0x0492 every ``keepalive_period_s`` while the port is open (updates or not)."""
        while not self._closing.wait(self.keepalive_period_s):
            if self._lost is not None:
                return
            try:
                self._send(short(Msg.MOT_ACK_DCSTATUSUPDATE))
            except DeviceError:
                return  # the reader notices a lost link on its next read
