"""The SteelPath robot protocol v2 (docs/protocol.md): frames, messages, commands, programs.

- :mod:`~robots.protocol.framing` — COBS framing, CRC-16/CCITT-FALSE, :class:`FrameDecoder`.
- :mod:`~robots.protocol.auth` — per-robot secret, challenge–response, per-frame HMAC.
- :mod:`~robots.protocol.messages` — every wire message as a dataclass of integers.
- :mod:`~robots.protocol.commands` — program commands in SI units (what plans compile to).
- :mod:`~robots.protocol.program` — :class:`Program`, an immutable list of commands.
- :mod:`~robots.protocol.capture` — :class:`SensorCapture` (a camera frame the robot
  brings back) and :class:`CaptureAssembler` (its reassembly from header + chunks).
"""

from robots.protocol.auth import (
    AuthError,
    HostHandshake,
    SecretError,
    SecretFileError,
    SessionMac,
    generate_secret,
    load_or_create_secret,
    parse_secret,
)
from robots.protocol.capture import CaptureAssembler, SensorCapture
from robots.protocol.commands import (
    COMMAND_TYPES,
    BasePose,
    Capture,
    Command,
    CommandError,
    JointMove,
    LiftArm,
    LimitingPlate,
    Nozzle,
    SetMagnet,
    Stop,
    WheelSpeeds,
    command_from_dict,
    command_from_message,
)
from robots.protocol.framing import (
    MAX_PAYLOAD,
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    Frame,
    FrameDecoder,
    FrameError,
    ProtocolError,
    crc16,
    decode_frame,
    encode_frame,
)
from robots.protocol.messages import (
    LINK_FAULTS,
    MAX_CAPTURE_POINTS,
    MESSAGE_CLASSES,
    ROBOT_FAULTS,
    CaptureChunk,
    CaptureHeader,
    FallRule,
    FaultFlag,
    Message,
    MessageError,
    Mode,
    MsgType,
    NakReason,
    State,
    decode_message,
    encode_message,
)
from robots.protocol.program import Program

__all__ = [
    "COMMAND_TYPES",
    "LINK_FAULTS",
    "MAX_CAPTURE_POINTS",
    "MAX_PAYLOAD",
    "MESSAGE_CLASSES",
    "PROTOCOL_MAJOR",
    "PROTOCOL_MINOR",
    "ROBOT_FAULTS",
    "AuthError",
    "BasePose",
    "Capture",
    "CaptureAssembler",
    "CaptureChunk",
    "CaptureHeader",
    "Command",
    "CommandError",
    "FallRule",
    "FaultFlag",
    "Frame",
    "FrameDecoder",
    "FrameError",
    "HostHandshake",
    "JointMove",
    "LiftArm",
    "LimitingPlate",
    "Message",
    "MessageError",
    "Mode",
    "MsgType",
    "NakReason",
    "Nozzle",
    "Program",
    "ProtocolError",
    "SecretError",
    "SecretFileError",
    "SensorCapture",
    "SessionMac",
    "SetMagnet",
    "State",
    "Stop",
    "WheelSpeeds",
    "command_from_dict",
    "command_from_message",
    "crc16",
    "decode_frame",
    "decode_message",
    "encode_frame",
    "encode_message",
    "generate_secret",
    "load_or_create_secret",
    "parse_secret",
]
