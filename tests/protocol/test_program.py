"""Program commands: SI ↔ wire quantisation, JSON form, programs from trajectories."""

from __future__ import annotations

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

# deadline=None everywhere: a loaded 2-core machine must not fail a property on time.
from robots.protocol import (
    COMMAND_TYPES,
    BasePose,
    Capture,
    CommandError,
    JointMove,
    LiftArm,
    LimitingPlate,
    Nozzle,
    Program,
    SetMagnet,
    Stop,
    WheelSpeeds,
    command_from_dict,
    command_from_message,
)
from robots.protocol.framing import FrameDecoder
from robots.protocol.messages import decode_message, encode_message

angles = st.floats(-100.0, 100.0, allow_nan=False)
durations = st.floats(0.0, 1e5, allow_nan=False)
commands = st.one_of(
    st.builds(JointMove, st.lists(angles, max_size=12).map(tuple), durations),
    st.builds(WheelSpeeds, st.lists(st.floats(-2.0, 2.0), max_size=4).map(tuple), durations),
    st.builds(SetMagnet, st.integers(0, 7), st.booleans()),
    st.builds(LiftArm, angles, durations),
    st.builds(LimitingPlate, st.integers(0, 7), st.booleans()),
    st.builds(Nozzle, st.booleans()),
    st.just(Stop()),
    st.builds(
        BasePose,
        st.lists(st.floats(-2000.0, 2000.0), min_size=3, max_size=3).map(tuple),
        st.lists(st.floats(-2 * math.pi, 2 * math.pi), min_size=3, max_size=3).map(tuple),
    ),
    st.just(Capture()),
)

EVERY_KIND = [
    JointMove((0.1, -0.2, 0.3), 0.5),
    WheelSpeeds((0.05, 0.05), 2.0),
    SetMagnet(1, True),
    LiftArm(0.7, 1.0),
    LimitingPlate(0, False),
    Nozzle(True),
    Stop(),
    BasePose((12.5, -3.0, 0.25), (0.0, 0.1, 1.5)),
    Capture(),
]


def test_every_command_kind_is_listed() -> None:
    assert {c.OP for c in EVERY_KIND} == set(COMMAND_TYPES)


@settings(deadline=None)
@given(commands, st.integers(1, 2**32 - 1), st.integers(0, 2**32 - 1))
def test_wire_round_trip_within_one_quantum(cmd, run_id: int, index: int) -> None:
    msg = cmd.to_message(run_id, index)
    back_msg = decode_message(FrameDecoder().feed(encode_message(msg, 1))[0])
    assert back_msg == msg and (msg.run_id, msg.index) == (run_id, index)
    back = command_from_message(back_msg)
    assert type(back) is type(cmd)
    for (name, a), b in zip(cmd.to_dict().items(), back.to_dict().values(), strict=True):
        if isinstance(a, list):
            assert np.allclose(a, b, atol=1e-6, rtol=0), name
        elif isinstance(a, float):
            assert math.isclose(a, b, abs_tol=1e-3 if name == "duration_s" else 1e-6), name
        else:
            assert a == b, name


@settings(deadline=None)
@given(st.lists(commands, max_size=20))
def test_json_round_trip(cmds) -> None:
    prog = Program(tuple(cmds), robot="generic", meta={"plan": "p1"})
    assert Program.from_json(prog.to_json()) == prog
    assert Program.from_dicts(prog.to_dicts()).commands == prog.commands


@pytest.mark.parametrize(
    ("d", "match"),
    [
        ({"op": "fly"}, "op='fly'"),
        ({"op": "joints", "q_rad": "abc"}, "joints.q_rad"),
        ({"op": "joints", "q_rad": [0.0, float("nan")]}, "joints.q_rad"),
        ({"op": "joints", "q_rad": [0.0], "duration_s": -1}, "joints.duration_s"),
        ({"op": "wheels", "speeds_m_s": [1e9]}, r"wheels.speeds_m_s\[0\]"),
        ({"op": "magnet", "magnet": 1, "touched": "yes"}, "magnet.touched"),
        ({"op": "magnet", "magnet": 9, "touched": True}, "magnet.magnet"),
        ({"op": "plate", "plate": 1.5, "engaged": True}, "plate.plate"),
        ({"op": "nozzle"}, "nozzle.on"),
        ({"op": "lift", "angle_rad": None}, "lift.angle_rad"),
        ({"op": "base_pose", "position_m": [0, 0], "rpy_rad": [0, 0, 0]}, "position_m"),
        ({"op": "base_pose", "position_m": [2000.5, 0, 0], "rpy_rad": [0, 0, 0]}, "±2000"),
        ({"op": "base_pose", "position_m": [0, 0, 0], "rpy_rad": [0, 7, 0]}, r"rpy_rad\[1\]"),
        ({"op": "base_pose", "position_m": [0, 0, 0]}, "base_pose.rpy_rad"),
        ({"op": "base_pose", "position_m": [0, None, 0], "rpy_rad": [0, 0, 0]}, "position_m"),
    ],
)
def test_bad_dicts_name_the_field(d: dict, match: str) -> None:
    with pytest.raises(CommandError, match=match):
        command_from_dict(d)


def test_base_pose_and_capture_dicts() -> None:
    d = {"op": "base_pose", "position_m": [1.0, -2.0, 0.5], "rpy_rad": [0.0, 0.0, 3.0]}
    cmd = command_from_dict(d)
    assert cmd == BasePose((1.0, -2.0, 0.5), (0.0, 0.0, 3.0)) and cmd.to_dict() == d
    assert cmd.duration_s == 0.0
    msg = cmd.to_message(7, 3)
    assert (msg.x_um, msg.y_um, msg.z_um, msg.yaw_urad) == (
        1_000_000,
        -2_000_000,
        500_000,
        3_000_000,
    )
    assert command_from_dict({"op": "capture"}) == Capture()
    assert Capture().to_dict() == {"op": "capture"} and Capture().duration_s == 0.0


def test_program_error_names_the_index() -> None:
    with pytest.raises(CommandError, match="program command 1"):
        Program.from_dicts([{"op": "stop"}, {"op": "nozzle", "on": 1}])
    with pytest.raises(CommandError, match="not a Command"):
        Program(({"op": "stop"},))  # type: ignore[arg-type]


def test_from_joint_trajectory_blasting() -> None:
    q = np.array([[0.0, 0.0], [0.1, 0.2], [0.2, 0.4]])
    t = np.array([0.0, 0.5, 1.5])
    prog = Program.from_joint_trajectory(q, t, nozzle=True, robot="denso_vm6083")
    ops = [c.OP for c in prog]
    assert ops == ["joints", "nozzle", "joints", "joints", "nozzle"]
    assert prog[1] == Nozzle(True) and prog[-1] == Nozzle(False)
    assert [c.duration_s for c in prog if isinstance(c, JointMove)] == [0.0, 0.5, 1.0]
    assert prog.duration_s == pytest.approx(1.5)
    with pytest.raises(CommandError, match="shapes"):
        Program.from_joint_trajectory(q, t[:2])
    with pytest.raises(CommandError, match="non-decreasing"):
        Program.from_joint_trajectory(q, t[::-1])


def test_check_joint_limits() -> None:
    lim = np.array([[-1.0, 1.0], [-0.5, 0.5]])
    prog = Program((JointMove((0.0, 0.0)), Nozzle(True), JointMove((0.0, 0.6)), JointMove((1.0,))))
    problems = prog.check_joint_limits(lim)
    assert len(problems) == 2
    assert problems[0].startswith("command 2: joint 1")
    assert problems[1].startswith("command 3: 1 joints")
