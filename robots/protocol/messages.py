"""Message types of the SteelPath robot protocol v2 (docs/protocol.md §3–§5, §11).

Every message is a frozen dataclass holding the integers exactly as they go
on the wire (fixed point: µrad, ms, µm/s), so encode → decode is exact and a
microcontroller never needs floating point.  The SI-unit view used by plans
lives in :mod:`robots.protocol.commands`.

Payload layouts are declared as a compact string per class (``name:code``):
``B``/``H``/``I`` unsigned 8/16/32-bit, ``h``/``i`` signed 16/32-bit, ``o`` a
bool byte (0 or 1 only), ``A`` an array (u8 count, then that many i32), ``S``
an ASCII string (u8 length, then bytes), ``N`` 16 raw bytes (a nonce or a
proof), ``a`` an array of i16 and ``u`` an array of u8 (each: u8 count, then
that many elements; at most :data:`MAX_ARRAY`).  All multi-byte fields are
little-endian.  A payload is at most
:data:`~robots.protocol.framing.MAX_MESSAGE_PAYLOAD` bytes, leaving room for
the authentication trailer (:mod:`robots.protocol.auth`).
"""

from __future__ import annotations

import enum
import struct
from dataclasses import astuple, dataclass, fields
from typing import Any, ClassVar

from robots.protocol.framing import (
    MAX_MESSAGE_PAYLOAD,
    PROTOCOL_MAJOR,
    PROTOCOL_MINOR,
    Frame,
    ProtocolError,
    encode_frame,
)


class MessageError(ProtocolError):
    """A frame whose type or payload is not a valid message."""


class MsgType(enum.IntEnum):
    """Message type byte.  0x01–0x3F host → robot, 0x81–0xBF robot → host."""

    HELLO = 0x01
    HEARTBEAT = 0x02
    ESTOP = 0x03
    AUTH = 0x04
    CMD_JOINTS = 0x10
    CMD_WHEELS = 0x11
    CMD_MAGNET = 0x12
    CMD_LIFT = 0x13
    CMD_PLATE = 0x14
    CMD_NOZZLE = 0x15
    CMD_STOP = 0x16
    CMD_BASE_POSE = 0x17
    CMD_CAPTURE = 0x18
    PAUSE = 0x20
    RESUME = 0x21
    ABORT = 0x22
    CLEAR = 0x23
    HELLO_ACK = 0x81
    ACK = 0x82
    NAK = 0x83
    STATE = 0x84
    CHALLENGE = 0x85
    CAPTURE = 0x86
    CAPTURE_CHUNK = 0x87


def is_sequenced(msg_type: int) -> bool:
    """Types carried by the reliable, in-order channel (commands and controls 0x10–0x2F)."""
    return 0x10 <= msg_type <= 0x2F


def is_command(msg_type: int) -> bool:
    """Program commands (0x10–0x1F): they carry a run id and a command index."""
    return 0x10 <= msg_type <= 0x1F


class Mode(enum.IntEnum):
    """Robot mode in a state report (derived: E-stop > fault > paused > moving > idle)."""

    IDLE = 0
    MOVING = 1
    PAUSED = 2
    FAULT = 3
    ESTOP = 4


class FaultFlag(enum.IntFlag):
    """Latched fault bits; cleared only by a ``CLEAR`` frame naming them."""

    NONE = 0
    WATCHDOG = 0x0001  # host heartbeats stopped while a run was active
    LINK_RESET = 0x0002  # a new session (HELLO) or a dropped connection interrupted a run
    ESTOP = 0x0004  # emergency stop latched
    DRIVE = 0x0008  # robot-side hardware fault (fault_code says which)
    FALL_RISK = 0x0010  # a command refused because the robot would fall (fault_code: FallRule)


#: Faults of the robot itself: only an operator's explicit clear may resume from them.
ROBOT_FAULTS = FaultFlag.DRIVE | FaultFlag.FALL_RISK


class FallRule(enum.IntEnum):
    """Which feet rule refused a command (``fault_code`` with ``FALL_RISK``, NAK detail)."""

    JOINTS_WITHOUT_MAGNET = 1  # a joint move off the mobile configuration, no magnet touched
    RELEASE_LAST_HOLD = 2  # a magnet release that would leave no foot held
    WHEELS_FOOT_IN_AIR = 3  # a wheels command while a foot is in the air


#: Faults caused by the link, not the robot: a host resuming a run clears them itself.
LINK_FAULTS = FaultFlag.WATCHDOG | FaultFlag.LINK_RESET


class NakReason(enum.IntEnum):
    """Why a sequenced frame was refused."""

    SEQ_GAP = 1  # transient: an earlier frame is missing; resend from expected_seq
    BUSY = 2  # transient: buffer full or robot busy; resend later
    LIMIT = 3  # permanent: a target is outside the joint limits (detail = joint index)
    INVALID = 4  # permanent: malformed payload or hardware the robot lacks (detail = field)
    FAULTED = 5  # permanent: a fault or E-stop is latched (detail = fault bits)
    INDEX = 6  # permanent: command index does not follow the run (detail = expected low 16 bits)
    NOT_READY = 7  # no session: the host must handshake again
    RUN_ACTIVE = 8  # permanent: another run is queued or executing (abort it first)
    FALL_RISK = 9  # permanent: the robot would fall (detail = FallRule); FALL_RISK latched


TRANSIENT_NAKS = frozenset({NakReason.SEQ_GAP, NakReason.BUSY})


class AckStatus(enum.IntEnum):
    OK = 0  # accepted (command queued / control applied)
    ALREADY_DONE = 1  # command index already executed in this run: not executed again


class HelloStatus(enum.IntEnum):
    """Status of a ``HELLO_ACK`` or ``CHALLENGE``."""

    OK = 0
    VERSION_UNSUPPORTED = 1  # HELLO_ACK, plain: another major version
    LINE_BUSY = 2  # CHALLENGE, plain: another controller holds the line (no takeover asked)


class HelloFlag(enum.IntFlag):
    """Bits of ``HELLO.flags``."""

    NONE = 0
    TAKEOVER = 0x01  # drop the robot's current controller once this host authenticates


class Feature(enum.IntFlag):
    NONE = 0
    LIFT_ARM = 0x01
    NOZZLE = 0x02
    CAMERA = 0x04  # executes CMD_CAPTURE (sends CAPTURE + CAPTURE_CHUNK)


_CODES = {"B": "B", "H": "H", "I": "I", "h": "h", "i": "i", "o": "B"}
#: Array layout codes → struct code of one element.
_ARRAYS = {"A": "i", "a": "h", "u": "B"}
MAX_ARRAY = 32
NONCE_FIELD_SIZE = 16  # layout code "N"


@dataclass(frozen=True)
class Message:
    """Base class; subclasses set ``TYPE`` and ``LAYOUT``."""

    TYPE: ClassVar[int] = -1
    LAYOUT: ClassVar[str] = ""
    _spec: ClassVar[list[tuple[str, str]]]

    def __init_subclass__(cls, **kwargs: Any) -> None:
        super().__init_subclass__(**kwargs)
        cls._spec = [tuple(item.split(":")) for item in cls.LAYOUT.split()]  # type: ignore[misc]

    def payload(self) -> bytes:
        """Payload bytes (no header or CRC); raises ``ValueError`` on out-of-range fields."""
        out = bytearray()
        for name, code in self._spec:
            value = getattr(self, name)
            try:
                if code in _ARRAYS:
                    if len(value) > MAX_ARRAY:
                        raise ValueError(f"{len(value)} elements > {MAX_ARRAY}")
                    out += struct.pack(f"<B{len(value)}{_ARRAYS[code]}", len(value), *value)
                elif code == "S":
                    raw = value.encode("ascii")
                    if len(raw) > MAX_ARRAY:
                        raise ValueError(f"{len(raw)} characters > {MAX_ARRAY}")
                    out += struct.pack("<B", len(raw)) + raw
                elif code == "N":
                    raw = bytes(value)
                    if len(raw) != NONCE_FIELD_SIZE:
                        raise ValueError(f"{len(raw)} bytes, expected {NONCE_FIELD_SIZE}")
                    out += raw
                else:
                    out += struct.pack("<" + _CODES[code], int(value))
            except (struct.error, UnicodeEncodeError, TypeError) as exc:
                raise ValueError(f"{type(self).__name__}.{name}={value!r}: {exc}") from exc
        if len(out) > MAX_MESSAGE_PAYLOAD:
            raise ValueError(
                f"{type(self).__name__} payload of {len(out)} bytes > {MAX_MESSAGE_PAYLOAD}"
            )
        return bytes(out)

    @classmethod
    def from_payload(cls, data: bytes) -> Message:
        """Parse a payload; raises :class:`MessageError` unless it matches ``LAYOUT`` exactly."""
        values: dict[str, Any] = {}
        pos = 0
        if len(data) > MAX_MESSAGE_PAYLOAD:
            raise MessageError(
                f"{cls.__name__} payload of {len(data)} bytes > {MAX_MESSAGE_PAYLOAD}"
            )
        try:
            for name, code in cls._spec:
                if code in _ARRAYS:
                    (count,) = struct.unpack_from("<B", data, pos)
                    if count > MAX_ARRAY:
                        raise MessageError(f"{cls.__name__}.{name}: {count} elements > {MAX_ARRAY}")
                    fmt = f"<{count}{_ARRAYS[code]}"
                    values[name] = struct.unpack_from(fmt, data, pos + 1)
                    pos += 1 + struct.calcsize(fmt)
                elif code == "S":
                    (count,) = struct.unpack_from("<B", data, pos)
                    raw = data[pos + 1 : pos + 1 + count]
                    if len(raw) != count or count > MAX_ARRAY or not raw.isascii():
                        raise MessageError(f"{cls.__name__}.{name}: bad string")
                    values[name] = raw.decode("ascii")
                    pos += 1 + count
                elif code == "N":
                    raw = data[pos : pos + NONCE_FIELD_SIZE]
                    if len(raw) != NONCE_FIELD_SIZE:
                        raise struct.error("short nonce")
                    values[name] = bytes(raw)
                    pos += NONCE_FIELD_SIZE
                else:
                    fmt = "<" + _CODES[code]
                    (value,) = struct.unpack_from(fmt, data, pos)
                    if code == "o":
                        if value > 1:
                            raise MessageError(f"{cls.__name__}.{name}: bool byte {value}")
                        value = bool(value)
                    values[name] = value
                    pos += struct.calcsize(fmt)
        except struct.error as exc:
            raise MessageError(f"{cls.__name__} payload too short ({len(data)} bytes)") from exc
        if pos != len(data):
            raise MessageError(f"{cls.__name__} payload has {len(data) - pos} trailing bytes")
        return cls(**values)


# --- host → robot -------------------------------------------------------------------


_ZERO_NONCE = bytes(NONCE_FIELD_SIZE)


@dataclass(frozen=True)
class Hello(Message):
    """Asks for a session: version, timing, flags and the host's challenge nonce.

    Sent without a MAC (the host has no session key yet); the robot answers
    with :class:`Challenge`, and the session starts only with a valid
    :class:`Auth`, whose key is bound to these exact bytes (docs/protocol.md §5).
    """

    TYPE = MsgType.HELLO
    LAYOUT = "major:B minor:B heartbeat_ms:H watchdog_ms:H flags:B host_nonce:N"
    major: int = PROTOCOL_MAJOR
    minor: int = PROTOCOL_MINOR
    heartbeat_ms: int = 100
    watchdog_ms: int = 500
    flags: int = 0
    host_nonce: bytes = _ZERO_NONCE


@dataclass(frozen=True)
class Auth(Message):
    """Host's proof (its MAC under the new session key); opens the session on the robot."""

    TYPE = MsgType.AUTH


@dataclass(frozen=True)
class Heartbeat(Message):
    """Keeps the robot's watchdog fed when the host has nothing else to send."""

    TYPE = MsgType.HEARTBEAT


@dataclass(frozen=True)
class Estop(Message):
    """Emergency stop: acted on at once, outside the sequence order, in any state."""

    TYPE = MsgType.ESTOP


@dataclass(frozen=True)
class CommandMessage(Message):
    """Common head of every program command: which run and which command of it."""

    run_id: int = 0
    index: int = 0


@dataclass(frozen=True)
class JointsCmd(CommandMessage):
    """Move all arm joints linearly to ``q_urad`` (µrad) over ``duration_ms``."""

    TYPE = MsgType.CMD_JOINTS
    LAYOUT = "run_id:I index:I duration_ms:I q_urad:A"
    duration_ms: int = 0
    q_urad: tuple[int, ...] = ()


@dataclass(frozen=True)
class WheelsCmd(CommandMessage):
    """Hold wheel surface speeds ``speeds_um_s`` (µm/s) for ``duration_ms``."""

    TYPE = MsgType.CMD_WHEELS
    LAYOUT = "run_id:I index:I duration_ms:I speeds_um_s:A"
    duration_ms: int = 0
    speeds_um_s: tuple[int, ...] = ()


@dataclass(frozen=True)
class MagnetCmd(CommandMessage):
    """Energise (touched) or release (untouched) magnet ``magnet``."""

    TYPE = MsgType.CMD_MAGNET
    LAYOUT = "run_id:I index:I magnet:B touched:o"
    magnet: int = 0
    touched: bool = False


@dataclass(frozen=True)
class LiftCmd(CommandMessage):
    """Rotate the lifting arm to ``angle_urad`` over ``duration_ms``."""

    TYPE = MsgType.CMD_LIFT
    LAYOUT = "run_id:I index:I duration_ms:I angle_urad:i"
    duration_ms: int = 0
    angle_urad: int = 0


@dataclass(frozen=True)
class PlateCmd(CommandMessage):
    """Engage (clamp) or release limiting plate ``plate``."""

    TYPE = MsgType.CMD_PLATE
    LAYOUT = "run_id:I index:I plate:B engaged:o"
    plate: int = 0
    engaged: bool = False


@dataclass(frozen=True)
class NozzleCmd(CommandMessage):
    """Open or close the blasting/spray nozzle."""

    TYPE = MsgType.CMD_NOZZLE
    LAYOUT = "run_id:I index:I on:o"
    on: bool = False


@dataclass(frozen=True)
class StopCmd(CommandMessage):
    """Program step: bring wheels to zero and hold joints (the run continues)."""

    TYPE = MsgType.CMD_STOP
    LAYOUT = "run_id:I index:I"


@dataclass(frozen=True)
class BasePoseCmd(CommandMessage):
    """Program step: the base is at this pose of the program's world frame (µm, µrad).

    The robot re-anchors its base pose there; later wheel motion moves the
    base in its own x–y plane from it.  Orientation: roll, pitch, yaw
    (``R = Rz(yaw)·Ry(pitch)·Rx(roll)``).
    """

    TYPE = MsgType.CMD_BASE_POSE
    LAYOUT = "run_id:I index:I x_um:i y_um:i z_um:i roll_urad:i pitch_urad:i yaw_urad:i"
    x_um: int = 0
    y_um: int = 0
    z_um: int = 0
    roll_urad: int = 0
    pitch_urad: int = 0
    yaw_urad: int = 0


@dataclass(frozen=True)
class CaptureCmd(CommandMessage):
    """Program step: take one sensor frame now (zero duration); the robot sends
    a :class:`CaptureHeader` and its :class:`CaptureChunk` messages."""

    TYPE = MsgType.CMD_CAPTURE
    LAYOUT = "run_id:I index:I"


@dataclass(frozen=True)
class Pause(Message):
    """Hold position; keep the buffer."""

    TYPE = MsgType.PAUSE


@dataclass(frozen=True)
class Resume(Message):
    """Continue after :class:`Pause`."""

    TYPE = MsgType.RESUME


@dataclass(frozen=True)
class Abort(Message):
    """Stop motion and drop every queued command (run id and last_done are kept)."""

    TYPE = MsgType.ABORT


@dataclass(frozen=True)
class Clear(Message):
    """Clear the latched fault bits in ``faults`` (``FaultFlag``)."""

    TYPE = MsgType.CLEAR
    LAYOUT = "faults:H"
    faults: int = 0


# --- robot → host -------------------------------------------------------------------


@dataclass(frozen=True)
class Challenge(Message):
    """Answer to :class:`Hello`: the robot's nonce and its proof that it knows the secret.

    ``status`` :attr:`HelloStatus.LINE_BUSY` refuses the HELLO (another
    controller holds the line); nonce and proof are then zero.
    """

    TYPE = MsgType.CHALLENGE
    LAYOUT = "major:B minor:B status:B robot_nonce:N proof:N"
    major: int = PROTOCOL_MAJOR
    minor: int = PROTOCOL_MINOR
    status: int = HelloStatus.OK
    robot_nonce: bytes = _ZERO_NONCE
    proof: bytes = _ZERO_NONCE


@dataclass(frozen=True)
class HelloAck(Message):
    """Answer to :class:`Hello`: the robot's version, limits of the session and progress."""

    TYPE = MsgType.HELLO_ACK
    LAYOUT = (
        "major:B minor:B status:B watchdog_ms:H state_period_ms:H buffer_capacity:B "
        "n_joints:B n_wheels:B n_magnets:B n_plates:B features:B run_id:I last_done:i name:S"
    )
    major: int = PROTOCOL_MAJOR
    minor: int = PROTOCOL_MINOR
    status: int = HelloStatus.OK
    watchdog_ms: int = 500
    state_period_ms: int = 100
    buffer_capacity: int = 16
    n_joints: int = 0
    n_wheels: int = 0
    n_magnets: int = 0
    n_plates: int = 0
    features: int = 0
    run_id: int = 0
    last_done: int = -1
    name: str = ""


@dataclass(frozen=True)
class Ack(Message):
    """Positive answer to the sequenced frame ``ref_seq`` (or to an ``ESTOP``)."""

    TYPE = MsgType.ACK
    LAYOUT = "ref_type:B ref_seq:H status:B buffer_free:B"
    ref_type: int = 0
    ref_seq: int = 0
    status: int = AckStatus.OK
    buffer_free: int = 0


@dataclass(frozen=True)
class Nak(Message):
    """Refusal of the sequenced frame ``ref_seq``; ``expected_seq`` is the next seq the robot wants."""

    TYPE = MsgType.NAK
    LAYOUT = "ref_type:B ref_seq:H reason:B expected_seq:H detail:h"
    ref_type: int = 0
    ref_seq: int = 0
    reason: int = NakReason.INVALID
    expected_seq: int = 0
    detail: int = 0

    @property
    def transient(self) -> bool:
        return self.reason in TRANSIENT_NAKS


@dataclass(frozen=True)
class State(Message):
    """Periodic state report; also the robot → host heartbeat.

    ``last_done`` is cumulative (every command of ``run_id`` up to it has
    finished), so a lost report costs nothing: the next one carries it too.
    """

    TYPE = MsgType.STATE
    LAYOUT = (
        "mode:B faults:H fault_code:H run_id:I last_done:i executing:i buffer_level:B "
        "t_ms:I magnets:B plates:B nozzle:o lift_urad:i q_urad:A odometry_um:A"
    )
    mode: int = Mode.IDLE
    faults: int = 0
    fault_code: int = 0
    run_id: int = 0
    last_done: int = -1
    executing: int = -1
    buffer_level: int = 0
    t_ms: int = 0
    magnets: int = 0
    plates: int = 0
    nozzle: bool = False
    lift_urad: int = 0
    q_urad: tuple[int, ...] = ()
    odometry_um: tuple[int, ...] = ()


#: Most points one capture may announce (the host refuses more; the robot thins to it).
MAX_CAPTURE_POINTS = 2048
#: Points per :class:`CaptureChunk`: 4+2 bytes of head, 3 × (1 + 2n) coordinates,
#: 1 + n intensities = 10 + 7n ≤ MAX_MESSAGE_PAYLOAD (220) → n ≤ 30.
CHUNK_POINTS = 30
#: Quaternion components on the wire: units of 1e-9.
QUAT_SCALE = 1_000_000_000


@dataclass(frozen=True)
class CaptureHeader(Message):
    """First message of a capture: who asked, when, where the camera was, how many points.

    ``capture_id`` is the robot's number of this capture (increasing, kept
    across restarts); ``run_id``/``index`` the ``CMD_CAPTURE`` that asked;
    ``t_ms`` the robot clock.  Camera → world transform: position ``*_um``
    (µm) and unit quaternion ``q*`` (units of 1e-9, w first).  ``n_points``
    points follow in :class:`CaptureChunk` messages (0 when the camera saw
    nothing); ``has_intensity``: each chunk carries one u8 intensity per point.
    """

    TYPE = MsgType.CAPTURE
    LAYOUT = (
        "capture_id:I run_id:I index:I t_ms:I x_um:i y_um:i z_um:i "
        "qw:i qx:i qy:i qz:i n_points:H has_intensity:o"
    )
    capture_id: int = 0
    run_id: int = 0
    index: int = 0
    t_ms: int = 0
    x_um: int = 0
    y_um: int = 0
    z_um: int = 0
    qw: int = QUAT_SCALE
    qx: int = 0
    qy: int = 0
    qz: int = 0
    n_points: int = 0
    has_intensity: bool = False


@dataclass(frozen=True)
class CaptureChunk(Message):
    """Points ``offset … offset + len(x_mm) − 1`` of capture ``capture_id``:
    camera-frame coordinates in millimetres (i16) and, when the header says
    so, one intensity byte per point (else ``intensity`` is empty)."""

    TYPE = MsgType.CAPTURE_CHUNK
    LAYOUT = "capture_id:I offset:H x_mm:a y_mm:a z_mm:a intensity:u"
    capture_id: int = 0
    offset: int = 0
    x_mm: tuple[int, ...] = ()
    y_mm: tuple[int, ...] = ()
    z_mm: tuple[int, ...] = ()
    intensity: tuple[int, ...] = ()


MESSAGE_CLASSES: dict[int, type[Message]] = {
    cls.TYPE: cls
    for cls in (
        Hello,
        Heartbeat,
        Estop,
        Auth,
        JointsCmd,
        WheelsCmd,
        MagnetCmd,
        LiftCmd,
        PlateCmd,
        NozzleCmd,
        StopCmd,
        BasePoseCmd,
        CaptureCmd,
        Pause,
        Resume,
        Abort,
        Clear,
        HelloAck,
        Ack,
        Nak,
        State,
        Challenge,
        CaptureHeader,
        CaptureChunk,
    )
}


def encode_message(msg: Message, seq: int = 0) -> bytes:
    """Wire bytes of ``msg`` as one frame with sequence number ``seq``."""
    return encode_frame(msg.TYPE, seq, msg.payload())


def decode_message(frame: Frame) -> Message:
    """The message in ``frame``; raises :class:`MessageError` for unknown types or bad payloads."""
    cls = MESSAGE_CLASSES.get(frame.type)
    if cls is None:
        raise MessageError(f"unknown message type 0x{frame.type:02X}")
    return cls.from_payload(frame.payload)


def message_fields(msg: Message) -> dict[str, Any]:
    """Field values of ``msg`` as a dict (for logs and JSON)."""
    return {f.name: v for f, v in zip(fields(msg), astuple(msg), strict=True)}
