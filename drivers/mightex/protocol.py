"""Pure encode/decode of the Mightex "Buffer USB Camera" protocol (no I/O).

Wire facts are from ``shared/docs/device-protocols.md`` section A: commands on EP 0x01 are
``[id][n][params...]`` with big-endian parameters, query replies on EP 0x81 are
``[result][n][data...]`` (any non-zero result is OK), frames on EP 0x82 are pixel data, zero
padding up to a multiple of 512 bytes and a 512-byte little-endian property trailer.

Choices where the public sources are silent (documented in the camera README section):

* geometry: width and height multiples of 4 (S-series rule), at least 8 (gclef clamp), at most
  the sensor size; padding rounds the pixel bytes up to the next multiple of 512;
* the MT9M001 bin codes are undocumented, so only bin code 0 (no binning) is accepted;
* per-model facts (exposure field, bit depths, timing, buffer policy) are profiles in
  :mod:`benchlab.drivers.mightex.profile`.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass

import numpy as np
import numpy.typing as npt

from benchlab.drivers.errors import ProtocolError, SettingOutOfRangeError
from benchlab.drivers.mightex.profile import DEFAULT_PID, SPECS, CameraSpec, spec_for

__all__ = ["DEFAULT_PID", "SPECS", "CameraSpec", "spec_for"]  # re-exported: the profile

VENDOR_ID = 0x04B4
EP_COMMAND_OUT = 0x01
EP_REPLY_IN = 0x81
EP_FRAME_IN = 0x82
INTERFACE = 0

CMD_FIRMWARE = 0x01
CMD_DEVICE_INFO = 0x21
CMD_WORK_MODE = 0x30
CMD_CLOCK = 0x32
CMD_QUERY_BUFFER = 0x33
CMD_GET_IMAGE = 0x34
CMD_CLEAR_BUFFER = 0x35
CMD_SOFT_TRIGGER = 0x36
CMD_RESET = 0x50
CMD_RESOLUTION = 0x60
CMD_GAIN = 0x62
CMD_EXPOSURE = 0x63
CMD_FRAME_TIME = 0x64

EXPOSURE_STEP_MS = 0.05
GAIN_RAW_PER_UNITY = 8
TRAILER_BYTES = 512
FRAME_ALIGN_BYTES = 512
DEVICE_INFO_BYTES = 43
MODES = {"normal": 0, "trigger": 1}
MODE_NAMES = {v: k for k, v in MODES.items()}

#: Relative slack when checking a float setting against its limits (float round-off only).
_RANGE_SLACK = 1e-9


# --------------------------------------------------------------------------- settings -> raw


def _finite(name: str, value: float) -> float:
    v = float(value)
    if not math.isfinite(v):
        raise SettingOutOfRangeError(f"{name} must be a finite number, got {value!r}")
    return v


def exposure_counts(exposure_ms: float, spec: CameraSpec) -> int:
    """Exposure in the model's counts (nearest step); refuses values outside its range."""
    v = _finite("exposure_ms", exposure_ms)
    lo, hi = spec.exposure_unit_ms, spec.exposure_max_ms
    if not lo * (1 - _RANGE_SLACK) <= v <= hi * (1 + _RANGE_SLACK):
        raise SettingOutOfRangeError(
            f"exposure {v:g} ms out of range: {spec.model} accepts {lo:g} .. {hi:g} ms "
            f"in {spec.exposure_unit_ms:g} ms steps"
        )
    return min(max(round(v / spec.exposure_unit_ms), 1), spec.exposure_max_counts)


def gain_raw(gain: float, spec: CameraSpec) -> int:
    """Raw gain code (gain x 8, nearest step); refuses gains outside raw 1..64."""
    v = _finite("gain", gain)
    lo = spec.gain_raw_min / GAIN_RAW_PER_UNITY
    hi = spec.gain_raw_max / GAIN_RAW_PER_UNITY
    if not lo * (1 - _RANGE_SLACK) <= v <= hi * (1 + _RANGE_SLACK):
        raise SettingOutOfRangeError(
            f"gain {v:g}x out of range: {spec.model} accepts {lo:g} .. {hi:g}x "
            f"in steps of {1 / GAIN_RAW_PER_UNITY:g} (raw {spec.gain_raw_min}..{spec.gain_raw_max})"
        )
    return min(max(round(v * GAIN_RAW_PER_UNITY), spec.gain_raw_min), spec.gain_raw_max)


def frame_time_counts(frame_time_ms: float, spec: CameraSpec) -> int:
    """Frame time in the model's units (nearest step), 1 .. 65535 units."""
    v = _finite("frame_time_ms", frame_time_ms)
    unit = spec.frame_time_unit_ms
    if not unit * (1 - _RANGE_SLACK) <= v <= spec.frame_time_max_ms * (1 + _RANGE_SLACK):
        raise SettingOutOfRangeError(
            f"frame time {v:g} ms out of range: {spec.model} accepts {unit:g} .. "
            f"{spec.frame_time_max_ms:g} ms in {unit:g} ms steps"
        )
    return min(max(round(v / unit), 1), 0xFFFF)


def check_geometry(
    spec: CameraSpec, *, width: int, height: int, bits: int, mode: str, bin_code: int,
    buffer_count: int,
) -> None:
    """Refuse any acquisition setting the model does not accept (nothing is sent)."""
    limits = (("width", width, spec.max_width), ("height", height, spec.max_height))
    for name, value, limit in limits:
        if (
            not isinstance(value, int | np.integer)
            or not spec.min_size <= value <= limit
            or value % spec.size_step
        ):
            raise SettingOutOfRangeError(
                f"{name} {value!r} out of range: {spec.model} accepts {spec.min_size} .. {limit} "
                f"pixels in multiples of {spec.size_step}"
            )
    if bits not in spec.bit_depths:
        raise SettingOutOfRangeError(
            f"bit depth {bits!r} not supported: {spec.model} accepts "
            f"{' or '.join(map(str, spec.bit_depths))}"
        )
    if mode not in MODES:
        raise SettingOutOfRangeError(f"mode {mode!r} unknown: use one of {', '.join(MODES)}")
    if bin_code not in spec.bin_codes:
        raise SettingOutOfRangeError(
            f"bin code {bin_code!r} not supported: {spec.model} accepts "
            f"{', '.join(f'0x{c:02X}' for c in spec.bin_codes)}"
        )
    if not isinstance(buffer_count, int) or not 1 <= buffer_count <= spec.max_buffer_count:
        raise SettingOutOfRangeError(
            f"buffer count {buffer_count!r} out of range: {spec.model} accepts "
            f"1 .. {spec.max_buffer_count} frames"
        )


# --------------------------------------------------------------------------- commands


def command(cmd_id: int, *params: int) -> bytes:
    """``[id][n][params]``; every parameter is one byte (multi-byte values pre-split BE)."""
    return bytes((cmd_id, len(params), *params))


def encode_firmware_query() -> bytes:
    return command(CMD_FIRMWARE, 0x01)


def encode_device_info_query() -> bytes:
    return command(CMD_DEVICE_INFO, 0x00)


def encode_work_mode(mode: str, bits: int) -> bytes:
    return command(CMD_WORK_MODE, MODES[mode], bits)


def encode_clock(divider: int) -> bytes:
    return command(CMD_CLOCK, divider)


def encode_query_buffer() -> bytes:
    return command(CMD_QUERY_BUFFER, 0x00)


def encode_get_image(n_frames: int = 1) -> bytes:
    return command(CMD_GET_IMAGE, n_frames)


def encode_clear_buffer(n_frames: int) -> bytes:
    return command(CMD_CLEAR_BUFFER, n_frames)


def encode_soft_trigger() -> bytes:
    return command(CMD_SOFT_TRIGGER, 0x00)


def encode_reset() -> bytes:
    return command(CMD_RESET, 0x01)


def encode_resolution(width: int, height: int, bin_code: int, buffer_count: int) -> bytes:
    # "Row" is the line length (width), "Column" the number of lines (height); BufOpt = 0.
    return command(CMD_RESOLUTION, *width.to_bytes(2, "big"), *height.to_bytes(2, "big"),
                   bin_code, buffer_count, 0)


def encode_gain(raw: int) -> bytes:
    # Monochrome sensor: the green channel is the gain; all three get the same value.
    return command(CMD_GAIN, raw, raw, raw)


def encode_exposure(counts: int, n_bytes: int) -> bytes:
    return command(CMD_EXPOSURE, *counts.to_bytes(n_bytes, "big"))


def encode_frame_time(counts: int) -> bytes:
    return command(CMD_FRAME_TIME, *counts.to_bytes(2, "big"))


# --------------------------------------------------------------------------- replies


def encode_reply(data: bytes, status: int = 0x01) -> bytes:
    return bytes((status, len(data))) + data


def decode_reply(reply: bytes, what: str, expected_len: int) -> bytes:
    """Check ``[result][n][data]`` framing and return ``data`` (``expected_len`` bytes).

    Any non-zero result byte is accepted: a 0x33 reply was seen with 0x08 instead of 0x01.
    """
    if len(reply) < 2:
        raise ProtocolError(f"{what}: reply too short ({len(reply)} bytes: {reply.hex(' ')})")
    status, n = reply[0], reply[1]
    if status == 0:
        raise ProtocolError(f"{what}: camera reported an error (reply {reply[:8].hex(' ')})")
    if n != len(reply) - 2:
        raise ProtocolError(
            f"{what}: reply length byte says {n} but {len(reply) - 2} data bytes followed "
            f"(reply starts {reply[:8].hex(' ')})"
        )
    if n != expected_len:
        raise ProtocolError(f"{what}: expected {expected_len} data bytes, got {n}")
    return bytes(reply[2:])


def decode_firmware(data: bytes) -> tuple[int, int, int]:
    return data[0], data[1], data[2]


@dataclass(frozen=True)
class DeviceInfo:
    """Reply of 0x21: configuration revision, module number (model), serial, date."""

    config_revision: int
    model: str
    serial: str
    manufacture_date: str


def _field(raw: bytes) -> str:
    return raw.split(b"\0", 1)[0].decode("ascii", "replace").strip()


def decode_device_info(data: bytes) -> DeviceInfo:
    return DeviceInfo(data[0], _field(data[1:15]), _field(data[15:29]), _field(data[29:43]))


def encode_device_info(info: DeviceInfo) -> bytes:
    def pad(text: str) -> bytes:
        raw = text.encode("ascii")[:14]
        return raw + b"\0" * (14 - len(raw))

    return bytes((info.config_revision,)) + pad(info.model) + pad(info.serial) + pad(
        info.manufacture_date
    )


@dataclass(frozen=True)
class BufferStatus:
    """Reply of 0x33: frames waiting and the geometry of the oldest one."""

    frames: int
    width: int
    height: int
    bin_code: int


def decode_buffer_status(data: bytes) -> BufferStatus:
    return BufferStatus(
        data[0], int.from_bytes(data[1:3], "big"), int.from_bytes(data[3:5], "big"), data[5]
    )


def encode_buffer_status(status: BufferStatus) -> bytes:
    return (
        bytes((status.frames,)) + status.width.to_bytes(2, "big")
        + status.height.to_bytes(2, "big") + bytes((status.bin_code,))
    )


# --------------------------------------------------------------------------- frames

_TRAILER = struct.Struct("<14HI")


@dataclass(frozen=True)
class FrameTrailer:
    """The 512-byte little-endian frame property block that follows every frame."""

    row: int
    column: int
    bin_code: int
    x_start: int
    y_start: int
    red_gain: int
    green_gain: int
    blue_gain: int
    timestamp_ms: int
    trigger_occurred: int
    trigger_count: int
    user_mark: int
    frame_time: int
    clock: int
    exposure_counts: int


class TrailerGeometryError(ProtocolError):
    """A frame trailer's geometry differs from the configured one (``trailer`` is the
    (first, second) word pair as received, ``configured`` the (width, height))."""

    def __init__(self, message: str, trailer: tuple[int, int],
                 configured: tuple[int, int]) -> None:
        super().__init__(message)
        self.trailer, self.configured = trailer, configured

    @property
    def swapped(self) -> bool:
        """Whether the trailer gives the same geometry with its words the other way round."""
        return self.trailer == self.configured[::-1] != self.configured


def encode_trailer(t: FrameTrailer, order: str = "row_column") -> bytes:
    first, second = (t.row, t.column) if order == "row_column" else (t.column, t.row)
    head = _TRAILER.pack(
        first, second, t.bin_code, t.x_start, t.y_start, t.red_gain, t.green_gain,
        t.blue_gain, t.timestamp_ms & 0xFFFF, t.trigger_occurred, t.trigger_count & 0xFFFF,
        t.user_mark, t.frame_time, t.clock, t.exposure_counts,
    )
    return head + bytes(TRAILER_BYTES - len(head))


def decode_trailer(raw: bytes | memoryview, order: str = "row_column") -> FrameTrailer:
    """The trailer; ``order`` is the profile's :attr:`~CameraSpec.trailer_order`."""
    if len(raw) != TRAILER_BYTES:
        raise ProtocolError(f"frame trailer is {len(raw)} bytes, expected {TRAILER_BYTES}")
    first, second, *rest = _TRAILER.unpack_from(raw)
    row, column = (first, second) if order == "row_column" else (second, first)
    return FrameTrailer(row, column, *rest)


@dataclass(frozen=True)
class FrameLayout:
    """Byte layout of one frame transfer: pixels, zero padding, trailer."""

    width: int
    height: int
    bits: int

    @property
    def bytes_per_pixel(self) -> int:
        return 1 if self.bits == 8 else 2

    @property
    def pixel_bytes(self) -> int:
        return self.width * self.height * self.bytes_per_pixel

    @property
    def padding_bytes(self) -> int:
        return -self.pixel_bytes % FRAME_ALIGN_BYTES

    @property
    def total_bytes(self) -> int:
        return self.pixel_bytes + self.padding_bytes + TRAILER_BYTES

    @property
    def trailer_offset(self) -> int:
        return self.pixel_bytes + self.padding_bytes


#: Chunk of pixels unpacked at a time, so the four passes run in cache (64k pixels = 128 kB).
_UNPACK_CHUNK = 1 << 16


def unpack_12bit_inplace(words: npt.NDArray[np.uint16]) -> npt.NDArray[np.uint16]:
    """Turn packed 12-bit pixels into values 0..4095, in place, and return the same array.

    Each pixel arrives as two bytes: byte0 = 8 MSBs, low nibble of byte1 = 4 LSBs. Read as a
    little-endian u16 ``w = b0 | b1 << 8``; ``t = w * 16`` (wrapping) leaves ``b0`` in bits
    4..11 and the low nibble of ``b1`` in bits 12..15 (its high nibble falls off), so the value
    is ``(t >> 12) | (t & 0x0FF0)``. Four vectorised passes per cache-sized chunk.
    """
    flat = words.reshape(-1)
    tmp = np.empty(min(_UNPACK_CHUNK, flat.size), dtype=np.uint16)
    sixteen, twelve, mask = np.uint16(16), np.uint16(12), np.uint16(0x0FF0)
    for start in range(0, flat.size, _UNPACK_CHUNK):
        w = flat[start:start + _UNPACK_CHUNK]
        t = tmp[: w.size]
        np.multiply(w, sixteen, out=t)  # a multiply is faster than left_shift in numpy
        np.right_shift(t, twelve, out=w)
        np.bitwise_and(t, mask, out=t)
        np.bitwise_or(w, t, out=w)
    return words


def pack_12bit(values: npt.NDArray[np.uint16], out: npt.NDArray[np.uint16]) -> None:
    """Inverse of :func:`unpack_12bit_inplace`: write ``b0 = v >> 4``, ``b1 = v & 0xF`` words."""
    v = values.reshape(-1)
    o = out.reshape(-1)
    np.right_shift(v, np.uint16(4), out=o)
    low = np.bitwise_and(v, np.uint16(0x000F))
    np.left_shift(low, np.uint16(8), out=low)
    np.bitwise_or(o, low, out=o)


def unpack_10bit_inplace(words: npt.NDArray[np.uint16]) -> npt.NDArray[np.uint16]:
    """Turn packed 10-bit pixels into values 0..1023, in place ([SH]'s BTN-B013U mode).

    Each pixel arrives as two bytes, byte0 = 8 MSBs and byte1 = the 2 LSBs; read as a
    little-endian u16 ``w = b0 | b1 << 8`` the value is ``(w & 0xFF) << 2 | (w >> 8) & 3``.
    (Decoded with the 12-bit rule instead, 1023 would read 4083.)
    """
    flat = words.reshape(-1)
    low = np.right_shift(flat, np.uint16(8))
    np.bitwise_and(low, np.uint16(0x3), out=low)
    np.bitwise_and(flat, np.uint16(0xFF), out=flat)
    np.left_shift(flat, np.uint16(2), out=flat)
    np.bitwise_or(flat, low, out=flat)
    return words


def pack_10bit(values: npt.NDArray[np.uint16], out: npt.NDArray[np.uint16]) -> None:
    """Inverse of :func:`unpack_10bit_inplace`: ``b0 = v >> 2``, ``b1 = v & 3`` words."""
    v = values.reshape(-1)
    o = out.reshape(-1)
    np.right_shift(v, np.uint16(2), out=o)
    low = np.bitwise_and(v, np.uint16(0x3))
    np.left_shift(low, np.uint16(8), out=low)
    np.bitwise_or(o, low, out=o)


def depth_of_transfer(received: int, width: int, height: int) -> str:
    """What a frame transfer of ``received`` bytes would be at this geometry (for messages)."""
    for bits in (8, 12):
        if FrameLayout(width, height, bits).total_bytes == received:
            return "an 8-bit frame" if bits == 8 else "a 10/12-bit frame"
    return "no frame of this size"


def decode_frame(
    buffer: bytearray | memoryview | object, layout: FrameLayout, received: int,
    trailer_order: str = "row_column",
) -> tuple[npt.NDArray[np.uint8] | npt.NDArray[np.uint16], FrameTrailer]:
    """Split one received frame into pixels (a view of ``buffer``, no copy) and its trailer.

    ``buffer`` must be writable (12-bit frames are unpacked in place). Raises
    :class:`ProtocolError` if ``received`` differs from the layout's transfer size, and
    :class:`TrailerGeometryError` if the trailer's geometry (read in ``trailer_order``)
    differs from ``layout``.
    """
    if received != layout.total_bytes:
        raise ProtocolError(
            f"frame transfer was {received} bytes, expected {layout.total_bytes} for "
            f"{layout.width}x{layout.height} {layout.bits}-bit ({received} bytes is "
            f"{depth_of_transfer(received, layout.width, layout.height)}: if the camera did not "
            "take the bit depth, its profile differs - run `benchlab doctor`)"
        )
    mv = memoryview(buffer).cast("B")  # type: ignore[arg-type]
    trailer = decode_trailer(mv[layout.trailer_offset:layout.total_bytes], trailer_order)
    if (trailer.row, trailer.column) != (layout.width, layout.height):
        raise TrailerGeometryError(
            f"frame trailer says {trailer.row}x{trailer.column}, configured "
            f"{layout.width}x{layout.height} (trailer read in {trailer_order} order)",
            (trailer.row, trailer.column), (layout.width, layout.height))
    n = layout.width * layout.height
    pixels: npt.NDArray[np.uint8] | npt.NDArray[np.uint16]
    if layout.bits == 8:
        pixels = np.frombuffer(mv, dtype=np.uint8, count=n)
    elif layout.bits == 10:
        pixels = unpack_10bit_inplace(np.frombuffer(mv, dtype="<u2", count=n))
    else:
        pixels = unpack_12bit_inplace(np.frombuffer(mv, dtype="<u2", count=n))
    return pixels.reshape(layout.height, layout.width), trailer
