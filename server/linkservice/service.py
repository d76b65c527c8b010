"""The robot-link service: a process of its own that owns every robot link.

``steelpath serve`` starts it as a child (``python -m server.linkservice``)
and talks to it over two inherited ``socketpair`` ends (no name on disk, so
no other local process can reach it):

- the **E-stop channel**: a thread that does nothing but wait on it.  A
  request is answered only after ESTOP has been written to every target
  link; bookkeeping (streamers, store) comes after, on another thread;
- the **RPC channel**: requests (``dispatch``, ``pause``, ``robot_status``…)
  run on a small pool of threads; replies and pushed events leave through
  one bounded send queue, so a web server that stops reading can never block
  a streamer, a link or the mirror thread (excess events are dropped and
  counted, replies never).

Each robot link runs its own I/O thread (heartbeats, retransmission, link
watchdog) in this process, where no HTTP handler, upload parser, scene or
planner shares the GIL.  The process asks for a higher scheduling priority
(``os.nice(-5)``, granted to root) and dies with its parent
(``PR_SET_PDEATHSIG`` plus a check of the parent pid): a robot must not go
on moving while no operator console or E-stop can reach it.
"""

from __future__ import annotations

import argparse
import concurrent.futures
import contextlib
import json
import logging
import os
import queue
import signal
import socket
import sys
import threading
import time
from pathlib import Path
from typing import Any

from robots.background_io import log_through_a_queue
from server.dispatch.engine import DispatchEngine, DispatchError
from server.lifecycle import IllegalTransitionError
from server.lifetime import die_with_parent
from server.linkservice.channel import STOP_OP, Channel, ChannelClosed
from server.settings import Settings
from server.store import NotFoundError, Store

log = logging.getLogger("steelpath.linkservice")

#: Pushed events waiting for the web server; beyond this the oldest are dropped.
EVENT_QUEUE = 2000


class _Outbox:
    """One sender thread for replies and events; events are droppable."""

    def __init__(self, channel: Channel) -> None:
        self.channel = channel
        self._q: queue.Queue[dict[str, Any] | None] = queue.Queue()
        self._events = 0
        self._lock = threading.Lock()
        self.dropped_events = 0
        self._thread = threading.Thread(target=self._run, name="link-service outbox", daemon=True)
        self._thread.start()

    def reply(self, msg: dict[str, Any]) -> None:
        self._q.put(msg)

    def publish(self, type_: str, data: dict[str, Any]) -> None:
        with self._lock:
            if self._events >= EVENT_QUEUE:
                self.dropped_events += 1
                return
            self._events += 1
        self._q.put({"event": type_, "data": data})

    def close(self) -> None:
        self._q.put(None)
        self._thread.join(timeout=2)

    def _run(self) -> None:
        while True:
            msg = self._q.get()
            if msg is None:
                return
            if "event" in msg:
                with self._lock:
                    self._events -= 1
            try:
                self.channel.send(msg)
            except ChannelClosed:
                return
            except (TypeError, ValueError):
                log.exception("could not encode %s", str(msg)[:200])


def _error(exc: BaseException) -> dict[str, Any]:
    if isinstance(exc, DispatchError):
        return {"type": "DispatchError", "message": str(exc), "status": exc.status}
    if isinstance(exc, IllegalTransitionError):
        return {
            "type": "IllegalTransitionError",
            "message": str(exc),
            "entity": exc.entity,
            "entity_id": exc.entity_id,
            "state": exc.state,
            "action": exc.action,
            "allowed": list(exc.allowed),
        }
    if isinstance(exc, NotFoundError):
        return {"type": "NotFoundError", "message": str(exc)}
    return {"type": type(exc).__name__, "message": str(exc), "status": 500}


class LinkService:
    """The child side: an engine, an RPC loop and an E-stop loop."""

    OPS = (
        "robot_names",
        "robot_status",
        "robot_statuses",
        "set_connection",
        "takeover",
        "clear_estop",
        "wait_connected",
        "dispatch",
        "pause",
        "resume",
        "abort",
        "estop",
        "stats",
    )

    def __init__(
        self,
        settings: Settings,
        rpc: Channel,
        estop: Channel,
        emulator_urls: dict[str, str],
        *,
        server_id: str = "",
        server_url: str = "",
    ) -> None:
        self.settings = settings
        self.server_id = server_id
        self.server_url = server_url
        self.emulator_urls = dict(emulator_urls)
        self.keeper: Any = None  # server.ownership.LeaseKeeper once running
        self.rpc = rpc
        self.estop_channel = estop
        self.outbox = _Outbox(rpc)
        self.store = Store(settings.data, database_url=settings.database_url)
        self.engine = DispatchEngine(
            self.store,
            self.outbox,
            settings,
            emulator_urls=emulator_urls,
            secret_for=self._secret_for,
        )
        self.engine.server_id = server_id or None
        self.pool = concurrent.futures.ThreadPoolExecutor(8, thread_name_prefix="link-rpc")
        self._book = concurrent.futures.ThreadPoolExecutor(1, thread_name_prefix="estop-book")
        self.stopping = threading.Event()
        # Set by the web server's "stop" message (LinkServiceClient.shutdown):
        # only then are the leases released.  A parent-pid check could not
        # tell: a killed server's process can outlive the thread that started
        # this one (the kernel then reparents us to a sibling thread, and
        # getppid() still names the dying server), and the channels' EOF comes
        # either way.
        self.asked_to_stop = False
        self.estops = 0

    def _secret_for(self, name: str) -> bytes | None:
        try:
            from robots.protocol.auth import load_or_create_secret
        except ImportError:  # protocol without authentication
            return None
        return load_or_create_secret(robot_key_path(self.settings.data, name))

    # ----------------------------------------------------------------- E-stop
    def estop_loop(self) -> None:
        while not self.stopping.is_set():
            try:
                req = self.estop_channel.recv()
            except ChannelClosed:
                self.stopping.set()
                return
            robot = req.get("robot")
            t0 = time.monotonic()
            try:
                reached = self.engine.estop_links(robot, str(req.get("reason") or "E-stop"))
                reply: dict[str, Any] = {"id": req.get("id"), "ok": True, "result": reached}
            except Exception as exc:
                reply = {"id": req.get("id"), "ok": False, "error": _error(exc)}
            reply["took_s"] = time.monotonic() - t0
            self.estops += 1
            with contextlib.suppress(ChannelClosed):
                self.estop_channel.send(reply)
            reason = str(req.get("reason") or "E-stop")
            self._book.submit(self._estop_bookkeeping, robot, reason)

    def _estop_bookkeeping(self, robot: str | None, reason: str) -> None:
        try:
            self.engine.estop_bookkeeping(robot, reason)
        except Exception:
            log.exception("E-stop bookkeeping failed")

    # -------------------------------------------------------------------- RPC
    def rpc_loop(self) -> None:
        while not self.stopping.is_set():
            try:
                req = self.rpc.recv()
            except ChannelClosed:
                self.stopping.set()
                return
            if req.get("op") == STOP_OP:
                # Read here, in order, not on the pool: the channel's EOF that
                # follows must not overtake it.
                self.asked_to_stop = True
                continue
            self.pool.submit(self._handle, req)

    def _handle(self, req: dict[str, Any]) -> None:
        op = req.get("op")
        args = req.get("args") or {}
        try:
            if op not in self.OPS:
                raise ValueError(f"unknown operation {op!r}")
            result = self._call(str(op), args)
            reply = {"id": req.get("id"), "ok": True, "result": result}
        except Exception as exc:
            if not isinstance(exc, DispatchError | IllegalTransitionError | NotFoundError):
                log.exception("link service %s failed", op)
            reply = {"id": req.get("id"), "ok": False, "error": _error(exc)}
        self.outbox.reply(reply)

    def _call(self, op: str, args: dict[str, Any]) -> Any:
        eng = self.engine
        if op == "robot_names":
            return eng.robot_names()
        if op == "robot_status":
            return eng.robot_status(args["name"])
        if op == "robot_statuses":
            return [eng.robot_status(n) for n in eng.robot_names()]
        if op == "set_connection":
            secret = args.get("secret")
            writer = None
            if secret is not None:

                def writer(name: str) -> None:
                    write_secret(robot_key_path(self.settings.data, name), str(secret))

            return eng.set_connection(args["name"], args["url"], args["actor"], writer)
        if op == "takeover":
            return eng.takeover(args["name"], args["actor"])
        if op == "clear_estop":
            return eng.clear_estop(args["name"], args["actor"])
        if op == "wait_connected":
            return eng.wait_connected(args["name"], float(args["timeout"]))
        if op == "dispatch":
            return eng.dispatch(
                args["plan_id"], args["robot"], args["actor"], args.get("kind_robot")
            ).public()
        if op == "pause":
            return eng.pause(args["execution_id"], args["actor"]).public()
        if op == "resume":
            return eng.resume(
                args["execution_id"], args["actor"], bool(args.get("clear_faults"))
            ).public()
        if op == "abort":
            return eng.abort(args["execution_id"], args["actor"]).public()
        if op == "estop":
            return eng.estop(args.get("robot"), str(args.get("reason") or "E-stop"))
        if op == "stats":
            return {
                "pid": os.getpid(),
                "nice": os.nice(0),
                "estops": self.estops,
                "dropped_events": self.outbox.dropped_events,
            }
        raise ValueError(op)  # pragma: no cover - OPS guards it

    # -------------------------------------------------------------- lifecycle
    def run(self) -> None:
        if self.server_id:
            # Several servers may share the store: drive only the robots whose
            # lease this server holds (server.ownership.keeper).
            from robots import ROBOT_NAMES
            from server.ownership.keeper import LeaseKeeper

            self.engine.start(leased=True)
            self.keeper = LeaseKeeper(
                self.engine,
                self.store.db,
                server_id=self.server_id,
                url=self.server_url,
                lease_s=self.settings.robot_lease_s,
                robots=ROBOT_NAMES,
                emulator_urls=self.emulator_urls,
            ).start()
        else:
            self.engine.start()
        threading.Thread(target=self.estop_loop, name="estop", daemon=True).start()
        threading.Thread(target=self.rpc_loop, name="link-rpc reader", daemon=True).start()
        self.outbox.publish("linkservice", {"state": "ready", "pid": os.getpid()})
        # SIGTERM is blocked in every thread main() starts and taken here
        # synchronously: a Python handler calling Event.set() can deadlock on
        # the lock its own thread holds inside Event.wait(), which once left an
        # orphaned service running for good.  Threads started while importing,
        # before main() runs (OpenBLAS's), block it too: the client's bootstrap
        # blocks it before the first import (client.BOOTSTRAP).
        while not self.stopping.is_set():
            if signal.sigtimedwait({signal.SIGTERM}, 0.5) is not None:
                break
        self.shutdown()

    def _orphaned(self) -> None:
        # Whatever a thread is stuck in, this process ends soon: armed first.
        threading.Timer(10.0, lambda: os._exit(1)).start()
        self.stopping.set()
        log.error("the web server is gone: stopping every link")

    def shutdown(self) -> None:
        self.stopping.set()
        if self.keeper is not None:
            self.keeper.stop()
        self.engine.shutdown()
        # Released only when the web server asked us to stop: a killed
        # server's leases lapse instead, after its robots' watchdogs have
        # stopped them for certain.
        if self.keeper is not None and self.asked_to_stop:
            self.keeper.release()
        self.pool.shutdown(wait=False, cancel_futures=True)
        self._book.shutdown(wait=False, cancel_futures=True)
        self.outbox.close()
        self.store.close()


def write_secret(path: Path, hex_secret: str) -> None:
    """Replace a robot's secret file atomically (mode 0600): for real hardware."""
    from robots.protocol.auth import format_secret, parse_secret

    text = format_secret(parse_secret(hex_secret)) + "\n"
    path.parent.mkdir(parents=True, exist_ok=True, mode=0o700)
    tmp = path.with_name(f".{path.name}.{os.getpid()}.tmp")
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    try:
        os.fchmod(fd, 0o600)
        os.write(fd, text.encode("ascii"))
        os.fsync(fd)
    finally:
        os.close(fd)
    os.replace(tmp, path)


def robot_key_path(data: Path, robot: str) -> Path:
    """Where a robot's link secret lives: ``<data>/robots/<robot>.key`` (mode 0600)."""
    return Path(data) / "robots" / f"{robot}.key"


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="python -m server.linkservice")
    p.add_argument("--rpc-fd", type=int, required=True)
    p.add_argument("--estop-fd", type=int, required=True)
    p.add_argument("--parent-pid", type=int, required=True)
    p.add_argument("--config", required=True, help="JSON: settings and emulator URLs")
    ns = p.parse_args(argv)
    # Armed before anything slow (imports, connecting the robots): a server
    # killed while this process starts must not leave it running on its own.
    service: LinkService | None = None

    def orphaned() -> None:
        if service is None:
            os._exit(1)
        service._orphaned()

    signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGTERM})
    # A link's I/O thread waiting for the GIL gets it from a busy RPC thread
    # within 1 ms, not the default 5 ms: heartbeats come first.
    sys.setswitchinterval(0.001)
    die_with_parent(ns.parent_pid, sig=signal.SIGTERM, on_orphaned=orphaned, poll_s=0.1)
    cfg = json.loads(ns.config)
    logging.basicConfig(
        level=getattr(logging, str(cfg.get("log_level", "info")).upper(), logging.INFO),
        format="%(asctime)s link-service %(levelname)s %(name)s: %(message)s",
        stream=sys.stderr,
    )
    # A link thread that logs must not wait for stderr (a file or pipe the
    # server drains when it can): records go through a queue.
    log_listener = log_through_a_queue()
    try:
        os.nice(-5)
    except OSError:
        log.info("running at the default priority (raising it needs root or CAP_SYS_NICE)")
    settings = Settings(**cfg["settings"])
    rpc = Channel(socket.socket(fileno=ns.rpc_fd))
    estop = Channel(socket.socket(fileno=ns.estop_fd))
    service = LinkService(
        settings,
        rpc,
        estop,
        cfg.get("emulator_urls") or {},
        server_id=str(cfg.get("server_id") or ""),
        server_url=str(cfg.get("server_url") or ""),
    )
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when we stop
    service.run()
    # Links are closed and the store is durable: do not wait at interpreter exit
    # for an RPC thread still inside a long call (wait_connected, a busy SQLite).
    log_listener.stop()
    logging.shutdown()
    os._exit(0)
