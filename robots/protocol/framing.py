"""Byte-level framing of the SteelPath robot protocol (docs/protocol.md §2).

A frame on the wire is ``COBS(header ‖ payload ‖ crc16) ‖ 0x00``:

====== ====  ==========================================================
offset size  field
====== ====  ==========================================================
0      1     ``ver``  protocol major version (2)
1      1     ``type`` message type (:class:`robots.protocol.messages.MsgType`)
2      2     ``seq``  sequence number, unsigned little-endian
4      1     ``len``  payload length ``N`` (0…:data:`MAX_PAYLOAD`)
5      N     payload
5+N    2     CRC-16/CCITT-FALSE of bytes ``0 … 4+N``, little-endian
====== ====  ==========================================================

COBS (Consistent Overhead Byte Stuffing) removes every zero byte so ``0x00``
only ever marks a frame end: a receiver that lost sync (noise, a reboot mid
frame) is back in sync at the next zero, and an Arduino needs one 256-byte
buffer and a dozen lines of C to decode it.  CRC-16/CCITT-FALSE (poly 0x1021,
init 0xFFFF) is ``_crc_xmodem_update`` seeded with 0xFFFF in avr-libc and
``binascii.crc_hqx(data, 0xFFFF)`` in Python; it detects every error of up to
3 bits and every burst up to 16 bits in frames this short.

The CRC only catches line noise.  Authenticity is a separate layer
(:mod:`robots.protocol.auth`): in protocol 2 every frame of a session ends its
payload region with a 20-byte trailer (counter ‖ truncated HMAC-SHA256), so a
message itself may use at most :data:`MAX_MESSAGE_PAYLOAD` bytes.
"""

from __future__ import annotations

import binascii
import struct
from dataclasses import dataclass

PROTOCOL_MAJOR = 2
PROTOCOL_MINOR = 0
HEADER_SIZE = 5
CRC_SIZE = 2
MAX_PAYLOAD = 240
#: Bytes an authenticated frame appends to its message: u32 counter ‖ 16-byte MAC.
AUTH_TRAILER_SIZE = 20
#: Largest message payload, so that message + trailer always fits ``MAX_PAYLOAD``.
MAX_MESSAGE_PAYLOAD = MAX_PAYLOAD - AUTH_TRAILER_SIZE
MAX_RAW_FRAME = HEADER_SIZE + MAX_PAYLOAD + CRC_SIZE  # 247 bytes
#: Longest COBS-encoded frame, delimiter excluded: one code byte per 254 data bytes.
MAX_ENCODED_FRAME = MAX_RAW_FRAME + MAX_RAW_FRAME // 254 + 1
DELIMITER = b"\x00"

_HEADER = struct.Struct("<BBHB")


def crc16(data: bytes, crc: int = 0xFFFF) -> int:
    """CRC-16/CCITT-FALSE (poly 0x1021, init 0xFFFF, no reflection, xorout 0).

    ``crc16(b"123456789") == 0x29B1`` (the catalogue check value).
    """
    return binascii.crc_hqx(data, crc)


def cobs_encode(data: bytes) -> bytes:
    """COBS-encode ``data``; the result contains no zero byte."""
    out = bytearray()
    block = bytearray()
    for byte in data:
        if byte == 0:
            out.append(len(block) + 1)
            out += block
            block.clear()
        else:
            block.append(byte)
            if len(block) == 254:
                out.append(255)
                out += block
                block.clear()
    out.append(len(block) + 1)
    out += block
    return bytes(out)


class ProtocolError(ValueError):
    """Base of every error raised for bytes or messages that break the protocol."""


class FrameError(ProtocolError):
    """A frame whose bytes are invalid (length, version, CRC, COBS)."""


class CobsError(FrameError):
    """A byte string that is not valid COBS."""


def cobs_decode(data: bytes) -> bytes:
    """Inverse of :func:`cobs_encode`; raises :class:`CobsError` on malformed input."""
    out = bytearray()
    i = 0
    n = len(data)
    while i < n:
        code = data[i]
        if code == 0:
            raise CobsError("zero byte inside a COBS block")
        end = i + code
        if end > n:
            raise CobsError("COBS block runs past the end of the frame")
        block = data[i + 1 : end]
        if 0 in block:
            raise CobsError("zero byte inside a COBS block")
        out += block
        i = end
        # A code < 255 stands for "block, then a zero" except at the very end.
        if code < 255 and i < n:
            out.append(0)
    return bytes(out)


@dataclass(frozen=True)
class Frame:
    """One decoded frame: header fields and the raw payload (CRC already checked)."""

    type: int
    seq: int
    payload: bytes = b""
    ver: int = PROTOCOL_MAJOR


def frame_header(msg_type: int, seq: int, length: int, ver: int = PROTOCOL_MAJOR) -> bytes:
    """The 5 header bytes ``ver type seq len`` (validated)."""
    if not 0 <= msg_type <= 0xFF:
        raise ValueError(f"message type {msg_type} outside 0..255")
    if not 0 <= seq <= 0xFFFF:
        raise ValueError(f"sequence number {seq} outside 0..65535")
    if not 0 <= length <= MAX_PAYLOAD:
        raise ValueError(f"payload of {length} bytes exceeds {MAX_PAYLOAD}")
    if not 0 <= ver <= 0xFF:
        raise ValueError(f"version {ver} outside 0..255")
    return _HEADER.pack(ver, msg_type, seq, length)


def encode_frame(msg_type: int, seq: int, payload: bytes = b"", ver: int = PROTOCOL_MAJOR) -> bytes:
    """Wire bytes of one frame, delimiter included."""
    raw = frame_header(msg_type, seq, len(payload), ver) + payload
    raw += crc16(raw).to_bytes(2, "little")
    return cobs_encode(raw) + DELIMITER


def parse_raw_frame(raw: bytes, *, accept_any_version: bool = False) -> Frame:
    """Check and split a COBS-decoded frame; raises :class:`FrameError`."""
    if len(raw) < HEADER_SIZE + CRC_SIZE:
        raise FrameError(f"frame of {len(raw)} bytes is shorter than header + CRC")
    ver, msg_type, seq, length = _HEADER.unpack_from(raw)
    if length > MAX_PAYLOAD or len(raw) != HEADER_SIZE + length + CRC_SIZE:
        raise FrameError(f"length field {length} disagrees with frame size {len(raw)}")
    body, crc = raw[:-CRC_SIZE], int.from_bytes(raw[-CRC_SIZE:], "little")
    if crc16(body) != crc:
        raise FrameError("CRC mismatch")
    if ver != PROTOCOL_MAJOR and not accept_any_version:
        raise FrameError(f"protocol major version {ver} (this side speaks {PROTOCOL_MAJOR})")
    return Frame(type=msg_type, seq=seq, payload=bytes(raw[HEADER_SIZE:-CRC_SIZE]), ver=ver)


def decode_frame(wire: bytes) -> Frame:
    """Decode one complete frame (with or without its trailing delimiter)."""
    if wire.endswith(DELIMITER):
        wire = wire[:-1]
    return parse_raw_frame(cobs_decode(wire))


class FrameDecoder:
    """Incremental decoder: feed any bytes, get back the valid frames.

    Invalid input is never raised as an exception; it is counted in
    :attr:`errors` (and the last reason kept in :attr:`last_error`) because a
    noisy link is normal operation, not a bug.  Runs of bytes longer than any
    valid frame are discarded up to the next delimiter, so memory stays bounded.
    """

    def __init__(self, *, accept_any_version: bool = False) -> None:
        self._buf = bytearray()
        self._overflow = False
        self._accept_any_version = accept_any_version
        self.errors = 0
        self.frames = 0
        self.last_error = ""

    def reset(self) -> None:
        """Forget any partial frame (after reopening a port)."""
        self._buf.clear()
        self._overflow = False

    def feed(self, data: bytes) -> list[Frame]:
        """Consume ``data``; return the frames completed by it, in order."""
        frames: list[Frame] = []
        start = 0
        while True:
            end = data.find(0, start)
            chunk = data[start:] if end < 0 else data[start:end]
            if not self._overflow:
                if len(self._buf) + len(chunk) > MAX_ENCODED_FRAME:
                    self._overflow = True
                    self._buf.clear()
                else:
                    self._buf += chunk
            if end < 0:
                return frames
            # A delimiter closes the current frame.
            if self._overflow:
                self._reject("frame longer than the maximum")
            elif self._buf:
                try:
                    frames.append(
                        parse_raw_frame(
                            cobs_decode(bytes(self._buf)),
                            accept_any_version=self._accept_any_version,
                        )
                    )
                    self.frames += 1
                except FrameError as exc:
                    self._reject(str(exc))
            # Empty frames (repeated delimiters) are legal idle filler.
            self._buf.clear()
            self._overflow = False
            start = end + 1

    def _reject(self, reason: str) -> None:
        self.errors += 1
        self.last_error = reason
