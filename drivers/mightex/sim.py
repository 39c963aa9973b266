"""Firmware-level simulator of the Mightex buffer camera (MCE-B013-U by default).

:class:`SimulatedCamera` holds the firmware state and answers the same bytes as the camera;
:class:`~benchlab.drivers.mightex.sim_usb.SimCameraBackend` presents one or more of them as
USB devices to pyusb::

    cam = SimulatedCamera(scene=bar_target_scene(), bench_state=lambda: {"led_ma": 300})
    with MightexCamera.open(backend=SimCameraBackend([cam])) as driver:
        frame = driver.grab()

Time comes from an injectable clock. The default :class:`VirtualClock` never sleeps: when the
host polls an empty buffer it jumps ahead to the moment the next frame is ready, so ``grab()``
returns at once. :class:`ManualClock` only moves when a test says so; :class:`RealTimeClock`
follows ``time.monotonic()`` (live view at the camera's true frame rate).

The model's facts come from a device profile (:mod:`benchlab.drivers.mightex.profile`),
given apart from the driver's: exposure field and unit, bit depths, what a full buffer does
(default: new frames are dropped), how long the camera ignores commands after the work-mode
command and after power-up. A test can so build a camera that disagrees with the driver.

Firmware behaviour where the public sources are silent (choices, not facts): invalid settings
are ignored (and listed in ``rejected_commands``); 0x30 and 0x60 empty the buffer; readout
takes width x height pixels at 48 MHz / 2**divider; timestamps are ms since power-on at the end
of the exposure; ``min_exposure_counts`` raises shorter exposures (the trailer says so).
"""

from __future__ import annotations

import hashlib
import threading
import time
from collections import deque
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any, Protocol

from benchlab.drivers.mightex import protocol as p
from benchlab.drivers.mightex.sim_sensor import (
    BarTargetScene,
    FlatFieldScene,
    SensorModel,
    bar_target_scene,
    flat_field_scene,
)
from benchlab.drivers.mightex.sim_usb import DeviceUnplugged, SimCameraBackend
from benchlab.drivers.sensor import AcquisitionState, Scene
from benchlab.drivers.simulation.clock import ManualClock
from benchlab.drivers.simulation.dispatch import CommandTable

__all__ = [
    "BarTargetScene", "CameraFaults", "Clock", "FlatFieldScene", "ManualClock", "RealTimeClock",
    "SIM_CAMERA_SERIAL", "SentFrame", "SimCameraBackend", "SimulatedCamera", "VirtualClock",
    "bar_target_scene", "flat_field_scene",
]

#: The simulated camera's serial number, the same wherever a simulated bench is opened.
SIM_CAMERA_SERIAL = "SIM-130001"

PIXEL_CLOCK_HZ = 48e6


# --------------------------------------------------------------------------- clocks


class Clock(Protocol):
    def now(self) -> float:
        """Seconds since an arbitrary origin."""

    def wait_until(self, t_s: float) -> bool:
        """Let time reach ``t_s`` if this clock may do so without the host waiting."""


class VirtualClock:
    """Simulated time that jumps forward when the firmware would otherwise wait."""

    def __init__(self, start_s: float = 0.0) -> None:
        self._t = float(start_s)

    def now(self) -> float:
        return self._t

    def advance(self, dt_s: float) -> None:
        self._t += max(0.0, dt_s)

    def wait_until(self, t_s: float) -> bool:
        self._t = max(self._t, t_s)
        return True


class RealTimeClock:
    """Wall time (``time.monotonic``): frames arrive at the camera's real rate."""

    def __init__(self) -> None:
        self._t0 = time.monotonic()

    def now(self) -> float:
        return time.monotonic() - self._t0

    def wait_until(self, t_s: float) -> bool:
        return False


# --------------------------------------------------------------------------- firmware state


@dataclass
class CameraFaults:
    """Fault injection; counters are consumed one event at a time."""

    #: Next N query replies are never sent (the host's read times out).
    drop_replies: int = 0
    #: Next N query replies come late: the host's read for each times out, and the reply is
    #: waiting for its next read (the simulated bus never waits, so "late" counts reads).
    late_replies: int = 0
    #: Next N query replies are garbled (length byte does not match).
    garbage_replies: int = 0
    #: Next N frame transfers end 4 kB early.
    short_frames: int = 0
    #: On the next frame transfer the camera disappears from the bus (see ``replug``).
    unplug_mid_frame: bool = False
    #: The next settings change leaves N frames with the old settings in the buffer.
    stale_frames: int = 0
    #: Result byte of good replies; any non-zero value is legal (0x08 was seen in the field).
    reply_status: int = 0x01
    # Firmware behaviours that last (not consumed), each a first-day failure on a real bench:
    #: The firmware takes only the full sensor resolution; any other 0x60 is ignored.
    refuse_roi: bool = False
    #: Frames are exposed and counted in the buffer (0x33) but never sent on EP 0x82.
    frames_never_sent: bool = False
    #: The firmware reads a 4-byte exposure (0x63) whatever the length byte says: the bytes
    #: past a 2-byte command are what its command buffer still holds from earlier commands.
    exposure_reads_4_bytes: bool = False


@dataclass
class SentFrame:
    """One frame transfer as the simulator began it: the ground truth a soak test checks the
    host against (enable with ``SimulatedCamera.sent_frames = []``)."""

    #: The simulator's own frame counter: every transfer, never reset (power cycles included).
    seq: int
    exposure_counts: int
    gain_raw: int
    #: SHA-256 of the pixel bytes as rendered, before any transfer fault.
    pixels_sha256: str
    #: Power-on generation (bumped by every unplug) and the trailer's timestamp: with the
    #: exposure, what the host can tell frames apart by.
    generation: int
    timestamp_ms: int
    #: "sending", then "intact", "short" (ended 4 kB early) or "unplugged" (cut mid-frame).
    outcome: str = "sending"


@dataclass(frozen=True)
class FirmwareSettings:
    """Acquisition registers of the firmware (power-on values)."""

    mode: int = 0
    bits: int = 8
    width: int = 1280
    height: int = 1024
    bin_code: int = 0
    buffer_count: int = 4
    exposure_counts: int = 200
    gain_raw: int = 8
    frame_time_counts: int = 1
    clock_divider: int = 0


@dataclass
class _Frame:
    settings: FirmwareSettings
    ready_s: float
    index: int
    trigger_occurred: bool
    trigger_count: int
    scene: Scene
    bench: Mapping[str, Any] = field(default_factory=dict)


class SimulatedCamera:
    """Firmware state of one simulated camera (see the module docstring).

    Parameters
    ----------
    scene : Scene, optional
        Light on the sensor (default: a flat field). Settable at any time.
    serial, model, pid, firmware
        Identity reported over USB; ``model`` selects the protocol spec (exposure encoding).
    clock : Clock, optional
        Default :class:`VirtualClock`.
    seed : int, optional
        Noise seed. ``noise=False`` renders exact noise-free codes.
    profile : CameraSpec, optional
        The model's facts (default: the profile of ``model``); may differ from the driver's.
    min_exposure_counts : int
        Shortest exposure the sensor makes; shorter settings are raised to it.
    bench_state : callable, optional
        Returns the mapping passed to the scene as ``AcquisitionState.bench`` (stage, LEDs);
        sampled when each frame is exposed. Settable at any time.
    """

    #: Command byte -> handler taking the argument bytes; ``False`` = rejected.
    commands: CommandTable[int] = CommandTable()

    def __init__(
        self, scene: Scene | None = None, *, serial: str = SIM_CAMERA_SERIAL,
        model: str = "MCE-B013-U", pid: int = p.DEFAULT_PID,
        firmware: tuple[int, int, int] = (1, 0, 6), clock: Clock | None = None,
        seed: int | None = None, bench_state: Callable[[], Mapping[str, Any]] | None = None,
        noise: bool = True, profile: p.CameraSpec | None = None, min_exposure_counts: int = 1,
    ) -> None:
        self.spec = profile if profile is not None else p.spec_for(model)
        self.min_exposure_counts = min_exposure_counts
        #: Frames the camera exposed but could not store (buffer full, drop-new policy).
        self.dropped_frames = 0
        #: Until this clock time the firmware ignores commands (power-up, after 0x30).
        self._deaf_until = -float("inf")
        self.scene: Scene = scene if scene is not None else flat_field_scene()
        self.bench_state = bench_state
        self.serial, self.model, self.pid, self.firmware = serial, model, pid, tuple(firmware)
        self.clock: Clock = clock if clock is not None else VirtualClock()
        self.sensor = SensorModel(seed, noise=noise)
        self.faults = CameraFaults()
        self.command_log: deque[bytes] = deque(maxlen=10_000)
        self.rejected_commands: deque[bytes] = deque(maxlen=1_000)
        self.connected = True
        #: Bumped on every unplug so handles opened before it stay dead.
        self.generation = 0
        #: Set to a list to record every frame transfer (:class:`SentFrame`); None: off.
        self.sent_frames: list[SentFrame] | None = None
        self._sent_seq = 0
        self._sending: SentFrame | None = None
        #: The firmware's command buffer (EP 0x01): each command overwrites its start.
        self._command_buffer = bytearray(64)
        self._lock = threading.RLock()
        self._power_on()

    # ------------------------------------------------------------------ state

    def _power_on(self) -> None:
        self.settings = FirmwareSettings()
        self._t0 = self.clock.now()
        self._fifo: deque[_Frame] = deque()
        self._replies: deque[bytes] = deque()
        self._late_reply: bytes | None = None  # misses the next read, then is the next reply
        self._outgoing: deque[_Frame] = deque()
        self._transfer: memoryview | None = None
        self._pending_triggers: list[tuple[float, int]] = []  # (ready time, trigger count)
        self._trigger_count = 0
        self._frame_index = 0
        self._next_ready = self._t0 + self.period_s

    @property
    def period_s(self) -> float:
        """Free-running frame period: the longest of exposure, frame time and readout."""
        s = self.settings
        exposure_ms = s.exposure_counts * self.spec.exposure_unit_ms
        frame_ms = s.frame_time_counts * self.spec.frame_time_unit_ms
        return max(exposure_ms, frame_ms, self._readout_ms()) / 1e3

    def _readout_ms(self) -> float:
        s = self.settings
        return s.width * s.height / (PIXEL_CLOCK_HZ / 2**s.clock_divider) * 1e3

    @property
    def frames_sent(self) -> int:
        """Frame transfers begun since power-on of this instance (every read the host made,
        frames it then dropped included)."""
        with self._lock:
            return self._sent_seq

    @property
    def buffered_frames(self) -> int:
        with self._lock:
            self._catch_up()
            return len(self._fifo)

    def _capture(self, ready_s: float, triggered: bool, trigger_count: int = 0) -> None:
        bench = dict(self.bench_state()) if self.bench_state is not None else {}
        frame = _Frame(self.settings, ready_s, self._frame_index, triggered,
                       trigger_count, self.scene, bench)
        self._frame_index += 1
        if len(self._fifo) >= self.settings.buffer_count:
            if self.spec.buffer_full == "drop_new":
                self.dropped_frames += 1
                return
            self._fifo.popleft()  # ring buffer: the oldest frame is overwritten
        self._fifo.append(frame)

    def _catch_up(self) -> None:
        now = self.clock.now()
        if self.settings.mode == 0:
            period = self.period_s
            due = int((now - self._next_ready) // period) + 1 if now >= self._next_ready else 0
            room = self.settings.buffer_count - len(self._fifo)
            if self.spec.buffer_full == "drop_new":
                skip = max(0, due - max(room, 0))  # no room: exposed, then dropped
                self.dropped_frames += skip
                for _ in range(due - skip):
                    self._capture(self._next_ready, triggered=False)
                    self._next_ready += period
                self._next_ready += skip * period
                self._frame_index += skip
                return
            skip = max(0, due - self.settings.buffer_count)  # would be overwritten anyway
            if skip:
                self._next_ready += skip * period
                self._frame_index += skip
            for _ in range(due - skip):
                self._capture(self._next_ready, triggered=False)
                self._next_ready += period
        else:
            while self._pending_triggers and self._pending_triggers[0][0] <= now:
                ready_s, count = self._pending_triggers.pop(0)
                self._capture(ready_s, triggered=True, trigger_count=count)

    def _next_event_s(self) -> float | None:
        if self.settings.mode == 0:
            return self._next_ready
        return self._pending_triggers[0][0] if self._pending_triggers else None

    def _restart_exposure(self) -> None:
        self._next_ready = self.clock.now() + self.period_s

    def inject_stale_frames(self, n: int, settings: FirmwareSettings | None = None) -> None:
        """Put ``n`` frames exposed with ``settings`` (default: the current ones) in the buffer."""
        with self._lock:
            saved = self.settings
            self.settings = settings or saved
            for _ in range(n):
                self._capture(self.clock.now(), triggered=False)
            self.settings = saved

    # ------------------------------------------------------------------ bus presence

    def unplug(self) -> None:
        """Take the camera off the bus; open handles fail with 'no such device'."""
        with self._lock:
            self.connected = False
            self.generation += 1

    def replug(self) -> None:
        """Put the camera back on the bus, freshly powered on (deaf for the power-up time)."""
        with self._lock:
            self._power_on()
            self._deaf_until = self.clock.now() + self.spec.power_up_wait_s
            self.connected = True

    # ------------------------------------------------------------------ EP 0x01

    def _reply(self, data: bytes) -> None:
        f = self.faults
        if f.drop_replies > 0:
            f.drop_replies -= 1
            return
        if f.garbage_replies > 0:
            f.garbage_replies -= 1
            self._replies.append(b"\x5a\x13\xde\xad\xbe\xef")
            return
        if f.late_replies > 0 and self._late_reply is None:
            f.late_replies -= 1
            self._late_reply = p.encode_reply(data, f.reply_status)
            return
        self._replies.append(p.encode_reply(data, f.reply_status))

    def _device_info(self) -> bytes:
        return p.encode_device_info(p.DeviceInfo(1, self.model, self.serial, ""))

    def write_command(self, data: bytes) -> None:
        """Handle one command transfer from the host."""
        with self._lock:
            if not self.connected:
                raise DeviceUnplugged
            self.command_log.append(bytes(data))
            self._command_buffer[:len(data)] = data[:len(self._command_buffer)]
            self._catch_up()
            if self.clock.now() < self._deaf_until:  # powering up, or busy after 0x30
                self.rejected_commands.append(bytes(data))
                return
            if len(data) == 1 and data[0] in (p.CMD_FIRMWARE, 0x02, p.CMD_DEVICE_INFO):
                # Bare wake-up bytes used by older clients ([SH]): answer like the full query.
                self._answer(data[0])
                return
            if len(data) < 2 or data[1] != len(data) - 2:
                self.rejected_commands.append(bytes(data))
                return
            if not self._execute(data[0], bytes(data[2:])):
                self.rejected_commands.append(bytes(data))

    def _answer(self, cmd: int) -> None:
        if cmd in (p.CMD_FIRMWARE, 0x02):
            self._reply(bytes(self.firmware))
        else:
            self._reply(self._device_info())

    def _execute(self, cmd: int, args: bytes) -> bool:
        """Run one command; ``False`` (rejected) for unknown commands and bad arguments."""
        handler = self.commands.handler(self, cmd)
        return bool(handler is not None and handler(args))

    @commands.handles(p.CMD_FIRMWARE)
    def _firmware(self, args: bytes) -> bool:
        self._answer(p.CMD_FIRMWARE)
        return True

    @commands.handles(p.CMD_DEVICE_INFO)
    def _device_info_cmd(self, args: bytes) -> bool:
        self._answer(p.CMD_DEVICE_INFO)
        return True

    @commands.handles(p.CMD_QUERY_BUFFER)
    def _query_buffer_cmd(self, args: bytes) -> bool:
        self._query_buffer()
        return True

    @commands.handles(p.CMD_GET_IMAGE)
    def _get_image(self, args: bytes) -> bool:
        if len(args) != 1:
            return False
        for _ in range(min(args[0], len(self._fifo))):
            self._outgoing.append(self._fifo.popleft())
        return True

    @commands.handles(p.CMD_CLEAR_BUFFER)
    def _clear_buffer(self, args: bytes) -> bool:
        if len(args) != 1:
            return False
        for _ in range(min(args[0], len(self._fifo))):
            self._fifo.popleft()
        return True

    @commands.handles(p.CMD_SOFT_TRIGGER)
    def _soft_trigger(self, args: bytes) -> bool:
        if len(args) != 1:
            return False
        s = self.settings
        if s.mode == 1:
            self._trigger_count += 1
            exposure_ms = s.exposure_counts * self.spec.exposure_unit_ms
            ready_s = self.clock.now() + (exposure_ms + self._readout_ms()) / 1e3
            self._pending_triggers.append((ready_s, self._trigger_count))
        return True

    @commands.handles(p.CMD_RESET)
    def _reset(self, args: bytes) -> bool:
        if args != b"\x01":
            return False
        self._power_on()
        self._deaf_until = self.clock.now() + self.spec.power_up_wait_s
        return True

    @commands.handles(p.CMD_WORK_MODE)
    def _work_mode(self, args: bytes) -> bool:
        if len(args) != 2 or args[0] not in p.MODE_NAMES or args[1] not in self.spec.bit_depths:
            return False
        self._change(replace(self.settings, mode=args[0], bits=args[1]), flush=True)
        if args[0] == 1:
            self._trigger_count = 0
        self._pending_triggers.clear()
        self._deaf_until = self.clock.now() + self.spec.work_mode_wait_s
        return True

    @commands.handles(p.CMD_RESOLUTION)
    def _resolution(self, args: bytes) -> bool:
        if len(args) != 7:
            return False
        s = self.settings
        width, height = int.from_bytes(args[0:2], "big"), int.from_bytes(args[2:4], "big")
        if self.faults.refuse_roi and (width, height) != (self.spec.max_width,
                                                           self.spec.max_height):
            return False
        try:
            p.check_geometry(self.spec, width=width, height=height, bits=s.bits,
                             mode=p.MODE_NAMES[s.mode], bin_code=args[4], buffer_count=args[5])
        except ValueError:
            return False
        self._change(replace(s, width=width, height=height, bin_code=args[4],
                             buffer_count=args[5]), flush=True)
        return True

    @commands.handles(p.CMD_GAIN)
    def _gain(self, args: bytes) -> bool:
        if len(args) != 3 or not self.spec.gain_raw_min <= args[1] <= self.spec.gain_raw_max:
            return False
        self._change(replace(self.settings, gain_raw=args[1]))
        return True

    @commands.handles(p.CMD_EXPOSURE)
    def _exposure(self, args: bytes) -> bool:
        if self.faults.exposure_reads_4_bytes:  # the length byte is not looked at
            counts = int.from_bytes(self._command_buffer[2:6], "big")
            self._change(replace(self.settings, exposure_counts=max(counts, 1)))
            return True
        if len(args) != self.spec.exposure_bytes:
            return False
        counts = int.from_bytes(args, "big")
        if not 1 <= counts <= self.spec.exposure_max_counts:
            return False
        counts = max(counts, self.min_exposure_counts)  # the trailer tells the host
        self._change(replace(self.settings, exposure_counts=counts))
        return True

    @commands.handles(p.CMD_FRAME_TIME)
    def _frame_time(self, args: bytes) -> bool:
        if len(args) != 2 or int.from_bytes(args, "big") == 0:
            return False
        self._change(replace(self.settings, frame_time_counts=int.from_bytes(args, "big")))
        return True

    @commands.handles(p.CMD_CLOCK)
    def _clock(self, args: bytes) -> bool:
        if len(args) != 1 or args[0] > 4:
            return False
        self._change(replace(self.settings, clock_divider=args[0]))
        return True

    def _change(self, new: FirmwareSettings, *, flush: bool = False) -> None:
        old = self.settings
        if new == old:
            return
        self.settings = new
        if flush:
            self._fifo.clear()
        if self.faults.stale_frames > 0:
            n, self.faults.stale_frames = self.faults.stale_frames, 0
            self.inject_stale_frames(n, old)
        self._restart_exposure()

    def _query_buffer(self) -> None:
        if not self._fifo:
            target = self._next_event_s()
            if target is not None and self.clock.wait_until(target):
                self._catch_up()
        head = self._fifo[0].settings if self._fifo else self.settings
        status = p.BufferStatus(min(len(self._fifo), 255), head.width, head.height,
                                head.bin_code)
        self._reply(p.encode_buffer_status(status))

    # ------------------------------------------------------------------ EP 0x81 / 0x82

    def read_reply(self, size: int) -> bytes | None:
        """Next reply for EP 0x81, or ``None`` when there is none (host times out)."""
        with self._lock:
            if not self.connected:
                raise DeviceUnplugged
            if self._late_reply is not None:  # this read times out; the reply lands after it
                self._replies.appendleft(self._late_reply)
                self._late_reply = None
                return None
            return self._replies.popleft()[:size] if self._replies else None

    def read_frame_data(self, size: int) -> memoryview | None:
        """Up to ``size`` bytes of the frame transfer in progress on EP 0x82 (``None``: none)."""
        with self._lock:
            if not self.connected:
                raise DeviceUnplugged
            if self._transfer is None:
                if not self._outgoing or self.faults.frames_never_sent:
                    return None
                self._transfer = self._render(self._outgoing.popleft())
            if self.faults.unplug_mid_frame:
                self.faults.unplug_mid_frame = False
                self._transfer = None
                self._sent("unplugged")
                self.unplug()
                raise DeviceUnplugged
            chunk, rest = self._transfer[:size], self._transfer[size:]
            self._transfer = rest if len(rest) else None
            if self._transfer is None:
                self._sent("intact")
            return chunk

    def _sent(self, outcome: str) -> None:
        record, self._sending = self._sending, None
        if record is not None and record.outcome == "sending":
            record.outcome = outcome

    def _render(self, frame: _Frame) -> memoryview:
        s = frame.settings
        layout = p.FrameLayout(s.width, s.height, s.bits)
        payload = bytearray(layout.total_bytes)
        exposure_ms = s.exposure_counts * self.spec.exposure_unit_ms
        state = AcquisitionState(
            exposure_ms=exposure_ms, gain=s.gain_raw / p.GAIN_RAW_PER_UNITY, bits=s.bits,
            width=s.width, height=s.height, time_s=frame.ready_s - exposure_ms / 1e3,
            frame_index=frame.index, bench=frame.bench,
        )
        self.sensor.render_into(payload, frame.scene, state)
        timestamp_ms = int((frame.ready_s - self._t0) * 1000 / self.spec.timestamp_unit_ms)
        payload[layout.trailer_offset:] = p.encode_trailer(p.FrameTrailer(
            row=s.width, column=s.height, bin_code=s.bin_code, x_start=0, y_start=0,
            red_gain=s.gain_raw, green_gain=s.gain_raw, blue_gain=s.gain_raw,
            timestamp_ms=timestamp_ms,
            trigger_occurred=int(frame.trigger_occurred), trigger_count=frame.trigger_count,
            user_mark=0, frame_time=s.frame_time_counts, clock=s.clock_divider,
            exposure_counts=s.exposure_counts,
        ), self.spec.trailer_order)
        view = memoryview(payload)
        if self.sent_frames is not None:
            self._sending = SentFrame(
                self._sent_seq, s.exposure_counts, s.gain_raw,
                hashlib.sha256(view[:layout.pixel_bytes]).hexdigest(), self.generation,
                timestamp_ms)
            self.sent_frames.append(self._sending)
        self._sent_seq += 1
        if self.faults.short_frames > 0:
            self.faults.short_frames -= 1
            view = view[: max(0, len(view) - 4096)]
            if self._sending is not None:
                self._sending.outcome = "short"
        return view
