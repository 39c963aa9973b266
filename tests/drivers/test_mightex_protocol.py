"""Byte-exact tests of the Mightex buffer-camera protocol (pure encode/decode, no I/O)."""

from __future__ import annotations

import array

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchlab.drivers.errors import ProtocolError, SettingOutOfRangeError
from benchlab.drivers.mightex import protocol as p

MCE = p.SPECS["MCE-B013-U"]  # the CMOS defaults: 2-byte exposure, 0.05 ms frame time
V106 = p.SPECS["MCE-B013-U/v1.0.6"]  # the v1.0.6 document: 4-byte exposure, 0.1 ms
BTN = p.SPECS["BTN-B013U"]


@pytest.mark.parametrize(
    ("encoded", "expected"),
    [
        (p.encode_firmware_query(), "01 01 01"),
        (p.encode_device_info_query(), "21 01 00"),
        (p.encode_work_mode("normal", 8), "30 02 00 08"),
        (p.encode_work_mode("trigger", 12), "30 02 01 0c"),
        (p.encode_clock(2), "32 01 02"),
        (p.encode_query_buffer(), "33 01 00"),
        (p.encode_get_image(1), "34 01 01"),
        (p.encode_clear_buffer(3), "35 01 03"),
        (p.encode_soft_trigger(), "36 01 00"),
        (p.encode_reset(), "50 01 01"),
        (p.encode_resolution(1280, 1024, 0, 4), "60 07 05 00 04 00 00 04 00"),
        (p.encode_resolution(8, 12, 0, 24), "60 07 00 08 00 0c 00 18 00"),
        (p.encode_gain(8), "62 03 08 08 08"),
        (p.encode_gain(64), "62 03 40 40 40"),
        (p.encode_exposure(6000, 4), "63 04 00 00 17 70"),
        (p.encode_exposure(4_000_000, 4), "63 04 00 3d 09 00"),
        (p.encode_exposure(15_000, 2), "63 02 3a 98"),
        (p.encode_frame_time(1), "64 02 00 01"),
        (p.encode_frame_time(0xFFFF), "64 02 ff ff"),
    ],
)
def test_command_bytes(encoded: bytes, expected: str) -> None:
    assert encoded == bytes.fromhex(expected)


def test_setting_conversions() -> None:
    assert p.exposure_counts(300, MCE) == 6000
    assert p.exposure_counts(0.05, MCE) == 1
    assert p.exposure_counts(200_000, V106) == 4_000_000
    assert p.exposure_counts(750, MCE) == 15_000
    assert p.exposure_counts(750, BTN) == 15_000
    assert p.exposure_counts(0.074, MCE) == 1  # nearest 0.05 ms step
    assert p.gain_raw(1.0, MCE) == 8
    assert p.gain_raw(0.125, MCE) == 1
    assert p.gain_raw(8, MCE) == 64
    assert p.frame_time_counts(0.1, V106) == 1
    assert p.frame_time_counts(0.1, MCE) == 2
    assert p.frame_time_counts(100, BTN) == 2000


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: p.exposure_counts(0.02, V106), "0.05 .. 200000 ms"),
        (lambda: p.exposure_counts(750.05, MCE), "0.05 .. 750 ms"),
        (lambda: p.exposure_counts(750.05, BTN), "0.05 .. 750 ms"),
        (lambda: p.exposure_counts(float("nan"), MCE), "finite"),
        (lambda: p.gain_raw(0.1, MCE), "0.125 .. 8x"),
        (lambda: p.gain_raw(8.2, MCE), "raw 1..64"),
        (lambda: p.frame_time_counts(0.0, V106), "0.1 .. 6553.5 ms"),
        (lambda: p.frame_time_counts(0.0, MCE), "0.05 .. 3276.75 ms"),
    ],
)
def test_out_of_range_messages_name_the_range(call, message: str) -> None:
    with pytest.raises(SettingOutOfRangeError, match=message.replace(".", r"\.")):
        call()


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"width": 1284}, "width 1284 out of range: MCE-B013-U accepts 8 .. 1280 pixels"),
        ({"width": 4}, "multiples of 4"),
        ({"height": 1026}, "height 1026 out of range"),
        ({"bits": 16}, "accepts 8 or 10 or 12"),
        ({"mode": "burst"}, "normal, trigger"),
        ({"bin_code": 0x81}, "0x00"),
        ({"buffer_count": 25}, "1 .. 24 frames"),
    ],
)
def test_geometry_refusals(kwargs: dict, message: str) -> None:
    args = {"width": 1280, "height": 1024, "bits": 8, "mode": "normal", "bin_code": 0,
            "buffer_count": 4, **kwargs}
    with pytest.raises(SettingOutOfRangeError, match=message):
        p.check_geometry(MCE, **args)


def test_reply_decoding_and_quirks() -> None:
    assert p.decode_reply(bytes.fromhex("01 03 01 00 06"), "fw", 3) == b"\x01\x00\x06"
    # Result byte 0x08 instead of 0x01 was observed on 0x33 replies: accepted.
    data = p.decode_reply(bytes.fromhex("08 06 02 05 00 04 00 00"), "buffer", 6)
    assert p.decode_buffer_status(data) == p.BufferStatus(2, 1280, 1024, 0)
    with pytest.raises(ProtocolError, match="camera reported an error"):
        p.decode_reply(bytes.fromhex("00 03 01 00 06"), "fw", 3)
    with pytest.raises(ProtocolError, match="length byte says 5 but 3"):
        p.decode_reply(bytes.fromhex("01 05 01 00 06"), "fw", 3)
    with pytest.raises(ProtocolError, match="too short"):
        p.decode_reply(b"\x01", "fw", 3)
    with pytest.raises(ProtocolError, match="expected 6 data bytes, got 3"):
        p.decode_reply(bytes.fromhex("01 03 01 00 06"), "buffer", 6)


def test_device_info_layout() -> None:
    raw = (b"\x01" + b"MCE-B013-U\0\0\0\0" + b"13-000123     " + b"\0" * 14)
    assert len(raw) == 43
    info = p.decode_device_info(raw)
    assert info == p.DeviceInfo(1, "MCE-B013-U", "13-000123", "")
    assert p.encode_device_info(p.DeviceInfo(1, "MCE-B013-U", "13-000123", "")) == (
        b"\x01" + b"MCE-B013-U\0\0\0\0" + b"13-000123\0\0\0\0\0" + b"\0" * 14)


TRAILER_HEX = (
    "0005 0004 0000 0000 0000 0800 0800 0800"  # row 1280, column 1024, bin, x, y, R G B gain 8
    "3412 0100 0700 0000 0a00 0000 70170000"  # timestamp 0x1234, trig 1, count 7, mark, ft 10,
)  # clock 0, exposure 6000 (LE u32)


def test_trailer_decoding_is_little_endian() -> None:
    raw = bytes.fromhex(TRAILER_HEX) + bytes(480)
    t = p.decode_trailer(raw)
    assert t == p.FrameTrailer(row=1280, column=1024, bin_code=0, x_start=0, y_start=0,
                               red_gain=8, green_gain=8, blue_gain=8, timestamp_ms=0x1234,
                               trigger_occurred=1, trigger_count=7, user_mark=0,
                               frame_time=10, clock=0, exposure_counts=6000)
    assert p.encode_trailer(t) == raw
    with pytest.raises(ProtocolError, match="511 bytes"):
        p.decode_trailer(raw[:511])


def test_frame_layout_padding() -> None:
    assert p.FrameLayout(1280, 1024, 8).padding_bytes == 0
    assert p.FrameLayout(1280, 1024, 12).total_bytes == 2 * 1280 * 1024 + 512
    odd = p.FrameLayout(12, 8, 8)  # 96 pixel bytes -> 416 bytes of padding
    assert (odd.pixel_bytes, odd.padding_bytes, odd.total_bytes) == (96, 416, 1024)
    assert p.FrameLayout(12, 8, 12).padding_bytes == 512 - 192


def test_12bit_unpack_known_bytes_ignores_high_nibble() -> None:
    raw = bytearray(bytes.fromhex("ab 0c ff 0f 00 00 12 f3"))  # high nibble of b1 is junk
    words = np.frombuffer(raw, dtype="<u2")
    assert p.unpack_12bit_inplace(words).tolist() == [0xABC, 0xFFF, 0x000, 0x123]


@settings(max_examples=30, deadline=None)
@given(st.lists(st.integers(0, 4095), min_size=1, max_size=70_000))
def test_12bit_round_trip(values: list[int]) -> None:
    v = np.array(values, dtype=np.uint16)
    packed = np.empty_like(v)
    p.pack_12bit(v, packed)
    raw = packed.astype("<u2").tobytes()
    assert raw[:2] == bytes(((values[0] >> 4), values[0] & 0xF))
    assert np.array_equal(p.unpack_12bit_inplace(np.frombuffer(bytearray(raw), "<u2")), v)


def _frame_bytes(width: int, height: int, bits: int, pixels: bytes) -> array.array:
    layout = p.FrameLayout(width, height, bits)
    trailer = p.encode_trailer(p.FrameTrailer(width, height, 0, 0, 0, 8, 8, 8, 5, 0, 0, 0, 1,
                                              0, 200))
    return array.array("B", pixels + bytes(layout.padding_bytes) + trailer)


def test_decode_frame_8bit_is_a_view() -> None:
    buf = _frame_bytes(8, 8, 8, bytes(range(64)))
    pixels, trailer = p.decode_frame(buf, p.FrameLayout(8, 8, 8), len(buf))
    assert pixels.shape == (8, 8) and pixels[1, 0] == 8 and trailer.timestamp_ms == 5
    assert np.shares_memory(pixels, np.frombuffer(buf, np.uint8))


def test_decode_frame_rejects_wrong_length_and_geometry() -> None:
    buf = _frame_bytes(8, 8, 8, bytes(64))
    with pytest.raises(ProtocolError, match="1000 bytes, expected 1024"):
        p.decode_frame(buf, p.FrameLayout(8, 8, 8), 1000)
    trailer_8x8 = bytes(buf[-512:])
    wrong = array.array("B", bytes(96 + 416) + trailer_8x8)  # an 8x12 transfer, 8x8 trailer
    with pytest.raises(ProtocolError, match="trailer says 8x8, configured 8x12"):
        p.decode_frame(wrong, p.FrameLayout(8, 12, 8), 1024)


def test_10bit_decode_is_the_cmos_clients_and_not_the_12bit_rule() -> None:
    """Difference 2: the MT9M001 is 10-bit; [SH] packs byte0 = 8 MSBs, byte1 = 2 LSBs."""
    values = np.array([0, 1, 2, 3, 4, 511, 512, 1022, 1023], dtype=np.uint16)
    words = np.empty_like(values)
    p.pack_10bit(values, words)
    raw = words.astype("<u2").tobytes()
    assert raw[-2:] == bytes((0xFF, 0x03))  # 1023: b0 = 0xFF, b1 = 0x03
    back = p.unpack_10bit_inplace(np.frombuffer(bytearray(raw), dtype="<u2").copy())
    assert back.tolist() == values.tolist()
    as12 = p.unpack_12bit_inplace(np.frombuffer(bytearray(raw), dtype="<u2").copy())
    assert as12[-1] == 4083  # what the 12-bit decode makes of 1023 (the example)


def test_10bit_frame_decodes_through_decode_frame() -> None:
    layout = p.FrameLayout(8, 8, 10)
    values = (np.arange(64, dtype=np.uint16) * 16) % 1024
    buf = bytearray(layout.total_bytes)
    p.pack_10bit(values, np.frombuffer(buf, dtype="<u2", count=64))
    buf[layout.trailer_offset:] = p.encode_trailer(p.FrameTrailer(
        8, 8, 0, 0, 0, 8, 8, 8, 0, 0, 0, 0, 1, 0, 200))
    pixels, trailer = p.decode_frame(buf, layout, layout.total_bytes)
    assert pixels.reshape(-1).tolist() == values.tolist() and trailer.exposure_counts == 200


def test_a_transfer_of_another_depth_is_named() -> None:
    layout = p.FrameLayout(64, 16, 10)
    with pytest.raises(ProtocolError, match="1536 bytes is an 8-bit frame"):
        p.decode_frame(bytearray(1536), layout, 1536)
