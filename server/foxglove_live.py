"""Live Foxglove WebSocket server ("Live"): the recording's channels while a robot runs.

Off by default; ``STEELPATH_FOXGLOVE_PORT=<port>`` starts it in the app's
lifespan (:func:`server.app.create_app`) with the Foxglove SDK
(``foxglove-sdk``, :func:`foxglove.start_server`), always bound to
127.0.0.1: the Foxglove WebSocket protocol has no authentication, so remote
users connect through the API's authenticated proxy ``/foxglove``
(:mod:`server.routers.foxglove`).

It publishes the channels of the MCAP recording (:mod:`server.recording.mcap`),
with the same schemas and messages (:mod:`server.recording.messages`), from
the service's :class:`~server.events.EventBus`:

* ``/robot/state`` (``steelpath.RobotState``), ``/tf``
  (``foxglove.FrameTransforms``) and ``/robot/tool_pose``
  (``foxglove.PoseInFrame``): each state report (``robot`` events with a
  ``report``, mirrored at 2 Hz by the dispatch engine) of a robot while it
  runs an execution; the frames by pinocchio FK of the reported joints
  (:class:`server.recording.channels.RobotFrames`);
* ``/commands/acknowledged`` (``steelpath.AcknowledgedCommand``): each
  command as its acknowledgement arrives (the ``acked`` count of
  ``execution`` events);
* ``/operator`` (``foxglove.Log``): a line per execution state change
  (``execution`` events: started, paused, resumed, faulted, completed,
  aborted…) and per E-stop (``estop`` events);
* ``/plan/program`` (``steelpath.PlannedCommand``), ``/plan/path``
  (``foxglove.PosesInFrame``) and ``/plan/cloud`` (``foxglove.PointCloud``,
  thinned to ≤ 200 000 points): once, when an execution starts, from the
  stored plan (:func:`~server.recording.channels.planned_path`,
  :func:`~server.recording.channels.plan_cloud`).  They are *latched*: a
  client that subscribes to one of them while a run goes on (a late joiner,
  or one that reconnected) gets the running plan's messages again then.

Log times are the Unix nanoseconds at which the service published the event.
The bus listener (:meth:`FoxgloveLive.on_event`) only queues the event; a
worker thread reads the store, runs the kinematics and logs to the SDK.  A
full queue drops events (counted in :attr:`FoxgloveLive.dropped`).
"""

from __future__ import annotations

import contextlib
import json
import logging
import queue
import threading
import time
from dataclasses import dataclass, field
from typing import TYPE_CHECKING, Any, cast

if TYPE_CHECKING:
    import foxglove
    from foxglove.websocket import WebSocketServer

    from server.recording.channels import RobotFrames
    from server.store.store import Store

log = logging.getLogger(__name__)

#: The only address the server binds to.
HOST = "127.0.0.1"
#: Execution states after which a run publishes nothing more.
_FINAL = {"completed", "aborted"}
#: Execution states logged as warnings.
_WARN = {"aborted", "faulted", "interrupted"}


@dataclass
class _Run:
    """An execution the server has seen start."""

    id: str
    plan_id: str
    robot: str
    program: list[dict[str, Any]]
    state: str = ""
    acked: int = 0
    frames: RobotFrames | None = field(default=None, repr=False)


class FoxgloveLive:
    """The SDK's WebSocket server on 127.0.0.1 and the worker that feeds it."""

    def __init__(self, store: Store, port: int, *, queue_size: int = 10_000) -> None:
        self.store = store
        self.requested_port = port
        self.dropped = 0
        self._q: queue.Queue[tuple[int, str, dict[str, Any]] | None] = queue.Queue(queue_size)
        self._runs: dict[str, _Run] = {}
        self._by_robot: dict[str, str] = {}
        self._frames: dict[str, RobotFrames | None] = {}
        self._server: WebSocketServer | None = None
        self._ctx: foxglove.Context | None = None
        self._channels: dict[str, foxglove.Channel] = {}
        self._thread: threading.Thread | None = None
        self._stopped = False
        #: topic → the messages of the last run's plan, sent again to a late subscriber
        self._latched: dict[str, list[dict[str, Any]]] = {}
        self._latched_run: str | None = None
        self.resent = 0

    # ------------------------------------------------------------ lifecycle
    def start(self) -> FoxgloveLive:
        """Start the server (``RuntimeError`` saying why it cannot) and the worker."""
        import foxglove

        from server.recording.messages import CHANNELS

        # A context per app (tests start several in one process); held for the
        # server's life: once it is collected, the server advertises no channel.
        self._ctx = ctx = foxglove.Context()
        for topic, (name, schema) in CHANNELS.items():
            self._channels[topic] = foxglove.Channel(
                topic,
                schema=foxglove.Schema(
                    name=name, encoding="jsonschema", data=json.dumps(schema).encode()
                ),
                message_encoding="json",
                context=ctx,
            )
        try:
            self._server = foxglove.start_server(
                name="SteelPath",
                host=HOST,
                port=self.requested_port,
                context=ctx,
                # a Protocol the SDK calls by method name; only on_subscribe is needed
                server_listener=cast("foxglove.ServerListener", _LateJoiners(self)),
            )
        except Exception as exc:
            raise RuntimeError(
                f"could not start the live Foxglove server on {HOST}:{self.requested_port} "
                f"(STEELPATH_FOXGLOVE_PORT): {exc}"
            ) from exc
        self._thread = threading.Thread(target=self._loop, name="foxglove-live", daemon=True)
        self._thread.start()
        log.info("live Foxglove server on ws://%s:%d (proxied at /foxglove)", HOST, self.port)
        return self

    @property
    def running(self) -> bool:
        return self._server is not None and not self._stopped

    @property
    def port(self) -> int:
        """The port the server listens on (the requested one, or the OS's pick for 0)."""
        return int(self._server.port) if self._server is not None else 0

    def stop(self) -> None:
        """Stop the worker and the server (idempotent)."""
        if self._stopped:
            return
        self._stopped = True
        with contextlib.suppress(queue.Full):
            self._q.put_nowait(None)
        if self._thread is not None:
            self._thread.join(timeout=5)
        if self._server is not None:
            self._server.stop()
        for ch in self._channels.values():
            with contextlib.suppress(Exception):
                ch.close()

    # ------------------------------------------------------------- the bus
    def on_event(self, type_: str, data: dict[str, Any]) -> None:
        """Bus listener, on the publisher's thread: queue the events it publishes."""
        if self._stopped or type_ not in ("robot", "execution", "estop"):
            return
        if type_ == "robot" and "report" not in data:
            return  # a link-state change, E-stop latch, takeover
        try:
            self._q.put_nowait((time.time_ns(), type_, data))
        except queue.Full:
            self.dropped += 1

    def subscribed(self, topic: str) -> None:
        """A client subscribed to ``topic`` (on the SDK's thread): queue a re-send
        of the running plan's latched messages, if it has any."""
        if self._stopped or topic not in LATCHED:
            return
        try:
            self._q.put_nowait((time.time_ns(), "resend", {"topic": topic}))
        except queue.Full:
            self.dropped += 1

    def _loop(self) -> None:
        while True:
            item = self._q.get()
            if item is None:
                return
            ns, type_, data = item
            try:
                if type_ == "resend":
                    self._resend(ns, str(data["topic"]))
                elif type_ == "robot":
                    self._report(ns, str(data["name"]), data["report"])
                elif type_ == "execution":
                    self._execution(ns, data)
                elif type_ == "estop":
                    self._estop(ns, data)
            except Exception:
                log.exception("live Foxglove: could not publish a %s event", type_)

    # ------------------------------------------------------------ handlers
    def _log(self, topic: str, ns: int, msg: dict[str, Any]) -> None:
        try:
            data = json.dumps(msg, separators=(",", ":"), allow_nan=False).encode()
        except ValueError:  # NaN/inf: not JSON (the MCAP refuses them too)
            log.warning("live Foxglove: dropped a %s message holding NaN or inf", topic)
            return
        self._channels[topic].log(data, log_time=ns)

    def _robot_frames(self, robot: str) -> RobotFrames | None:
        if robot not in self._frames:
            from server.recording.channels import robot_frames

            self._frames[robot] = robot_frames(robot)[0]
        return self._frames[robot]

    def _execution(self, ns: int, data: dict[str, Any]) -> None:
        from server.recording.messages import INFO, WARNING, acked_msg, log_msg

        eid, state = str(data.get("id", "")), str(data.get("state", ""))
        run = self._runs.get(eid)
        if run is None:
            if state in _FINAL:
                return  # ended before this server saw it start
            run = self._start_run(ns, eid)
        acked = int(data.get("acked", run.acked) or 0)
        for idx in range(run.acked, acked):
            self._log("/commands/acknowledged", ns, acked_msg(run.program, idx))
        run.acked = max(run.acked, acked)
        if state and state != run.state:
            words = f"execution {eid} of plan {run.plan_id} on {run.robot}: {run.state or '–'} → {state}"
            if data.get("fault"):
                words += f" ({data['fault']})"
            level = WARNING if state in _WARN else INFO
            words += f", {run.acked}/{len(run.program)} commands acknowledged"
            self._log("/operator", ns, log_msg(ns, level, words, "execution"))
            run.state = state
        if state in _FINAL:
            self._runs.pop(eid, None)
            if self._by_robot.get(run.robot) == eid:
                del self._by_robot[run.robot]
            if self._latched_run == eid:  # nothing runs that plan any more
                self._latched, self._latched_run = {}, None

    def _start_run(self, ns: int, eid: str) -> _Run:
        from server.recording.channels import plan_cloud, planned_path
        from server.recording.messages import cloud_msg, path_msg, program_msgs

        ex = self.store.get_execution(eid)
        plan = self.store.get_plan(ex.plan_id, result=False)
        program = list(plan.program or [])
        run = _Run(eid, plan.id, ex.robot, program, frames=self._robot_frames(ex.robot))
        self._runs[eid] = run
        self._by_robot[ex.robot] = eid
        latched: dict[str, list[dict[str, Any]]] = {"/plan/program": program_msgs(program)}
        path, _ = planned_path(plan)
        if path is not None:
            latched["/plan/path"] = [path_msg(ns, path)]
        cloud = plan_cloud(self.store, plan)
        if cloud.points is not None:
            latched["/plan/cloud"] = [cloud_msg(ns, cloud.points)]
        self._latched, self._latched_run = latched, eid
        for topic, msgs in latched.items():
            for msg in msgs:
                self._log(topic, ns, msg)
        return run

    def _resend(self, ns: int, topic: str) -> None:
        # The SDK logs to every subscriber of the channel, so earlier ones get
        # the same messages again: harmless for a plan that has not changed.
        for msg in self._latched.get(topic, []):
            self._log(topic, ns, msg)
            self.resent += 1

    def _report(self, ns: int, robot: str, report: dict[str, Any]) -> None:
        from server.recording.messages import state_msg, tf_msg, tool_pose_msg

        eid = self._by_robot.get(robot)
        run = self._runs.get(eid) if eid is not None else None
        if run is None or not report:
            return
        self._log("/robot/state", ns, state_msg(robot, report))
        frames = run.frames
        sample = frames.at(list(report.get("q_rad") or [])) if frames is not None else None
        if frames is None or sample is None:
            return
        self._log("/tf", ns, tf_msg(ns, sample))
        tool = tool_pose_msg(ns, frames.base, sample)
        if tool is not None:
            self._log("/robot/tool_pose", ns, tool)

    def _estop(self, ns: int, data: dict[str, Any]) -> None:
        from server.recording.messages import WARNING, log_msg

        robot = data.get("robot") or "every robot"
        words = f"E-stop of {robot} by {data.get('by') or 'unknown'}"
        if data.get("reason"):
            words += f": {data['reason']}"
        self._log("/operator", ns, log_msg(ns, WARNING, words, "estop"))


#: Topics whose last run's messages a late subscriber gets again.
LATCHED = frozenset({"/plan/program", "/plan/path", "/plan/cloud"})


class _LateJoiners:
    """The SDK's server listener: tells :class:`FoxgloveLive` of each subscription."""

    def __init__(self, live: FoxgloveLive) -> None:
        self._live = live

    def on_subscribe(self, client: Any, channel: Any) -> None:
        self._live.subscribed(str(channel.topic))
