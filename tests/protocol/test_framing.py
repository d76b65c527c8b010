"""Framing: COBS, CRC-16/CCITT-FALSE, frame layout, and the streaming decoder."""

from __future__ import annotations

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

# deadline=None everywhere: a loaded 2-core machine must not fail a property on time.
from robots.protocol.framing import (
    DELIMITER,
    MAX_ENCODED_FRAME,
    MAX_PAYLOAD,
    CobsError,
    Frame,
    FrameDecoder,
    FrameError,
    cobs_decode,
    cobs_encode,
    crc16,
    decode_frame,
    encode_frame,
    parse_raw_frame,
)
from robots.protocol.messages import Heartbeat, JointsCmd, encode_message

frames_st = st.builds(
    Frame,
    type=st.integers(0, 255),
    seq=st.integers(0, 0xFFFF),
    payload=st.binary(max_size=MAX_PAYLOAD),
)


def test_crc_check_value() -> None:
    # Catalogue check value of CRC-16/CCITT-FALSE (a.k.a. CRC-16/IBM-3740).
    assert crc16(b"123456789") == 0x29B1


def test_crc_matches_bitwise_reference() -> None:
    def ref(data: bytes) -> int:  # the loop an Arduino runs (docs/protocol.md §2)
        crc = 0xFFFF
        for byte in data:
            crc ^= byte << 8
            for _ in range(8):
                crc = ((crc << 1) ^ 0x1021) & 0xFFFF if crc & 0x8000 else (crc << 1) & 0xFFFF
        return crc

    for data in (b"", b"\x00", b"\xff" * 7, bytes(range(256))):
        assert crc16(data) == ref(data)


@settings(deadline=None)
@given(st.binary(max_size=1000))
def test_cobs_round_trip_and_no_zero(data: bytes) -> None:
    enc = cobs_encode(data)
    assert 0 not in enc
    assert len(enc) <= len(data) + len(data) // 254 + 1
    assert cobs_decode(enc) == data


def test_cobs_known_vectors() -> None:
    # Vectors from the COBS paper / Wikipedia.
    assert cobs_encode(b"\x00") == b"\x01\x01"
    assert cobs_encode(b"\x00\x00") == b"\x01\x01\x01"
    assert cobs_encode(b"\x11\x22\x00\x33") == b"\x03\x11\x22\x02\x33"
    assert cobs_encode(b"\x11\x00\x00\x00") == b"\x02\x11\x01\x01\x01"
    assert cobs_encode(bytes(range(1, 255))) == b"\xff" + bytes(range(1, 255)) + b"\x01"


@pytest.mark.parametrize("bad", [b"\x05\x11", b"\x03\x11\x00", b"\x00"])
def test_cobs_rejects_malformed(bad: bytes) -> None:
    with pytest.raises(CobsError):
        cobs_decode(bad)


def test_worked_example_from_docs() -> None:
    # docs/protocol.md §2.4: HEARTBEAT with seq 0, and a 2-joint way-point (plain
    # frames, before the authentication trailer of §12 is added).
    assert encode_message(Heartbeat(), 0).hex(" ") == "03 02 02 01 01 03 e7 b8 00"
    wire = encode_message(
        JointsCmd(run_id=7, index=3, duration_ms=500, q_urad=(1_570_796, -785_398)), 5
    )
    assert wire.hex(" ") == (
        "04 02 10 05 03 15 07 01 01 02 03 01 01 03 f4 01 01 05 02 ec f7 17 07 0a 04 f4 ff 05 23 00"
    )
    frame = decode_frame(wire)
    assert (frame.type, frame.seq, len(frame.payload)) == (0x10, 5, 21)


@settings(deadline=None)
@given(frames_st)
def test_frame_round_trip(frame: Frame) -> None:
    wire = encode_frame(frame.type, frame.seq, frame.payload)
    assert wire.endswith(DELIMITER) and 0 not in wire[:-1]
    assert len(wire) - 1 <= MAX_ENCODED_FRAME
    assert decode_frame(wire) == frame


@settings(deadline=None)
@given(frames_st, st.data())
def test_any_single_bit_flip_in_a_frame_is_rejected(frame: Frame, data: st.DataObject) -> None:
    raw = cobs_decode(encode_frame(frame.type, frame.seq, frame.payload)[:-1])
    bit = data.draw(st.integers(0, len(raw) * 8 - 1))
    flipped = bytearray(raw)
    flipped[bit // 8] ^= 1 << (bit % 8)
    with pytest.raises(FrameError):
        parse_raw_frame(bytes(flipped))


def test_encode_rejects_out_of_range() -> None:
    with pytest.raises(ValueError, match="payload"):
        encode_frame(1, 0, bytes(MAX_PAYLOAD + 1))
    with pytest.raises(ValueError, match="sequence"):
        encode_frame(1, 70000)
    with pytest.raises(ValueError, match="type"):
        encode_frame(256, 0)


def test_other_major_version_is_rejected_unless_asked() -> None:
    wire = encode_frame(0x01, 0, b"", ver=3)
    with pytest.raises(FrameError, match="version"):
        decode_frame(wire)
    assert FrameDecoder(accept_any_version=True).feed(wire)[0].ver == 3
    dec = FrameDecoder()
    assert dec.feed(wire) == [] and dec.errors == 1


@settings(max_examples=400, deadline=None)
@given(st.binary(max_size=2000))
def test_decoder_never_crashes_and_yields_only_valid_frames(data: bytes) -> None:
    dec = FrameDecoder()
    frames = dec.feed(data)
    for f in frames:
        # Every frame it yields is one a sender could have produced, byte for byte.
        assert encode_frame(f.type, f.seq, f.payload) in data + DELIMITER
        assert len(f.payload) <= MAX_PAYLOAD
    assert dec.frames == len(frames)


@settings(deadline=None)
@given(st.lists(st.binary(max_size=300), max_size=20))
def test_decoder_any_chunks_never_crash(chunks: list[bytes]) -> None:
    dec = FrameDecoder()
    for c in chunks:
        dec.feed(c)
    assert len(dec._buf) <= MAX_ENCODED_FRAME


@settings(deadline=None)
@given(
    st.lists(st.tuples(st.binary(max_size=60), frames_st), max_size=8),
    st.lists(st.integers(0, 4000), max_size=10),
)
def test_frames_survive_garbage_and_any_split(
    items: list[tuple[bytes, Frame]], cuts: list[int]
) -> None:
    # Garbage between frames (ended by a delimiter, as after line noise) never hides a frame,
    # and splitting the stream anywhere gives the same result.
    stream = b"".join(g + DELIMITER + encode_frame(f.type, f.seq, f.payload) for g, f in items)
    whole = FrameDecoder().feed(stream)
    dec = FrameDecoder()
    pieces: list[Frame] = []
    prev = 0
    for c in sorted(set(c % (len(stream) + 1) for c in cuts)) + [len(stream)]:
        pieces += dec.feed(stream[prev:c])
        prev = c
    assert pieces == whole
    sent = [f for _, f in items]
    # Garbage may itself decode to a valid frame only by matching its CRC; the real
    # frames are all there, in order.
    it = iter(whole)
    assert all(any(f == g for g in it) for f in sent)


def test_overlong_run_is_discarded_and_decoder_recovers() -> None:
    dec = FrameDecoder()
    good = encode_frame(0x02, 0, b"")
    assert dec.feed(b"\x01" * 5000) == []
    assert dec.feed(DELIMITER + good) == [Frame(0x02, 0, b"")]
    assert dec.errors == 1
