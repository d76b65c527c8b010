"""What a plan kind's scene drawer receives.

Drawers (``server/scene/<kind>.py``) draw a *stored* plan into the viser scene
under ``ctx.root``; they never compute plans (DESIGN §3).  Interaction that
changes a plan goes through ``ctx.propose``, which records a *proposal* for a
new plan revision; an operator accepts it over REST (DESIGN §10).
"""

from __future__ import annotations

import threading
from collections.abc import Callable
from contextvars import ContextVar
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

#: The viser client id whose event is being handled (set around click
#: callbacks), so proposals can be rate-limited per client.
current_scene_client: ContextVar[int | None] = ContextVar("current_scene_client", default=None)


@dataclass
class Animation:
    """A looping animation: ``update(t)`` for ``t`` in ``[0, duration_s]``."""

    duration_s: float
    update: Callable[[float], None]


@dataclass
class DrawContext:
    """Handles a drawer may use.

    - ``scene``: the viser ``SceneApi`` (``server.scene``); name every node
      under ``root`` (e.g. ``f"{ctx.root}/route"``) so a redraw clears it.
    - ``gui``: the viser ``GuiApi`` for small per-plan controls (toggles).
    - ``propose(patch)``: propose a new plan whose params are this plan's
      params updated with ``patch`` (e.g. ``{"start": 3}``); returns the
      proposal id, or ``None`` when rate-limited.  It never creates a plan.
    - ``add_urdf(robot, name)``: a ``viser.extras.ViserUrdf`` of a robot
      description under ``root``; call ``update_cfg(q)`` on it.
    - ``animate(duration_s, update)``: register a looping animation callback.
    - ``tools``: interactive editors the drawer made, by name (the scene
      keeps them while the plan is shown).
    """

    scene: Any
    gui: Any
    root: str
    propose: Callable[[dict[str, Any]], str | None]
    server: Any = None  # the viser.ViserServer (ViserUrdf needs it, not the SceneApi)
    lock: threading.RLock = field(default_factory=threading.RLock)
    animations: list[Animation] = field(default_factory=list)
    gui_handles: list[Any] = field(default_factory=list)
    #: Interactive tools a drawer set up (e.g. ``"obstacles"``), kept by the scene.
    tools: dict[str, Any] = field(default_factory=dict)
    #: The robots drawn with :meth:`add_urdf`: node name → ViserUrdf (the
    #: planned ghost; the scene puts the reported robot under that node).
    robots: dict[str, Any] = field(default_factory=dict)
    #: The root frame of each robot drawn with :meth:`add_urdf` (same keys), for
    #: drawers that move the planned robot's base.
    robot_frames: dict[str, Any] = field(default_factory=dict)

    def add_urdf(self, robot: str, name: str, root_pose: np.ndarray | None = None) -> Any:
        from viser.extras import ViserUrdf

        from robots import load_robot

        model = load_robot(robot)
        frame = self.scene.add_frame(f"{self.root}/{name}", show_axes=False)
        if root_pose is not None:
            set_frame_pose(frame, root_pose)
        target = self.server if self.server is not None else _SceneOnly(self.scene)
        # ViserUrdf reads only ``target.scene``; its annotation names the two viser
        # types that have one, so the scene-only stand-in is outside it
        handle = ViserUrdf(
            target,  # type: ignore[arg-type]
            Path(model.urdf_path),
            root_node_name=f"{self.root}/{name}",
        )
        self.robots[f"{self.root}/{name}"] = handle
        self.robot_frames[f"{self.root}/{name}"] = frame
        return handle

    def animate(self, duration_s: float, update: Callable[[float], None]) -> None:
        self.animations.append(Animation(max(float(duration_s), 1e-3), update))


@dataclass
class _SceneOnly:
    """What ``ViserUrdf`` reads from its target: the ``scene`` attribute."""

    scene: Any


def set_frame_pose(handle: Any, T: np.ndarray) -> None:
    """Set a viser node's position and wxyz quaternion from a 4×4 transform."""
    from scipy.spatial.transform import Rotation

    T = np.asarray(T, dtype=float)
    x, y, z, w = Rotation.from_matrix(T[:3, :3]).as_quat()
    handle.position = tuple(T[:3, 3])
    handle.wxyz = (w, x, y, z)
