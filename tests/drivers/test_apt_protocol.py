"""APT framing, payload structures, unit conversion and resynchronisation (no I/O)."""

from __future__ import annotations

import struct
from pathlib import Path

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from benchlab.drivers.apt.protocol import (
    HOST,
    UNIT,
    DcStatus,
    FrameReader,
    HwInfo,
    Msg,
    StatusBits,
    Units,
    VelParamsRaw,
    long,
    pack_position,
    short,
)

FRAMES = Path(__file__).resolve().parents[2] / "fixtures" / "serial" / "apt_example_frames.txt"
Z8 = Units(34554.96)


def _examples() -> dict[str, bytes]:
    out = {}
    for line in FRAMES.read_text().splitlines():
        if line and not line.startswith("#"):
            name, hexbytes = (part.strip() for part in line.split("|"))
            out[name] = bytes.fromhex(hexbytes)
    return out


def test_example_frames_from_the_notes() -> None:
    ex = _examples()
    built = {
        "identify": short(Msg.MOD_IDENTIFY, 1),
        "enable channel": short(Msg.MOD_SET_CHANENABLESTATE, 1, 1),
        "request info": short(Msg.HW_REQ_INFO),
        "start updates": short(Msg.HW_START_UPDATEMSGS),
        "home": short(Msg.MOT_MOVE_HOME, 1),
        "homed (cube -> host)": short(Msg.MOT_MOVE_HOMED, 1, dest=HOST, source=UNIT),
        "move absolute 10 mm": long(Msg.MOT_MOVE_ABSOLUTE, pack_position(Z8.counts(10))),
        "move relative -1 mm": long(Msg.MOT_MOVE_RELATIVE, pack_position(Z8.counts(-1))),
        "stop profiled": short(Msg.MOT_MOVE_STOP, 1, 2),
        "request status": short(Msg.MOT_REQ_DCSTATUSUPDATE, 1),
        "request position": short(Msg.MOT_REQ_POSCOUNTER, 1),
        "set vel params 2 mm/s 1.5 mm/s2": long(
            Msg.MOT_SET_VELPARAMS, VelParamsRaw(Z8.acc_raw(1.5), Z8.vel_raw(2.0)).pack()),
        "keep-alive": short(Msg.MOT_ACK_DCSTATUSUPDATE),
    }
    assert set(built) == set(ex)
    for name, msg in built.items():
        assert msg.pack() == ex[name], name


def test_unit_conversion_matches_published_factors() -> None:
    assert Z8.counts(10) == 345550
    assert Z8.vel_raw(1.0) == 772981  # VEL per mm/s 772981.3692
    assert Z8.acc_raw(1.0) == 264  # ACC per mm/s^2 263.8443072
    assert Units(34304).vel_raw(1.0) == 767367
    assert Z8.mm(Z8.counts(17.25)) == pytest.approx(17.25, abs=1 / 34554.96)


def test_structures_round_trip() -> None:
    st_ = DcStatus(-12345, 77, -3, StatusBits.HOMED | StatusBits.ENABLED)
    assert len(st_.pack()) == 14
    assert DcStatus.unpack(st_.pack()) == st_
    info = HwInfo(27000001, "KDC101", 16, (3, 0, 10), 1, 0, 1, stage_id=8)
    raw = info.pack()
    assert len(raw) == 84
    assert raw[:4] == struct.pack("<I", 27000001) and raw[4:12] == b"KDC101\x00\x00"
    assert raw[14:18] == bytes([10, 0, 3, 0])  # minor, interim, major, unused
    assert HwInfo.unpack(raw) == info
    with pytest.raises(ValueError):
        HwInfo.unpack(raw[:80])


def test_reader_handles_split_frames_and_both_forms() -> None:
    r = FrameReader(dests={HOST}, sources={UNIT})
    homed = short(Msg.MOT_MOVE_HOMED, 1, dest=HOST, source=UNIT).pack()
    pos = long(Msg.MOT_GET_POSCOUNTER, pack_position(42), dest=HOST, source=UNIT).pack()
    stream = homed + pos
    got = []
    for i in range(len(stream)):  # one byte at a time
        got += r.feed(stream[i:i + 1])
    assert [m.msg_id for m in got] == [Msg.MOT_MOVE_HOMED, Msg.MOT_GET_POSCOUNTER]
    assert got[1].data == pack_position(42) and got[1].dest == HOST
    assert r.dropped_bytes == 0


@pytest.mark.parametrize("msg_id", [Msg.MOT_MOVE_HOMED, Msg.MOT_MOVE_STOP, Msg.HW_DISCONNECT])
def test_a_long_header_for_a_short_only_id_is_stray_bytes(msg_id: Msg) -> None:
    """Six stray bytes shaped like a long MOVE_HOMED of 20 bytes must not swallow the real
    MOVE_COMPLETED behind them and turn it into a homed stage (the doc: the long flag is
    bit 7 of byte 4, and only ids with a long form have one, at one length)."""
    r = FrameReader(dests={HOST}, sources={UNIT})
    junk = struct.pack("<HHBB", msg_id, 20, HOST | 0x80, UNIT)
    done = long(Msg.MOT_MOVE_COMPLETED, DcStatus(345550, 0, 0, StatusBits.HOMED).pack(),
                dest=HOST, source=UNIT)
    got = r.feed(junk + done.pack())
    assert [(m.msg_id, m.data) for m in got] == [(Msg.MOT_MOVE_COMPLETED, done.data)]
    assert r.dropped_bytes == len(junk)


@settings(max_examples=60, deadline=None)
@given(junk=st.binary(max_size=40))
def test_reader_resynchronises_after_garbage(junk: bytes) -> None:
    r = FrameReader(dests={HOST}, sources={UNIT})
    frames = [
        long(Msg.MOT_GET_DCSTATUSUPDATE, DcStatus(5, 0, 0, StatusBits.HOMED).pack(),
             dest=HOST, source=UNIT),
        short(Msg.MOT_MOVE_HOMED, 1, dest=HOST, source=UNIT),
    ]
    # No 0x50 (the cube's source address) in the junk, so no header can form inside it:
    # every junk byte must be skipped and every following frame recovered.
    junk = junk.replace(bytes([UNIT]), b"")
    tail = b"".join(f.pack() for f in frames) * 3
    got = r.feed(junk + tail)
    assert [(m.msg_id, m.data) for m in got] == [(f.msg_id, f.data) for f in frames] * 3
    assert r.dropped_bytes == len(junk)
