"""Building robot command programs from plan results (used by kinds' ``compile``).

Commands are :mod:`robots.protocol.commands` objects; a kind's ``compile``
returns ``[c.to_dict() for c in commands]`` and the job runner validates the
program against the robot's joint limits before the plan can be approved.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

from planners.navigation.wheel_steps import wheel_steps
from robots.protocol.commands import Command, JointMove, LiftArm, Stop, WheelSpeeds


def differential_drive(
    xy: np.ndarray,
    *,
    track_m: float,
    speed_m_s: float,
    turn_rate_rad_s: float,
    heading_rad: float = 0.0,
    min_step_m: float = 1e-4,
    allow_reverse: bool = False,
) -> list[Command]:
    """Turn-in-place then drive-straight wheel commands along a polyline.

    ``xy`` (K,2) in the robot's surface frame; the robot starts at ``xy[0]``
    facing ``heading_rad``.  Each straight piece is one ``WheelSpeeds`` of
    equal left/right speed; each heading change an in-place turn with wheel
    speeds ``∓ω·B/2`` (differential drive kinematics).  Consecutive pieces in
    the same direction merge into one command.  With ``allow_reverse`` a piece
    pointing more than 90° away from the heading is driven backwards, so the
    robot never turns more than 90° in place (a U-turn at a bar end becomes a
    reversal: no sweep beyond the flange).
    """
    xy = np.asarray(xy, dtype=float).reshape(-1, 2)
    cmds: list[Command] = []
    heading = float(heading_rad)
    run, direction = 0.0, 1.0

    def flush() -> None:
        nonlocal run
        if run > 0:
            v = direction * speed_m_s
            cmds.append(WheelSpeeds((v, v), run / speed_m_s))
            run = 0.0

    for a, b in itertools.pairwise(xy):
        d = b - a
        length = float(np.hypot(*d))
        if length < min_step_m:
            continue
        target = float(np.arctan2(d[1], d[0]))
        turn = (target - heading + np.pi) % (2 * np.pi) - np.pi
        sense = 1.0
        if allow_reverse and abs(turn) > np.pi / 2:
            sense = -1.0
            turn = (turn + 2 * np.pi) % (2 * np.pi) - np.pi  # face away, drive backwards
        if abs(turn) > np.radians(0.5) or sense != direction:
            flush()
            if abs(turn) > np.radians(0.5):
                w = float(np.sign(turn) * turn_rate_rad_s * track_m / 2.0)
                cmds.append(WheelSpeeds((-w, w), abs(turn) / turn_rate_rad_s))
                heading = (heading + turn + np.pi) % (2 * np.pi) - np.pi
            direction = sense
        run += length
    flush()
    cmds.append(Stop())
    return cmds


def differential_drive_poses(
    poses: np.ndarray,
    *,
    track_m: float,
    speed_m_s: float,
    turn_rate_rad_s: float,
    position_tol_m: float = 1e-6,
    lateral_tol_m: float = 1e-5,
    yaw_tol_rad: float = 1e-6,
) -> list[Command]:
    """Wheel commands that drive exactly the pose sequence ``poses``.

    ``poses`` (K,3) = (x, y, yaw) in the robot's surface frame, as planned for
    a differential drive: each consecutive pair is either a turn in place
    (same position) or a straight drive along the shared heading, forwards
    or backwards (same yaw).  A pair that is neither — a sideways slide the
    wheels cannot make — raises ``ValueError`` naming it.  Runs of the same
    motion (same turn sense, same drive direction) merge into one command.

    Each command is quantised as the wire carries it (durations in ms,
    speeds in µm/s): the duration is rounded up to whole milliseconds at the
    nominal speed and the wheel speed then set so that speed × duration is
    the planned angle or distance — so a replay of the commands reproduces
    the planned poses to within µm-level rounding of the speeds, with no
    drift from rounded durations.
    """
    q = np.asarray(poses, dtype=float).reshape(-1, 3)
    if len(q) < 1:
        raise ValueError("no poses to drive")
    st = wheel_steps(
        q, position_tol_m=position_tol_m, lateral_tol_m=lateral_tol_m, yaw_tol_rad=yaw_tol_rad
    )
    dist, dyaw, along, lateral, turn = st.dist, st.dyaw, st.along, st.lateral, st.turn
    bad = st.sideways
    if bad.any():
        k = int(np.argmax(bad))
        raise ValueError(
            f"poses {k} → {k + 1} move {dist[k] * 1000:.1f} mm with "
            f"{np.degrees(dyaw[k]):.2f}° of turn and {lateral[k] * 1000:.2f} mm sideways: "
            "a differential drive can only turn in place or drive along its heading"
        )
    # (kind, sign) per step: kind 0 = turn, 1 = drive; zero steps are dropped.
    kind = np.where(turn, 0, 1)
    amount = np.where(turn, dyaw, along)
    moving = np.abs(amount) > np.where(turn, yaw_tol_rad, position_tol_m)
    cmds: list[Command] = []
    k = 0
    steps = np.nonzero(moving)[0]
    while k < len(steps):
        i = steps[k]
        sign = np.sign(amount[i])
        total = 0.0
        while k < len(steps) and kind[steps[k]] == kind[i] and np.sign(amount[steps[k]]) == sign:
            total += float(amount[steps[k]])
            k += 1
        if kind[i] == 0:
            dur = float(np.ceil(abs(total) / turn_rate_rad_s * 1000.0 - 1e-6) / 1000.0)
            w = round(total * track_m / 2.0 / dur, 6)
            cmds.append(WheelSpeeds((-w, w), dur))
        else:
            dur = float(np.ceil(abs(total) / speed_m_s * 1000.0 - 1e-6) / 1000.0)
            v = round(total / dur, 6)
            cmds.append(WheelSpeeds((v, v), dur))
    cmds.append(Stop())
    return cmds


def replay_wheels(
    pose0: np.ndarray,
    commands: Sequence[Command],
    *,
    track_m: float,
    step_m: float = 0.01,
    step_rad: float = 0.05,
) -> np.ndarray:
    """(P,3) poses of a differential drive replaying ``commands`` from ``pose0``.

    Exact integration of the unicycle model for each ``WheelSpeeds`` command
    held for its duration (v = (vl + vr)/2, ω = (vr − vl)/B; straight, turn
    in place or arc), sampled every ``step_m`` of travel and ``step_rad`` of
    turn; other commands do not move the base.  Independent of how the
    commands were made: this is what the wheels do.
    """
    x, y, th = (float(v) for v in np.asarray(pose0, dtype=float)[:3])
    out = [np.array([[x, y, th]])]
    for c in commands:
        if not isinstance(c, WheelSpeeds) or c.duration_s <= 0:
            continue
        vl, vr = float(c.speeds_m_s[0]), float(c.speeds_m_s[1])
        v, w = (vl + vr) / 2.0, (vr - vl) / track_m
        n = max(
            1, int(np.ceil(max(abs(v) * c.duration_s / step_m, abs(w) * c.duration_s / step_rad)))
        )
        t = np.linspace(0.0, c.duration_s, n + 1)[1:]
        a = th + w * t
        if abs(w) > 1e-12:
            px = x + v / w * (np.sin(a) - np.sin(th))
            py = y - v / w * (np.cos(a) - np.cos(th))
        else:
            px = x + v * t * np.cos(th)
            py = y + v * t * np.sin(th)
        seg = np.column_stack([px, py, (a + np.pi) % (2 * np.pi) - np.pi])
        out.append(seg)
        x, y, th = float(px[-1]), float(py[-1]), float(a[-1])
    return np.vstack(out)


def sampled_wheels_and_lift(
    t_s: np.ndarray,
    wheels_m_s: np.ndarray,
    lift_rad: np.ndarray | None = None,
    *,
    dt_s: float = 0.5,
    speed_tol_m_s: float = 1e-3,
    lift_tol_rad: float = np.radians(0.5),
) -> list[Command]:
    """Piecewise-constant wheel (and lift-arm) commands from time series.

    Samples every ``dt_s``, merges runs whose wheel speeds stay within
    ``speed_tol_m_s``, and emits a ``LiftArm`` whenever the arm moves more
    than ``lift_tol_rad`` — a compact program that reproduces the simulated
    speeds to within the tolerances.
    """
    t = np.asarray(t_s, dtype=float)
    w = np.asarray(wheels_m_s, dtype=float)
    if t.size == 0:
        return [Stop()]
    grid = np.arange(t[0], t[-1], dt_s)
    ws = np.stack([np.interp(grid, t, w[:, k]) for k in range(w.shape[1])], axis=1)
    arm = None if lift_rad is None else np.interp(grid, t, np.asarray(lift_rad, dtype=float))
    cmds: list[Command] = []
    current = ws[0]
    duration = 0.0
    last_arm = None if arm is None else float(arm[0])
    if last_arm is not None:
        cmds.append(LiftArm(last_arm, 0.0))
    for k in range(len(grid)):
        moved_arm = arm is not None and abs(float(arm[k]) - float(last_arm)) > lift_tol_rad  # type: ignore[arg-type]
        if np.max(np.abs(ws[k] - current)) > speed_tol_m_s or moved_arm:
            if duration > 0:
                cmds.append(WheelSpeeds(tuple(float(v) for v in current), duration))
            current, duration = ws[k], 0.0
            if moved_arm:
                cmds.append(LiftArm(float(arm[k]), 0.0))  # type: ignore[index]
                last_arm = float(arm[k])  # type: ignore[index]
        duration += dt_s
    if duration > 0:
        cmds.append(WheelSpeeds(tuple(float(v) for v in current), duration))
    cmds.append(Stop())
    return cmds


def sampled_joints_with_events(
    t_s: np.ndarray,
    q_rad: np.ndarray,
    events: Sequence[tuple[float, Command]],
    *,
    sample_s: float = 0.1,
) -> list[Command]:
    """Joint way-points every ``sample_s`` of a timed trajectory, with timed
    device commands (magnets, plates) inserted in time order.

    ``t_s`` (T,) increasing times, ``q_rad`` (T,J).  The first way-point has
    duration 0 (move there before the run's clock starts), each later one the
    time since the previous way-point; the last sample is always kept, and so
    is the last sample at or before each event's time.  An event at time t
    goes right after that way-point (never before it), so e.g. a magnet lets
    go only once the way-point where the other foot holds has been reached.
    """
    t = np.asarray(t_s, dtype=float).reshape(-1)
    q = np.asarray(q_rad, dtype=float)
    if len(t) == 0 or q.shape[0] != len(t):
        raise ValueError(f"trajectory needs matching times and joints, got {len(t)} and {q.shape}")
    step = max(1, round(sample_s / max(float(np.median(np.diff(t))), 1e-6))) if len(t) > 1 else 1
    ev = sorted(events, key=lambda e: e[0])
    # The sample each event belongs to is always a way-point: without it an
    # event between two kept samples (foot 1's magnet on at its landing, foot 2's
    # release) went out after the earlier one, with the foot still above the steel.
    at_events = [max(0, int(np.searchsorted(t, te, side="right")) - 1) for te, _ in ev]
    idx = np.unique(np.r_[np.arange(0, len(t), step), len(t) - 1, at_events].astype(int))
    cmds: list[Command] = []
    k_ev = 0
    prev = float(t[idx[0]])
    for n, i in enumerate(idx):
        cmds.append(JointMove(tuple(float(v) for v in q[i]), 0.0 if n == 0 else float(t[i] - prev)))
        prev = float(t[i])
        next_t = float(t[idx[n + 1]]) if n + 1 < len(idx) else np.inf
        while k_ev < len(ev) and ev[k_ev][0] < next_t:
            cmds.append(ev[k_ev][1])
            k_ev += 1
    cmds.append(Stop())
    return cmds


def as_dicts(commands: Sequence[Command]) -> list[dict]:
    return [c.to_dict() for c in commands]
