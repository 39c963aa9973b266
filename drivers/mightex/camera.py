"""pyusb driver for the Mightex MCE-B013-U buffer camera (and its v1.0.5 sibling BTN-B013U).

Typical use::

    with MightexCamera.open() as cam:          # first camera found (VID 0x04B4, PID 0x0428)
        cam.configure(bits=12)
        cam.set_exposure_ms(300)
        cam.set_gain(1.0)
        frame = cam.grab()                       # frame.pixels (uint16), frame.meta

Pass ``backend=SimCameraBackend([...])`` (``benchlab.drivers.mightex.sim``) to talk to the
simulated firmware through the very same pyusb calls. Settings are checked before any byte is
sent; USB failures map to :mod:`benchlab.drivers.errors` types.
"""

from __future__ import annotations

import array
import errno
import functools
import logging
import math
import shlex
import threading
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from datetime import UTC, datetime
from importlib import resources
from pathlib import Path
from typing import Any, ParamSpec, TypeVar

import numpy.typing as npt
import usb.core
import usb.util

from benchlab.drivers.errors import (
    DeviceError,
    DeviceLostError,
    DeviceNotFoundError,
    DeviceTimeoutError,
    ProtocolError,
    SettingOutOfRangeError,
)
from benchlab.drivers.interfaces import Camera, DeviceIdentity, Frame
from benchlab.drivers.mightex import protocol as p
from benchlab.drivers.trace import io_trace

log = logging.getLogger(__name__)

__all__ = [
    "CameraInfo", "CameraProfileMismatchError", "Frame", "FrameMeta", "MightexCamera",
    "find_cameras", "DEFAULT_PID", "VENDOR_ID", "CameraRoiRefusedError", "UsbDeviceSeen",
    "FrameEndpointTimeoutError",
    "udev_rule_line", "vendor_devices",
]

VENDOR_ID = p.VENDOR_ID
DEFAULT_PID = p.DEFAULT_PID
REPLY_TIMEOUT_MS = 500
#: Pause between firmware queries while a camera powers up.
WAKE_RETRY_S = 0.5
#: Polling interval while the camera buffer is empty (real hardware, or trigger mode).
POLL_INTERVAL_S = 0.002
#: Frames in a row whose trailer is off the settings (beyond the profile's tolerance) before
#: a grab calls the profile wrong; the first may come from the settings before the last change.
MAX_DISCARDS = 3
#: Reads of the frame endpoint that drain surplus bytes after a frame of the wrong size (at
#: most; each reads up to :data:`DRAIN_CHUNK_BYTES` and the drain ends at the first timeout).
MAX_DRAIN_READS = 64
DRAIN_CHUNK_BYTES = 1 << 16
DRAIN_TIMEOUT_MS = 50
_LIBUSB_NO_DEVICE = -4
UDEV_RULE = "99-benchlab-mightex.rules"
_LIBUSB_PIPE = -9


class CameraProfileMismatchError(ProtocolError):
    """The camera does not behave as its model's profile says (exposure field, bit depth)."""


class FrameEndpointTimeoutError(DeviceTimeoutError):
    """The camera said a frame was waiting, but none came on the frame endpoint (EP 0x82)."""


class CameraRoiRefusedError(ProtocolError):
    """The camera keeps sending frames of another geometry than the one set (0x60 refused)."""


@dataclass(frozen=True)
class UsbDeviceSeen:
    """A USB device that may be the camera: the vendor's id, or strings naming Mightex."""

    vid: int
    pid: int
    bus: int | None
    address: int | None
    manufacturer: str
    product: str
    serial: str

    def describe(self) -> str:
        strings = " ".join(x for x in (self.manufacturer, self.product) if x) or "(no strings)"
        return (f"{self.vid:04x}:{self.pid:04x} {strings}"
                + (f" serial {self.serial}" if self.serial else "")
                + (f" (usb {self.bus}:{self.address})" if self.bus is not None else ""))

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


def udev_rule_line(vid: int, pid: int) -> str:
    """The udev rule line that gives the plugdev group this device (as the packaged rule)."""
    return (f'SUBSYSTEM=="usb", ATTR{{idVendor}}=="{vid:04x}", ATTR{{idProduct}}=="{pid:04x}", '
            'MODE="0660", GROUP="plugdev", TAG+="uaccess"')


def vendor_devices(backend: Any = None) -> list[UsbDeviceSeen]:
    """Every USB device with the camera vendor's id (any product id), or whose manufacturer
    or product string names Mightex; strings that cannot be read (no permission) are ''."""
    from benchlab.drivers.trace import replay

    if backend is None:
        backend = replay.usb_backend()
    try:
        devices = list(usb.core.find(find_all=True, backend=backend) or [])
    except usb.core.NoBackendError:
        return []
    seen = []
    for dev in devices:
        strings = [_usb_string(dev, i) for i in (dev.iManufacturer, dev.iProduct,
                                                 dev.iSerialNumber)]
        names_mightex = any("mightex" in x.lower() for x in strings[:2])
        if dev.idVendor == VENDOR_ID or names_mightex:
            seen.append(UsbDeviceSeen(dev.idVendor, dev.idProduct, dev.bus, dev.address,
                                      *strings))
    return seen


def _usb_string(dev: Any, index: int) -> str:
    if not index:
        return ""
    try:
        return str(usb.util.get_string(dev, index) or "")
    except (usb.core.USBError, ValueError, NotImplementedError):
        return ""  # no permission to open it, or no language table


@dataclass(frozen=True)
class CameraInfo:
    """Identity of one camera; ``error`` is set when it was found but could not be opened."""

    model: str
    serial: str
    firmware: str
    pid: int
    bus: int | None
    address: int | None
    error: str | None = None

    def to_dict(self) -> dict[str, Any]:
        return asdict(self)


@dataclass(frozen=True)
class FrameMeta:
    """Acquisition metadata of one frame (trailer values plus the host's configuration)."""

    width: int
    height: int
    bits: int
    mode: str
    bin_code: int
    gain: float
    gain_raw: int
    exposure_ms: float
    exposure_counts: int
    frame_time_ms: float
    #: Trailer timestamp in ms (raw word x the profile's ``timestamp_unit_ms``), wraps.
    timestamp_ms: float
    trigger_occurred: bool
    trigger_count: int
    x_start: int
    y_start: int
    received_utc: str
    #: A pixel's size on the sensor ``(x, y)``, um: the profile's pitch times the binning
    #: (:meth:`~benchlab.drivers.mightex.profile.CameraSpec.pixel_size_um`); storage copies it
    #: into the TIFF's calibration.
    pixel_size_um: tuple[float, float]
    #: What the host set; ``exposure_ms`` / ``gain`` are the trailer's (the frame's truth).
    set_exposure_ms: float = 0.0
    set_gain: float = 0.0

    def to_dict(self) -> dict[str, Any]:
        """JSON-safe dictionary (plain ints, floats, bools and strings)."""
        return asdict(self)


@dataclass
class _Settings:
    width: int = 1280
    height: int = 1024
    bits: int = 8
    mode: str = "normal"
    bin_code: int = 0
    buffer_count: int = 4
    exposure_counts: int = 200  # 10 ms
    gain_raw: int = 8  # unity
    frame_time_counts: int = 1  # shortest: run as fast as exposure and readout allow


_P = ParamSpec("_P")
_R = TypeVar("_R")


def _locked(method: Callable[_P, _R]) -> Callable[_P, _R]:
    """Serialise a public method: a UI thread and a worker may share one camera."""

    @functools.wraps(method)
    def wrapper(*args: _P.args, **kwargs: _P.kwargs) -> _R:
        with args[0]._lock:  # type: ignore[attr-defined]
            return method(*args, **kwargs)

    return wrapper


@contextmanager
def _usb_errors(what: str) -> Iterator[None]:
    """Translate pyusb exceptions into benchlab errors (timeout, lost device, other)."""
    try:
        yield
    except usb.core.USBTimeoutError as exc:
        raise DeviceTimeoutError(f"camera did not answer ({what})") from exc
    except usb.core.USBError as exc:
        if exc.errno in (errno.ENODEV, errno.ENXIO, errno.ESHUTDOWN) or exc.backend_error_code in (
            _LIBUSB_NO_DEVICE,
        ):
            raise DeviceLostError(f"camera disconnected ({what}): {exc}") from exc
        if exc.errno in (errno.EACCES, errno.EPERM):
            raise DeviceError(f"no permission to open the camera ({what}). {udev_hint()}") from exc
        raise DeviceError(f"USB error ({what}): {exc}") from exc


def udev_rule_path() -> Path:
    """The udev rule installed with benchlab (package data of ``benchlab.drivers``)."""
    return Path(str(resources.files("benchlab.drivers") / "data" / UDEV_RULE))


def udev_hint() -> str:
    """What to run, exactly, so that the camera opens without root (Linux)."""
    rule = shlex.quote(str(udev_rule_path()))
    return ("Install the udev rule that came with benchlab, then unplug and replug the camera:\n"
            f"  sudo install -m 644 {rule} /etc/udev/rules.d/\n"
            "  sudo udevadm control --reload-rules && sudo udevadm trigger\n"
            '  sudo groupadd -f plugdev && sudo usermod -aG plugdev "$USER"  # then log out and in')


def _find_devices(backend: Any, pid: int | None) -> list[usb.core.Device]:
    from benchlab.drivers.trace import replay

    if backend is None:
        backend = replay.usb_backend()  # a cassette replayed: its camera, no USB
    try:
        found = usb.core.find(
            find_all=True, idVendor=VENDOR_ID, idProduct=DEFAULT_PID if pid is None else pid,
            backend=backend,
        )
        return list(found or [])
    except usb.core.NoBackendError as exc:
        raise DeviceNotFoundError(
            "no USB backend available: install libusb-1.0 (e.g. apt install libusb-1.0-0)"
        ) from exc


def find_cameras(backend: Any = None, pid: int | None = None) -> list[CameraInfo]:
    """Every matching camera with model, serial and firmware (each is opened briefly).

    Parameters
    ----------
    backend : usb.backend.IBackend, optional
        pyusb backend; ``None`` uses libusb. Pass a ``SimCameraBackend`` for simulated cameras.
    pid : int, optional
        USB product ID to match (default 0x0428).
    """
    infos = []
    for dev in _find_devices(backend, pid):
        try:
            cam = MightexCamera._from_device(dev, configure=False)
        except DeviceError as exc:
            infos.append(CameraInfo("?", "?", "?", dev.idProduct, dev.bus, dev.address, str(exc)))
            continue
        infos.append(cam.info)
        cam.close()
    return infos


class MightexCamera(Camera[FrameMeta]):
    """One open camera. Use :meth:`open`; close with :meth:`close` or a ``with`` block.

    Frames are :class:`~benchlab.drivers.interfaces.Frame` with :class:`FrameMeta`."""

    def __init__(self, dev: usb.core.Device, spec: p.CameraSpec, info: CameraInfo,
                 backend: Any) -> None:
        self._dev: usb.core.Device | None = dev
        self._spec = spec
        self.info = info
        self._backend = backend
        self._settings = _Settings()
        #: Exposure counts and gain before the last change: frames with them are stale.
        self._previous = (self._settings.exposure_counts, self._settings.gain_raw)
        self._resync_replies = False
        #: Frames read and dropped because they carried older settings (diagnostics).
        self.discarded_frames = 0
        #: Older frames a normal-mode grab cleared unread to return the newest (diagnostics).
        self.skipped_frames = 0
        self._sleep: Callable[[float], None] = time.sleep
        #: The profile's protocol waits; a simulator's backend lends its clock (no real wait).
        self._wait: Callable[[float], None] = getattr(backend, "sleep", None) or time.sleep
        #: The host's clock for timing frames: a simulator's backend lends its own.
        self._now: Callable[[], float] = getattr(backend, "now", None) or time.monotonic
        #: Bytes read and dropped from the frame endpoint after wrong-size frames.
        self.drained_bytes = 0
        self._lock = threading.RLock()

    # ------------------------------------------------------------------ opening

    @classmethod
    def open(
        cls, serial: str | None = None, backend: Any = None, pid: int | None = None,
        model: str | None = None, profile: p.CameraSpec | None = None,
    ) -> MightexCamera:
        """Open the camera with this serial number (or the first one found) and configure it.

        The profile (exposure field, bit depths, waits, trailer tolerance) is ``profile``, else
        that of ``model``, else that of the device's own module number when known, else the
        MCE-B013-U's. Default acquisition: 1280x1024, 8-bit, normal mode,
        exposure 10 ms, gain 1, 4 buffered frames.

        Raises
        ------
        DeviceNotFoundError
            No camera matched (the message lists the serials that were found).
        """
        if model is not None and profile is None:
            profile = p.spec_for(model)  # refuse an unknown model before touching USB
        if backend is None:
            from benchlab.drivers.trace import replay

            backend = replay.usb_backend()  # None unless a cassette is replayed
        devices = _find_devices(backend, pid)
        seen = []
        errors = []
        for dev in devices:
            try:
                cam = cls._from_device(dev, configure=False, profile=profile, backend=backend)
            except DeviceError as exc:  # busy or unreadable: maybe another camera matches
                errors.append(f"usb {dev.bus}:{dev.address}: {exc}")
                continue
            if serial is None or cam.info.serial == serial:
                try:
                    cam._apply_all()
                except BaseException:
                    cam.close()
                    raise
                log.info("camera %s serial %s firmware %s opened", cam.info.model,
                         cam.info.serial, cam.info.firmware)
                return cam
            seen.append(cam.info.serial)
            cam.close()
        if errors and serial is None:
            raise DeviceError("camera found but could not be opened: " + "; ".join(errors))
        pid_text = f"0x{DEFAULT_PID if pid is None else pid:04X}"
        if serial is None:
            raise DeviceNotFoundError(
                f"no Mightex camera found (VID 0x{VENDOR_ID:04X}, PID {pid_text}); check the "
                "cable, the udev rule, or pass --pid"
            )
        raise DeviceNotFoundError(
            f"no camera with serial {serial!r} (PID {pid_text}); found: {', '.join(seen) or 'none'}"
        )

    @classmethod
    def _from_device(cls, dev: usb.core.Device, *, configure: bool,
                     profile: p.CameraSpec | None = None, backend: Any = None) -> MightexCamera:
        with _usb_errors("open"):
            try:
                if dev.is_kernel_driver_active(p.INTERFACE):
                    dev.detach_kernel_driver(p.INTERFACE)
            except (NotImplementedError, usb.core.USBError):
                pass  # no kernel driver binds this camera on Linux; other OSes lack the call
            dev.set_configuration()
            usb.util.claim_interface(dev, p.INTERFACE)
        io_trace.opened("camera", vid=dev.idVendor, pid=dev.idProduct)
        start = profile or p.spec_for("MCE-B013-U")
        cam = cls(dev, start, CameraInfo(start.model, "?", "?", dev.idProduct, dev.bus,
                                         dev.address), backend)
        try:
            fw = cam._wake_up()
            info = p.decode_device_info(cam._query(p.encode_device_info_query(), "device info",
                                                   p.DEVICE_INFO_BYTES))
            spec = profile or p.SPECS.get(info.model, cam._spec)
            cam._spec = spec
            cam.info = CameraInfo(info.model or spec.model, info.serial, fw, dev.idProduct,
                                  dev.bus, dev.address)
            if configure:
                cam._apply_all()
        except BaseException:
            cam.close()
            raise
        return cam

    def _wake_up(self) -> str:
        """Drop stale replies, then ask for the firmware version until the camera answers:
        for the profile's power-up time (~3 s), a query every :data:`WAKE_RETRY_S`."""
        self._drain_replies()
        last: Exception | None = None
        tries = math.ceil(self._spec.power_up_wait_s / WAKE_RETRY_S) + 2
        for attempt in range(tries):
            try:
                return "{}.{}.{}".format(*p.decode_firmware(
                    self._query(p.encode_firmware_query(), "firmware version", 3)))
            except DeviceTimeoutError as exc:
                last = exc
                if attempt + 1 < tries:
                    self._wait(WAKE_RETRY_S)
        raise DeviceTimeoutError(
            f"camera did not answer the firmware query for "
            f"{tries * WAKE_RETRY_S:g} s ({tries} tries)") from last

    @_locked
    def reopen(self) -> None:
        """Reconnect to the same serial number (after a lost device) and restore all settings."""
        settings = self._settings
        log.info("camera %s: reconnecting", self.info.serial)
        self.close()
        fresh = type(self).open(self.info.serial, backend=self._backend, pid=self.info.pid,
                                profile=self._spec)
        self._dev, self._spec, self.info = fresh._dev, fresh._spec, fresh.info
        fresh._dev = None
        self._settings = settings
        self._resync_replies = False
        self._apply_all()

    def close(self) -> None:
        """Release the USB interface (safe to call twice, and after the device was lost)."""
        dev, self._dev = self._dev, None
        if dev is None:
            return
        try:
            usb.util.dispose_resources(dev)
        except (usb.core.USBError, ValueError):
            pass  # already gone

    def __enter__(self) -> MightexCamera:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------ transport

    @property
    def _device(self) -> usb.core.Device:
        if self._dev is None:
            raise DeviceLostError("camera is closed; call reopen() or MightexCamera.open()")
        return self._dev

    def _send(self, data: bytes) -> None:
        io_trace.record("camera", ">", data, p.EP_COMMAND_OUT)
        with _usb_errors(f"command 0x{data[0]:02X}"):
            self._device.write(p.EP_COMMAND_OUT, data, REPLY_TIMEOUT_MS)

    def _read(self, ep: int, size_or_buffer: int | array.array[int], timeout_ms: int,
              what: str) -> Any:
        """One bulk read, recorded in the cassette (a timeout too: replay repeats it)."""
        try:
            with _usb_errors(what):
                data = self._device.read(ep, size_or_buffer, timeout_ms)
        except DeviceTimeoutError:
            io_trace.timed_out("camera", ep)
            raise
        if isinstance(size_or_buffer, int):
            io_trace.record("camera", "<", data, ep)
        else:
            io_trace.record("camera", "<", memoryview(size_or_buffer)[:data], ep)
        return data

    def _drain_replies(self) -> None:
        for _ in range(8):
            try:
                self._read(p.EP_REPLY_IN, 255, 20, "drain")
            except DeviceTimeoutError:
                return
        self._resync_replies = False

    def _query(self, data: bytes, what: str, expected_len: int) -> bytes:
        if self._resync_replies:  # a late reply to an earlier, failed query may be waiting
            self._drain_replies()
            self._resync_replies = False
        self._send(data)
        try:
            reply = bytes(self._read(p.EP_REPLY_IN, 255, REPLY_TIMEOUT_MS, what))
            return p.decode_reply(reply, what, expected_len)
        except (DeviceTimeoutError, ProtocolError, KeyboardInterrupt):  # Ctrl-C, SIGTERM too
            self._resync_replies = True
            raise

    # ------------------------------------------------------------------ settings

    @property
    def identity(self) -> DeviceIdentity:
        return DeviceIdentity(self.info.model, self.info.serial, self.info.firmware)

    @property
    def spec(self) -> p.CameraSpec:
        return self._spec

    def use_profile(self, spec: p.CameraSpec) -> None:
        """Read the camera with another profile from now on (facts settled on the bench, e.g.
        the trailer order); nothing is sent."""
        self._spec = spec

    def host_time_s(self) -> float:
        """The host's clock, seconds (a simulated camera's own clock when simulated)."""
        return self._now()

    @property
    def exposure_ms(self) -> float:
        """Exposure as set on the camera (rounded to the model's step)."""
        return round(self._settings.exposure_counts * self._spec.exposure_unit_ms, 9)

    @property
    def gain(self) -> float:
        return self._settings.gain_raw / p.GAIN_RAW_PER_UNITY

    @property
    def frame_time_ms(self) -> float:
        return self._settings.frame_time_counts * self._spec.frame_time_unit_ms

    @property
    def settings(self) -> dict[str, Any]:
        """Current configuration (JSON-safe)."""
        s = self._settings
        return {"width": s.width, "height": s.height, "bits": s.bits, "mode": s.mode,
                "bin_code": s.bin_code, "buffer_count": s.buffer_count,
                "exposure_ms": self.exposure_ms, "gain": self.gain,
                "frame_time_ms": self.frame_time_ms}

    @_locked
    def _do_configure(self, *, width: int, height: int, bits: int, mode: str,
                      bin_code: int = 0, buffer_count: int = 4, **unknown: int) -> None:
        """Set work mode, bit depth, geometry, bin code and buffer depth; flush old frames.

        Options: ``bin_code`` (0 = no decimation) and ``buffer_count`` (frames the camera
        buffers). Raises ``SettingOutOfRangeError`` (nothing sent) for values the model
        refuses: width/height multiples of 4 in 8..1280 x 8..1024, bits 8 or 12, buffer 1..24.
        """
        if unknown:
            raise SettingOutOfRangeError(
                f"camera: unknown option(s) {', '.join(sorted(unknown))}; nothing sent")
        p.check_geometry(self._spec, width=width, height=height, bits=bits, mode=mode,
                         bin_code=bin_code, buffer_count=buffer_count)
        s = self._settings
        s.width, s.height, s.bits, s.mode = width, height, bits, mode
        s.bin_code, s.buffer_count = bin_code, buffer_count
        self._send(p.encode_work_mode(mode, bits))
        self._wait(self._spec.work_mode_wait_s)  # commands right after 0x30 can be lost
        self._send(p.encode_resolution(width, height, bin_code, buffer_count))
        self.clear_buffer()

    @_locked
    def _do_set_exposure_ms(self, exposure_ms: float) -> None:
        """Exposure in ms, in the profile's steps (0.05 .. 750 ms on the MCE-B013-U)."""
        counts = p.exposure_counts(exposure_ms, self._spec)
        self._send(p.encode_exposure(counts, self._spec.exposure_bytes))
        self._remember_previous()
        self._settings.exposure_counts = counts

    @_locked
    def _do_set_gain(self, gain: float) -> None:
        """Gain multiplier 0.125 .. 8 in 1/8 steps (1.0 = unity, raw code = gain x 8)."""
        raw = p.gain_raw(gain, self._spec)
        self._send(p.encode_gain(raw))
        self._remember_previous()
        self._settings.gain_raw = raw

    def _remember_previous(self) -> None:
        s = self._settings
        self._previous = (s.exposure_counts, s.gain_raw)

    @_locked
    def set_frame_time_ms(self, frame_time_ms: float) -> None:
        """Free-running frame period in normal mode (model unit: 0.1 or 0.05 ms)."""
        counts = p.frame_time_counts(frame_time_ms, self._spec)
        self._send(p.encode_frame_time(counts))
        self._settings.frame_time_counts = counts

    def _apply_all(self) -> None:
        s = self._settings
        self.configure(width=s.width, height=s.height, bits=s.bits, mode=s.mode,
                       bin_code=s.bin_code, buffer_count=s.buffer_count)
        self._send(p.encode_exposure(s.exposure_counts, self._spec.exposure_bytes))
        self._send(p.encode_frame_time(s.frame_time_counts))
        self._send(p.encode_gain(s.gain_raw))

    @_locked
    def firmware_version(self) -> str:
        return "{}.{}.{}".format(*p.decode_firmware(
            self._query(p.encode_firmware_query(), "firmware version", 3)))

    @_locked
    def device_info(self) -> p.DeviceInfo:
        return p.decode_device_info(
            self._query(p.encode_device_info_query(), "device info", p.DEVICE_INFO_BYTES))

    @_locked
    def buffer_status(self) -> p.BufferStatus:
        """Frames waiting in the camera and the geometry of the oldest one (command 0x33)."""
        return p.decode_buffer_status(self._query(p.encode_query_buffer(), "buffer query", 6))

    @_locked
    def clear_buffer(self) -> int:
        """Discard every frame waiting in the camera; returns how many there were."""
        n = self.buffer_status().frames
        if n:
            self._send(p.encode_clear_buffer(n))
        return n

    @_locked
    def software_trigger(self) -> None:
        """Expose one frame now (trigger mode only; ignored by the camera otherwise)."""
        self._send(p.encode_soft_trigger())

    @_locked
    def reset(self) -> None:
        """Reset the camera firmware, wait for it to power up, restore this driver's settings."""
        self._send(p.encode_reset())
        self._wake_up()
        self._apply_all()

    # ------------------------------------------------------------------ frames

    @property
    def layout(self) -> p.FrameLayout:
        s = self._settings
        return p.FrameLayout(s.width, s.height, s.bits)

    @_locked
    def _do_grab(self, timeout_s: float | None, *, fresh: bool = True) -> Frame[FrameMeta]:
        """Normal mode, ``fresh``: a frame exposed wholly after this call. Frames already in
        the camera are cleared unread; the one being exposed at the call (the first to arrive
        after the clear) is read and dropped; of the frames after it the newest is returned.
        ``fresh=False`` (a live stream): the newest frame the camera holds, maybe exposed
        before the call.
        Trigger mode: the next frame in order (one per trigger, none lost). Waits for a frame
        if none is there; ``timeout_s`` defaults to three frame periods plus 5 s.

        The frame's trailer is its truth (``meta.exposure_ms``, ``meta.gain``): the camera
        may raise an exposure to its minimum or clamp a gain, within the profile's tolerance.
        A trailer further off in :data:`MAX_DISCARDS` frames in a row means the camera does not
        follow this model's profile (exposure field, unit): :class:`CameraProfileMismatchError`.

        Raises
        ------
        DeviceTimeoutError
            No frame within ``timeout_s`` (e.g. trigger mode without a trigger).
        DeviceLostError, ProtocolError
            Unplugged mid-transfer; short, oversize or inconsistent frame.
        """
        s = self._settings
        if timeout_s is None:
            timeout_s = 3 * max(self.exposure_ms, self.frame_time_ms) / 1e3 + 5.0
        deadline = time.monotonic() + timeout_s
        normal = s.mode == "normal"
        under_way = normal and fresh  # the frame being exposed now began before this call
        if under_way:
            self.skipped_frames += self.clear_buffer()
        off_settings: list[p.FrameTrailer] = []
        other_geometry = 0
        while True:
            status = self.buffer_status()
            if status.frames == 0:
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise DeviceTimeoutError(
                        f"no frame within {timeout_s:g} s (mode {s.mode}, exposure "
                        f"{self.exposure_ms:g} ms)")
                self._sleep(min(POLL_INTERVAL_S, remaining))
                continue
            if (status.width, status.height, status.bin_code) != (s.width, s.height, s.bin_code):
                self._send(p.encode_clear_buffer(status.frames))  # older geometry: unreadable
                self.discarded_frames += status.frames
                other_geometry += 1
                if other_geometry >= MAX_DISCARDS:  # new frames keep coming in another one
                    raise CameraRoiRefusedError(
                        f"camera keeps sending {status.width}x{status.height} frames (bin "
                        f"0x{status.bin_code:02X}) after {s.width}x{s.height} was set: it did "
                        "not take the resolution command (0x60)")
                continue
            if normal and status.frames == 1 and under_way:
                # The one under way at the call: read and dropped (not cleared: its trailer
                # is checked, and 0x35 does not say which frame it discards).
                self._read_frame()
                self.skipped_frames += 1
                under_way = False
                continue
            if normal and status.frames > 1:  # keep only the newest: exposed after the call
                self._send(p.encode_clear_buffer(status.frames - 1))
                self.skipped_frames += status.frames - 1
                under_way = False
            pixels, trailer = self._read_frame()
            if self._trailer_fits(trailer):
                return self._make_frame(pixels, trailer)
            self.discarded_frames += 1
            off_settings.append(trailer)
            if len(off_settings) >= MAX_DISCARDS:
                raise CameraProfileMismatchError(self._mismatch_text(off_settings[-1]))

    def _trailer_fits(self, t: p.FrameTrailer) -> bool:
        """Within the profile's tolerance of the settings - and not a frame exposed with the
        settings before the last change (the tolerance is for the camera's own limits)."""
        s, spec = self._settings, self._spec
        current = (s.exposure_counts, s.gain_raw)
        if (t.exposure_counts, t.green_gain) == self._previous != current:
            return False
        return (spec.exposure_within_tolerance(s.exposure_counts, t.exposure_counts)
                and abs(t.green_gain - s.gain_raw) <= spec.gain_tolerance_raw)

    def _mismatch_text(self, t: p.FrameTrailer) -> str:
        s, spec = self._settings, self._spec
        return (
            f"camera frames disagree with the {spec.model} profile: {MAX_DISCARDS} frames in a "
            f"row carry exposure {t.exposure_counts} counts and gain raw {t.green_gain} in "
            f"their trailer, but the driver set {s.exposure_counts} counts "
            f"({s.exposure_counts * spec.exposure_unit_ms:g} ms as a {spec.exposure_bytes}-byte "
            f"field of {spec.exposure_unit_ms:g} ms units) and gain raw {s.gain_raw}. The camera "
            "ignored or misread the setting: its exposure field or unit differs. Run `benchlab "
            "doctor` and set [camera] model to the profile that fits")

    def _read_frame(self) -> tuple[npt.NDArray[Any], p.FrameTrailer]:
        layout = self.layout
        self._send(p.encode_get_image(1))
        # One fresh buffer per frame: the returned pixels are a view of it (no copy).
        buf = array.array("B", b"\0") * layout.total_bytes
        timeout_ms = 1000 + layout.total_bytes // 20_000  # >= 20 MB/s on USB 2.0
        try:
            received = self._read(p.EP_FRAME_IN, buf, timeout_ms, "frame read")
        except DeviceTimeoutError as exc:
            raise FrameEndpointTimeoutError(
                f"no frame came on EP 0x{p.EP_FRAME_IN:02X} within {timeout_ms} ms, although "
                "the camera's buffer query said one was waiting") from exc
        try:
            return p.decode_frame(buf, layout, received, self._spec.trailer_order)
        except ProtocolError:
            # A frame of another size than expected: what is left of it (or of the next one)
            # would be read as the start of the following frame. Drain the endpoint first.
            self._drain_frames()
            raise

    def _drain_frames(self) -> None:
        """Read the frame endpoint until it times out (or :data:`MAX_DRAIN_READS` reads)."""
        for _ in range(MAX_DRAIN_READS):
            try:
                chunk = self._read(p.EP_FRAME_IN, DRAIN_CHUNK_BYTES, DRAIN_TIMEOUT_MS, "drain")
            except DeviceTimeoutError:
                return
            self.drained_bytes += len(chunk)

    def _make_frame(self, pixels: npt.NDArray[Any], t: p.FrameTrailer) -> Frame:
        s = self._settings
        meta = FrameMeta(
            width=t.row, height=t.column, bits=s.bits, mode=s.mode, bin_code=t.bin_code,
            gain=t.green_gain / p.GAIN_RAW_PER_UNITY, gain_raw=t.green_gain,
            exposure_ms=round(t.exposure_counts * self._spec.exposure_unit_ms, 6),
            exposure_counts=t.exposure_counts,
            frame_time_ms=round(t.frame_time * self._spec.frame_time_unit_ms, 6),
            timestamp_ms=_timestamp_ms(t.timestamp_ms, self._spec.timestamp_unit_ms),
            trigger_occurred=bool(t.trigger_occurred),
            trigger_count=t.trigger_count, x_start=t.x_start, y_start=t.y_start,
            received_utc=datetime.now(UTC).isoformat(timespec="milliseconds"),
            pixel_size_um=self._spec.pixel_size_um(t.bin_code),
            set_exposure_ms=self.exposure_ms, set_gain=self.gain,
        )
        return Frame(pixels, meta)


def _timestamp_ms(counts: int, unit_ms: float) -> float:
    """A trailer timestamp in ms (an int when the unit is 1 ms, as it was recorded before)."""
    return counts if unit_ms == 1.0 else round(counts * unit_ms, 1)
