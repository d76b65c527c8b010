"""Every message type round-trips; arbitrary payloads decode or raise MessageError."""

from __future__ import annotations

import contextlib
import dataclasses

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

# deadline=None everywhere: a loaded 2-core machine must not fail a property on time.
from robots.protocol.framing import MAX_MESSAGE_PAYLOAD, Frame, FrameDecoder, ProtocolError
from robots.protocol.messages import (
    CHUNK_POINTS,
    MESSAGE_CLASSES,
    BasePoseCmd,
    CaptureChunk,
    CaptureHeader,
    Hello,
    JointsCmd,
    Message,
    MessageError,
    MsgType,
    Nak,
    NakReason,
    State,
    decode_message,
    encode_message,
    is_command,
    is_sequenced,
)

_FIELD = {
    "B": st.integers(0, 0xFF),
    "H": st.integers(0, 0xFFFF),
    "I": st.integers(0, 0xFFFFFFFF),
    "h": st.integers(-(2**15), 2**15 - 1),
    "i": st.integers(-(2**31), 2**31 - 1),
    "o": st.booleans(),
    # 23 elements keeps the largest message (State, two arrays) within
    # MAX_MESSAGE_PAYLOAD (the payload region less the authentication trailer).
    "A": st.lists(st.integers(-(2**31), 2**31 - 1), max_size=23).map(tuple),
    "S": st.text(st.characters(min_codepoint=32, max_codepoint=126), max_size=32),
    "N": st.binary(min_size=16, max_size=16),
    # Capture chunks: three i16 arrays and one u8 array of ≤ 30 (CHUNK_POINTS)
    # fill MAX_MESSAGE_PAYLOAD exactly at most.
    "a": st.lists(st.integers(-(2**15), 2**15 - 1), max_size=30).map(tuple),
    "u": st.lists(st.integers(0, 255), max_size=30).map(tuple),
}


def message_strategy(cls: type[Message]) -> st.SearchStrategy[Message]:
    return st.builds(cls, **{name: _FIELD[code] for name, code in cls._spec})


any_message = st.sampled_from(sorted(MESSAGE_CLASSES.values(), key=lambda c: c.TYPE)).flatmap(
    message_strategy
)


def test_every_type_has_a_class_and_back() -> None:
    assert set(MESSAGE_CLASSES) == {t.value for t in MsgType}
    for t, cls in MESSAGE_CLASSES.items():
        assert t == cls.TYPE
        # Every dataclass field is on the wire, and nothing else.
        assert [f.name for f in dataclasses.fields(cls)] == [n for n, _ in cls._spec]


@pytest.mark.parametrize("cls", sorted(MESSAGE_CLASSES.values(), key=lambda c: c.TYPE))
def test_defaults_round_trip(cls: type[Message]) -> None:
    msg = cls()
    frame = FrameDecoder().feed(encode_message(msg, 42))[0]
    assert frame.seq == 42 and decode_message(frame) == msg


@settings(max_examples=300, deadline=None)
@given(any_message, st.integers(0, 0xFFFF))
def test_round_trip_every_message(msg: Message, seq: int) -> None:
    frames = FrameDecoder().feed(encode_message(msg, seq))
    assert len(frames) == 1 and frames[0].seq == seq and frames[0].type == msg.TYPE
    assert decode_message(frames[0]) == msg


@settings(max_examples=400, deadline=None)
@given(st.integers(0, 255), st.binary(max_size=240))
def test_arbitrary_payload_decodes_or_is_rejected(msg_type: int, payload: bytes) -> None:
    try:
        msg = decode_message(Frame(msg_type, 0, payload))
    except MessageError:
        return
    # Whatever decodes re-encodes to exactly the same payload (strict parsing).
    assert msg.payload() == payload


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=3000))
def test_byte_stream_to_messages_never_crashes(data: bytes) -> None:
    for frame in FrameDecoder().feed(data):
        with contextlib.suppress(ProtocolError):
            decode_message(frame)


def test_strict_parsing_examples() -> None:
    with pytest.raises(MessageError, match="unknown message type"):
        decode_message(Frame(0x7F, 0, b""))
    with pytest.raises(MessageError, match="trailing"):
        decode_message(Frame(MsgType.HEARTBEAT, 0, b"\x00"))
    with pytest.raises(MessageError, match="too short"):
        decode_message(Frame(MsgType.HELLO, 0, b"\x01"))
    good = JointsCmd(run_id=1, index=2, duration_ms=3, q_urad=(4, 5)).payload()
    with pytest.raises(MessageError, match="too short"):
        decode_message(Frame(MsgType.CMD_JOINTS, 0, good[:-1]))
    with pytest.raises(MessageError, match="bool"):
        decode_message(Frame(MsgType.CMD_NOZZLE, 0, bytes(8) + b"\x02"))
    with pytest.raises(MessageError, match="elements"):
        decode_message(Frame(MsgType.CMD_JOINTS, 0, bytes(12) + b"\x21" + bytes(4 * 33)))


def test_encode_rejects_out_of_range_fields() -> None:
    with pytest.raises(ValueError, match=r"Hello\.heartbeat_ms"):
        Hello(heartbeat_ms=70000).payload()
    with pytest.raises(ValueError, match=r"JointsCmd\.q_urad"):
        JointsCmd(q_urad=(2**31,)).payload()
    with pytest.raises(ValueError, match="elements"):
        JointsCmd(q_urad=(0,) * 33).payload()
    with pytest.raises(ValueError, match="payload"):
        State(q_urad=(0,) * 32, odometry_um=(0,) * 32).payload()


def test_capture_messages_fit_and_refuse_what_does_not() -> None:
    full = CaptureChunk(
        capture_id=2**32 - 1,
        offset=0xFFFF,
        x_mm=(-(2**15),) * CHUNK_POINTS,
        y_mm=(2**15 - 1,) * CHUNK_POINTS,
        z_mm=(0,) * CHUNK_POINTS,
        intensity=(255,) * CHUNK_POINTS,
    )
    assert len(full.payload()) <= MAX_MESSAGE_PAYLOAD
    assert decode_message(Frame(MsgType.CAPTURE_CHUNK, 0, full.payload())) == full
    with pytest.raises(ValueError, match=r"CaptureChunk\.x_mm"):
        CaptureChunk(x_mm=(2**15,)).payload()
    with pytest.raises(ValueError, match=r"CaptureChunk\.intensity"):
        CaptureChunk(intensity=(256,)).payload()
    with pytest.raises(ValueError, match="payload"):  # 31 points do not fit with intensity
        CaptureChunk(x_mm=(0,) * 31, y_mm=(0,) * 31, z_mm=(0,) * 31, intensity=(0,) * 31).payload()
    assert len(CaptureHeader().payload()) <= MAX_MESSAGE_PAYLOAD
    assert len(BasePoseCmd().payload()) <= MAX_MESSAGE_PAYLOAD
    # Array codes are strict too: an i16 array's count must match its bytes.
    with pytest.raises(MessageError, match="too short"):
        decode_message(Frame(MsgType.CAPTURE_CHUNK, 0, bytes(6) + b"\x02" + bytes(3)))


def test_type_classes() -> None:
    assert is_sequenced(MsgType.CMD_JOINTS) and is_sequenced(MsgType.CLEAR)
    assert not is_sequenced(MsgType.ESTOP) and not is_sequenced(MsgType.HEARTBEAT)
    assert is_command(MsgType.CMD_STOP) and not is_command(MsgType.PAUSE)
    assert is_command(MsgType.CMD_BASE_POSE) and is_command(MsgType.CMD_CAPTURE)
    assert not is_sequenced(MsgType.CAPTURE) and not is_sequenced(MsgType.CAPTURE_CHUNK)
    assert not Nak(reason=NakReason.FALL_RISK).transient
    assert Nak(reason=NakReason.SEQ_GAP).transient and Nak(reason=NakReason.BUSY).transient
    assert not Nak(reason=NakReason.LIMIT).transient
