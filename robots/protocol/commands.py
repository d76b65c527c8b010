"""Program commands in SI units, and their wire form.

These are what a plan kind's compiler produces (a :class:`robots.protocol.program.Program`
is a tuple of them).  Each converts to one wire message with
:meth:`Command.to_message` (quantised: µrad, ms, µm/s) and back with
:func:`command_from_message`.  The JSON form (:meth:`Command.to_dict` /
:func:`command_from_dict`) is what gets stored with a plan:
``{"op": "joints", "q_rad": [...], "duration_s": 0.5}``.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any, ClassVar

from robots.protocol.messages import (
    MAX_ARRAY,
    BasePoseCmd,
    CaptureCmd,
    CommandMessage,
    JointsCmd,
    LiftCmd,
    MagnetCmd,
    NozzleCmd,
    PlateCmd,
    StopCmd,
    WheelsCmd,
)

URAD_PER_RAD = 1_000_000
UM_PER_M = 1_000_000
MS_PER_S = 1000
MAX_DURATION_S = 0xFFFFFFFF / MS_PER_S
#: A program's world frame is local (its origin is recorded with the plan): positions
#: stay within this, so that µm fit an i32 and metres a float32 to well under 1 mm.
MAX_WORLD_M = 2000.0
#: Angles of a base pose (roll, pitch, yaw) stay within ± this, rad.
MAX_ANGLE_RAD = 2.0 * math.pi


class CommandError(ValueError):
    """A command with values the protocol cannot carry (names the field)."""


def _duration_ms(duration_s: float, what: str) -> int:
    if not math.isfinite(duration_s) or not 0.0 <= duration_s <= MAX_DURATION_S:
        raise CommandError(f"{what}.duration_s={duration_s!r}: must be 0…{MAX_DURATION_S:.0f} s")
    return round(duration_s * MS_PER_S)


def _fixed(values: Sequence[float], scale: int, what: str) -> tuple[int, ...]:
    if len(values) > MAX_ARRAY:
        raise CommandError(f"{what}: {len(values)} values, at most {MAX_ARRAY}")
    out = []
    for i, v in enumerate(values):
        f = float(v)
        if not math.isfinite(f) or abs(f * scale) >= 2**31:
            raise CommandError(f"{what}[{i}]={v!r} is not a finite value in the i32 range")
        out.append(round(f * scale))
    return tuple(out)


@dataclass(frozen=True)
class Command:
    """Base of every program command."""

    OP: ClassVar[str] = ""

    def to_message(self, run_id: int, index: int) -> CommandMessage:
        raise NotImplementedError

    def to_dict(self) -> dict[str, Any]:
        raise NotImplementedError

    @property
    def duration_s(self) -> float:
        return 0.0


@dataclass(frozen=True)
class JointMove(Command):
    """Timed joint way-point: reach ``q_rad`` ``duration_s`` after the previous command ends."""

    OP = "joints"
    q_rad: tuple[float, ...]
    duration_s: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "q_rad", tuple(float(v) for v in self.q_rad))

    def to_message(self, run_id: int, index: int) -> JointsCmd:
        return JointsCmd(
            run_id=run_id,
            index=index,
            duration_ms=_duration_ms(self.duration_s, "joints"),
            q_urad=_fixed(self.q_rad, URAD_PER_RAD, "joints.q_rad"),
        )

    def to_dict(self) -> dict[str, Any]:
        return {"op": self.OP, "q_rad": list(self.q_rad), "duration_s": self.duration_s}


@dataclass(frozen=True)
class WheelSpeeds(Command):
    """Hold wheel surface speeds (m/s, one per wheel) for ``duration_s``."""

    OP = "wheels"
    speeds_m_s: tuple[float, ...]
    duration_s: float = 0.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "speeds_m_s", tuple(float(v) for v in self.speeds_m_s))

    def to_message(self, run_id: int, index: int) -> WheelsCmd:
        return WheelsCmd(
            run_id=run_id,
            index=index,
            duration_ms=_duration_ms(self.duration_s, "wheels"),
            speeds_um_s=_fixed(self.speeds_m_s, UM_PER_M, "wheels.speeds_m_s"),
        )

    def to_dict(self) -> dict[str, Any]:
        return {"op": self.OP, "speeds_m_s": list(self.speeds_m_s), "duration_s": self.duration_s}


@dataclass(frozen=True)
class SetMagnet(Command):
    """Magnet ``magnet`` touched (energised, holding) or untouched (released)."""

    OP = "magnet"
    magnet: int
    touched: bool

    def to_message(self, run_id: int, index: int) -> MagnetCmd:
        if not 0 <= self.magnet <= 7:
            raise CommandError(f"magnet.magnet={self.magnet}: must be 0…7")
        return MagnetCmd(run_id=run_id, index=index, magnet=self.magnet, touched=self.touched)

    def to_dict(self) -> dict[str, Any]:
        return {"op": self.OP, "magnet": self.magnet, "touched": self.touched}


@dataclass(frozen=True)
class LiftArm(Command):
    """Rotate the lifting arm to ``angle_rad`` over ``duration_s``."""

    OP = "lift"
    angle_rad: float
    duration_s: float = 0.0

    def to_message(self, run_id: int, index: int) -> LiftCmd:
        return LiftCmd(
            run_id=run_id,
            index=index,
            duration_ms=_duration_ms(self.duration_s, "lift"),
            angle_urad=_fixed([self.angle_rad], URAD_PER_RAD, "lift.angle_rad")[0],
        )

    def to_dict(self) -> dict[str, Any]:
        return {"op": self.OP, "angle_rad": self.angle_rad, "duration_s": self.duration_s}


@dataclass(frozen=True)
class LimitingPlate(Command):
    """Engage (clamp the guardrail) or release limiting plate ``plate``."""

    OP = "plate"
    plate: int
    engaged: bool

    def to_message(self, run_id: int, index: int) -> PlateCmd:
        if not 0 <= self.plate <= 7:
            raise CommandError(f"plate.plate={self.plate}: must be 0…7")
        return PlateCmd(run_id=run_id, index=index, plate=self.plate, engaged=self.engaged)

    def to_dict(self) -> dict[str, Any]:
        return {"op": self.OP, "plate": self.plate, "engaged": self.engaged}


@dataclass(frozen=True)
class Nozzle(Command):
    """Nozzle on (blasting/spraying) or off."""

    OP = "nozzle"
    on: bool

    def to_message(self, run_id: int, index: int) -> NozzleCmd:
        return NozzleCmd(run_id=run_id, index=index, on=self.on)

    def to_dict(self) -> dict[str, Any]:
        return {"op": self.OP, "on": self.on}


@dataclass(frozen=True)
class Stop(Command):
    """Program step: wheels to zero, joints held; the run goes on with the next command."""

    OP = "stop"

    def to_message(self, run_id: int, index: int) -> StopCmd:
        return StopCmd(run_id=run_id, index=index)

    def to_dict(self) -> dict[str, Any]:
        return {"op": self.OP}


def _bounded(values: Sequence[float], limit: float, scale: int, what: str) -> tuple[int, ...]:
    if len(values) != 3:
        raise CommandError(f"{what}: {len(values)} values, expected 3")
    for i, v in enumerate(values):
        f = float(v)
        if not math.isfinite(f) or abs(f) > limit:
            raise CommandError(f"{what}[{i}]={v!r}: must be a finite number within ±{limit:g}")
    return _fixed(values, scale, what)


@dataclass(frozen=True)
class BasePose(Command):
    """Program step: the base is at ``position_m`` / ``rpy_rad`` in the program's world frame.

    The robot re-anchors its base pose there (its wheel odometry counters go
    on counting; only the pose it integrates from them restarts here), and
    later wheel motion moves the base in its own x–y plane.  ``rpy_rad`` is
    roll, pitch, yaw: ``R = Rz(yaw)·Ry(pitch)·Rx(roll)``.  Positions within
    ±:data:`MAX_WORLD_M` m (the world frame is local), angles within
    ±:data:`MAX_ANGLE_RAD`.  Zero duration.
    """

    OP = "base_pose"
    position_m: tuple[float, ...]
    rpy_rad: tuple[float, ...] = (0.0, 0.0, 0.0)

    def __post_init__(self) -> None:
        object.__setattr__(self, "position_m", tuple(float(v) for v in self.position_m))
        object.__setattr__(self, "rpy_rad", tuple(float(v) for v in self.rpy_rad))

    def to_message(self, run_id: int, index: int) -> BasePoseCmd:
        x, y, z = _bounded(self.position_m, MAX_WORLD_M, UM_PER_M, "base_pose.position_m")
        r, p, w = _bounded(self.rpy_rad, MAX_ANGLE_RAD, URAD_PER_RAD, "base_pose.rpy_rad")
        return BasePoseCmd(
            run_id=run_id,
            index=index,
            x_um=x,
            y_um=y,
            z_um=z,
            roll_urad=r,
            pitch_urad=p,
            yaw_urad=w,
        )

    def to_dict(self) -> dict[str, Any]:
        return {"op": self.OP, "position_m": list(self.position_m), "rpy_rad": list(self.rpy_rad)}


@dataclass(frozen=True)
class Capture(Command):
    """Program step: take one sensor frame now (zero duration).

    The robot sends it to the host as a header and point chunks
    (docs/protocol.md); the host's link reassembles a
    :class:`robots.protocol.capture.SensorCapture`.  Executed exactly once like
    any command: a resume does not take it again.
    """

    OP = "capture"

    def to_message(self, run_id: int, index: int) -> CaptureCmd:
        return CaptureCmd(run_id=run_id, index=index)

    def to_dict(self) -> dict[str, Any]:
        return {"op": self.OP}


COMMAND_TYPES: dict[str, type[Command]] = {
    c.OP: c
    for c in (
        JointMove,
        WheelSpeeds,
        SetMagnet,
        LiftArm,
        LimitingPlate,
        Nozzle,
        Stop,
        BasePose,
        Capture,
    )
}


def _as_bool(d: Mapping[str, Any], key: str, op: str) -> bool:
    value = d.get(key)
    if not isinstance(value, bool):
        raise CommandError(f"{op}.{key}={value!r}: must be true or false")
    return value


def _as_number(d: Mapping[str, Any], key: str, op: str, default: float | None = None) -> float:
    value = d.get(key, default)
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise CommandError(f"{op}.{key}={value!r}: must be a finite number")
    return float(value)


def _as_numbers(d: Mapping[str, Any], key: str, op: str) -> tuple[float, ...]:
    value = d.get(key)
    if not isinstance(value, Sequence) or isinstance(value, str):
        raise CommandError(f"{op}.{key}={value!r}: must be a list of numbers")
    return tuple(_as_number({key: v}, key, op) for v in value)


def _as_int(d: Mapping[str, Any], key: str, op: str) -> int:
    value = d.get(key)
    if isinstance(value, bool) or not isinstance(value, int):
        raise CommandError(f"{op}.{key}={value!r}: must be an integer")
    return value


def command_from_dict(d: Mapping[str, Any]) -> Command:
    """Parse the JSON form of one command; raises :class:`CommandError` naming the bad field."""
    op = d.get("op") if isinstance(d, Mapping) else None
    if op not in COMMAND_TYPES:
        raise CommandError(f"command op={op!r}: must be one of {', '.join(COMMAND_TYPES)}")
    if op == "joints":
        cmd: Command = JointMove(_as_numbers(d, "q_rad", op), _as_number(d, "duration_s", op, 0.0))
    elif op == "wheels":
        cmd = WheelSpeeds(_as_numbers(d, "speeds_m_s", op), _as_number(d, "duration_s", op, 0.0))
    elif op == "magnet":
        cmd = SetMagnet(_as_int(d, "magnet", op), _as_bool(d, "touched", op))
    elif op == "lift":
        cmd = LiftArm(_as_number(d, "angle_rad", op), _as_number(d, "duration_s", op, 0.0))
    elif op == "plate":
        cmd = LimitingPlate(_as_int(d, "plate", op), _as_bool(d, "engaged", op))
    elif op == "nozzle":
        cmd = Nozzle(_as_bool(d, "on", op))
    elif op == "base_pose":
        cmd = BasePose(_as_numbers(d, "position_m", op), _as_numbers(d, "rpy_rad", op))
    elif op == "capture":
        cmd = Capture()
    else:
        cmd = Stop()
    cmd.to_message(1, 0)  # range checks (durations, i32 fixed point) fail here, not on the wire
    return cmd


def command_from_message(msg: CommandMessage) -> Command:
    """SI-unit command of a wire command message (the inverse of ``to_message``)."""
    if isinstance(msg, JointsCmd):
        return JointMove(tuple(v / URAD_PER_RAD for v in msg.q_urad), msg.duration_ms / MS_PER_S)
    if isinstance(msg, WheelsCmd):
        return WheelSpeeds(tuple(v / UM_PER_M for v in msg.speeds_um_s), msg.duration_ms / MS_PER_S)
    if isinstance(msg, MagnetCmd):
        return SetMagnet(msg.magnet, msg.touched)
    if isinstance(msg, LiftCmd):
        return LiftArm(msg.angle_urad / URAD_PER_RAD, msg.duration_ms / MS_PER_S)
    if isinstance(msg, PlateCmd):
        return LimitingPlate(msg.plate, msg.engaged)
    if isinstance(msg, NozzleCmd):
        return Nozzle(msg.on)
    if isinstance(msg, StopCmd):
        return Stop()
    if isinstance(msg, BasePoseCmd):
        return BasePose(
            (msg.x_um / UM_PER_M, msg.y_um / UM_PER_M, msg.z_um / UM_PER_M),
            tuple(v / URAD_PER_RAD for v in (msg.roll_urad, msg.pitch_urad, msg.yaw_urad)),
        )
    if isinstance(msg, CaptureCmd):
        return Capture()
    raise CommandError(f"{type(msg).__name__} is not a program command")
