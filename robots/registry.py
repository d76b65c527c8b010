"""Robot registry: the robots SteelPath knows (DESIGN §5) and how their
description packages ``robots/<name>/`` are found and loaded (each has a
``load()`` returning a :class:`robots.model.RobotModel`).

A robot *is* its description folder: every sub-package ``robots/<name>/``
that holds ``<name>.urdf`` is a robot, so adding one needs no list edited
here (docs/DEVELOPING.md, "Adding a robot").
"""

from __future__ import annotations

import importlib
from pathlib import Path

from robots.model import RobotModel


def _discover(root: Path) -> tuple[str, ...]:
    """Names of the description folders under ``root``: ``<name>/<name>.urdf`` and ``__init__.py``."""
    return tuple(
        sorted(
            d.name
            for d in root.iterdir()
            if d.is_dir() and (d / f"{d.name}.urdf").is_file() and (d / "__init__.py").is_file()
        )
    )


ROBOT_NAMES: tuple[str, ...] = _discover(Path(__file__).resolve().parent)

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
