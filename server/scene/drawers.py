"""Scene drawers, looked up by plan-kind name.

The scene draws a stored plan from what the plan record holds (its kind name,
result and arrays), so it needs neither the kinds registry nor the kind
modules, and a kind module never imports its drawer: the two layers meet
only in the kind *name* ("one-way imports").  Each built-in
drawer module declares the kinds it draws in a ``DRAWS`` literal, read from
its source (:func:`discover_drawers`), so adding a kind's drawer is adding
its module; a drawer is imported on its first draw, so that importing the
scene service stays as cheap as it was.
Site-specific kinds (``STEELPATH_EXTRA_KINDS``) add theirs with
:func:`register_drawer` from their own module.

Each entry also names the robot whose URDF the scene shows live beside the
planned ghost (``SceneService.update_live_robot``); a test checks it against
the robot each registered kind drives.
"""

from __future__ import annotations

import ast
import importlib
import threading
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from server.planview import PlanView
    from server.scene.context import DrawContext

#: ``draw(ctx, plan)``: ``plan`` is the stored record, seen as a
#: :class:`server.planview.PlanView` (``id``, ``kind``, ``params``, ``result``,
#: ``checks``, ``array(name)``).
Drawer = Callable[["DrawContext", "PlanView"], None]


@dataclass(frozen=True)
class DrawerSpec:
    """Where a kind's drawer lives and which robot its plans move."""

    target: str  #: ``"package.module:function"``
    robot: str | None = None


def discover_drawers(package_dir: Path, package: str) -> dict[str, DrawerSpec]:
    """Kind name → drawer, from the ``DRAWS`` literal of each module in ``package_dir``.

    A drawer module declares what it draws at top level, e.g.
    ``DRAWS = {"sbg.inspect": ("draw", "sbg_climber")}`` (kind → function
    name, robot shown live).  The literal is read from the source with
    :func:`ast.literal_eval`, so finding the drawers imports none of them;
    a kind declared twice raises ``ValueError``.
    """
    found: dict[str, DrawerSpec] = {}
    for path in sorted(package_dir.glob("*.py")):
        source = path.read_text(encoding="utf-8")
        if "DRAWS" not in source:
            continue
        for node in ast.parse(source, filename=str(path)).body:
            if isinstance(node, ast.Assign) and len(node.targets) == 1:
                target, value = node.targets[0], node.value
            elif isinstance(node, ast.AnnAssign) and node.value is not None:
                target, value = node.target, node.value
            else:
                continue
            if not (isinstance(target, ast.Name) and target.id == "DRAWS"):
                continue
            table = ast.literal_eval(value)
            for kind, (function, robot) in table.items():
                if kind in found:
                    raise ValueError(f"plan kind {kind!r} has two drawers ({path.name})")
                found[kind] = DrawerSpec(f"{package}.{path.stem}:{function}", robot)
    return found


#: Kind name → drawer of every built-in kind, found in this package's modules.
DRAWERS: dict[str, DrawerSpec] = discover_drawers(Path(__file__).resolve().parent, "server.scene")

_registered: dict[str, tuple[Drawer, str | None]] = {}
_lock = threading.Lock()  # registration may race the scene thread's first lookup


def register_drawer(kind: str, draw: Drawer, robot: str | None = None) -> None:
    """Draw plans of ``kind`` with ``draw`` (a site-specific kind's drawer).

    A built-in kind keeps its own drawer: registering one for it raises
    ``ValueError`` rather than silently replacing what operators see.
    """
    if kind in DRAWERS:
        raise ValueError(f"plan kind {kind!r} already has a built-in drawer")
    with _lock:
        _registered[kind] = (draw, robot)


def _load(target: str) -> Drawer:
    module, _, name = target.partition(":")
    fn: Drawer = getattr(importlib.import_module(module), name)
    return fn


def drawer_for(kind: str) -> Drawer | None:
    """The drawer of ``kind``, or None for a kind the scene cannot draw."""
    with _lock:
        if kind in _registered:
            return _registered[kind][0]
    spec = DRAWERS.get(kind)
    return None if spec is None else _load(spec.target)


def robot_for(kind: str) -> str | None:
    """The robot whose plans ``kind`` holds (shown live in the scene), if any."""
    with _lock:
        if kind in _registered:
            return _registered[kind][1]
    spec = DRAWERS.get(kind)
    return None if spec is None else spec.robot


def drawable_kinds() -> list[str]:
    """Every kind name the scene has a drawer for."""
    with _lock:
        return sorted(set(DRAWERS) | set(_registered))
