"""Robot descriptions, kinematics loaders, hardware adapters and the emulator.

``load_robot(name)`` returns a :class:`robots.model.RobotModel` for each robot
SteelPath knows (DESIGN §5).  Each robot lives in its own sub-package
``robots/<name>/`` holding ``<name>.urdf``, ``params.toml`` (seed facts and
chosen values, marked) and a ``load()`` function.
"""

from __future__ import annotations

import importlib

from robots.model import DHRobotModel, RobotModel

ROBOT_NAMES: tuple[str, ...] = ("ara", "cmbot", "denso_vm6083", "sbg_climber")

__all__ = ["ROBOT_NAMES", "DHRobotModel", "RobotModel", "available_robots", "load_robot"]


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
