"""A fault soak of the camera driver, and random bytes into the three reply parsers
(issue 10, item 4). ``benchlab benchmark soak`` is the long version (10,000 frames)."""

from __future__ import annotations

import collections

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from benchlab.cli.main import main
from benchlab.drivers.apt import protocol as apt
from benchlab.drivers.errors import DeviceError, ProtocolError
from benchlab.drivers.mightex import protocol as mp
from benchlab.drivers.mightex.camera import Frame, MightexCamera
from benchlab.drivers.mightex.soak import FAULT_KINDS, run_soak
from benchlab.drivers.slc.controller import SlcController, parse_current_reply


# ---- the soak --------------------------------------------------------------------------------
def test_soak_every_fault_kind_nothing_lost_duplicated_or_corrupted() -> None:
    report = run_soak(1200, fault_rate=0.12, seed=3, width=64, height=48)
    assert report.ok, report.format()
    assert (report.delivered, report.lost, report.duplicated, report.corrupted) == (1200, 0, 0, 0)
    assert all(report.injected[k] >= 5 for k in FAULT_KINDS), report.injected
    for kind in ("timeout", "garbage", "short", "unplug"):  # each one made the driver fail...
        assert report.errors[kind] >= report.injected[kind]
        assert len(report.recovery_s[kind]) == report.injected[kind]  # ...and it recovered
    assert report.sim_frames["short"] == report.injected["short"]
    assert report.sim_frames["unplugged"] == report.injected["unplug"] == report.reconnects
    assert report.stale_discarded >= 3 * report.injected["stale"]


def _sabotaged(monkeypatch: pytest.MonkeyPatch, how: str) -> None:
    real = MightexCamera.grab
    count = {"n": 0}
    last: dict[str, Frame] = {}

    def grab(self: MightexCamera, timeout_s: float | None = None, *,
             fresh: bool = True) -> Frame:
        count["n"] += 1
        if how == "duplicate" and count["n"] % 97 == 0 and "f" in last:
            return last["f"]
        if how == "drop" and count["n"] % 97 == 0:
            real(self, timeout_s, fresh=fresh)  # read a good frame and throw it away
        frame = real(self, timeout_s, fresh=fresh)
        if how == "corrupt" and count["n"] % 97 == 0:
            frame.pixels[0, 0] ^= 1
        last["f"] = frame
        return frame

    monkeypatch.setattr(MightexCamera, "grab", grab)


@pytest.mark.parametrize("how,field", [("duplicate", "duplicated"), ("drop", "lost"),
                                       ("corrupt", "corrupted")])
def test_the_soak_catches_a_driver_that_misbehaves(
    monkeypatch: pytest.MonkeyPatch, how: str, field: str
) -> None:
    _sabotaged(monkeypatch, how)
    report = run_soak(400, fault_rate=0.0, seed=1, width=32, height=16)
    assert not report.ok
    assert getattr(report, field) >= 3, report.format()


def test_benchmark_soak_command(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["benchmark", "soak", "--frames", "300", "--fault-rate", "0.2"]) == 0
    out = capsys.readouterr().out
    assert "delivered 300   lost 0   duplicated 0   corrupted 0   out of order 0   -> PASS" in out
    assert "recovery median ms" in out and "unplug" in out
    assert main(["benchmark", "soak", "--fault-rate", "2"]) == 2


# ---- random bytes into the reply parsers -------------------------------------------------------
FUZZ = settings(max_examples=300, deadline=None,
                suppress_health_check=[HealthCheck.too_slow])


@FUZZ
@given(reply=st.binary(max_size=80), expected=st.sampled_from([3, 6, mp.DEVICE_INFO_BYTES]))
def test_mightex_replies_raise_only_protocol_error(reply: bytes, expected: int) -> None:
    decoders = {3: mp.decode_firmware, 6: mp.decode_buffer_status,
                mp.DEVICE_INFO_BYTES: mp.decode_device_info}
    try:
        data = mp.decode_reply(reply, "fuzz", expected)
    except ProtocolError:
        return
    assert len(data) == expected
    decoders[expected](data)  # a reply that passed the frame check always decodes


def _valid_frame(values: list[int], bits: int, exposure_counts: int) -> bytearray:
    """An 8x8 frame as the camera sends it: pixels, padding, then the encoded trailer."""
    layout = mp.FrameLayout(8, 8, bits)
    buf = bytearray(layout.total_bytes)
    if bits == 8:
        buf[: layout.pixel_bytes] = bytes(v & 0xFF for v in values)
    else:
        words = np.empty(len(values), dtype=np.uint16)
        mp.pack_12bit(np.array(values, dtype=np.uint16), words)
        buf[: layout.pixel_bytes] = words.astype("<u2").tobytes()
    trailer = mp.FrameTrailer(8, 8, 0, 0, 0, 8, 8, 8, 1234, 0, 0, 0, 100, 0, exposure_counts)
    buf[layout.trailer_offset:] = mp.encode_trailer(trailer)
    return buf


@pytest.mark.slow
def test_mightex_frames_decode_exactly_or_raise_protocol_error() -> None:
    """A valid frame, then random byte mutations and a short transfer: decodes to exactly
    the bytes' pixels while the length and the trailer's geometry hold, else ProtocolError.
    Both outcomes must occur, or the fuzz only ever tested one branch."""
    outcomes: collections.Counter[str] = collections.Counter()

    @FUZZ
    @given(bits=st.sampled_from([8, 12]), values=st.lists(st.integers(0, 4095), min_size=64,
                                                          max_size=64),
           exposure=st.integers(1, 0xFFFFFFFF), short=st.sampled_from([0, 0, 0, 1, 3]),
           mutations=st.lists(st.tuples(st.sampled_from(["pixels", "geometry", "trailer", "any"]),
                                        st.integers(0, 10**6), st.integers(0, 255)),
                              max_size=4))
    def check(bits: int, values: list[int], exposure: int, short: int,
              mutations: list[tuple[str, int, int]]) -> None:
        layout = mp.FrameLayout(8, 8, bits)
        buf = _valid_frame(values, bits, exposure)
        t0 = layout.trailer_offset
        geometry = bytes(buf[t0:t0 + 4])  # the trailer's row and column words
        regions = {"pixels": (0, layout.pixel_bytes), "geometry": (t0, 4),
                   "trailer": (t0, mp.TRAILER_BYTES), "any": (0, len(buf))}
        for region, at, byte in mutations:
            start, size = regions[region]
            buf[start + at % size] = byte
        raw = bytes(buf)
        if short or raw[layout.trailer_offset:layout.trailer_offset + 4] != geometry:
            with pytest.raises(ProtocolError):
                mp.decode_frame(buf, layout, layout.total_bytes - short)
            outcomes["refused"] += 1
            return
        pixels, trailer = mp.decode_frame(buf, layout, layout.total_bytes)
        if bits == 8:
            expected = list(raw[:64])
        else:  # byte 0 holds the 8 MSBs, the low nibble of byte 1 the 4 LSBs
            expected = [raw[2 * i] << 4 | raw[2 * i + 1] & 0x0F for i in range(64)]
        assert pixels.shape == (8, 8) and pixels.reshape(-1).tolist() == expected
        if not mutations:
            assert expected == [v & 0xFF if bits == 8 else v for v in values]
            assert trailer.exposure_counts == exposure
        outcomes["decoded"] += 1

    check()
    assert outcomes["decoded"] >= 20 and outcomes["refused"] >= 20, outcomes


class _ReplyPort:
    """A serial port that answers every command with the given bytes."""

    def __init__(self, reply: bytes) -> None:
        self.reply = reply
        self.in_waiting = 0

    def reset_input_buffer(self) -> None: ...

    def write(self, data: bytes) -> int:
        return len(data)

    def read_until(self, end: bytes) -> bytes:
        return self.reply

    def read(self, n: int) -> bytes:
        return b""

    def close(self) -> None: ...


@pytest.mark.slow
@settings(max_examples=120, deadline=None)
@given(reply=st.one_of(st.binary(max_size=60),
                       st.binary(max_size=40).map(lambda b: b"#" + b + b"\n\r"),
                       st.text(max_size=30).map(lambda t: ("#" + t + "\n\r").encode("utf-8"))))
def test_slc_replies_raise_only_device_errors(reply: bytes) -> None:
    slc = SlcController("fuzz", ceilings_ma={1: 50.0})
    slc._ser = _ReplyPort(reply)  # type: ignore[assignment]
    slc._channel_count = 4
    for call in (lambda: slc.get_mode(1), lambda: slc.get_current(1), lambda: slc.off(1)):
        try:
            call()
        except DeviceError as exc:  # the driver's documented errors (SlcCommandError & co)
            assert str(exc)


@FUZZ
@given(payload=st.text(max_size=40))
def test_slc_current_payload_raises_only_bad_reply(payload: str) -> None:
    try:
        imax, iset = parse_current_reply("?CURRENT 1", payload)
    except DeviceError:
        return
    assert 0 <= iset <= imax


@FUZZ
@given(chunks=st.lists(st.binary(max_size=64), max_size=12))
def test_apt_reader_never_raises_and_only_yields_valid_messages(chunks: list[bytes]) -> None:
    reader = apt.FrameReader(dests={apt.HOST}, sources={apt.UNIT})
    for chunk in chunks:
        for msg in reader.feed(chunk):
            assert msg.msg_id in apt.Msg._value2member_map_
            assert msg.source == apt.UNIT
            if msg.data is not None:  # long form: the catalogue length, so payloads unpack
                assert 0 < len(msg.data) <= apt.MAX_DATA_LEN
                try:
                    if msg.msg_id == apt.Msg.HW_GET_INFO:
                        apt.HwInfo.unpack(msg.data)
                    elif len(msg.data) >= 14:
                        apt.DcStatus.unpack(msg.data)
                except ValueError:
                    pass  # HwInfo's documented refusal; the driver reports AptBadReplyError
