"""The in-process viser server and what it shows.

viser runs in its own daemon thread bound to 127.0.0.1 (it has no
authentication of its own); operators reach it only through the authenticated
proxy in :mod:`server.scene.proxy`, and viser refuses any websocket that does
not carry a one-time ticket from that proxy (:mod:`server.scene.wsguard`).
Scene interactions never create plans: they become proposals
(:mod:`server.scene.proposals`) that an operator accepts over REST.  The scene
is drawn from stored plans only, so a restart redraws the same picture.
Drawers and viser callbacks run on different threads, so every redraw holds
``self._lock``.
"""

from __future__ import annotations

import contextlib
import logging
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from server.lifecycle import PlanState
from server.scene import cloud_colours
from server.scene.context import Animation, DrawContext, current_scene_client
from server.scene.drawers import drawer_for, robot_for
from server.scene.finding_pick import MODIFIER as FINDING_MODIFIER
from server.scene.finding_pick import FindingPicker, point_view
from server.scene.framing import BoundsRecorder, apply_view, framing
from server.scene.measure import Measurer
from server.scene.proposals import ACCEPTING, PENDING, ProposalBook
from server.scene.wsguard import TicketDesk, guarded_viser_start
from server.store import NotFoundError, PlanRecord, Store

log = logging.getLogger(__name__)

MAX_CLOUD_POINTS = 300_000

#: Told of every new proposal (``Proposal.public()``), e.g. to publish it.
ProposeFn = Callable[[dict[str, Any]], None]
#: Finding marker colour per condition state (good, fair, poor, severe).
CONDITION_RGB = {1: (60, 170, 80), 2: (230, 200, 40), 3: (240, 130, 30), 4: (220, 30, 30)}
#: Publishes a scene event (type, data) to the console, e.g. a measuring pick.
PublishFn = Callable[[str, dict[str, Any]], object]


class SceneService:
    def __init__(
        self,
        store: Store,
        port: int,
        propose: ProposeFn,
        *,
        proposals: ProposalBook | None = None,
        publish: PublishFn | None = None,
    ) -> None:
        self.store = store
        self.requested_port = port
        self.port: int | None = None
        self._propose = propose
        self.tickets = TicketDesk()
        self._lock = threading.RLock()
        self._server: Any = None
        self._animations: list[Animation] = []
        self._gui_handles: list[Any] = []
        self.tools: dict[str, Any] = {}
        self._follow: str | None = None
        self._stop = threading.Event()
        self._anim_thread: threading.Thread | None = None
        self.current: dict[str, Any] = {}
        self._live: dict[str, Any] = {}
        self._live_cfg: dict[str, np.ndarray] = {}
        # The planned robot (ghost) of the plan shown, and the program's
        # command start times: an execution of the plan drives both.
        self._ghosts: dict[str, Any] = {}
        self._timeline: np.ndarray | None = None
        self._driven: str | None = None  # the execution now driving the animations
        # The replay robot of a recorded run (server.scene.replay), if shown.
        self._replay: dict[str, Any] = {}
        self.proposals = proposals if proposals is not None else ProposalBook()
        self._publish = publish
        self.measurer = Measurer()
        self.finding_picker = FindingPicker()

    # -------------------------------------------------------------- lifecycle
    @property
    def running(self) -> bool:
        return self._server is not None

    @property
    def server(self) -> Any:
        return self._server

    def start(self) -> None:
        import viser

        with guarded_viser_start(self.tickets) as wrapped:
            self._server = viser.ViserServer(
                host="127.0.0.1", port=self.requested_port, verbose=False
            )
        if not wrapped:
            # Fail closed: an unguarded viser port lets any local process drive the scene.
            self._server.stop()
            self._server = None
            log.error(
                "the 3D scene is disabled: viser did not start through "
                "websockets.asyncio.server.serve, so its websocket cannot be tied to the "
                "/scene/ proxy (viser upgraded? see server/scene/wsguard.py)"
            )
            return
        # viser silently moves to the next free port: read back what it got.
        self.port = int(self._server.get_port())
        self._server.scene.set_up_direction("+z")
        # The control panel starts minimized (one click opens it): it covered
        # a third of the console's scene view.
        with contextlib.suppress(AttributeError):  # viser without panel placement
            self._server.gui.main_panel.minimize()
        self._server.scene.add_grid("/grid", width=10.0, height=10.0, cell_size=0.25, plane="xy")
        # Shift-click measures (plain clicks stay the drawers' pickers).
        self._server.scene.on_click(modifier="shift")(self._on_measure_click)
        # Ctrl/Cmd-click on a face of an ara.inspect plan proposes a finding there.
        self._server.scene.on_click(modifier=FINDING_MODIFIER)(self._on_finding_click)
        self._anim_thread = threading.Thread(target=self._animate, name="scene-anim", daemon=True)
        self._anim_thread.start()
        log.info("viser scene on 127.0.0.1:%s", self.port)

    def stop(self) -> None:
        self._stop.set()
        if self._anim_thread is not None:
            self._anim_thread.join(timeout=2)
        if self._server is not None:
            self._server.stop()
            self._server = None

    # ---------------------------------------------------------------- drawing
    def _clear(self) -> None:
        scene = self._server.scene
        for name in ("/plan", "/cloud", "/measure", "/findings"):
            scene.remove_by_name(name)
        for h in self._gui_handles:
            with contextlib.suppress(Exception):  # already gone with its client
                h.remove()
        self._gui_handles = []
        self._animations = []
        self._live = {}
        self._live_cfg = {}
        self.tools = {}
        self._ghosts = {}
        self._timeline = None
        self._driven = None
        self._replay = {}
        self.finding_picker.set_plan(None)

    def show_plan(self, plan_id: str) -> dict[str, Any]:
        """Draw a stored plan (its kind's drawer); follow it if still planning."""
        plan = self.store.get_plan(plan_id)
        if not self.running:
            return {"shown": None, "reason": "scene is not running"}
        if plan.state in (PlanState.QUEUED, PlanState.PLANNING):
            self._follow = plan.id
        with self._lock:
            self._clear()
            self.current = {
                "plan_id": plan.id,
                "kind": plan.kind,
                "state": plan.state,
                "robot": robot_for(plan.kind),
                "base_pose": plan.result.get("robot_base_pose"),
            }
            if plan.result or plan.arrays:
                self._draw(plan)
        return {"shown": plan.id, "state": plan.state, "following": self._follow == plan.id}

    def _draw(self, plan: PlanRecord) -> None:
        # By kind name from the stored record: the scene never loads the kinds registry.
        try:
            draw = drawer_for(plan.kind)
        except Exception:  # a broken drawer module must not take the scene down
            log.exception("loading the drawer of kind %s failed", plan.kind)
            draw = None
        if draw is None:
            return
        recorder = BoundsRecorder(self._server.scene)
        ctx = DrawContext(
            scene=recorder,
            gui=self._server.gui,
            root="/plan",
            propose=lambda patch: self._on_propose(plan.id, patch),
            server=self._server,
            lock=self._lock,
        )
        try:
            draw(ctx, plan)
        except Exception:
            log.exception("drawing plan %s failed", plan.id)
            self._server.scene.add_label(
                "/plan/error", text=f"could not draw {plan.id}", position=(0, 0, 0.3)
            )
        self._animations = list(ctx.animations)
        self._gui_handles = list(ctx.gui_handles)
        self.tools = dict(ctx.tools)
        self._ghosts = dict(ctx.robots)
        self._timeline = _timeline(plan.program)
        self._frame(recorder.points)
        self.measurer.set_points(recorder.pickable)
        self.finding_picker.set_plan(plan)
        self._draw_findings(plan.id)

    # -------------------------------------------------------------- findings
    def _draw_findings(self, plan_id: str) -> None:
        """The plan's findings as markers coloured by condition state, each
        labelled with its type and condition."""
        from server.store.findings import CONDITION_STATES, FindingStore

        scene = self._server.scene
        scene.remove_by_name("/findings")
        store = FindingStore(self.store.db, self.store.data_dir / "photos")
        found = store.listed(plan_id=plan_id)
        where, colours = [], []
        for f in found:
            pts = [f.point_m] if f.point_m is not None else (f.region_m or [])
            if not pts:
                continue
            p = np.asarray(pts, dtype=float).mean(axis=0)
            where.append(p)
            colours.append(CONDITION_RGB[f.condition_state])
            scene.add_label(
                f"/findings/labels/{f.id}",
                text=f"{f.type.replace('_', ' ')} ({CONDITION_STATES[f.condition_state]})",
                position=tuple(p + [0.0, 0.0, 0.08]),
            )
        if where:
            from server.scene.common import add_spheres

            add_spheres(scene, "/findings/markers", np.asarray(where), radius=0.04,
                        colors=np.asarray(colours, dtype=np.uint8))  # fmt: skip
        self.current["findings"] = len(where)

    def findings_changed(self, plan_id: str) -> None:
        """A finding of ``plan_id`` was added, edited or withdrawn."""
        if self.running and self.current.get("plan_id") == plan_id:
            with self._lock:
                self._draw_findings(plan_id)

    def _on_finding_click(self, event: Any) -> None:
        """A Ctrl/Cmd-click: propose a finding at the face under the cursor
        (:mod:`server.scene.finding_pick`); off every face, nothing."""
        place = self.finding_picker.pick(event.ray_origin, event.ray_direction)
        if place is None:
            log.info("finding click of scene client %s is on no face", event.client_id)
            return
        patch = {k: place[k] for k in ("member_id", "face_id", "point_m")}
        token = current_scene_client.set(event.client_id)
        try:
            pid = self._on_propose(place["plan_id"], patch, action="finding")
        finally:
            current_scene_client.reset(token)
        if pid is not None and self.running:
            with self._lock:  # a white marker until the proposal is decided
                handle = self._server.scene.add_icosphere(
                    f"/findings/proposed/{pid}",
                    radius=0.03,
                    color=(255, 255, 255),
                    position=tuple(place["point_m"]),
                )
                # decided between its recording and this marker (the API
                # lists it at once): proposal_decided found no marker to remove
                if self._proposal_state(pid) not in (PENDING, ACCEPTING):
                    handle.remove()

    def _proposal_state(self, proposal_id: str) -> str:
        try:
            return self.proposals.get(proposal_id).state
        except NotFoundError:
            return "gone"

    def proposal_decided(self, proposal_id: str) -> None:
        """A finding proposal was accepted or dismissed: its marker goes."""
        if not self.running:
            return
        with self._lock:
            handle = self._server.scene.get_handle_by_name(f"/findings/proposed/{proposal_id}")
            if handle is not None:
                handle.remove()

    def frame_point(self, point: Any, normal: Any | None = None) -> dict[str, Any]:
        """Move every viewer's camera to look at ``point`` (a finding's place)."""
        view = point_view(point, float(self._server.initial_camera.fov), normal)
        with self._lock:
            apply_view(self._server, view)
            self.current["view"] = {
                "look_at": [round(float(v), 4) for v in view.look_at],
                "position": [round(float(v), 4) for v in view.position],
                "radius_m": round(view.radius, 4),
            }
        return dict(self.current["view"])

    def _frame(self, points: list[np.ndarray] | np.ndarray) -> None:
        """Fit every viewer's camera to what was just drawn."""
        view = framing(points, float(self._server.initial_camera.fov))
        if view is not None:
            apply_view(self._server, view)
            self.current["view"] = {
                "look_at": [round(float(v), 4) for v in view.look_at],
                "position": [round(float(v), 4) for v in view.position],
                "radius_m": round(view.radius, 4),
            }

    def show_cloud(self, cloud_id: str, colour_by: str = "auto") -> dict[str, Any]:
        """Draw a stored cloud, coloured by ``colour_by`` (:mod:`server.scene.cloud_colours`:
        ``auto`` is its RGB when it has one, else height); a colour the cloud has
        no attribute for raises :class:`NotFoundError`."""
        rec = self.store.get_cloud(cloud_id)
        colour = cloud_colours.resolve(colour_by, rec.attributes)
        if colour in ("rgb", "intensity"):
            attr = self.store.cloud_attribute(cloud_id, colour)  # NotFoundError: none
        if not self.running:
            return {"shown": None, "reason": "scene is not running"}
        pts = self.store.cloud_points(cloud_id)
        step = 1
        if len(pts) > MAX_CLOUD_POINTS:
            # Deterministic thinning keeps the browser responsive on big scans.
            step = int(np.ceil(len(pts) / MAX_CLOUD_POINTS))
            pts = pts[::step]
        if colour == "rgb":
            bits = (rec.survey.get("attributes") or {}).get("rgb", {}).get("bits")
            colors = cloud_colours.by_rgb(np.asarray(attr[::step]), bits)
        elif colour == "intensity":
            colors = cloud_colours.by_intensity(np.asarray(attr[::step]))
        else:
            colors = cloud_colours.by_height(pts)
        with self._lock:
            self._clear()
            self.current = {"cloud_id": rec.id, "colour_by": colour}
            center = pts.mean(axis=0)
            # float32 relative to the centre keeps precision far from the origin.
            self._server.scene.add_point_cloud(
                "/cloud",
                points=(pts - center).astype(np.float32),
                colors=colors,
                point_size=0.01,
                precision="float32",
                position=tuple(center),
            )
            self._frame(pts)
            self.measurer.set_points([pts])
        return {"shown": rec.id, "points_drawn": len(pts), "colour_by": colour}

    # -------------------------------------------------------------- measuring
    def _on_measure_click(self, event: Any) -> None:
        """A shift-click: pick the drawn point under the cursor; the second
        pick of a client closes a measurement (drawn, and published)."""
        try:
            result = self.measurer.click(event.client_id, event.ray_origin, event.ray_direction)
        except ValueError:  # a degenerate ray from a client: nothing to pick
            return
        if result["state"] != "missed" and self.running:
            with self._lock:
                self._draw_measure(result)
        if self._publish is not None:
            try:
                self._publish("measurement", result)
            except Exception:  # publishing must not break viser's callback thread
                log.exception("publishing a measurement failed")

    def _draw_measure(self, result: dict[str, Any]) -> None:
        scene = self._server.scene
        view = self.current.get("view") or {}
        r = max(0.005, 0.006 * float(view.get("radius_m", 1.0)))
        colour = (255, 60, 200)
        if result["state"] == "first":
            scene.remove_by_name("/measure")
            scene.add_icosphere("/measure/a", radius=r, color=colour, position=result["point_m"])
            return
        a, b = np.asarray(result["a_m"]), np.asarray(result["b_m"])
        scene.add_icosphere("/measure/a", radius=r, color=colour, position=tuple(a))
        scene.add_icosphere("/measure/b", radius=r, color=colour, position=tuple(b))
        scene.add_line_segments(
            "/measure/line", points=np.array([[a, b]], dtype=np.float32), colors=colour
        )
        scene.add_label(
            "/measure/label",
            text=f"{result['distance_mm']:.0f} mm",
            position=tuple((a + b) / 2.0),
        )

    def clear_measurement(self) -> None:
        self.measurer.clear()
        if self.running:
            with self._lock:
                self._server.scene.remove_by_name("/measure")

    def update_live_robot(self, robot: str, q: np.ndarray) -> None:
        """Show the robot's *reported* joints beside the planned ghost (orange)."""
        if not self.running or self.current.get("robot") != robot:
            return
        with self._lock:
            handle = self._live.get(robot)
            if handle is None:
                handle = self._add_live(robot)
                if handle is None:
                    return
            names = list(handle.get_actuated_joint_names())
            cfg = self._live_cfg.get(robot)
            if cfg is None or len(cfg) != len(names):
                cfg = np.zeros(len(names))
            q = np.asarray(q, dtype=float).ravel()
            ghost = self._ghost_cfg(names)
            if ghost is not None:
                cfg = ghost.copy()
            if len(q) == len(names):
                cfg = q.copy()
            else:
                # The robot reports its own joints (CMBOT: the 7-DoF arm of a
                # 12-joint URDF): placed by name, the others as planned now
                # (the ghost's), else where they were.
                index = {n: i for i, n in enumerate(names)}
                reported = self._reported_joints(robot)
                if len(reported) != len(q) or not all(n in index for n in reported):
                    return
                cfg = cfg.copy()
                cfg[[index[n] for n in reported]] = q
            self._live_cfg[robot] = cfg
            handle.update_cfg(cfg)

    @staticmethod
    def _reported_joints(robot: str) -> list[str]:
        from robots import load_robot

        try:
            return list(load_robot(robot).joint_names)
        except ValueError:
            return []

    def _ghost_cfg(self, names: list[str]) -> np.ndarray | None:
        """The planned robot's joints now, in ``names`` order (None: no ghost
        of that URDF)."""
        for g in self._ghosts.values():
            with contextlib.suppress(Exception):
                if list(g.get_actuated_joint_names()) == names:
                    return np.asarray(g._urdf.cfg, dtype=float)
        return None

    def _add_live(self, robot: str) -> Any:

        from robots import load_robot

        try:
            path = Path(load_robot(robot).urdf_path)
        except ValueError:
            return None
        _, handle = self.attach_urdf(robot, path, "live", (1.0, 0.55, 0.1, 0.7))
        self._live[robot] = handle
        return handle

    def attach_urdf(
        self, robot: str, path: Path, name: str, rgba: tuple[float, float, float, float]
    ) -> tuple[str, Any]:
        """A tinted copy of ``robot``'s URDF (the live or a replayed robot):
        its node name and ViserUrdf.  Under the planned robot's own node when
        the drawer made one, so the reported joints ride on the planned base
        as it moves (an inch-worm or a climber changes its base; a report has
        joints only)."""
        from viser.extras import ViserUrdf

        from server.scene.context import set_frame_pose

        parent = next(iter(self._ghosts), None)
        node = f"{parent}/{name}" if parent is not None else f"/plan/{name}_{robot}"
        frame = self._server.scene.add_frame(node, show_axes=False)
        if parent is None and self.current.get("base_pose") is not None:
            set_frame_pose(frame, np.asarray(self.current["base_pose"], dtype=float))
        return node, ViserUrdf(self._server, path, root_node_name=node, mesh_color_override=rgba)

    def execution_progress(self, plan_id: str, execution_id: str, state: str, acked: int) -> None:
        """An execution of the plan shown moved on: the planned robot (the
        ghost) and everything animated stand where the plan is after the
        ``acked`` commands done (by their planned durations) instead of
        looping; a finished or stopped run holds its last pose."""
        if not self.running or self.current.get("plan_id") != plan_id:
            return
        with self._lock:
            tl = self._timeline
            if tl is None or tl[-1] <= 0:
                return
            self._driven = execution_id
            frac = float(tl[min(max(acked, 0), len(tl) - 1)] / tl[-1])
            self.current["execution"] = {
                "id": execution_id,
                "state": state,
                "acked": acked,
                "fraction": round(frac, 4),
            }
            for a in list(self._animations):
                try:
                    a.update(frac * a.duration_s)
                except Exception:
                    log.exception("scene animation failed; dropping it")
                    self._animations.remove(a)

    def plan_finished(self, plan_id: str) -> None:
        """Called when a plan leaves planning; redraw if it is the one followed."""
        if self.running and self._follow == plan_id:
            self._follow = None
            self.show_plan(plan_id)

    def issue_ticket(self) -> str:
        """A one-time ticket for the proxy's next upstream websocket."""
        return self.tickets.issue()

    def follow(self, plan_id: str) -> None:
        """Redraw ``plan_id`` when it finishes planning (an accepted proposal)."""
        self._follow = plan_id

    def _on_propose(
        self, plan_id: str, patch: dict[str, Any], action: str = "revise"
    ) -> str | None:
        """A scene interaction: record a proposal (never a plan); its id or None if dropped."""
        client = current_scene_client.get()
        try:
            kind = self.store.get_plan(plan_id).kind
        except KeyError:  # the plan shown was deleted meanwhile
            log.warning("scene proposal for missing plan %s dropped", plan_id)
            return None
        source = "scene" if client is None else f"scene client {client}"
        proposal = self.proposals.propose(
            plan_id, kind, patch, client=client, source=source, action=action
        )
        if proposal is None:
            return None
        try:
            self._propose(proposal.public())
        except Exception:  # publishing must not break viser's callback thread
            log.exception("publishing scene proposal %s failed", proposal.id)
        return proposal.id

    # -------------------------------------------------------------- animation
    def _animate(self) -> None:
        t0 = time.monotonic()
        while not self._stop.wait(0.05):
            with self._lock:
                # An execution of the plan drives its animations instead.
                anims = [] if self._driven is not None else list(self._animations)
                for a in anims:
                    try:
                        a.update((time.monotonic() - t0) % a.duration_s)
                    except Exception:
                        log.exception("scene animation failed; dropping it")
                        self._animations.remove(a)


def _timeline(program: list[dict[str, Any]] | None) -> np.ndarray | None:
    """Planned time (s) after each number of commands done: ``t[k]`` = the
    sum of the first ``k`` commands' ``duration_s`` (``len + 1`` values)."""
    if not program:
        return None
    d = np.array([max(float(c.get("duration_s", 0.0) or 0.0), 0.0) for c in program])
    return np.concatenate([[0.0], np.cumsum(d)])
