"""Framing the camera on what a plan or cloud drew ("Show in
scene frames the plan's content").

Drawers add nodes through ``ctx.scene``; :class:`BoundsRecorder` stands in
for viser's ``SceneApi`` and notes, for every ``add_*`` call, where the node's
points lie in the world frame (its own position/orientation and those of the
frames it is named under).  :func:`framing` turns those points into a view:
look at the centre of the bulk (2nd–98th percentile box, so a stray point does
not zoom the view out), from far enough that the box fills the field of view,
broadside to the bulk's longest horizontal extent.
"""

from __future__ import annotations

import contextlib
from dataclasses import dataclass
from typing import Any

import numpy as np

#: Points kept per recorded call (evenly thinned), so recording stays cheap.
_PER_CALL = 2_000
#: Calls whose points a measuring pick may land on (drawn geometry; labels,
#: frames and the like only mark a place and are left out).
_PICKABLE = frozenset(
    {"add_point_cloud", "add_line_segments", "add_batched_meshes_simple", "add_mesh_simple"}
)
#: Direction from the content's centre to the camera (front-left, above; z up).
_VIEW_DIR = np.array([-0.55, -1.0, 0.75]) / np.linalg.norm([-0.55, -1.0, 0.75])
#: Turn from broadside towards the content's long axis (rad), for depth.
_YAW_RAD = np.radians(25.0)
#: Smallest half-size framed (m): a single marker is not filled to the edges.
_MIN_RADIUS_M = 0.3


@dataclass(frozen=True)
class View:
    """A camera ``position`` looking at ``look_at`` (world frame, metres)."""

    position: np.ndarray
    look_at: np.ndarray
    radius: float


def _rotation(wxyz: Any) -> np.ndarray:
    w, x, y, z = (float(v) for v in wxyz)
    n = np.sqrt(w * w + x * x + y * y + z * z) or 1.0
    w, x, y, z = w / n, x / n, y / n, z / n
    return np.array(
        [
            [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
            [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
            [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
        ]
    )


class BoundsRecorder:
    """viser's ``SceneApi`` with every ``add_*`` call's world points noted in
    :attr:`points` (a list of (k, 3) arrays)."""

    def __init__(self, scene: Any) -> None:
        self._scene = scene
        self._frames: dict[str, np.ndarray] = {}
        self.points: list[np.ndarray] = []
        #: Drawn geometry's points, unthinned (world frame), for the measuring tool.
        self.pickable: list[np.ndarray] = []

    def __getattr__(self, name: str) -> Any:
        attr = getattr(self._scene, name)
        if not name.startswith("add_") or not callable(attr):
            return attr

        def call(*args: Any, **kwargs: Any) -> Any:
            handle = attr(*args, **kwargs)
            # Framing is a convenience: a call it cannot read is left out.
            with contextlib.suppress(Exception):
                self._record(name, args, kwargs)
            return handle

        return call

    def _parent(self, node: str) -> np.ndarray:
        best, pose = -1, np.eye(4)
        for frame, T in self._frames.items():
            if node.startswith(frame + "/") and len(frame) > best:
                best, pose = len(frame), T
        return pose

    def _record(self, method: str, args: tuple[Any, ...], kwargs: dict[str, Any]) -> None:
        node = str(args[0] if args else kwargs["name"])
        local = np.eye(4)
        local[:3, :3] = _rotation(kwargs.get("wxyz", (1.0, 0.0, 0.0, 0.0)))
        local[:3, 3] = np.asarray(kwargs.get("position", (0.0, 0.0, 0.0)), dtype=float)
        world = self._parent(node) @ local
        if method == "add_frame":
            self._frames[node] = world
        pts = kwargs.get("points")
        if pts is None and method in ("add_point_cloud", "add_line_segments") and len(args) > 1:
            pts = args[1]
        if pts is None:
            pts = kwargs.get("batched_positions")  # instanced meshes: one point each
        if method in _PICKABLE:
            pick = pts if pts is not None else kwargs.get("vertices")
            if pick is not None:
                self.pickable.append(self._world(pick, world))
        if pts is None:
            pts = np.zeros((1, 3))  # the node's origin
        W = self._world(pts, world)
        if len(W) > _PER_CALL:
            W = W[:: int(np.ceil(len(W) / _PER_CALL))]
        if len(W):
            self.points.append(W)

    @staticmethod
    def _world(pts: Any, world: np.ndarray) -> np.ndarray:
        P = np.asarray(pts, dtype=float).reshape(-1, 3)
        P = P[np.isfinite(P).all(axis=1)]
        return P @ world[:3, :3].T + world[:3, 3]


def framing(points: list[np.ndarray] | np.ndarray, fov_rad: float) -> View | None:
    """The view that fits ``points`` (world frame) in a camera of vertical
    field of view ``fov_rad``; ``None`` when there are none."""
    P = np.vstack(points) if isinstance(points, list) and points else np.asarray(points)
    if P.size == 0:
        return None
    P = P.reshape(-1, 3)
    lo, hi = np.percentile(P, 2, axis=0), np.percentile(P, 98, axis=0)
    centre = (lo + hi) / 2.0
    radius = max(float(np.linalg.norm(hi - lo)) / 2.0, _MIN_RADIUS_M)
    distance = 1.15 * radius / np.sin(max(fov_rad, 0.1) / 2.0)
    bulk = P[np.all((lo <= P) & (hi >= P), axis=1)]
    return View(centre + _view_direction(bulk) * distance, centre, radius)


def _view_direction(P: np.ndarray) -> np.ndarray:
    """Unit vector from the content to the camera: broadside to the
    content's longest horizontal extent (a girder seen along its length
    shows nothing), turned :data:`_YAW_RAD` towards its axis for depth and
    raised as :data:`_VIEW_DIR` is; content with no dominant horizontal
    axis is seen along :data:`_VIEW_DIR`."""
    if len(P) < 3:
        return _VIEW_DIR
    xy = P[:, :2] - P[:, :2].mean(axis=0)
    w, V = np.linalg.eigh(xy.T @ xy / len(xy))
    if not w[1] > 2.0 * max(w[0], 1e-12):
        return _VIEW_DIR
    major = V[:, 1]
    side = np.array([-major[1], major[0]])
    if side @ _VIEW_DIR[:2] < 0:  # the side nearer the usual view
        side = -side
    if major @ _VIEW_DIR[:2] < 0:
        major = -major
    c, s = np.cos(_YAW_RAD), np.sin(_YAW_RAD)
    horiz = c * side + s * major
    flat = float(np.linalg.norm(_VIEW_DIR[:2]))
    out = np.array([horiz[0] * flat, horiz[1] * flat, _VIEW_DIR[2]])
    return out / np.linalg.norm(out)


def apply_view(server: Any, view: View) -> None:
    """Point every connected client's camera at ``view`` and make it the
    view new clients open with (and "Reset View" returns to)."""
    position, look_at = tuple(view.position), tuple(view.look_at)
    cam = server.initial_camera
    cam.look_at = look_at
    cam.position = position
    for client in server.get_clients().values():
        with contextlib.suppress(Exception):  # a client that just left
            # Position first: viser moves look_at along with a new position
            # (to keep the orientation), so look_at set before it was shifted
            # away and an open console looked past what was drawn.
            client.camera.position = position
            client.camera.look_at = look_at
