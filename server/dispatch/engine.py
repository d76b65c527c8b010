"""The dispatch engine: approved plans → robots, with a human in the loop.

Nothing else in the service talks to a robot.  The engine runs inside the
robot-link service process (:mod:`server.linkservice`), apart from the HTTP
event loop, the scene and the planning workers.  It keeps one
:class:`robots.adapters.link.RobotLink` per robot, streams a plan's compiled
program with a :class:`robots.adapters.streamer.Streamer`, records every
completion in SQLite *before* the streamer may advance (``on_acks`` runs on
the streamer's thread, never on a link's I/O thread), and mirrors robot state
into the store and the event sink from a thread of its own, so a slow SQLite
write can never delay a heartbeat.

Executions survive a server restart as ``interrupted`` and resume from the
last recorded completion with the same ``run_id``: the robot refuses to re-run
a command it has completed and continues an interrupted one from where it
stopped (docs/protocol.md §8.2), so nothing runs twice and nothing is skipped.
The E-stop (:meth:`DispatchEngine.estop_links`) writes to every link from the
caller's thread, in any state, including while a link is reconnecting; the
bookkeeping (streamers, store transitions) comes after.
"""

from __future__ import annotations

import functools
import logging
import queue
import secrets
import threading
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass, is_dataclass
from typing import Any, Protocol

from robots import ROBOT_NAMES
from robots.adapters.link import (
    CONNECTED_STATES,
    LinkConfig,
    LinkState,
    LinkStateChanged,
    ReportReceived,
    RobotLink,
)
from robots.adapters.streamer import ExecState, Outcome, Streamer, StreamFault
from robots.protocol.commands import CommandError
from robots.protocol.messages import LINK_FAULTS, FaultFlag, State
from robots.protocol.program import Program
from server.captures.service import CaptureRecorder, capture_of
from server.captures.world import write_plan_world
from server.diskspace import describe
from server.lifecycle import ExecutionState, IllegalTransitionError, PlanState
from server.settings import Settings
from server.store import ExecutionRecord, NotFoundError, Store

log = logging.getLogger(__name__)

RESUMABLE = {ExecutionState.PAUSED, ExecutionState.INTERRUPTED, ExecutionState.FAULTED}
ACTIVE = {ExecutionState.PENDING, ExecutionState.RUNNING} | RESUMABLE


class DispatchError(Exception):
    """Dispatch refused; ``status`` is the HTTP status the API answers with."""

    def __init__(self, message: str, status: int = 409) -> None:
        super().__init__(message)
        self.status = status


class EventSink(Protocol):
    """Where the engine publishes plan/execution/robot changes (``EventBus`` or a channel)."""

    def publish(self, type_: str, data: dict[str, Any]) -> Any: ...


@dataclass
class _Robot:
    name: str
    url: str
    link: RobotLink
    last_state: dict[str, Any] | None = None
    last_saved: float = 0.0


def state_to_dict(report: State | None) -> dict[str, Any] | None:
    """A state report as JSON (SI units: rad, m) for the store, API and scene."""
    if report is None:
        return None
    d = asdict(report) if is_dataclass(report) else dict(vars(report))
    q = [v * 1e-6 for v in d.pop("q_urad", ())]
    odo = [v * 1e-6 for v in d.pop("odometry_um", ())]
    lift = d.pop("lift_urad", 0) * 1e-6
    return {**d, "q_rad": q, "odometry_m": odo, "lift_rad": lift}


class DispatchEngine:
    """Owns robot links and running executions (inside the link service)."""

    def __init__(
        self,
        store: Store,
        events: EventSink,
        settings: Settings,
        *,
        link_config: LinkConfig | None = None,
        emulator_urls: dict[str, str] | None = None,
        secret_for: Callable[[str], bytes | None] | None = None,
    ) -> None:
        self.store = store
        self.events = events
        self.settings = settings
        self._link_config = link_config
        self._emulator_urls = dict(emulator_urls or {})
        self._secret_for = secret_for or (lambda _name: None)
        self._lock = threading.RLock()
        self._robots: dict[str, _Robot] = {}
        self._streamers: dict[str, Streamer] = {}
        # Latest report per robot, written to the store by the mirror thread:
        # the link I/O thread only drops it here (a dict store, never blocks).
        self._mirror_q: queue.SimpleQueue[tuple[str, dict[str, Any]] | None] = queue.SimpleQueue()
        self._mirror_thread: threading.Thread | None = None
        # Several servers: with ``leased`` the engine drives only
        # the robots whose lease this server holds (adopt/drop); a streamer of
        # a dropped robot is detached: it never writes to the store again,
        # since the robot's execution now belongs to whichever server owns it.
        self.leased = False
        self.server_id: str | None = None
        self._streamer_robot: dict[str, str] = {}
        self._estop_reasons: dict[str, str] = {}  # robot → the reason of its latest E-stop
        self._detached: set[str] = set()
        self._store_emulated: dict[str, str] = {}
        # Set by :meth:`shutdown` before it closes the links: the link losses
        # that follow are this engine's doing, not the robots' (see _on_fault).
        self._stopping = False
        # What the robots' cameras saw, stored on a thread of its own (server/captures).
        self.captures = CaptureRecorder(store, events, settings)

    # ------------------------------------------------------------- lifecycle
    def start(self, *, leased: bool = False) -> None:
        """Open every robot's link; with ``leased``, none yet: :meth:`adopt` opens
        each once this server holds its lease (``server.ownership.LeaseKeeper``)."""
        self.leased = leased
        self._mirror_thread = threading.Thread(
            target=self._mirror_loop, name="robot-state mirror", daemon=True
        )
        self._mirror_thread.start()
        if leased:
            # No server can own a robot that is not one of ours: what runs on it is over.
            self._interrupt_leftovers(lambda robot: robot not in ROBOT_NAMES)
            return
        self._interrupt_leftovers()
        stored = self.store.robot_urls()
        for name in ROBOT_NAMES:
            url = stored.get(name) or self._emulator_urls.get(name)
            if url is None:
                url = "loop://"  # no robot configured: a link that never handshakes
            self._robots[name] = _Robot(name, url, self._new_link(name, url))

    def _new_link(self, name: str, url: str) -> RobotLink:
        base = self._link_config or LinkConfig()
        fields: dict[str, Any] = {**asdict(base), "expected_robot": name}
        secret = self._secret_for(name)
        if secret is not None and "secret" in fields:
            fields["secret"] = secret
        link = RobotLink(url, LinkConfig(**fields), name=name)
        link.subscribe(functools.partial(self._on_link_event, name))
        return link.start()

    def shutdown(self) -> None:
        """Close every link, then the streamers.

        What was running stays as the store shows it: the link losses this
        causes are not recorded as the robots' (``_on_fault``).  The run's
        next driver interrupts it, once, with the true reason (:meth:`adopt`:
        a server that takes the robot's released or lapsed lease, this one
        after a restart included; :meth:`start` without leases), the same
        whether this process stops in order or is killed outright.
        """
        with self._lock:
            self._stopping = True
            streamers = list(self._streamers.values())
            robots = list(self._robots.values())
        # Links first: a closed connection stops a TCP robot at once (and a
        # serial one within its watchdog), whatever its streamer is doing.
        for r in robots:
            r.link.close(timeout=2)
        for s in streamers:
            s.close(timeout=2)
        self.captures.close()
        self._mirror_q.put(None)
        if self._mirror_thread is not None:
            self._mirror_thread.join(timeout=2)

    def _interrupt_leftovers(
        self,
        which: Callable[[str], bool] = lambda _robot: True,
        reason: str = "server restarted during execution",
    ) -> None:
        """Executions a previous server left running are interrupted (resumable)."""
        for ex in self.store.list_executions(limit=10_000):
            if ex.state in (
                ExecutionState.PENDING,
                ExecutionState.RUNNING,
                ExecutionState.PAUSED,
            ) and which(ex.robot):
                self._transition(ex.id, "interrupt", "system", reason)

    # ------------------------------------------------ ownership (several servers)
    def owns(self, name: str) -> bool:
        return name in self._robots

    def set_store_emulated(self, urls: dict[str, str]) -> None:
        """Robot URLs a server recorded for its embedded emulators (``emulated`` in statuses)."""
        self._store_emulated = dict(urls)

    def adopt(self, name: str, url: str, emulated: dict[str, str] | None = None) -> bool:
        """Start driving ``name`` (this server has just taken its lease); ``False``
        if it already does.

        Whatever the store still shows running on it was driven by a server that
        no longer holds it (killed, or this service before a restart): that run
        is interrupted first (resumable from its last acknowledged command, the
        robot refuses to repeat one), and only then the link opens.
        """
        if emulated is not None:
            self._store_emulated = dict(emulated)
        with self._lock:
            if name in self._robots:
                return False
            self._interrupt_leftovers(
                lambda robot: robot == name,
                f"server {self.server_id or '?'} took the robot over "
                "(its previous driver stopped or lost the robot's lease)",
            )
            self._robots[name] = _Robot(name, url, self._new_link(name, url))
        log.info("driving robot %s at %s", name, url)
        self.events.publish("robot", {"name": name, "url": url, "owned": True})
        return True

    def drop(self, name: str, why: str) -> bool:
        """Stop driving ``name`` (its lease is lost or could not be renewed).

        The link closes first (a TCP robot stops at once, a serial one within
        its watchdog); the robot's streamers are detached, so nothing this
        server does after it touches the execution the new owner takes over.
        """
        with self._lock:
            r = self._robots.pop(name, None)
            if r is None:
                return False
            eids = [e for e, robot in self._streamer_robot.items() if robot == name]
            streamers = []
            for eid in eids:
                self._detached.add(eid)
                self._streamer_robot.pop(eid, None)
                s = self._streamers.pop(eid, None)
                if s is not None:
                    streamers.append(s)
        log.warning("no longer driving robot %s: %s", name, why)
        r.link.close(timeout=2)
        for s in streamers:
            s.close(timeout=2)
        self.events.publish("robot", {"name": name, "owned": False, "reason": why})
        return True

    def sync_url(self, name: str, url: str) -> None:
        """Reconnect an owned robot whose URL in the shared store changed (another
        server's emulators recorded theirs, or an operator's change); never while
        a run streams to it."""
        with self._lock:
            r = self._robots.get(name)
            if r is None or r.url == url:
                return
            if self._active_execution_for(name, running_only=True):
                return
            # The caller read the store before an operator's change landed
            # (the lease keeper's tick racing PUT /connection): its URL is
            # stale, and acting on it would drop the link just made.
            stored = self.store.robot_urls().get(name)
            if stored is not None and stored != url:
                return
            was_latched = r.link.estop_latched
            r.link.close(timeout=2)
            r.url = url
            r.link = self._new_link(name, url)
            if was_latched:
                r.link.estop()
        self.events.publish("robot", {"name": name, "url": url, "state": str(r.link.state)})

    # --------------------------------------------------------------- robots
    def robot_names(self) -> list[str]:
        return list(ROBOT_NAMES) if self.leased else list(self._robots)

    def _robot(self, name: str) -> _Robot:
        r = self._robots.get(name)
        if r is not None:
            return r
        if self.leased and name in ROBOT_NAMES:
            raise DispatchError(
                f"robot {name} is not driven by this server (another server holds its "
                "lease, or none does yet); try again",
                503,
            )
        raise NotFoundError(
            f"no robot {name!r}; robots: {', '.join(self.robot_names()) or 'none'}"
        ) from None

    def _emulated(self, name: str, url: str) -> bool:
        return url in (self._emulator_urls.get(name), self._store_emulated.get(name))

    def robot_status(self, name: str) -> dict[str, Any]:
        if self.leased and name in ROBOT_NAMES and name not in self._robots:
            return self._remote_status(name)
        r = self._robot(name)
        st = r.link.status()
        busy = self._active_execution_for(name)
        return {
            "name": name,
            "url": r.url,
            "emulated": self._emulated(name, r.url),
            "owned": True,
            "state": str(st.state),
            "reason": st.reason,
            "connected": st.state in (LinkState.READY, LinkState.STREAMING),
            "estop_latched": st.estop_latched,
            "last_heartbeat": st.last_rx_wall,
            "robot_info": _plain(st.robot),
            "report": state_to_dict(st.report),
            "faults": int(st.report.faults) if st.report is not None else 0,
            "execution": busy,
            "stats": dict(st.stats),
        }

    def _remote_status(self, name: str) -> dict[str, Any]:
        """A robot another server drives: what the shared store knows (its owner's
        mirror writes the report twice a second); the web server adds the owner."""
        url = self.store.robot_urls().get(name)
        stored = self.store.robot_state(name)
        report = stored[0] if stored else None
        faults = int(report.get("faults", 0)) if report else 0
        return {
            "name": name,
            "url": url,
            "emulated": url is not None and self._emulated(name, url),
            "owned": False,
            "state": "remote",
            "reason": "driven by another server",
            "connected": None,
            "estop_latched": bool(faults & int(FaultFlag.ESTOP)) if report else None,
            "last_heartbeat": None,
            "robot_info": None,
            "report": report,
            "faults": faults,
            "execution": self._active_execution_for(name),
            "stats": {},
        }

    def set_connection(
        self,
        name: str,
        url: str,
        actor: str,
        secret_writer: Callable[[str], None] | None = None,
    ) -> dict[str, Any]:
        """Persist a robot's URL (and, for real hardware, its link secret) and reconnect.

        ``secret_writer(name)`` stores a new secret before the link is rebuilt,
        so the new link authenticates with it.  A latched E-stop carries over.
        """
        r = self._robot(name)
        if self._active_execution_for(name, running_only=True):
            raise DispatchError(f"robot {name} is executing; pause or abort it before reconnecting")
        was_latched = r.link.estop_latched
        if secret_writer is not None:
            secret_writer(name)
        with self._lock:
            self.store.set_robot_url(name, url, actor)
            r.link.close(timeout=2)
            r.url = url
            r.link = self._new_link(name, url)
            if was_latched:
                r.link.estop()
        self.events.publish("robot", {"name": name, "url": url, "state": str(r.link.state)})
        return self.robot_status(name)

    def takeover(self, name: str, actor: str) -> dict[str, Any]:
        """Take the robot's line over from another controller (an operator's explicit act).

        The robot accepts it only with this server's secret; it drops the other
        controller, stopping any motion it was making (``LINK_RESET``).
        """
        r = self._robot(name)
        if r.link.state in CONNECTED_STATES:
            raise DispatchError(f"robot {name} is already controlled by this server")
        r.link.takeover()
        self.store.audit(actor, "robot", name, "takeover", f"take over the line at {r.url}")
        self.events.publish("robot", {"name": name, "takeover": True})
        return self.robot_status(name)

    def clear_estop(self, name: str, actor: str, wait_s: float = 2.0) -> dict[str, Any]:
        """Clear the E-stop latch; waits (bounded) until the robot itself reports it cleared,
        so the answer says what the robot says, not only what the host sent."""
        r = self._robot(name)
        # Nothing moves unrecorded: the record is written before the latch is
        # cleared, and a store that refuses it leaves the robot E-stopped.
        try:
            self.store.audit(actor, "robot", name, "clear-estop")
        except Exception as exc:
            log.exception("clear-estop of %s not recorded; the latch stays", name)
            raise DispatchError(
                f"{name} stays E-stopped: the clear-estop could not be recorded "
                f"({describe(exc)}); free space on the server and try again",
                409,
            ) from None
        r.link.clear_estop()
        if r.link.state in CONNECTED_STATES:
            r.link.wait_for(
                lambda lk: (
                    lk.last_report is not None
                    and not int(lk.last_report.faults) & int(FaultFlag.ESTOP)
                ),
                wait_s,
            )
        self.events.publish("robot", {"name": name, "estop_latched": False})
        return self.robot_status(name)

    def wait_connected(self, name: str, timeout: float) -> bool:
        """Whether ``name`` has a session within ``timeout`` s, whichever link
        it is on: a reconnect (a new URL) replaces the link object, and a wait
        on the one it replaced would never end well."""
        deadline = time.monotonic() + timeout
        while True:
            left = deadline - time.monotonic()
            if self._robot(name).link.wait_connected(min(max(left, 0.0), 0.25)):
                return True
            if left <= 0:
                return False

    # ------------------------------------------------------------- dispatch
    def dispatch(
        self, plan_id: str, robot: str, actor: str, kind_robot: str | None = None
    ) -> ExecutionRecord:
        """Start executing an approved plan on ``robot`` (409 with the reason otherwise).

        ``kind_robot`` is the robot the plan's kind drives: the web server looks
        it up in the kind registry, so this process never imports the planners.
        """
        plan = self.store.get_plan(plan_id, result=False)
        r = self._robot(robot)
        if plan.state != PlanState.APPROVED:
            raise IllegalTransitionError(
                "plan", plan_id, plan.state, "dispatch", _allowed(plan.state)
            )
        if plan.failed_checks:
            names = ", ".join(c["name"] for c in plan.failed_checks)
            raise DispatchError(
                f"plan {plan_id} has failed checks ({names}); it cannot move a robot"
            )
        if kind_robot is not None and kind_robot != robot:
            raise DispatchError(f"plan kind {plan.kind} drives robot {kind_robot!r}, not {robot!r}")
        if not plan.program:
            raise DispatchError(
                f"plan {plan_id} has no compiled command program (kind {plan.kind} has no "
                "compiler, or the plan leaves nothing for the robot to do)"
            )
        try:
            program = Program.from_dicts(plan.program, robot=robot)
        except CommandError as exc:
            raise DispatchError(f"stored program of plan {plan_id} is invalid: {exc}") from None
        busy = self._active_execution_for(robot)
        if busy:
            raise DispatchError(f"robot {robot} is busy with execution {busy}")
        status = r.link.status()
        if status.estop_latched:
            raise DispatchError(f"robot {robot} is E-stopped; clear the E-stop first")
        why = not_ready_reason(status, allow_link_faults=True, require_idle=True)
        if why:
            raise DispatchError(f"robot {robot} {why}; check its connection ({r.url})")
        if r.url == self._emulator_urls.get(robot):  # built in: its camera sees the plan's scan
            write_plan_world(self.store, plan, robot, self.settings.data)
        run_id = secrets.randbelow(0xFFFFFFFE) + 1
        ex = self.store.create_execution(plan_id, robot, len(program), actor, run_id=run_id)
        self.events.publish(
            "plan", {"id": plan_id, "state": PlanState.EXECUTING, "kind": plan.kind}
        )
        self._start_streamer(ex, program, start=0)
        return self.store.get_execution(ex.id)

    def _start_streamer(self, ex: ExecutionRecord, program: Program, start: int) -> Streamer:
        r = self._robot(ex.robot)
        eid = ex.id
        streamer = Streamer(
            program,
            r.link,
            run_id=ex.run_id,
            start=start,
            on_acks=lambda first, last: self._on_acks(eid, first, last),
            on_done=lambda outcome: self._on_done(eid, outcome),
            on_fault=lambda fault: self._on_fault(eid, fault),
        )
        with self._lock:
            old = self._streamers.pop(eid, None)
            self._streamers[eid] = streamer
            self._streamer_robot[eid] = ex.robot
        if old is not None:
            old.close(timeout=2)
        if ex.state == ExecutionState.PENDING:
            self._transition(eid, "start", "dispatch", f"streaming {len(program)} commands")
        streamer.start()
        return streamer

    def _active_execution_for(self, robot: str, running_only: bool = False) -> str | None:
        states = {ExecutionState.PENDING, ExecutionState.RUNNING} if running_only else ACTIVE
        return self.store.newest_execution_of(robot, states)

    # ------------------------------------------------------- operator actions
    def pause(self, execution_id: str, actor: str) -> ExecutionRecord:
        if self.leased:
            self._robot(self.store.get_execution(execution_id).robot)  # 503 if driven elsewhere
        ex = self._transition(execution_id, "pause", actor, "operator pause", strict=True)
        assert ex is not None  # strict: a refused transition raised
        s = self._streamers.get(execution_id)
        if s is not None:
            s.pause()
        return ex

    def resume(self, execution_id: str, actor: str, clear_faults: bool = False) -> ExecutionRecord:
        ex = self.store.get_execution(execution_id)
        if ex.state not in RESUMABLE:
            raise IllegalTransitionError(
                "execution",
                execution_id,
                ex.state,
                "resume",
                ["pause", "abort"] if ex.state == ExecutionState.RUNNING else [],
            )
        r = self._robot(ex.robot)
        if r.link.estop_latched:
            raise DispatchError(f"robot {ex.robot} is E-stopped; clear the E-stop before resuming")
        if (
            ex.state == ExecutionState.FAULTED
            and ex.fault
            and "robot_fault" in ex.fault
            and not clear_faults
        ):
            raise DispatchError(
                f"execution {execution_id} stopped on a robot fault ({ex.fault}); resume with "
                '{"clear_faults": true} once the cause is fixed'
            )
        why = not_ready_reason(r.link.status(), allow_robot_faults=clear_faults)
        if why:
            raise DispatchError(f"robot {ex.robot} {why}")
        s = self._streamers.get(execution_id)
        resumed = self._transition(
            execution_id, "resume", actor, f"resume from command {ex.acked}", strict=True
        )
        assert resumed is not None  # strict: a refused transition raised
        ex = resumed
        if s is not None and s.state not in (
            ExecState.COMPLETED,
            ExecState.ABORTED,
            ExecState.ESTOPPED,
        ):
            s.resume(clear_robot_faults=clear_faults)
        else:
            # After a restart (or a terminal streamer): a new streamer, same run_id.
            plan = self.store.get_plan(ex.plan_id, result=False)
            program = Program.from_dicts(plan.program or [], robot=ex.robot)
            streamer = self._start_streamer(ex, program, start=ex.acked)
            if clear_faults:
                streamer.resume(clear_robot_faults=True)
        return self.store.get_execution(execution_id)

    def abort(self, execution_id: str, actor: str) -> ExecutionRecord:
        ex = self.store.get_execution(execution_id)
        if self.leased:
            self._robot(ex.robot)  # 503 if driven elsewhere
        s = self._streamers.get(execution_id)
        if s is not None and s.state not in (
            ExecState.COMPLETED,
            ExecState.ABORTED,
            ExecState.ESTOPPED,
        ):
            s.abort()
        return self._transition(execution_id, "abort", actor, "operator abort", strict=True) or ex

    def estop(self, robot: str | None, reason: str) -> list[str]:
        """Stop every robot (or one) now, then record it; returns the robots reached."""
        reached = self.estop_links(robot, reason)
        self.estop_bookkeeping(robot, reason)
        return reached

    def estop_links(self, robot: str | None, reason: str = "E-stop") -> list[str]:
        """The first-priority part: write ESTOP to every target link from this thread.

        ``link.estop()`` writes the frame at once and latches it for
        reconnects, so this never waits on a busy link, a streamer or SQLite.
        ``reason`` is kept per robot for the run it interrupts: the streamer may
        see the robot's stop before the bookkeeping runs.
        """
        if robot is None:
            targets = list(self._robots.values())
        elif robot in self._robots:
            targets = [self._robots[robot]]
        elif self.leased and robot in ROBOT_NAMES:
            return []  # driven by another server: the web server forwards to it
        else:
            targets = [self._robot(robot)]
        reached = []
        for r in targets:
            self._estop_reasons[r.name] = reason
            try:
                r.link.estop()
                reached.append(r.name)
            except Exception:  # one dead link must not stop the others' E-stop
                log.exception("E-stop to %s failed", r.name)
        return reached

    def estop_bookkeeping(self, robot: str | None, reason: str) -> None:
        """Stop the streamers and interrupt the executions of the E-stopped robots.

        An E-stop is a stop an operator recovers from, as from a link loss: the
        run is ``interrupted`` with the reason (its ``fault``), and once the
        E-stop is cleared *resume* continues from the last completed command
        (the robot keeps the remainder of the one it was in, docs/protocol.md
        §8.2).  Ending the run is the operator's explicit *abort*.
        """
        for eid, s in list(self._streamers.items()):
            ex = self.store.get_execution(eid)
            if robot is None or ex.robot == robot:
                s.estopped()  # estop_links already latched the link: never latch it again
                if ex.state in ACTIVE:
                    self._estop_interrupt(eid, reason)

    def _estop_interrupt(self, execution_id: str, reason: str) -> None:
        why = f"E-stop: {reason}" if reason else "E-stop"
        self._transition(
            execution_id,
            "interrupt",
            "estop",
            f"{why}; clear the E-stop, then resume (or abort)",
            fault=why,
        )

    # ------------------------------------------------------------- callbacks
    def _on_acks(self, execution_id: str, first: int, last: int) -> None:
        # Runs on the streamer thread; the streamer advances only after this returns.
        if execution_id in self._detached:
            return  # its robot is driven by another server now
        self.store.record_acks(execution_id, first, last)
        ex = self.store.get_execution(execution_id)
        self.events.publish(
            "execution",
            {
                "id": ex.id,
                "plan_id": ex.plan_id,
                "state": ex.state,
                "acked": ex.acked,
                "total": ex.total,
            },
        )

    def _on_done(self, execution_id: str, outcome: Outcome) -> None:
        if execution_id in self._detached:
            return
        if outcome == Outcome.ESTOPPED:  # recoverable, whoever pressed it
            name = self._streamer_robot.get(execution_id)
            r = self._robots.get(name) if name is not None else None
            host = r is not None and r.link.estop_latched and name in self._estop_reasons
            why = self._estop_reasons[name] if host and name else "reported by the robot"
            self._estop_interrupt(execution_id, why)
        else:
            action = {"completed": "complete", "aborted": "abort"}[str(outcome)]
            self._transition(execution_id, action, "robot", f"robot reported {outcome}")
        with self._lock:
            s = self._streamers.pop(execution_id, None)
            self._streamer_robot.pop(execution_id, None)
        if s is not None:
            threading.Thread(target=s.close, daemon=True).start()

    def _on_fault(self, execution_id: str, fault: StreamFault) -> None:
        if execution_id in self._detached:
            return
        if self._stopping:
            # Shutting down (a clean stop, or this service's web server killed):
            # the link loss is the closing of our own links, not a robot's
            # fault; recorded as one ("robot", "link_lost: closed") it hid why
            # the run stopped, and the next driver found nothing to interrupt.
            log.info("execution %s left to its next driver: %s while stopping", execution_id, fault)
            return
        action = "interrupt" if fault.kind.value == "link_lost" else "fault"
        self._transition(execution_id, action, "robot", str(fault), fault=str(fault))

    def _on_link_event(self, name: str, event: Any) -> None:
        # On the link's I/O thread: no import, no SQLite, no blocking call here.
        capture = capture_of(event)
        if capture is not None:  # a sensor frame: queued for the capture recorder
            self.captures.submit(name, capture)
            return
        r = self._robots.get(name)
        if r is None:
            return
        if isinstance(event, ReportReceived):
            # On the link's I/O thread: convert and hand on, nothing that blocks.
            now = time.monotonic()
            if now - r.last_saved > 0.5:  # mirror at 2 Hz: enough for a console
                r.last_saved = now
                state = state_to_dict(event.report)
                r.last_state = state
                self._mirror_q.put((name, state or {}))
        elif isinstance(event, LinkStateChanged):
            self.events.publish(
                "robot", {"name": name, "state": str(event.new), "reason": event.reason}
            )

    def _mirror_loop(self) -> None:
        while True:
            item = self._mirror_q.get()
            if item is None:
                return
            name, state = item
            if self.leased and name not in self._robots:
                continue  # a late report of a robot dropped meanwhile
            try:
                self.store.save_robot_state(name, state)
                # Recorded runs: the reports of an active execution.
                eid = self._active_execution_for(name)
                if eid is not None:
                    self.store.record_execution_state(eid, time.time(), state)
            except Exception:
                log.exception("could not store state of %s", name)
            self.events.publish("robot", {"name": name, "report": state})

    # --------------------------------------------------------------- helpers
    def _transition(
        self,
        execution_id: str,
        action: str,
        actor: str,
        reason: str = "",
        *,
        strict: bool = False,
        **fields: Any,
    ) -> ExecutionRecord | None:
        plan_action = {
            "start": None,
            "pause": "pause",
            "resume": "resume",
            "complete": "complete",
            "abort": "abort",
            "fault": "fault",
            "interrupt": "interrupt",
        }[action]
        try:
            ex = self.store.transition_execution(
                execution_id, action, actor, reason, plan_action=plan_action, **fields
            )
        except IllegalTransitionError:
            if strict:
                raise
            log.info("ignored %s of execution %s", action, execution_id)
            return None
        self.events.publish(
            "execution",
            {
                "id": ex.id,
                "plan_id": ex.plan_id,
                "state": ex.state,
                "acked": ex.acked,
                "total": ex.total,
                "fault": ex.fault,
            },
        )
        plan = self.store.get_plan(ex.plan_id, result=False, program=False)
        self.events.publish("plan", {"id": plan.id, "kind": plan.kind, "state": plan.state})
        return ex


def not_ready_reason(
    status: Any,
    *,
    allow_link_faults: bool = True,
    allow_robot_faults: bool = False,
    require_idle: bool = False,
) -> str | None:
    """Why the robot cannot take a run now, or ``None``.

    A robot that lost its host (watchdog, new session) latches a *link* fault;
    the streamer clears those itself when it starts, so they do not block.
    A robot-side fault (``DRIVE``) blocks until an operator clears it.
    """
    if status.state not in CONNECTED_STATES:
        return f"is not connected ({status.state}: {status.reason})"
    faults = int(status.report.faults) if status.report is not None else 0
    if faults & int(FaultFlag.ESTOP):
        # The host's latch is clear but the robot's report is not (yet): a run
        # sent now would be refused FAULTED at once.
        return "still reports its E-stop latched (the clear has not reached it yet); try again"
    if require_idle and status.report is not None and status.report.executing >= 0:
        return f"is still executing command {status.report.executing} of run {status.report.run_id}"
    other = faults & ~int(LINK_FAULTS) & ~int(FaultFlag.ESTOP)
    if faults & int(LINK_FAULTS) and not allow_link_faults:
        return f"reports link faults ({FaultFlag(faults & int(LINK_FAULTS))!r})"
    if other and not allow_robot_faults:
        return f"reports a robot fault ({FaultFlag(other)!r}, code {status.report.fault_code})"
    return None


def _allowed(state: str) -> list[str]:
    from server.lifecycle import allowed_actions

    return allowed_actions(state)


def _plain(obj: Any) -> Any:
    if obj is None:
        return None
    if is_dataclass(obj) and not isinstance(obj, type):
        return {k: _plain(v) for k, v in asdict(obj).items()}
    if isinstance(obj, tuple | list):
        return [_plain(v) for v in obj]
    if isinstance(obj, bytes):
        return obj.decode(errors="replace")
    return obj
