"""A command program: the ordered commands compiled from one approved plan.

A :class:`Program` is immutable; command ``i`` of the program is sent with
command index ``i`` on the wire, so "the last acknowledged index" is all an
execution needs to store to resume.  Its JSON form (:meth:`Program.to_dicts`)
is the ``list[dict]`` a plan kind's ``compile`` returns
(``server/kinds/base.py``).

Example::

    prog = Program.from_joint_trajectory(q, times, nozzle=True)   # blast
    prog = Program([WheelSpeeds((0.1, 0.1), 2.0), Stop()], robot="sbg_climber")
"""

from __future__ import annotations

import json
from collections.abc import Iterator, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any, overload

import numpy as np

from robots.protocol.commands import (
    Command,
    CommandError,
    JointMove,
    Nozzle,
    command_from_dict,
)


@dataclass(frozen=True)
class Program:
    """Ordered, immutable list of :class:`Command` for one robot."""

    commands: tuple[Command, ...]
    robot: str | None = None
    meta: Mapping[str, Any] = field(default_factory=dict)

    def __post_init__(self) -> None:
        cmds = tuple(self.commands)
        for i, c in enumerate(cmds):
            if not isinstance(c, Command):
                raise CommandError(f"program command {i} is a {type(c).__name__}, not a Command")
        object.__setattr__(self, "commands", cmds)

    def __len__(self) -> int:
        return len(self.commands)

    def __iter__(self) -> Iterator[Command]:
        return iter(self.commands)

    @overload
    def __getitem__(self, i: int) -> Command: ...
    @overload
    def __getitem__(self, i: slice) -> tuple[Command, ...]: ...
    def __getitem__(self, i: int | slice) -> Command | tuple[Command, ...]:
        return self.commands[i]

    @property
    def duration_s(self) -> float:
        """Sum of the commands' nominal durations."""
        return float(sum(c.duration_s for c in self.commands))

    def to_dicts(self) -> list[dict[str, Any]]:
        """JSON-ready list, one dict per command (what ``PlanKind.compile`` returns)."""
        return [c.to_dict() for c in self.commands]

    @classmethod
    def from_dicts(cls, items: Sequence[Mapping[str, Any]], robot: str | None = None) -> Program:
        """Parse the JSON form; raises :class:`CommandError` naming the bad command index."""
        cmds = []
        for i, d in enumerate(items):
            try:
                cmds.append(command_from_dict(d))
            except CommandError as exc:
                raise CommandError(f"program command {i}: {exc}") from exc
        return cls(tuple(cmds), robot=robot)

    def to_json(self) -> str:
        return json.dumps(
            {"robot": self.robot, "meta": dict(self.meta), "commands": self.to_dicts()}
        )

    @classmethod
    def from_json(cls, text: str) -> Program:
        data = json.loads(text)
        prog = cls.from_dicts(data["commands"], robot=data.get("robot"))
        return cls(prog.commands, robot=prog.robot, meta=data.get("meta") or {})

    @classmethod
    def from_joint_trajectory(
        cls,
        q: np.ndarray,
        times: np.ndarray,
        *,
        nozzle: bool = False,
        robot: str | None = None,
    ) -> Program:
        """Timed way-points from a (T,n) trajectory sampled at ``times`` (T,) seconds.

        The first row is reached with duration 0 (the robot must already be
        there or close; the emulator moves at once); each later row takes
        ``times[k] - times[k-1]``.  With ``nozzle=True`` the nozzle opens
        after the first way-point and closes after the last (blasting).
        """
        q = np.asarray(q, dtype=float)
        t = np.asarray(times, dtype=float)
        if q.ndim != 2 or t.shape != (q.shape[0],):
            raise CommandError(f"trajectory shapes q{q.shape} and times{t.shape} do not match")
        if q.shape[0] and (np.any(np.diff(t) < 0) or not np.all(np.isfinite(t))):
            raise CommandError("times must be finite and non-decreasing")
        cmds: list[Command] = []
        for k in range(q.shape[0]):
            dt = 0.0 if k == 0 else float(t[k] - t[k - 1])
            cmds.append(JointMove(tuple(q[k]), dt))
            if nozzle and k == 0:
                cmds.append(Nozzle(True))
        if nozzle and q.shape[0]:
            cmds.append(Nozzle(False))
        return cls(tuple(cmds), robot=robot)

    def check_joint_limits(self, joint_limits: np.ndarray, tol: float = 1e-9) -> list[str]:
        """Problems (empty when fine) of joint way-points against (n,2) limits in rad."""
        lim = np.asarray(joint_limits, dtype=float)
        problems = []
        for i, c in enumerate(self.commands):
            if not isinstance(c, JointMove):
                continue
            if len(c.q_rad) != lim.shape[0]:
                problems.append(f"command {i}: {len(c.q_rad)} joints, robot has {lim.shape[0]}")
                continue
            for j, v in enumerate(c.q_rad):
                if not lim[j, 0] - tol <= v <= lim[j, 1] + tol:
                    problems.append(
                        f"command {i}: joint {j} = {v:.6g} rad outside "
                        f"[{lim[j, 0]:.6g}, {lim[j, 1]:.6g}]"
                    )
        return problems
