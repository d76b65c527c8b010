"""Differential-drive wheel programs from planned poses
(``server.kinds.programs.differential_drive_poses``) and their replay
(``replay_wheels``, exact unicycle integration): round trips, merging of
runs, and refusal of sideways steps."""

from __future__ import annotations

import itertools

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from robots.protocol.commands import Stop, WheelSpeeds
from server.kinds.programs import differential_drive_poses, replay_wheels

TRACK = 0.14  # the ARA's wheel track (robots/ara/params.toml [foot])
SPEED, RATE = 0.05, 0.5  # ara.navigate's drive speed (m/s) and turn rate (rad/s)

# One step: ("turn", angle rad) or ("drive", signed distance m).
step = st.one_of(
    st.tuples(st.just("turn"), st.floats(-3.1, 3.1, allow_nan=False)),
    st.tuples(st.just("drive"), st.floats(-0.5, 0.5, allow_nan=False)),
)


def _wrap(a):
    return (np.asarray(a) + np.pi) % (2 * np.pi) - np.pi


def _poses(pose0: np.ndarray, steps: list[tuple[str, float]]) -> np.ndarray:
    """Planned poses: each step a turn in place or a straight drive along the
    current heading (negative: backwards)."""
    out = [np.asarray(pose0, dtype=float)]
    for kind, amount in steps:
        x, y, th = out[-1]
        if kind == "turn":
            out.append(np.array([x, y, float(_wrap(th + amount))]))
        else:
            out.append(np.array([x + amount * np.cos(th), y + amount * np.sin(th), th]))
    return np.array(out)


def _runs(steps: list[tuple[str, float]]) -> int:
    """Brute-force count of maximal runs of the same motion (kind and sign),
    ignoring zero steps: the number of wheel commands expected."""
    moving = [(k, np.sign(a)) for k, a in steps if abs(a) > 1e-6]
    return len([g for g, _ in itertools.groupby(moving)])


def _near(replay: np.ndarray, q: np.ndarray, r: float = 0.05) -> float:
    """Distance from pose ``q`` to the nearest replayed pose, a turn weighted
    by ``r`` (metres per radian)."""
    dxy = np.hypot(replay[:, 0] - q[0], replay[:, 1] - q[1])
    return float(np.min(np.hypot(dxy, r * np.abs(_wrap(replay[:, 2] - q[2])))))


@settings(max_examples=60, deadline=None)
@given(
    st.tuples(
        st.floats(-2, 2, allow_nan=False),
        st.floats(-2, 2, allow_nan=False),
        st.floats(-np.pi, np.pi, allow_nan=False, exclude_max=True),
    ),
    st.lists(step, min_size=1, max_size=25),
    st.sampled_from([TRACK, 0.05, 0.3]),
)
def test_replay_drives_through_every_planned_pose(pose0, steps, track) -> None:
    poses = _poses(np.array(pose0), steps)
    cmds = differential_drive_poses(poses, track_m=track, speed_m_s=SPEED, turn_rate_rad_s=RATE)
    assert isinstance(cmds[-1], Stop)
    wheels = cmds[:-1]
    assert all(isinstance(c, WheelSpeeds) for c in wheels)
    # Each command a straight drive (equal speeds) or a turn in place
    # (opposite speeds) — never an arc; durations whole milliseconds.
    for c in wheels:
        vl, vr = c.speeds_m_s
        assert vl == vr or vl == -vr
        assert c.duration_s * 1000 == pytest.approx(round(c.duration_s * 1000), abs=1e-6)
        assert c.duration_s > 0
    assert len(wheels) == _runs(steps)
    replay = replay_wheels(poses[0], cmds, track_m=track, step_m=0.001, step_rad=0.01)
    assert np.hypot(*(replay[-1, :2] - poses[-1, :2])) < 1e-3
    assert abs(float(_wrap(replay[-1, 2] - poses[-1, 2]))) < 1e-3
    # Every planned pose is passed near (1 mm of travel / 0.01 rad sampling).
    worst = max(_near(replay, q) for q in poses)
    assert worst < 1.5e-3, worst


def test_runs_of_the_same_motion_merge_into_one_command() -> None:
    """5 small forward drives, 3 backwards, 4 left turns, 2 right turns and a
    forward drive: five commands (plus Stop), each the run's total."""
    steps = (
        [("drive", 0.02)] * 5
        + [("drive", -0.01)] * 3
        + [("turn", 0.1)] * 4
        + [("turn", 0.0)]  # a repeated pose is dropped, not a command
        + [("turn", -0.2)] * 2
        + [("drive", 0.03)]
    )
    poses = _poses(np.array([0.1, -0.2, 0.3]), steps)
    cmds = differential_drive_poses(poses, track_m=TRACK, speed_m_s=SPEED, turn_rate_rad_s=RATE)
    wheels = [c for c in cmds if isinstance(c, WheelSpeeds)]
    assert len(wheels) == 5
    # Signed distance / angle each command makes (speed × duration).
    made = []
    for c in wheels:
        vl, vr = c.speeds_m_s
        if vl == vr:
            made.append(("drive", vl * c.duration_s))
        else:
            made.append(("turn", (vr - vl) / TRACK * c.duration_s))
    want = [("drive", 0.10), ("drive", -0.03), ("turn", 0.4), ("turn", -0.4), ("drive", 0.03)]
    for c, (k, a), (kw, aw) in zip(wheels, made, want, strict=True):
        # Wire quantisation: speeds in µm/s, so a run is exact to within
        # 0.5 µm/s × duration (an angle: that over half the track).
        tol = 0.5e-6 * c.duration_s * (2.0 / TRACK if k == "turn" else 1.0) + 1e-12
        assert k == kw and a == pytest.approx(aw, abs=tol)
    # Nominal speeds: the quantised duration is the run at the nominal rate
    # rounded up to a millisecond, so the speed never exceeds nominal.
    assert all(max(abs(v) for v in c.speeds_m_s) <= SPEED + 1e-6 for c in wheels[:2])
    assert 0.10 / SPEED <= wheels[0].duration_s <= 0.10 / SPEED + 0.001 + 1e-12


@pytest.mark.parametrize("k", [0, 3, 6])
@pytest.mark.parametrize(
    ("what", "delta"),
    [("sideways", (0.0, 0.005, 0.0)), ("arc", (0.02, 0.0, 0.05)), ("diagonal", (0.01, 0.01, 0.0))],
)
def test_a_step_the_wheels_cannot_make_raises_naming_it(k, what, delta) -> None:
    steps = [("drive", 0.05), ("turn", 0.5), ("drive", -0.04)] * 3
    poses = _poses(np.array([0.0, 0.0, 0.0]), steps)
    # Replace step k → k+1 by one with a sideways / arc / diagonal component
    # in the robot frame, and shift every later pose with it.
    th = poses[k, 2]
    dx, dy, dth = delta
    move = np.array([dx * np.cos(th) - dy * np.sin(th), dx * np.sin(th) + dy * np.cos(th), dth])
    bad = np.vstack([poses[: k + 1], poses[k + 1 :] - poses[k + 1] + poses[k] + move])
    with pytest.raises(ValueError, match=rf"poses {k} → {k + 1} move"):
        differential_drive_poses(bad, track_m=TRACK, speed_m_s=SPEED, turn_rate_rad_s=RATE)
    # The unmodified sequence compiles.
    differential_drive_poses(poses, track_m=TRACK, speed_m_s=SPEED, turn_rate_rad_s=RATE)


def test_replay_integrates_arcs_exactly() -> None:
    """Independent of how commands are made: a quarter circle of radius R
    (wheel speeds ω(R ∓ B/2)) ends where geometry says it does."""
    big_r, w, track = 0.5, 0.2, TRACK
    dur = (np.pi / 2) / w
    cmd = WheelSpeeds((w * (big_r - track / 2), w * (big_r + track / 2)), dur)
    out = replay_wheels(np.array([1.0, 2.0, 0.0]), [cmd, Stop()], track_m=track)
    np.testing.assert_allclose(out[-1], [1.0 + big_r, 2.0 + big_r, np.pi / 2], atol=1e-9)
    # Every sample lies on the circle about (1, 2 + R).
    np.testing.assert_allclose(
        np.hypot(out[:, 0] - 1.0, out[:, 1] - 2.0 - big_r), big_r, atol=1e-12
    )
    assert np.max(np.hypot(*np.diff(out[:, :2], axis=0).T)) <= 0.01 + 1e-12


def test_single_pose_compiles_to_stop_and_empty_input_is_refused() -> None:
    cmds = differential_drive_poses(
        np.array([[0.0, 0.0, 1.0]]), track_m=TRACK, speed_m_s=SPEED, turn_rate_rad_s=RATE
    )
    assert len(cmds) == 1 and isinstance(cmds[0], Stop)
    with pytest.raises(ValueError, match="no poses"):
        differential_drive_poses(
            np.zeros((0, 3)), track_m=TRACK, speed_m_s=SPEED, turn_rate_rad_s=RATE
        )
