"""What the robot's camera saw, drawn in the scene over the plan's model.

Each capture (:mod:`server.captures`) is a node ``/plan/captures/c<id>``
placed at the camera's pose (camera → world, the plan's ``world`` frame):
a wireframe camera frustum (viser's, the optical convention: z along the
view, y down) and the points, as the robot sent them in the camera frame,
coloured by intensity when the capture has it (dark to bright green) and
else by range from the camera (near yellow, far magenta), so they stand out
from the model drawn under them.  Under ``/plan`` they go when the scene
shows another plan.

- :func:`show` draws the captures of an execution (all of them, or those the
  host had received by a time after its start), the latest
  :data:`MAX_SHOWN` at most, each thinned to :data:`MAX_POINTS_EACH` points;
- :class:`CaptureFollower`, an event-bus listener, draws each new capture of
  the plan shown while its run goes on (``capture`` events of the link
  service; it only queues, its own thread draws);
- the replay (:mod:`server.scene.replay`) shows the latest capture received
  at or before the scrubbed time (:func:`show_at`).
"""

from __future__ import annotations

import bisect
import contextlib
import logging
import queue
import threading
from typing import TYPE_CHECKING, Any

import numpy as np

from server.captures.store import CaptureRecord, CaptureStore
from server.recording.channels import iso_ns

if TYPE_CHECKING:
    from server.scene.service import SceneService

log = logging.getLogger(__name__)

ROOT = "/plan/captures"
#: Points drawn of one capture (every ``stride``-th above it).
MAX_POINTS_EACH = 100_000
#: Captures drawn at once (the latest).
MAX_SHOWN = 50
#: Frustum of the drawn camera (viser: vertical field of view, aspect ratio).
FRUSTUM_FOV_RAD = 1.0
FRUSTUM_ASPECT = 4 / 3


class CaptureSceneError(Exception):
    """The captures cannot be shown (HTTP 409 with this message)."""


def node_of(capture_id: int) -> str:
    return f"{ROOT}/c{int(capture_id)}"


def colours(points: np.ndarray, intensity: np.ndarray | None) -> np.ndarray:
    """(N,3) uint8: by intensity (green ramp) or by range (yellow → magenta)."""
    n = len(points)
    if intensity is not None and len(intensity) == n:
        t = intensity.astype(np.float32) / 255.0
        return np.stack([40 + 60 * t, 90 + 165 * t, 40 + 60 * t], axis=1).astype(np.uint8)
    r = np.linalg.norm(points.astype(np.float32), axis=1) if n else np.zeros(0, np.float32)
    lo, span = (float(r.min()), float(np.ptp(r))) if n else (0.0, 0.0)
    t = (r - lo) / max(span, 1e-9)
    return np.stack([255 - 25 * t, 230 - 200 * t, 40 + 190 * t], axis=1).astype(np.uint8)


def _wxyz(R: np.ndarray) -> tuple[float, float, float, float]:
    from server.recording.channels import quaternion

    x, y, z, w = quaternion(R)
    return (w, x, y, z)


def draw(scene: SceneService, captures: CaptureStore, rec: CaptureRecord) -> dict[str, Any]:
    """Draw one capture (replacing a drawing of it); the caller holds ``scene._lock``."""
    pts = captures.points(rec)
    inten = captures.intensity(rec)
    stride = max(1, -(-len(pts) // MAX_POINTS_EACH))
    pts = pts[::stride]
    inten = None if inten is None else inten[::stride]
    T = rec.camera_pose
    api = scene.server.scene
    node = node_of(rec.capture_id)
    api.add_frame(node, show_axes=False, position=tuple(T[:3, 3]), wxyz=_wxyz(T[:3, :3]))
    api.add_camera_frustum(
        f"{node}/camera",
        fov=FRUSTUM_FOV_RAD,
        aspect=FRUSTUM_ASPECT,
        scale=0.08,
        color=(255, 200, 40) if rec.complete else (200, 60, 60),
    )
    if len(pts):
        api.add_point_cloud(
            f"{node}/points",
            points=np.ascontiguousarray(pts, dtype=np.float32),
            colors=colours(pts, inten),
            point_size=0.008,
            precision="float32",
        )
    return {"capture_id": rec.capture_id, "points_drawn": len(pts), "stride": stride}


def _start_s(scene: SceneService, execution_id: str) -> tuple[Any, float]:
    ex = scene.store.get_execution(execution_id)  # NotFoundError: 404
    return ex, iso_ns(ex.created_at) / 1e9


def _ensure_plan(scene: SceneService, plan_id: str) -> None:
    if scene.current.get("plan_id") != plan_id:
        shown = scene.show_plan(plan_id)
        if shown.get("shown") != plan_id:
            raise CaptureSceneError(f"the scene could not show plan {plan_id}: {shown}")


def show(
    scene: SceneService,
    execution_id: str,
    up_to_s: float | None = None,
    *,
    latest_only: bool = False,
) -> dict[str, Any]:
    """Show the execution's plan (unless shown) and its captures received by
    ``up_to_s`` seconds after its start (all, if ``None``): the latest
    :data:`MAX_SHOWN`, or with ``latest_only`` the latest one."""
    if not scene.running:
        raise CaptureSceneError("the 3D scene is not running")
    ex, start = _start_s(scene, execution_id)
    _ensure_plan(scene, ex.plan_id)
    captures = CaptureStore(scene.store)
    recs = captures.list(ex.id)
    if up_to_s is not None:
        times = [r.received_at - start for r in recs]
        recs = recs[: bisect.bisect_right(times, float(up_to_s))]
    recs = recs[-1:] if latest_only else recs[-MAX_SHOWN:]
    with scene._lock:
        scene.server.scene.remove_by_name(ROOT)
        drawn = []
        for rec in recs:
            try:
                drawn.append({**draw(scene, captures, rec), "t_s": rec.received_at - start})
            except OSError:
                log.exception("capture %s of %s: its points are unreadable", rec.capture_id, ex.id)
        info = {
            "execution_id": ex.id,
            "plan_id": ex.plan_id,
            "up_to_s": up_to_s,
            "shown": drawn,
            "node": ROOT,
        }
        scene.current["captures"] = info
    return info


def show_at(scene: SceneService, execution_id: str, t_s: float) -> dict[str, Any] | None:
    """The replay's capture: the latest received at or before ``t_s`` (s after
    the start), drawn alone; ``None`` if none was by then."""
    info = show(scene, execution_id, t_s, latest_only=True)
    return info["shown"][-1] if info["shown"] else None


def clear(scene: SceneService) -> bool:
    """Remove the drawn captures (True if some were shown)."""
    if not scene.running:
        return False
    with scene._lock:
        had = scene.current.pop("captures", None) is not None
        scene.server.scene.remove_by_name(ROOT)
    return had


class CaptureFollower:
    """Draws each new capture of the plan the scene shows, as it arrives.

    ``on_event`` is an :class:`server.events.EventBus` listener: it only
    queues ``capture`` events; a thread of its own loads and draws them.
    """

    def __init__(self, scene: SceneService, queue_size: int = 256) -> None:
        self.scene = scene
        self._q: queue.Queue[dict[str, Any] | None] = queue.Queue(queue_size)
        self._thread = threading.Thread(target=self._run, name="scene captures", daemon=True)
        self._thread.start()

    def on_event(self, type_: str, data: dict[str, Any]) -> None:
        if type_ != "capture" or data.get("refused") or data.get("capture_id") is None:
            return
        with contextlib.suppress(queue.Full):
            self._q.put_nowait(dict(data))

    def stop(self) -> None:
        with contextlib.suppress(queue.Full):
            self._q.put_nowait(None)
        self._thread.join(timeout=2)

    def drain(self, timeout: float = 5.0) -> None:
        """Wait until the queued events are drawn (tests)."""
        import time

        deadline = time.monotonic() + timeout
        while self._q.unfinished_tasks and time.monotonic() < deadline:
            time.sleep(0.01)

    def _run(self) -> None:
        while True:
            data = self._q.get()
            try:
                if data is None:
                    return
                self.draw_new(data)
            except Exception:
                log.exception("drawing a capture failed")
            finally:
                self._q.task_done()

    def draw_new(self, data: dict[str, Any]) -> bool:
        """Draw the capture of a ``capture`` event if its plan is shown and no
        replay scrubs the scene; whether it was drawn."""
        scene = self.scene
        if not scene.running or scene.current.get("plan_id") != data.get("plan_id"):
            return False
        if scene.current.get("replay") is not None:
            return False  # the replay shows the capture of its time, not the newest
        captures = CaptureStore(scene.store)
        rec = captures.get(str(data["execution_id"]), int(data["capture_id"]))
        _, start = _start_s(scene, rec.execution_id)
        with scene._lock:
            if scene.current.get("plan_id") != data.get("plan_id"):
                return False
            shown = scene.current.get("captures")
            if not shown or shown.get("execution_id") != rec.execution_id:
                shown = {
                    "execution_id": rec.execution_id,
                    "plan_id": data.get("plan_id"),
                    "up_to_s": None,
                    "shown": [],
                    "node": ROOT,
                }
                scene.server.scene.remove_by_name(ROOT)
            drawn = {**draw(scene, captures, rec), "t_s": rec.received_at - start}
            kept = [s for s in shown["shown"] if s["capture_id"] != rec.capture_id] + [drawn]
            for old in kept[:-MAX_SHOWN]:
                scene.server.scene.remove_by_name(node_of(old["capture_id"]))
            shown["shown"] = kept[-MAX_SHOWN:]
            scene.current["captures"] = shown
        return True


def follow(scene: SceneService, events: Any) -> CaptureFollower:
    """The scene's :class:`CaptureFollower`, listening on ``events`` (an
    ``EventBus``); made and added once per scene, later calls return it."""
    with scene._lock:
        follower: CaptureFollower | None = getattr(scene, "_capture_follower", None)
        if follower is None:
            follower = CaptureFollower(scene)
            events.add_listener(follower.on_event)
            scene._capture_follower = follower  # type: ignore[attr-defined]
    return follower
