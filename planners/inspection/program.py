"""Checks of an ARA inspection program (seed 000 §3.2).

A program is a list of command dicts (``robots/protocol/commands.py``
forms: ``joints``, ``wheels``, ``magnet``, ``base_pose``, ``capture``,
``stop``).  These functions read it as the robot would execute it; the robot
numbers come in as arguments.

:func:`simulate_attachment` is a step-by-step simulation of the two feet's
attachment (seed §3.1–3.2: in the mobile configuration both magnetic arrays
are untouched and the robot holds on its wheels; in the inch-worm
transformation the standing foot's array is touched): the state is the arm
configuration and the two magnets; a foot is *held* when its magnet is
touched, or when the robot is in its mobile configuration on its wheels.
Rules, checked at every command:

1. a joint motion that starts or ends off the mobile configuration needs
   exactly one magnet touched (the standing foot's; with none the robot
   falls, with both the arm fights a closed chain);
2. a magnet is released only while the other foot is held;
3. the wheels turn only in the mobile configuration with both magnets
   untouched;
4. after every command at least one foot is held (never both released).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np

from planners.result import Check, check_le

__all__ = [
    "AttachmentResult",
    "command_limits",
    "program_metrics",
    "simulate_attachment",
]

#: Magnet channel → foot (the ARA's wire numbering, as ``ara.switch``).
FEET: dict[int, str] = {0: "foot1", 1: "foot2"}


@dataclass(frozen=True)
class AttachmentResult:
    """Outcome of :func:`simulate_attachment`: ``ok``; ``step`` (index of the
    first offending command, ``None`` when ok) and ``message``; ``steps``
    simulated; ``jumps`` (joint motions off the mobile configuration)."""

    ok: bool
    step: int | None
    message: str
    steps: int
    motions_off_mobile: int


def simulate_attachment(
    program: Sequence[Mapping[str, Any]],
    *,
    q_mobile: np.ndarray,
    mobile_tol_rad: float = 0.02,
    channels: Mapping[int, str] | None = None,
) -> AttachmentResult:
    """Simulate the feet's attachment over ``program`` (module docstring).

    The robot starts in the mobile configuration ``q_mobile`` on its wheels,
    both magnets untouched; a configuration is mobile when every joint is
    within ``mobile_tol_rad`` of ``q_mobile``.  ``channels`` maps a magnet
    channel to a foot name (default :data:`FEET`)."""
    feet = dict(channels or FEET)
    names = sorted(set(feet.values()))
    qm = np.asarray(q_mobile, float)
    q = qm.copy()
    touched = dict.fromkeys(names, False)
    off_mobile = 0

    def mobile(x: np.ndarray) -> bool:
        return bool(np.all(np.abs(x - qm) <= mobile_tol_rad))

    def held(foot: str) -> bool:
        return touched[foot] or mobile(q)

    def fail(k: int, why: str) -> AttachmentResult:
        return AttachmentResult(False, k, f"command {k}: {why}", k + 1, off_mobile)

    for k, c in enumerate(program):
        op = c.get("op")
        if op == "magnet":
            ch = int(c["magnet"])
            if ch not in feet:
                return fail(k, f"magnet channel {ch} is no foot's")
            foot = feet[ch]
            if not bool(c["touched"]):
                others = [f for f in names if f != foot]
                if touched[foot] and not all(held(o) for o in others):
                    return fail(k, f"releases {foot} while {', '.join(others)} is not held")
            touched[foot] = bool(c["touched"])
        elif op == "joints":
            q_new = np.asarray(c["q_rad"], float)
            if not (mobile(q) and mobile(q_new)):
                n = sum(touched.values())
                off_mobile += 1
                if n == 0:
                    return fail(
                        k, "moves the arm off the mobile configuration with no foot touched"
                    )
                if n > 1:
                    return fail(k, "moves the arm with both feet touched (a closed chain)")
            q = q_new
        elif op == "wheels":
            moving = any(abs(float(v)) > 0 for v in c.get("speeds_m_s", ()))
            if moving and float(c.get("duration_s", 0.0)) > 0:
                if not mobile(q):
                    return fail(k, "drives the wheels off the mobile configuration")
                if any(touched.values()):
                    return fail(k, "drives the wheels with a magnet touched")
        if not any(held(f) for f in names):
            return fail(k, "leaves both feet released")
    return AttachmentResult(
        True, None, f"{len(program)} commands: a foot holds throughout", len(program), off_mobile
    )


def attachment_check(result: AttachmentResult) -> Check:
    """The ``feet_attached`` check of :func:`simulate_attachment`'s result."""
    msg = (
        f"never both feet released: {result.steps} commands simulated, "
        f"{result.motions_off_mobile} joint motions off the mobile configuration each "
        "with exactly the standing foot's magnet touched"
        if result.ok
        else f"both feet could be released: {result.message}"
    )
    return Check(
        "feet_attached",
        result.ok,
        float(result.step) if result.step is not None else -1.0,
        -1.0,
        msg,
    )


def command_limits(
    program: Sequence[Mapping[str, Any]],
    *,
    joint_limits: np.ndarray,
    max_speed: np.ndarray,
    drive_speed_m_s: float,
    turn_rate_rad_s: float,
    track_m: float,
    q_start: np.ndarray,
) -> list[Check]:
    """``program_joint_limits`` (largest excess over the joint limits, rad),
    ``program_joint_speeds`` (largest joint speed / limit between
    consecutive way-points, over each one's duration) and
    ``program_wheel_speeds`` (largest wheel speed / limit: straight drives
    against ``drive_speed_m_s``, turns in place against
    ``turn_rate_rad_s · track_m / 2``)."""
    lim = np.asarray(joint_limits, float)
    vmax = np.asarray(max_speed, float)
    q = np.asarray(q_start, float)
    excess, ratio, wheel = 0.0, 0.0, 0.0
    turn_limit = turn_rate_rad_s * track_m / 2.0
    for c in program:
        op = c.get("op")
        if op == "joints":
            q_new = np.asarray(c["q_rad"], float)
            excess = max(
                excess, float(np.max(np.maximum(lim[:, 0] - q_new, q_new - lim[:, 1]).clip(0)))
            )
            dq = np.abs(q_new - q)
            dt = float(c.get("duration_s", 0.0))
            if dt > 0:
                ratio = max(ratio, float(np.max(dq / dt / vmax)))
            elif float(dq.max()) > 1e-9:
                ratio = max(ratio, float("inf"))
            q = q_new
        elif op == "wheels":
            s = [float(v) for v in c.get("speeds_m_s", ())]
            if len(s) == 2:
                straight = abs(s[0] - s[1]) <= 1e-9
                limit = drive_speed_m_s if straight else turn_limit
                wheel = max(wheel, max(abs(s[0]), abs(s[1])) / limit)
    return [
        check_le(
            "program_joint_limits", excess, 0.0, "largest joint-limit excess in the program", " rad"
        ),
        check_le("program_joint_speeds", ratio, 1.0, "largest joint speed / limit in the program"),
        check_le("program_wheel_speeds", wheel, 1.0, "largest wheel speed / limit in the program"),
    ]


def program_metrics(program: Sequence[Mapping[str, Any]]) -> dict[str, float]:
    """``program_duration_s`` (sum of the timed commands' durations),
    ``program_distance_m`` (straight wheel drives), command, way-point,
    capture and magnet counts."""
    duration, distance = 0.0, 0.0
    counts = {"joints": 0, "capture": 0, "magnet": 0, "wheels": 0, "base_pose": 0}
    for c in program:
        op = str(c.get("op"))
        if op in counts:
            counts[op] += 1
        dt = float(c.get("duration_s", 0.0) or 0.0)
        if op in ("joints", "wheels"):
            duration += dt
        if op == "wheels":
            s = [float(v) for v in c.get("speeds_m_s", ())]
            if len(s) == 2 and abs(s[0] - s[1]) <= 1e-9:
                distance += abs(s[0]) * dt
    return {
        "program_duration_s": duration,
        "program_distance_m": distance,
        "program_commands": float(len(program)),
        **{f"program_{k}_commands": float(v) for k, v in counts.items()},
    }
