"""Robot registry: the robots SteelPath knows (DESIGN §5) and how their
description packages ``robots/<name>/`` are found and loaded (each has a
``load()`` returning a :class:`robots.model.RobotModel`).
"""

from __future__ import annotations

import importlib

from robots.model import RobotModel

ROBOT_NAMES: tuple[str, ...] = ("ara", "cmbot", "denso_vm6083", "sbg_climber")

__all__ = ["ROBOT_NAMES", "available_robots", "load_robot"]


def available_robots() -> list[str]:
    """Names whose description package is installed."""
    found = []
    for name in ROBOT_NAMES:
        try:
            importlib.import_module(f"robots.{name}")
        except ModuleNotFoundError:
            continue
        found.append(name)
    return found


def load_robot(name: str) -> RobotModel:
    """Load the kinematic model of ``name`` (one of :data:`ROBOT_NAMES`)."""
    if name not in ROBOT_NAMES:
        raise ValueError(f"unknown robot {name!r}; known robots: {', '.join(ROBOT_NAMES)}")
    try:
        module = importlib.import_module(f"robots.{name}")
    except ModuleNotFoundError as exc:
        raise ValueError(f"robot {name!r} has no description installed ({exc})") from exc
    return module.load()
