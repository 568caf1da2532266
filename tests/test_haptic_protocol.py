"""Wire protocol: CRC, COBS, frames, reassembly, and fuzzing of the host parser."""

from __future__ import annotations

import os
import struct

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from fieldbank.haptic import protocol as P


def test_crc_check_value_and_reference() -> None:
    # CRC-16/CCITT-FALSE catalogue check value
    assert P.crc16_ccitt_false(b"123456789") == 0x29B1
    assert P.crc16_ccitt_false_reference(b"123456789") == 0x29B1


@given(st.binary(max_size=200))
def test_crc_matches_bitwise_definition(data: bytes) -> None:
    assert P.crc16_ccitt_false(data) == P.crc16_ccitt_false_reference(data)


@pytest.mark.parametrize("data", [b"", b"\x00", b"\x00\x00", b"\x11\x00\x22", b"a" * 253,
                                  b"a" * 254, b"a" * 255, b"a" * 254 + b"\x00", b"\x00" * 300])
def test_cobs_edge_cases(data: bytes) -> None:
    enc = P.cobs_encode(data)
    assert 0 not in enc
    assert P.cobs_decode(enc) == data
    assert len(enc) <= len(data) + 1 + len(data) // 254 + 1


def test_cobs_known_vectors() -> None:
    # examples from Cheshire & Baker (1999) / the COBS Wikipedia table
    assert P.cobs_encode(b"\x00") == b"\x01\x01"
    assert P.cobs_encode(b"\x00\x00") == b"\x01\x01\x01"
    assert P.cobs_encode(b"\x11\x22\x00\x33") == b"\x03\x11\x22\x02\x33"
    assert P.cobs_encode(b"\x11\x00\x00\x00") == b"\x02\x11\x01\x01\x01"


@given(st.binary(max_size=600))
def test_cobs_round_trip(data: bytes) -> None:
    enc = P.cobs_encode(data)
    assert 0 not in enc
    assert P.cobs_decode(enc) == data


def test_cobs_rejects_overrun() -> None:
    with pytest.raises(P.FrameError):
        P.cobs_decode(b"\x05\x11\x22")


def test_force_frame_test_vector() -> None:
    # the example frame in docs/robot-protocol.md
    frame = P.encode_frame(P.MsgType.FORCE, 5, P.FORCE_FMT.pack(1.0, 2.0))
    assert frame.hex() == "04012005010103803f01010440751a00"
    f = P.decode_frame(frame[:-1])
    assert (f.type, f.seq) == (P.MsgType.FORCE, 5)
    assert P.FORCE_FMT.unpack(f.payload) == (1.0, 2.0)


def _payload(t: P.MsgType) -> bytes:
    return {
        P.MsgType.HELLO: P.HELLO_FMT.pack(1, 1000, 20),
        P.MsgType.HELLO_ACK: P.DeviceInfo(1, "dev", 4000, 40.0, 20).to_payload(),
        P.MsgType.STATE: P.STATE_FMT.pack(123456, 0.1, 0.4, -0.2, 0.0, 1, 77),
        P.MsgType.FORCE: P.FORCE_FMT.pack(-3.5, 12.25),
        P.MsgType.FAULT: P.FAULT_FMT.pack(2, 9),
        P.MsgType.SENSOR: P.SENSOR_FMT.pack(123456, -1.5, 0.25),
    }.get(t, b"")


@pytest.mark.parametrize("t", list(P.MsgType))
@pytest.mark.parametrize("seq", [0, 1, 255, 256, 65535])
def test_every_message_round_trips(t: P.MsgType, seq: int) -> None:
    frame = P.encode_frame(t, seq, _payload(t))
    assert frame.endswith(b"\x00") and 0 not in frame[:-1]
    f = P.decode_frame(frame[:-1])
    assert (f.type, f.seq, f.payload) == (t, seq, _payload(t))


def test_device_info_round_trip() -> None:
    info = P.DeviceInfo(1, "kinarm-2dof", 4000, 40.0, 20)
    assert P.DeviceInfo.from_payload(info.to_payload()) == info


@given(st.integers(0, 30), st.integers(0, 7))
def test_any_single_bit_error_is_rejected(pos: int, bit: int) -> None:
    frame = bytearray(P.encode_frame(P.MsgType.STATE, 9, _payload(P.MsgType.STATE))[:-1])
    pos %= len(frame)
    frame[pos] ^= 1 << bit
    if 0 in frame:
        # a flipped byte that became a delimiter splits the frame: both halves must be rejected
        reader = P.FrameReader()
        assert reader.feed(bytes(frame) + b"\x00") == []
        return
    with pytest.raises(P.FrameError):
        P.decode_frame(bytes(frame))


def test_wrong_version_type_and_length_are_rejected() -> None:
    def raw(body: bytes) -> bytes:
        body += struct.pack("<H", P.crc16_ccitt_false(body))
        return P.cobs_encode(body)

    with pytest.raises(P.FrameError) as e:
        P.decode_frame(raw(bytes([2, 0x20, 0, 0]) + P.FORCE_FMT.pack(0, 0)))
    assert e.value.kind == "version"
    with pytest.raises(P.FrameError) as e:
        P.decode_frame(raw(bytes([1, 0x77, 0, 0])))
    assert e.value.kind == "type"
    with pytest.raises(P.FrameError) as e:
        P.decode_frame(raw(bytes([1, 0x20, 0, 0]) + b"\x01\x02"))
    assert e.value.kind == "length"


@given(st.lists(st.integers(1, 40), min_size=1, max_size=20))
def test_reader_reassembles_across_arbitrary_splits(cuts: list[int]) -> None:
    frames = [P.encode_frame(P.MsgType.STATE, i, _payload(P.MsgType.STATE)) for i in range(8)]
    stream = b"".join(frames)
    reader = P.FrameReader()
    got = []
    i = 0
    for c in cuts:
        got += reader.feed(stream[i:i + c])
        i += c
    got += reader.feed(stream[i:])
    assert [f.seq for f in got] == list(range(8))
    assert reader.errors == {}


@settings(max_examples=300)
@given(st.binary(max_size=400))
def test_reader_never_raises_on_garbage(data: bytes) -> None:
    reader = P.FrameReader()
    frames = reader.feed(data)
    for f in frames:  # whatever survives is a well-formed frame
        assert f.type in P.PAYLOAD_SIZES
        assert len(f.payload) == P.PAYLOAD_SIZES[f.type]
    # a valid frame after garbage still gets through (resynchronisation at the next delimiter)
    good = P.encode_frame(P.MsgType.FORCE, 3, P.FORCE_FMT.pack(1.0, 1.0))
    assert reader.feed(b"\x00" + good)[-1].seq == 3


def test_reader_memory_is_bounded_without_delimiters() -> None:
    reader = P.FrameReader()
    for _ in range(100):
        reader.feed(os.urandom(50).replace(b"\x00", b"\x01"))
    assert len(reader._buf) <= P.MAX_FRAME_BYTES
    assert reader.errors.get("length", 0) > 0


def test_example_frames_in_the_protocol_document_match_the_encoder() -> None:
    from pathlib import Path

    doc = (Path(__file__).parent.parent / "docs" / "robot-protocol.md").read_text()
    lines = doc.splitlines()
    wires = [(lines[i - 1].split()[0], bytes.fromhex(ln[len("wire:"):]))
             for i, ln in enumerate(lines) if ln.startswith("wire:")]
    assert len(wires) == 8
    for name, wire in wires:
        assert wire.endswith(b"\x00")
        f = P.decode_frame(wire[:-1])
        assert P.MsgType(f.type).name == name
        assert P.encode_frame(f.type, f.seq, f.payload) == wire
    force = dict(wires)["FORCE"]
    assert P.FORCE_FMT.unpack(P.decode_frame(force[:-1]).payload) == (1.0, 2.0)
