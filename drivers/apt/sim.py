"""Simulated Thorlabs KDC101 + Z8 actuator speaking APT on a pseudo-terminal.

Behaviour follows shared/docs/device-protocols.md section C: moves and homes are not
acknowledged, completion (0x0464 / 0x0444) arrives only after the trapezoidal travel time at
the configured velocity and acceleration, status updates (0x0491) flow every 100 ms after
HW_START_UPDATEMSGS; without a keep-alive (0x0492) the cube stops sending unsolicited messages
after 50 of them - updates and move completions both count - until the next one (USB), limit
switches sit at the physical ends of travel (a move into one ends in MOVE_STOPPED with the
limit bit set). The position counter reads 0 at power-up wherever the carriage is; homing
drives to the reverse limit and zeroes it there.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace

from benchlab.drivers.apt.protocol import (
    CHAN1,
    DISABLE,
    ENABLE,
    HOST,
    STOP_IMMEDIATE,
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
    pack_statusbits,
    short,
    unpack_position,
)
from benchlab.drivers.simulation.dispatch import CommandTable
from benchlab.drivers.simulation.pty_device import Clock, PtyDevice

UPDATE_PERIOD_S = 0.1  # 0x0491 period after START_UPDATEMSGS (simulated time)
UPDATE_MIN_WALL_S = 0.1  # ...but never faster than this in wall time (fast-time mode)
UNACKED_UPDATE_LIMIT = 50
_KEEPALIVE_ID = int(Msg.MOT_ACK_DCSTATUSUPDATE).to_bytes(2, "little")
_EPS_MM = 1e-6


@dataclass
class AptFaults:
    """Fault injection; counters are one-shot and decrement as they fire."""

    no_reply: int = 0  # silently ignore the next N host messages
    # The next N host messages are acted on at once but their replies go out late_reply_s
    # (wall seconds, like the host's timeout) later; other traffic is not held up.
    late_reply: int = 0
    late_reply_s: float = 0.0
    garbage: bytes | None = None  # bytes emitted just before the next reply
    drop_on: int | None = None  # message id that makes the link drop when it arrives
    limit_at_mm: float | None = None  # a limit switch trips here during the next move across it
    # The USB link drops (cable pulled) as the next move passes here; like a real cube on its
    # own supply, the stage finishes the profiled move with nobody listening.
    drop_at_mm: float | None = None
    out_of_range: int = 0  # next N position-bearing replies carry an impossible position
    # The next MOVE_COMPLETED carries these extra status bits (e.g. POSITION_ERROR) ...
    completion_bits: StatusBits = StatusBits(0)
    # ... / the next move ends this far short of its target and still reports MOVE_COMPLETED
    # (the servo gave up inside its window, as a stalled or overloaded actuator can).
    stop_short_mm: float = 0.0
    # The next MOVE_COMPLETED goes out while the carriage is still this far short; it reaches
    # the target after ``settle_reads`` more position requests (the servo settling).
    settle_short_mm: float = 0.0
    settle_reads: int = 0
    # Lasting behaviours (not consumed), first-day failures of a real stage:
    #: The reverse limit switch never trips: homing drives into the end stop and never
    #: reports MOVE_HOMED (the carriage stands there, HOMING set, until stopped).
    home_never: bool = False
    #: Every completed move parks this many counts past its target (a servo that settles
    #: inside a wider window than the host assumed).
    park_off_counts: int = 0


class _Profile:
    """Trapezoidal (or triangular) motion from ``start_mm`` to ``end_mm``."""

    def __init__(self, start_mm: float, end_mm: float, v_mm_s: float, a_mm_s2: float,
                 t0_s: float) -> None:
        self.start_mm, self.end_mm, self.t0_s = start_mm, end_mm, t0_s
        self.direction = 1.0 if end_mm >= start_mm else -1.0
        d = abs(end_mm - start_mm)
        self.a = a_mm_s2
        if d >= v_mm_s * v_mm_s / a_mm_s2:  # reaches cruise velocity
            self.v = v_mm_s
            self.t_acc = v_mm_s / a_mm_s2
            self.duration_s = d / v_mm_s + self.t_acc
        else:
            self.t_acc = math.sqrt(d / a_mm_s2)
            self.v = a_mm_s2 * self.t_acc
            self.duration_s = 2 * self.t_acc
        self.distance = d

    def _dist_speed(self, t: float) -> tuple[float, float]:
        t = min(max(t, 0.0), self.duration_s)
        t_dec = self.duration_s - self.t_acc
        if t < self.t_acc:
            return 0.5 * self.a * t * t, self.a * t
        if t < t_dec:
            return 0.5 * self.a * self.t_acc**2 + self.v * (t - self.t_acc), self.v
        rem = self.duration_s - t
        return self.distance - 0.5 * self.a * rem * rem, self.a * rem

    def position(self, now_s: float) -> float:
        return self.start_mm + self.direction * self._dist_speed(now_s - self.t0_s)[0]

    def speed(self, now_s: float) -> float:
        return self._dist_speed(now_s - self.t0_s)[1]

    def done(self, now_s: float) -> bool:
        return now_s - self.t0_s >= self.duration_s


class _Decel:
    """Constant deceleration from ``speed_mm_s`` to rest (a profiled stop)."""

    def __init__(self, start_mm: float, speed_mm_s: float, direction: float, a_mm_s2: float,
                 t0_s: float) -> None:
        self.start_mm, self.v0, self.direction, self.a, self.t0_s = (
            start_mm, speed_mm_s, direction, a_mm_s2, t0_s)
        self.duration_s = speed_mm_s / a_mm_s2
        self.end_mm = start_mm + direction * speed_mm_s * speed_mm_s / (2 * a_mm_s2)

    def _t(self, now_s: float) -> float:
        return min(max(now_s - self.t0_s, 0.0), self.duration_s)

    def position(self, now_s: float) -> float:
        t = self._t(now_s)
        return self.start_mm + self.direction * (self.v0 * t - 0.5 * self.a * t * t)

    def speed(self, now_s: float) -> float:
        return self.v0 - self.a * self._t(now_s)

    def done(self, now_s: float) -> bool:
        return now_s - self.t0_s >= self.duration_s


@dataclass
class _Motion:
    profile: _Profile | _Decel
    kind: str  # "move" | "home" | "stop"
    limit_bits: StatusBits  # set when the profile ends on a limit switch


class SimulatedAptStage(PtyDevice):
    """A KDC101 cube driving a Z8-series actuator (an MTS50-Z8 with ``travel_mm=(0, 50)``)."""

    name = "apt-sim"
    #: Message id -> handler taking ``(message, now_s)``.
    commands: CommandTable[int] = CommandTable()

    def __init__(
        self,
        *,
        counts_per_mm: float = Z8_COUNTS_PER_MM,
        travel_mm: tuple[float, float] = (0.0, 25.0),
        velocity_mm_s: float = 2.0,
        clock: Clock | None = None,
        time_scale: float = 1.0,
        serial: int = 27000001,
        acceleration_mm_s2: float = 1.5,
        initial_position_mm: float = 0.0,
        homed: bool = False,
        model: str = "KDC101",
        firmware: tuple[int, int, int] = (3, 0, 10),
        home_velocity_mm_s: float | None = None,
    ) -> None:
        super().__init__(clock=clock, time_scale=time_scale)
        #: The controller's home velocity (MOT_GET_HOMEPARAMS); default: the move velocity.
        self.home_velocity_mm_s = home_velocity_mm_s
        self.units = Units(counts_per_mm)
        self.travel_mm = (float(travel_mm[0]), float(travel_mm[1]))
        self.velocity_mm_s = velocity_mm_s
        self.acceleration_mm_s2 = acceleration_mm_s2
        self.serial = serial
        self.model = model
        self.firmware = firmware
        self.faults = AptFaults()
        self.enabled = False
        self.homed = homed
        self.identify_count = 0
        self._pos_mm = float(initial_position_mm)
        # Physical position (mm) where the counter reads 0: power-up position until homed.
        self._zero_mm = self.travel_mm[0] if homed else float(initial_position_mm)
        self._motion: _Motion | None = None
        self._held_limit_bits = StatusBits(0)
        self._updates = False
        self.update_min_wall_s = UPDATE_MIN_WALL_S
        self._unacked = 0
        #: Unsolicited messages not sent because the host sent no keep-alive.
        self.suppressed_messages = 0
        self._settling: tuple[float, int] | None = None  # (target mm, reads left)
        self._last_update_sim_s = -math.inf
        self._last_update_wall_s = -math.inf
        self._reader = FrameReader(dests={UNIT}, sources={HOST})
        self._late_out: bytearray | None = None  # replies of the message being answered late
        self._late: list[tuple[float, bytes]] = []  # (send at, monotonic s; bytes) pending

    # ---- physical state ---------------------------------------------------------------------
    @property
    def position_mm(self) -> float:
        """Physical carriage position, mm from the reverse limit switch."""
        with self.lock:
            self._advance(self.clock())
            return self._pos_mm

    @property
    def moving(self) -> bool:
        with self.lock:
            self._advance(self.clock())
            return self._motion is not None

    @property
    def updates_flowing(self) -> bool:
        with self.lock:
            return self._updates and self._unacked < UNACKED_UPDATE_LIMIT

    def host_messages(self, *, keepalives: bool = False) -> list[bytes]:
        """Every frame the host sent, in order; keep-alives (sent on the host's timer, so at
        no fixed place in a sequence) only with ``keepalives``."""
        return [b for who, b in self.transcript
                if who == "host" and (keepalives or b[:2] != _KEEPALIVE_ID)]

    def _unsolicited(self, msg_id: int, *, long_data: bytes | None = None, p1: int = 0) -> None:
        """Send a status-type message the host did not ask for, unless 50 went unacknowledged."""
        if self._unacked >= UNACKED_UPDATE_LIMIT:
            self.suppressed_messages += 1
            return
        self._unacked += 1
        if long_data is None:
            self._reply_short(msg_id, p1)
        else:
            self._reply_long(msg_id, long_data)

    # ---- protocol ---------------------------------------------------------------------------
    def on_bytes(self, data: bytes) -> None:
        for msg in self._reader.feed(data):
            self.transcript.append(("host", msg.pack() if msg.data is None else
                                    Message(msg.msg_id, 0, 0, msg.data, UNIT, HOST).pack()))
            if not self.connected:
                return
            if self.faults.drop_on is not None and msg.msg_id == self.faults.drop_on:
                self.faults.drop_on = None
                self.drop_connection()
                return
            if self.faults.no_reply > 0:
                self.faults.no_reply -= 1
                continue
            if self.faults.late_reply > 0:
                self.faults.late_reply -= 1
                self._late_out = bytearray()
                try:
                    self._handle(msg)
                finally:
                    out, self._late_out = bytes(self._late_out), None
                    if out:
                        self._late.append((time.monotonic() + self.faults.late_reply_s, out))
                continue
            self._handle(msg)

    def _send(self, msg: Message) -> None:
        if self.faults.garbage is not None:
            junk, self.faults.garbage = self.faults.garbage, None
            self._out(junk)
        self._out(msg.pack())

    def _out(self, data: bytes) -> None:
        if self._late_out is not None:
            self._late_out += data
        else:
            self.write(data)

    def _reply_short(self, msg_id: int, p1: int = 0, p2: int = 0) -> None:
        self._send(short(msg_id, p1, p2, dest=HOST, source=UNIT))

    def _reply_long(self, msg_id: int, data: bytes) -> None:
        self._send(long(msg_id, data, dest=HOST, source=UNIT))

    def _handle(self, msg: Message) -> None:
        now = self.clock()
        self._advance(now)
        handler = self.commands.handler(self, msg.msg_id)
        if handler is not None:
            handler(msg, now)
        # HW_DISCONNECT, HW_NO_FLASH_PROGRAMMING and unknown ids: no reply, as on hardware.

    @commands.handles(Msg.MOD_IDENTIFY)
    def _identify(self, msg: Message, now: float) -> None:
        self.identify_count += 1

    @commands.handles(Msg.MOD_SET_CHANENABLESTATE)
    def _set_enable(self, msg: Message, now: float) -> None:
        if msg.param2 in (ENABLE, DISABLE):
            self.enabled = msg.param2 == ENABLE
            if not self.enabled:
                self._halt(now)  # output no longer driven

    @commands.handles(Msg.MOD_REQ_CHANENABLESTATE)
    def _req_enable(self, msg: Message, now: float) -> None:
        state = ENABLE if self.enabled else DISABLE
        self._reply_short(Msg.MOD_GET_CHANENABLESTATE, CHAN1, state)

    @commands.handles(Msg.HW_REQ_INFO)
    def _req_info(self, msg: Message, now: float) -> None:
        stage_id = 8 if self.travel_mm[1] - self.travel_mm[0] > 25 + _EPS_MM else 9
        info = HwInfo(self.serial, self.model, 16, self.firmware, 1, 0, 1, stage_id)
        self._reply_long(Msg.HW_GET_INFO, info.pack())

    @commands.handles(Msg.HW_START_UPDATEMSGS)
    def _start_updates(self, msg: Message, now: float) -> None:
        self._updates, self._unacked = True, 0

    @commands.handles(Msg.HW_STOP_UPDATEMSGS)
    def _stop_updates(self, msg: Message, now: float) -> None:
        self._updates = False

    @commands.handles(Msg.MOT_ACK_DCSTATUSUPDATE)
    def _ack_status(self, msg: Message, now: float) -> None:
        self._unacked = 0

    @commands.handles(Msg.MOT_REQ_POSCOUNTER)
    def _req_position(self, msg: Message, now: float) -> None:
        self._reply_long(Msg.MOT_GET_POSCOUNTER, pack_position(self._counter_reply()))

    @commands.handles(Msg.MOT_SET_POSCOUNTER)
    def _set_position(self, msg: Message, now: float) -> None:
        if msg.data is not None:
            counts = unpack_position(msg.data)[1]
            self._zero_mm = self._pos_mm - self.units.mm(counts)

    @commands.handles(Msg.MOT_REQ_STATUSBITS)
    def _req_statusbits(self, msg: Message, now: float) -> None:
        self._reply_long(Msg.MOT_GET_STATUSBITS, pack_statusbits(self._bits(now)))

    @commands.handles(Msg.MOT_REQ_DCSTATUSUPDATE)
    def _req_status(self, msg: Message, now: float) -> None:
        self._reply_long(Msg.MOT_GET_DCSTATUSUPDATE, self._status(now).pack())

    @commands.handles(Msg.MOT_REQ_VELPARAMS)
    def _req_velocity(self, msg: Message, now: float) -> None:
        raw = VelParamsRaw(self.units.acc_raw(self.acceleration_mm_s2),
                           self.units.vel_raw(self.velocity_mm_s))
        self._reply_long(Msg.MOT_GET_VELPARAMS, raw.pack())

    @commands.handles(Msg.MOT_SET_VELPARAMS)
    def _set_velocity(self, msg: Message, now: float) -> None:
        if msg.data is None:
            return
        raw = VelParamsRaw.unpack(msg.data)
        if raw.max_vel_raw > 0 and raw.accel_raw > 0:
            self.velocity_mm_s = self.units.vel_mm_s(raw.max_vel_raw)
            self.acceleration_mm_s2 = self.units.acc_mm_s2(raw.accel_raw)

    @commands.handles(Msg.MOT_REQ_HOMEPARAMS)
    def _req_home_params(self, msg: Message, now: float) -> None:
        raw = HomeParamsRaw(direction=2, limit_switch=1,  # reverse, to the reverse switch
                            velocity_raw=self.units.vel_raw(self._home_velocity()),
                            offset_counts=0)
        self._reply_long(Msg.MOT_GET_HOMEPARAMS, raw.pack())

    def _home_velocity(self) -> float:
        return self.home_velocity_mm_s or self.velocity_mm_s

    @commands.handles(Msg.MOT_MOVE_HOME)
    def _move_home(self, msg: Message, now: float) -> None:
        self._start(now, self.travel_mm[0] - 1.0, "home")  # runs into the reverse switch

    @commands.handles(Msg.MOT_MOVE_ABSOLUTE)
    def _move_absolute(self, msg: Message, now: float) -> None:
        if msg.data is not None:
            target = self._zero_mm + self.units.mm(unpack_position(msg.data)[1])
            self._start(now, target, "move")

    @commands.handles(Msg.MOT_MOVE_RELATIVE)
    def _move_relative(self, msg: Message, now: float) -> None:
        if msg.data is not None:
            self._start(now, self._pos_mm + self.units.mm(unpack_position(msg.data)[1]), "move")

    @commands.handles(Msg.MOT_MOVE_STOP)
    def _move_stop(self, msg: Message, now: float) -> None:
        self._stop_motion(now, immediate=msg.param2 == STOP_IMMEDIATE)

    # ---- motion -----------------------------------------------------------------------------
    def _start(self, now: float, target_mm: float, kind: str) -> None:
        if not self.enabled:
            return  # a disabled channel does not move
        lo, hi = self.travel_mm
        end, bits = target_mm, StatusBits(0)
        if end < lo:
            end, bits = lo, StatusBits.REV_HW_LIMIT
        elif end > hi:
            end, bits = hi, StatusBits.FWD_HW_LIMIT
        trip = self.faults.limit_at_mm
        if kind == "move" and trip is not None and min(self._pos_mm, end) < trip < max(
            self._pos_mm, end
        ):
            self.faults.limit_at_mm = None
            bits = StatusBits.FWD_HW_LIMIT if end > self._pos_mm else StatusBits.REV_HW_LIMIT
            end = trip
        elif kind == "move" and self.faults.stop_short_mm:
            short_mm, self.faults.stop_short_mm = self.faults.stop_short_mm, 0.0
            end -= short_mm if end >= self._pos_mm else -short_mm
        self._held_limit_bits = StatusBits(0)
        if kind == "home":
            self.homed = False
        if kind == "move" and self.faults.park_off_counts:
            end += self.units.mm(self.faults.park_off_counts) * (1 if end >= self._pos_mm else -1)
        velocity = self._home_velocity() if kind == "home" else self.velocity_mm_s
        profile = _Profile(self._pos_mm, end, velocity, self.acceleration_mm_s2, now)
        self._motion = _Motion(profile, kind, bits)

    def _stop_motion(self, now: float, *, immediate: bool) -> None:
        motion = self._motion
        if motion is None or immediate:
            self._halt(now)
            return
        # Profiled stop: decelerate to rest at the configured acceleration.
        decel = _Decel(motion.profile.position(now), motion.profile.speed(now),
                       motion.profile.direction, self.acceleration_mm_s2, now)
        self._motion = _Motion(decel, "stop", StatusBits(0))

    def _halt(self, now: float) -> None:
        if self._motion is not None:
            self._pos_mm = self._motion.profile.position(now)
            self._motion = None
        self._reply_long(Msg.MOT_MOVE_STOPPED, self._status(now).pack())

    def _advance(self, now: float) -> None:
        motion = self._motion
        if motion is None:
            return
        was_mm, self._pos_mm = self._pos_mm, motion.profile.position(now)
        drop = self.faults.drop_at_mm
        if (drop is not None and motion.kind == "move"
                and min(was_mm, self._pos_mm) <= drop <= max(was_mm, self._pos_mm)):
            self.faults.drop_at_mm = None
            self.drop_connection()
        if not motion.profile.done(now):
            return
        if motion.kind == "home" and self.faults.home_never:
            self._pos_mm = motion.profile.end_mm  # at the end stop, the switch silent: no
            return  # MOVE_HOMED; the motion stays "under way" (HOMING) until a stop
        self._pos_mm = motion.profile.end_mm
        self._motion = None
        if motion.kind == "home":
            self._zero_mm, self.homed = self._pos_mm, True
            self._unsolicited(Msg.MOT_MOVE_HOMED, p1=CHAN1)
        elif motion.limit_bits or motion.kind == "stop":
            self._held_limit_bits = motion.limit_bits
            self._unsolicited(Msg.MOT_MOVE_STOPPED, long_data=self._status(now).pack())
        else:
            f = self.faults
            settling = None
            if f.settle_short_mm:
                settling = (self._pos_mm, f.settle_reads)
                self._pos_mm -= f.settle_short_mm if motion.profile.direction > 0 else (
                    -f.settle_short_mm)
                f.settle_short_mm, f.settle_reads = 0.0, 0
            status = self._status(now)
            self._settling = settling
            extra, f.completion_bits = f.completion_bits, StatusBits(0)
            self._unsolicited(Msg.MOT_MOVE_COMPLETED,
                              long_data=replace(status, bits=status.bits | extra).pack())

    def on_tick(self, now_s: float) -> None:
        while self._late and time.monotonic() >= self._late[0][0]:
            self.write(self._late.pop(0)[1])
        self._advance(now_s)
        if not self._updates or self._unacked >= UNACKED_UPDATE_LIMIT:
            return
        wall = time.monotonic()
        if (now_s - self._last_update_sim_s >= UPDATE_PERIOD_S
                and wall - self._last_update_wall_s >= self.update_min_wall_s):
            self._last_update_sim_s, self._last_update_wall_s = now_s, wall
            self._unsolicited(Msg.MOT_GET_DCSTATUSUPDATE, long_data=self._status(now_s).pack())

    # ---- status -----------------------------------------------------------------------------
    def _counter(self) -> int:
        return self.units.counts(self._pos_mm - self._zero_mm)

    def _counter_reply(self) -> int:
        if self._settling is not None:  # each position reply is one step of settling
            target, left = self._settling
            self._settling = (target, left - 1) if left > 1 else None
            if left <= 1:
                self._pos_mm = target
        if self.faults.out_of_range > 0:
            self.faults.out_of_range -= 1
            return 0x7FFFFFF0  # ~62 m on a Z8: impossible
        return self._counter()

    def _bits(self, now: float) -> StatusBits:
        bits = StatusBits.MOTOR_CONNECTED | self._held_limit_bits
        lo, hi = self.travel_mm
        if self._pos_mm <= lo + _EPS_MM:
            bits |= StatusBits.REV_HW_LIMIT
        if self._pos_mm >= hi - _EPS_MM:
            bits |= StatusBits.FWD_HW_LIMIT
        if self.enabled:
            bits |= StatusBits.ENABLED
        if self.homed:
            bits |= StatusBits.HOMED
        m = self._motion
        if m is not None:
            if m.kind == "home":
                bits |= StatusBits.HOMING
            bits |= StatusBits.MOVING_FWD if m.profile.direction > 0 else StatusBits.MOVING_REV
        return bits

    def _status(self, now: float) -> DcStatus:
        speed = self._motion.profile.speed(now) if self._motion is not None else 0.0
        # Velocity word: device units are undocumented for this field; we report um/s.
        return DcStatus(self._counter_reply(), min(round(speed * 1000), 0xFFFF), 0,
                        self._bits(now))
