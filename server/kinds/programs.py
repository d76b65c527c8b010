"""Building robot command programs from plan results (used by kinds' ``compile``).

Commands are :mod:`robots.protocol.commands` objects; a kind's ``compile``
returns ``[c.to_dict() for c in commands]`` and the job runner validates the
program against the robot's joint limits before the plan can be approved.
"""

from __future__ import annotations

import itertools
from collections.abc import Sequence

import numpy as np

from robots.protocol.commands import Command, LiftArm, Stop, WheelSpeeds


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


def as_dicts(commands: Sequence[Command]) -> list[dict]:
    return [c.to_dict() for c in commands]
