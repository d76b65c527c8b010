"""The web server's handle on the robot-link service process.

:class:`LinkServiceClient` starts ``python -m server.linkservice`` (behind
:data:`BOOTSTRAP`) with two ``socketpair`` ends, and offers the dispatch
engine's methods as blocking calls (for FastAPI's sync handlers, which run in
worker threads).  Events the service pushes are published on the web server's
:class:`EventBus` and mirrored into the scene by one reader thread.

:meth:`LinkServiceClient.estop` uses its own channel and writes from the
caller's thread: it never waits behind an RPC, the event reader, or the
asyncio loop.  If the service dies (it should not), the client restarts it:
the robots stopped when their links closed, and the new service marks the
executions that were running ``interrupted``.
"""

from __future__ import annotations

import contextlib
import itertools
import json
import logging
import os
import secrets
import socket
import subprocess
import sys
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from server.dispatch.engine import DispatchError
from server.lifecycle import IllegalTransitionError
from server.linkservice.channel import STOP_OP, Channel, ChannelClosed
from server.settings import Settings
from server.store import ExecutionRecord, NotFoundError, Store

log = logging.getLogger(__name__)

#: How long a request may take before the API answers 503 (a dispatch checks
#: the store and starts a streamer: milliseconds; this is a wedge detector).
RPC_TIMEOUT_S = 15.0
ESTOP_TIMEOUT_S = 2.0

#: How the service is started: ``python -m server.linkservice`` behind a
#: bootstrap that blocks SIGTERM before any import.  Threads inherit the mask
#: of the thread that starts them, and importing the package starts some (a
#: BLAS pool when numpy loads): one that left SIGTERM open would take it and end
#: the process at once, without the orderly shutdown (main() takes SIGTERM with
#: ``sigtimedwait``).
BOOTSTRAP = (
    "import signal; signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM}); "
    "import runpy; runpy.run_module('server.linkservice', run_name='__main__', alter_sys=True)"
)


def new_server_id() -> str:
    """A fresh id per server process: a restarted server is a new server (its
    predecessor's leases lapse or were released, never silently inherited)."""
    return f"srv_{secrets.token_hex(6)}"


def server_url(settings: Settings) -> str:
    """This server's base URL as other servers reach it (``server_url``, or
    ``http://<host>:<port>``; a wildcard bind address is reached on loopback)."""
    if settings.server_url:
        return settings.server_url.rstrip("/")
    host = settings.host
    if host in ("0.0.0.0", "::", ""):
        host = "127.0.0.1"
    if ":" in host and not host.startswith("["):
        host = f"[{host}]"
    return f"http://{host}:{settings.port}"


class LinkServiceUnavailable(DispatchError):
    def __init__(self, message: str) -> None:
        super().__init__(message, status=503)


class _Pending:
    __slots__ = ("done", "reply")

    def __init__(self) -> None:
        self.done = threading.Event()
        self.reply: dict[str, Any] | None = None


def _raise(error: dict[str, Any]) -> None:
    kind = error.get("type")
    msg = str(error.get("message", ""))
    if kind == "DispatchError":
        raise DispatchError(msg, int(error.get("status", 409)))
    if kind == "IllegalTransitionError":
        raise IllegalTransitionError(
            error["entity"], error["entity_id"], error["state"], error["action"], error["allowed"]
        )
    if kind == "NotFoundError":
        raise NotFoundError(msg)
    raise DispatchError(f"link service error ({kind}): {msg}", 500)


#: Calls that change nothing (the others drop the cached robot statuses).
_READ_OPS = frozenset({"robot_names", "robot_status", "robot_statuses", "stats", "wait_connected"})


class LinkServiceClient:
    """Same public methods as :class:`server.dispatch.DispatchEngine`, across a process."""

    def __init__(
        self,
        store: Store,
        events: Any,
        settings: Settings,
        *,
        scene: Any = None,
        emulators: Any = None,
        kind_robot: Callable[[str], str | None] | None = None,
        server_id: str | None = None,
    ) -> None:
        #: This server's id in the shared store's ``servers`` table: the link
        #: service holds robot leases under it (and keeps it across a restart
        #: of the service, so the leases stay this server's).
        self.server_id = server_id or new_server_id()
        self.store = store
        self.events = events
        self.settings = settings
        self.scene = scene
        self.emulators = emulators
        self._kind_robot = kind_robot or (lambda _kind: None)
        self._ids = itertools.count(1)
        self._pending: dict[int, _Pending] = {}
        self._plock = threading.Lock()
        self._estop_lock = threading.Lock()
        self._proc: subprocess.Popen[bytes] | None = None
        self._rpc: Channel | None = None
        self._estop: Channel | None = None
        self._reader: threading.Thread | None = None
        self._closing = False
        self._ready = threading.Event()
        self._names: list[str] = []
        self._want_spawn = threading.Event()
        self._spawner: threading.Thread | None = None
        self.restarts = 0
        self._status_lock = threading.Lock()
        self._status_cache: tuple[float, list[dict[str, Any]]] | None = None
        # Bumped whenever the cache is dropped: an answer whose round trip
        # began before a drop (an E-stop, a link change) is not cached.
        self._status_gen = 0
        self._execution_states: dict[Any, Any] = {}  # last state pushed per execution
        self._refresh_guard = threading.Lock()
        self._refreshing = False

    # -------------------------------------------------------------- lifecycle
    def start(self, timeout: float = 60.0) -> LinkServiceClient:
        # The kernel signals a child when the *thread* that forked it exits
        # (PR_SET_PDEATHSIG), so every spawn happens on this long-lived thread.
        self._spawner = threading.Thread(
            target=self._spawn_loop, name="link-service spawner", daemon=True
        )
        self._spawner.start()
        self._want_spawn.set()
        if not self._ready.wait(timeout):
            raise RuntimeError(f"the robot-link service did not start within {timeout:.0f} s")
        self._names = list(self._call("robot_names", {}))
        return self

    def _spawn_loop(self) -> None:
        while True:
            self._want_spawn.wait()
            self._want_spawn.clear()
            if self._closing:
                return
            if self._proc is not None:
                with contextlib.suppress(Exception):
                    self._proc.wait(timeout=5)
            try:
                self._spawn()
            except Exception:
                log.exception("could not start the robot-link service; retrying in 1 s")
                time.sleep(1.0)
                self._want_spawn.set()

    def _spawn(self) -> None:
        rpc_parent, rpc_child = socket.socketpair()
        estop_parent, estop_child = socket.socketpair()
        urls = self.emulators.urls() if self.emulators is not None else {}
        cfg = {
            "settings": json.loads(self.settings.model_dump_json()),
            "emulator_urls": urls,
            "log_level": self.settings.log_level,
            "server_id": self.server_id,
            "server_url": server_url(self.settings),
        }
        cmd = [
            sys.executable,
            "-c",
            BOOTSTRAP,
            "--rpc-fd",
            str(rpc_child.fileno()),
            "--estop-fd",
            str(estop_child.fileno()),
            "--parent-pid",
            str(os.getpid()),
            "--config",
            json.dumps(cfg),
        ]
        root = str(Path(__file__).resolve().parents[2])
        env = {
            **os.environ,
            "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])),
        }
        self._ready.clear()
        self._proc = subprocess.Popen(
            cmd, pass_fds=(rpc_child.fileno(), estop_child.fileno()), env=env, close_fds=True
        )
        rpc_child.close()
        estop_child.close()
        self._rpc = Channel(rpc_parent)
        self._estop = Channel(estop_parent)
        self._reader = threading.Thread(
            target=self._read_loop, args=(self._rpc,), name="link-service reader", daemon=True
        )
        self._reader.start()

    def shutdown(self) -> None:
        self._closing = True
        self._want_spawn.set()  # lets the spawner thread end
        proc = self._proc
        if self._rpc is not None:
            # A stop in order: the service releases this server's leases (a
            # killed server sends nothing, and its leases lapse).
            with contextlib.suppress(ChannelClosed, OSError):
                self._rpc.send({"op": STOP_OP})
        for ch in (self._rpc, self._estop):
            if ch is not None:
                ch.close()
        if proc is not None:
            try:
                proc.wait(timeout=8)
            except subprocess.TimeoutExpired:
                proc.terminate()
                try:
                    proc.wait(timeout=3)
                except subprocess.TimeoutExpired:
                    proc.kill()
                    proc.wait()
        self._fail_pending("the robot-link service stopped")

    @property
    def pid(self) -> int | None:
        return self._proc.pid if self._proc is not None else None

    # ---------------------------------------------------------------- reading
    def _read_loop(self, channel: Channel) -> None:
        while True:
            try:
                msg = channel.recv()
            except ChannelClosed:
                break
            if "event" in msg:
                self._on_event(str(msg["event"]), msg.get("data") or {})
                continue
            with self._plock:
                pending = self._pending.pop(int(msg.get("id", -1)), None)
            if pending is not None:
                pending.reply = msg
                pending.done.set()
        self._fail_pending("the robot-link service exited")
        if not self._closing and channel is self._rpc:
            log.error("the robot-link service exited unexpectedly; restarting it")
            self.restarts += 1
            self._want_spawn.set()

    def _fail_pending(self, why: str) -> None:
        with self._plock:
            pending = list(self._pending.values())
            self._pending.clear()
        for p in pending:
            p.reply = {"ok": False, "error": {"type": "Unavailable", "message": why}}
            p.done.set()

    def _changes_statuses(self, type_: str, data: dict[str, Any]) -> bool:
        """Whether a pushed event makes the shared ``GET /robots`` answer stale.

        A state report alone, or an execution's progress (an ack, same state),
        does not: the 0.1 s TTL already bounds how old those may be shown.
        Dropping the answer on each of them (tens a second while robots
        stream) sent every poll to the busy link service, one at a time.
        A link state, E-stop, takeover or execution state change does.
        """
        if type_ == "robot":
            return set(data) != {"name", "report"}
        if type_ == "execution":
            eid, state = data.get("id"), data.get("state")
            seen = eid in self._execution_states
            before = self._execution_states.pop(eid, None)
            self._execution_states[eid] = state
            while len(self._execution_states) > 256:
                self._execution_states.pop(next(iter(self._execution_states)))
            return not seen or state is None or before != state
        return True

    def _on_event(self, type_: str, data: dict[str, Any]) -> None:
        if self._changes_statuses(type_, data):
            self._drop_statuses()  # the next GET /robots asks afresh
        if type_ == "linkservice":
            self._ready.set()
            return
        self.events.publish(type_, data)
        if type_ == "execution" and self.scene is not None and data.get("plan_id"):
            with contextlib.suppress(Exception):
                self.scene.execution_progress(
                    data["plan_id"], data["id"], str(data.get("state")), int(data.get("acked", 0))
                )
        if type_ == "robot" and self.scene is not None:
            report = data.get("report")
            if report and "q_rad" in report:
                with contextlib.suppress(Exception):
                    self.scene.update_live_robot(data["name"], np.asarray(report["q_rad"]))

    # ---------------------------------------------------------------- calling
    def _call(self, op: str, args: dict[str, Any], timeout: float = RPC_TIMEOUT_S) -> Any:
        if op not in _READ_OPS:
            self._drop_statuses()  # an operator action: statuses after it are fresh
        return self._roundtrip(op, args, timeout)

    def _drop_statuses(self) -> None:
        self._status_gen += 1
        self._status_cache = None

    def _roundtrip(self, op: str, args: dict[str, Any], timeout: float) -> Any:
        rpc = self._rpc
        if rpc is None:
            raise LinkServiceUnavailable("the robot-link service is not running")
        rid = next(self._ids)
        pending = _Pending()
        with self._plock:
            self._pending[rid] = pending
        try:
            rpc.send({"id": rid, "op": op, "args": args})
        except ChannelClosed:
            with self._plock:
                self._pending.pop(rid, None)
            raise LinkServiceUnavailable("the robot-link service is not running") from None
        if not pending.done.wait(timeout):
            with self._plock:
                self._pending.pop(rid, None)
            raise LinkServiceUnavailable(
                f"the robot-link service did not answer {op} within {timeout:.0f} s"
            )
        reply = pending.reply or {}
        if reply.get("ok"):
            return reply.get("result")
        error = reply.get("error") or {}
        if error.get("type") == "Unavailable":
            raise LinkServiceUnavailable(str(error.get("message")))
        _raise(error)

    # ------------------------------------------------------ the engine's API
    def robot_names(self) -> list[str]:
        return list(self._names)

    def robot_status(self, name: str) -> dict[str, Any]:
        return dict(self._call("robot_status", {"name": name}))

    #: How long one answer of :meth:`robot_statuses` serves every caller.
    STATUS_TTL_S = 0.1
    STATUS_STALE_OK_S = 2.0

    def recent_statuses(self) -> list[dict[str, Any]] | None:
        """The shared answer if it is younger than :data:`STATUS_STALE_OK_S`, and
        a refresh in the background when it is past :data:`STATUS_TTL_S`; else
        ``None``.  Never waits.

        A pushed change (link state, E-stop, an execution's state) drops the
        answer at once (:meth:`_changes_statuses`), so what this may show late
        is only report details and progress.  Without it, every poll that found
        the answer expired queued behind one round trip to a link service busy
        streaming four robots.
        """
        cached = self._status_cache
        if cached is None:
            return None
        age = time.monotonic() - cached[0]
        if age >= self.STATUS_STALE_OK_S:
            return None
        if age >= self.STATUS_TTL_S:
            self._refresh_in_background()
        return [dict(s) for s in cached[1]]

    def _refresh_in_background(self) -> None:
        with self._refresh_guard:
            if self._refreshing:
                return
            self._refreshing = True

        def refresh() -> None:
            try:
                self.robot_statuses()
            except Exception as exc:  # the next caller asks again, and sees the error
                log.debug("background GET /robots refresh failed: %s", exc)
            finally:
                with self._refresh_guard:
                    self._refreshing = False

        threading.Thread(target=refresh, name="robot status refresh", daemon=True).start()

    def robot_statuses(self) -> list[dict[str, Any]]:
        """Every robot's status in one round trip (``GET /robots``).

        Callers within :data:`STATUS_TTL_S` of the last round trip share its
        answer, so however many clients poll, the link service (whose threads
        send the heartbeats) answers at most ten of these a second.
        """
        with self._status_lock:
            cached = self._status_cache
            if cached is not None and time.monotonic() - cached[0] < self.STATUS_TTL_S:
                return [dict(s) for s in cached[1]]
            gen = self._status_gen
            statuses = [dict(s) for s in self._call("robot_statuses", {})]
            if gen == self._status_gen:  # no change was pushed meanwhile
                self._status_cache = (time.monotonic(), statuses)
            return [dict(s) for s in statuses]

    def set_connection(
        self, name: str, url: str, actor: str, secret: str | None = None
    ) -> dict[str, Any]:
        """Reconnect ``name`` at ``url``; ``secret`` (64 hex chars) replaces its link secret."""
        if secret is not None:
            from robots.protocol.auth import SecretError, parse_secret

            try:
                parse_secret(secret)
            except SecretError as exc:
                raise DispatchError(f"secret: {exc}", 422) from None
        args = {"name": name, "url": url, "actor": actor, "secret": secret}
        return dict(self._call("set_connection", args))

    def takeover(self, name: str, actor: str) -> dict[str, Any]:
        return dict(self._call("takeover", {"name": name, "actor": actor}))

    def clear_estop(self, name: str, actor: str) -> dict[str, Any]:
        return dict(self._call("clear_estop", {"name": name, "actor": actor}))

    def wait_connected(self, name: str, timeout: float) -> bool:
        return bool(
            self._call(
                "wait_connected", {"name": name, "timeout": timeout}, timeout + RPC_TIMEOUT_S
            )
        )

    def dispatch(self, plan_id: str, robot: str, actor: str) -> ExecutionRecord:
        plan = self.store.get_plan(plan_id, result=False, program=False)
        args = {
            "plan_id": plan_id,
            "robot": robot,
            "actor": actor,
            "kind_robot": self._kind_robot(plan.kind),
        }
        result = self._call("dispatch", args)
        return self.store.get_execution(str(result["id"]))

    def pause(self, execution_id: str, actor: str) -> ExecutionRecord:
        self._call("pause", {"execution_id": execution_id, "actor": actor})
        return self.store.get_execution(execution_id)

    def resume(self, execution_id: str, actor: str, clear_faults: bool = False) -> ExecutionRecord:
        args = {"execution_id": execution_id, "actor": actor, "clear_faults": clear_faults}
        self._call("resume", args)
        return self.store.get_execution(execution_id)

    def abort(self, execution_id: str, actor: str) -> ExecutionRecord:
        self._call("abort", {"execution_id": execution_id, "actor": actor})
        return self.store.get_execution(execution_id)

    def stats(self) -> dict[str, Any]:
        return dict(self._call("stats", {}))

    def estop(self, robot: str | None, reason: str) -> list[str]:
        """E-stop over the dedicated channel, from this thread; returns the robots reached.

        Raises :class:`LinkServiceUnavailable` when the service cannot be reached
        (its robots have then lost their links, and stop on their own).
        """
        ch = self._estop
        if ch is None:
            raise LinkServiceUnavailable("the robot-link service is not running")
        rid = next(self._ids)
        with self._estop_lock:  # one E-stop in flight at a time: replies come in order
            try:
                ch.send({"id": rid, "robot": robot, "reason": reason})
                ch.sock.settimeout(ESTOP_TIMEOUT_S)
                try:
                    reply = ch.recv()
                    while reply.get("id") != rid:  # a late answer to a timed-out E-stop
                        reply = ch.recv()
                finally:
                    ch.sock.settimeout(None)
            except (ChannelClosed, TimeoutError, OSError) as exc:
                raise LinkServiceUnavailable(
                    f"E-stop not confirmed by the robot-link service: {exc}"
                ) from None
        self._drop_statuses()  # the latch is set: no status from before it is shown again
        if not reply.get("ok"):
            _raise(reply.get("error") or {})
        return list(reply.get("result") or [])
