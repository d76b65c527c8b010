"""Evidence about a two-footed robot's feet and magnets (the ARA, docs/protocol.md §13)
for tests that run its programs through a server: what the program had done with the
magnets at a command, whether a state leaves a foot held, what the emulator's own log
says it switched.

The rules are the emulator's (:class:`robots.emulator.feet.FeetSpec` of the robot's
profile, built from its description as the embedded emulators build it).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from functools import lru_cache
from typing import Any

import numpy as np

from robots.emulator.feet import FeetSpec
from robots.emulator.profiles import resolve_profile
from robots.emulator.robot import ExecutionRecord
from robots.protocol import command_from_dict


@lru_cache(maxsize=4)
def feet_spec(robot: str = "ara") -> FeetSpec:
    spec = resolve_profile(robot).feet
    assert spec is not None, f"robot {robot} has no feet rules"
    return spec


def magnets_after(program: Sequence[dict[str, Any]], last_done: int, start: int = 0) -> int:
    """The magnet bitmask once commands 0 … ``last_done`` of ``program`` ran (from ``start``)."""
    mask = start
    for c in program[: last_done + 1]:
        if c["op"] == "magnet":
            bit = 1 << int(c["magnet"])
            mask = mask | bit if c["touched"] else mask & ~bit
    return mask


def magnet_commands(program: Sequence[dict[str, Any]], last_done: int | None = None) -> list:
    """``(index, magnet, touched)`` of the program's magnet commands up to ``last_done``."""
    end = len(program) if last_done is None else last_done + 1
    return [
        (i, int(c["magnet"]), bool(c["touched"]))
        for i, c in enumerate(program[:end])
        if c["op"] == "magnet"
    ]


def magnet_commands_done(
    log: Iterable[ExecutionRecord], run_id: int, program: Sequence[dict[str, Any]]
) -> list:
    """``(index, magnet, touched)`` of each magnet command the emulator's log shows
    completed in run ``run_id``, in log order (the log names the op and index; the
    program at that index says which magnet and which way)."""
    out = []
    for r in log:
        if r.run_id != run_id or r.outcome != "done" or r.op != "magnet":
            continue
        c = program[r.index]
        assert c["op"] == "magnet", (r, c)
        out.append((r.index, int(c["magnet"]), bool(c["touched"])))
    return out


def ops_match(log: Iterable[ExecutionRecord], run_id: int, program: Sequence[dict]) -> list[str]:
    """Records of run ``run_id`` whose op is not the program's op at their index."""
    return [
        f"command {r.index}: robot executed {r.op}, program has {program[r.index]['op']}"
        for r in log
        if r.run_id == run_id and r.op != program[r.index]["op"]
    ]


def held(magnets: int, q: Sequence[float], robot: str = "ara") -> int:
    """Bits of the feet held with ``magnets`` and joints ``q`` (0: the robot would fall)."""
    return feet_spec(robot).held(int(magnets), np.asarray(q, dtype=float))


def in_air(magnets: int, q: Sequence[float], robot: str = "ara") -> int:
    """Bits of the feet in the air (bit 0 foot 1, bit 1 foot 2)."""
    return feet_spec(robot).in_air(int(magnets), np.asarray(q, dtype=float))


def unheld_steps(
    program: Sequence[dict[str, Any]], q0: Sequence[float], magnets0: int = 0, robot: str = "ara"
) -> list[str]:
    """Where running ``program`` in order from ``q0``/``magnets0`` would break a feet
    rule (a command the robot would refuse) or leave no foot held; empty when none."""
    spec = feet_spec(robot)
    q = np.asarray(q0, dtype=float)
    magnets = int(magnets0)
    problems = []
    for i, c in enumerate(program):
        msg = command_from_dict(c).to_message(1, i)
        rule = spec.refusal(msg, magnets, q)
        if rule is not None:
            problems.append(f"command {i} ({c['op']}) breaks {rule.name}")
        if c["op"] == "magnet":
            bit = 1 << int(c["magnet"])
            magnets = magnets | bit if c["touched"] else magnets & ~bit
        elif c["op"] == "joints":
            q = np.asarray(msg.q_urad, dtype=float) / 1e6
        if not spec.held(magnets, q):
            problems.append(f"no foot held after command {i} ({c['op']})")
    return problems


def last_joints(program: Sequence[dict[str, Any]]) -> list[float] | None:
    """The program's last joint way-point, quantised as on the wire (µrad)."""
    q = None
    for c in program:
        if c["op"] == "joints":
            q = [round(v * 1e6) * 1e-6 for v in c["q_rad"]]
    return q


def wheel_odometry(program: Sequence[dict[str, Any]], odometry0: Sequence[float]) -> list[float]:
    """Per-wheel odometry once the program's wheel commands ran (µm/s and ms on the wire)."""
    odo = [float(v) for v in odometry0]
    for c in program:
        if c["op"] == "wheels":
            ms = round(c["duration_s"] * 1e3)
            for i, v in enumerate(c["speeds_m_s"]):
                odo[i] += round(v * 1e6) * ms * 1e-9
    return odo


__all__ = [
    "feet_spec",
    "held",
    "in_air",
    "last_joints",
    "magnet_commands",
    "magnet_commands_done",
    "magnets_after",
    "ops_match",
    "unheld_steps",
    "wheel_odometry",
]
