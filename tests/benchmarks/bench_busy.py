"""Busy-machine benchmark: E-stop, API reads and dispatches under load.

Run on demand (defaults are the issue's load; scale down with the flags)::

    .venv/bin/python tests/benchmarks/bench_busy.py \\
        [--clients 50] [--upload-mb 250] [--trials 60] [--dispatches 20]

Everything goes over loopback HTTP to a real ``steelpath serve`` subprocess
(its own data directory, token file and free port; built-in emulators):

1. *Set-up* (not measured): plan every kind that compiles to a robot program
   once with its default params; the kinds whose plan has a non-empty
   program and passes its checks are the dispatchable ones.  Revise those
   into ``--dispatches`` fresh plans (round robin over the kinds) and plan
   one ``demo.route`` per E-stop trial; approve them all.
2. *Quiet* (nothing else running): API reads by one client; E-stop trials.
3. *Loaded*: ``--clients`` asyncio clients polling a mix of reads (spread
   over load processes of at most 10 clients each), one process keeping ``--planning`` plans of heavy kinds in flight, one
   uploading a ``--upload-mb`` XYZ cloud in a loop; once all three are
   running: E-stop trials, then the dispatches (concurrently on every robot,
   one execution per robot at a time).

E-stop trial: dispatch an approved ``demo.route`` to ``ara``, wait until the
robot reports a command executing, wait a random 0–50 ms, note ``t0 =
time.monotonic()`` and ``POST /api/v1/estop``; the latency is the
emulator's own motion-stop instant (``{"record": "stop", "reason": "estop",
"t": ...}`` in ``<data>/emulators/ara.log.jsonl``, ``time.monotonic()`` of
the emulator process — CLOCK_MONOTONIC is system-wide on Linux) minus
``t0``.  If the emulator writes no stop records, the benchmark says so and
falls back to the instant the host first *sees* mode ESTOP in
``GET /robots/ara/state`` (an upper bound).  Then clear the E-stop and wait
for the link before the next trial.

Targets (loaded): E-stop → motion stop p95 < 100 ms and p99 < 200 ms; API
reads p95 < 250 ms with no failed read; every dispatch completed (0
interrupted, 0 faulted).  Each figure is printed beside the quiet one and
the ratio loaded/quiet.  Exit status: 0 when every target is met, 1 when one
is missed or the load was not applied, 2 when the run itself failed.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import math
import multiprocessing as mp
import os
import random
import shutil
import signal
import socket
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT))

from tests.benchmarks._load import (  # noqa: E402
    TERMINAL_PLAN_STATES,
    percentile,
    planning_load,
    read_clients,
    read_paths,
    upload_load,
    write_xyz,
)

ESTOP_P95_MS = 100.0
ESTOP_P99_MS = 200.0
READ_P95_MS = 250.0
#: Read clients per load process (asyncio pollers sharing one httpx loop).
CLIENTS_PER_PROCESS = 10
MODE_IDLE, MODE_MOVING, MODE_ESTOP = 0, 1, 4  # robots.protocol.messages.Mode
TERMINAL_EXEC_STATES = frozenset({"completed", "aborted", "faulted", "interrupted"})
HEAVY_KINDS = ("cmbot.climb", "blast", "sbg.inspect", "ara.navigate")
ESTOP_ROBOT = "ara"


class BenchError(RuntimeError):
    """The run could not measure what it set out to (server or set-up failure)."""


def log(msg: str) -> None:
    print(f"[{time.strftime('%H:%M:%S')}] {msg}", file=sys.stderr, flush=True)


def wait_for(what: str, pred: Callable[[], Any], timeout: float, interval: float = 0.05) -> Any:
    """Poll ``pred`` until it returns something truthy; BenchError naming ``what`` on timeout."""
    deadline = time.monotonic() + timeout
    while True:
        got = pred()
        if got:
            return got
        if time.monotonic() > deadline:
            raise BenchError(f"timed out after {timeout:.0f} s waiting for {what}")
        time.sleep(interval)


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


# -------------------------------------------------------------------- server
@dataclass
class Server:
    proc: subprocess.Popen[bytes]
    url: str
    data: Path
    log_path: Path
    admin_token: str = ""

    def log_tail(self, n: int = 40) -> str:
        try:
            return "\n".join(self.log_path.read_text(errors="replace").splitlines()[-n:])
        except OSError:
            return "(no server log)"


def descendants(root: int) -> list[int]:
    """Every live process below ``root`` (from ``/proc/*/stat`` parent ids)."""
    children: dict[int, list[int]] = {}
    for d in Path("/proc").iterdir():
        if not d.name.isdigit():
            continue
        try:
            stat = (d / "stat").read_text()
        except OSError:
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(d.name))
    out, todo = [], [root]
    while todo:
        for c in children.get(todo.pop(), []):
            out.append(c)
            todo.append(c)
    return out


def start_server(tmp: Path, args: argparse.Namespace, servers: list[Server]) -> Server:
    """Start ``python -m server.cli serve`` (appended to ``servers`` at once) and wait for it."""
    data = tmp / "var"
    port = free_port()
    env = dict(os.environ)
    env.update(
        {
            "STEELPATH_DATA": str(data),
            "STEELPATH_HOST": "127.0.0.1",
            "STEELPATH_PORT": str(port),
            "STEELPATH_SCENE_PORT": "0",
            "STEELPATH_TOKEN_FILE": str(tmp / "admin.token"),
            "STEELPATH_EMULATOR_TIME_SCALE": repr(args.time_scale),
            "STEELPATH_EMULATOR_NICE": str(args.emulator_nice),
            "STEELPATH_JOB_WORKERS": str(args.job_workers),
            "STEELPATH_MAX_UPLOAD_MB": repr(max(400.0, args.upload_mb * 1.5)),
            "STEELPATH_LOG_LEVEL": args.log_level,
        }
    )
    log_path = tmp / "server.log"
    fh = log_path.open("wb")
    proc = subprocess.Popen(
        [sys.executable, "-m", "server.cli", "serve"],
        cwd=ROOT,
        env=env,
        stdout=fh,
        stderr=subprocess.STDOUT,
    )
    fh.close()
    srv = Server(proc, f"http://127.0.0.1:{port}", data, log_path)
    servers.append(srv)

    def up() -> bool:
        if proc.poll() is not None:
            raise BenchError(f"server exited with {proc.returncode}:\n{srv.log_tail()}")
        try:
            return httpx.get(f"{srv.url}/api/v1/health", timeout=2).status_code == 200
        except httpx.HTTPError:
            return False

    wait_for("the server's /health", up, 120, 0.2)
    token_file = tmp / "admin.token"
    wait_for("the first-start admin token file", token_file.exists, 10)
    srv.admin_token = token_file.read_text().strip().splitlines()[-1]
    return srv


def stop_server(srv: Server) -> None:
    """SIGTERM the server, SIGKILL it after 20 s, then end anything it left behind."""
    tree = set(descendants(srv.proc.pid))
    for pf in (srv.data / "emulators").glob("*.port.json"):
        with contextlib.suppress(OSError, ValueError, KeyError):
            tree.add(int(json.loads(pf.read_text())["pid"]))
    if srv.proc.poll() is None:
        srv.proc.send_signal(signal.SIGTERM)
        try:
            srv.proc.wait(20)
        except subprocess.TimeoutExpired:
            log("server did not stop within 20 s of SIGTERM: SIGKILL")
            srv.proc.kill()
            srv.proc.wait(10)
    # Children get a moment to notice their parent is gone before they count as left behind.
    deadline = time.monotonic() + 5.0
    while time.monotonic() < deadline and any(Path(f"/proc/{p}").exists() for p in tree):
        time.sleep(0.1)
    left = {p: _cmdline(p) for p in tree if Path(f"/proc/{p}").exists()}
    for p in left:
        with contextlib.suppress(ProcessLookupError, PermissionError):
            os.kill(p, signal.SIGKILL)
    for p, cmd in left.items():
        log(f"killed pid {p}, left behind 5 s after the server stopped: {cmd}")


def _cmdline(pid: int) -> str:
    try:
        return Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()[:160]
    except OSError:
        return "?"


class RssSampler(threading.Thread):
    """Samples the resident memory of the server's process tree every 0.5 s."""

    def __init__(self, root: int, upload_flag: Any) -> None:
        super().__init__(daemon=True)
        self.root = root
        self.upload_flag = upload_flag
        self.halt = threading.Event()
        self.peak_tree_mb = 0.0
        self.peak_single: tuple[float, str] = (0.0, "")
        self.peak_single_upload: tuple[float, str] = (0.0, "")

    @staticmethod
    def _rss_mb(pid: int) -> tuple[float, str]:
        try:
            status = Path(f"/proc/{pid}/status").read_text()
            cmd = Path(f"/proc/{pid}/cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            return 0.0, ""
        for line in status.splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024, f"pid {pid}: {cmd[:80].strip()}"
        return 0.0, ""

    def run(self) -> None:
        while not self.halt.wait(0.5):
            pids = [self.root, *descendants(self.root)]
            sizes = [self._rss_mb(p) for p in pids]
            self.peak_tree_mb = max(self.peak_tree_mb, sum(s for s, _ in sizes))
            top = max(sizes, default=(0.0, ""))
            self.peak_single = max(self.peak_single, top)
            if self.upload_flag.value:
                self.peak_single_upload = max(self.peak_single_upload, top)


def vm_hwm_mb(pid: int) -> float:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return math.nan


# ----------------------------------------------------------------------- API
class Api:
    """A thin synchronous client: every unexpected status becomes a BenchError."""

    def __init__(self, url: str, token: str, timeout: float = 60.0) -> None:
        self.c = httpx.Client(
            base_url=f"{url}/api/v1",
            headers={"Authorization": f"Bearer {token}"},
            timeout=timeout,
        )

    def call(self, method: str, path: str, expect: tuple[int, ...] = (200,), **kw: Any) -> Any:
        r = self.c.request(method, path, **kw)
        if r.status_code not in expect:
            raise BenchError(f"{method} {path}: HTTP {r.status_code}: {r.text[:400]}")
        return r.json() if r.content else None

    def get(self, path: str, **kw: Any) -> Any:
        return self.call("GET", path, **kw)

    def post(self, path: str, body: Any = None, expect: tuple[int, ...] = (200,)) -> Any:
        return self.call("POST", path, expect=expect, json=body)

    def close(self) -> None:
        self.c.close()


class PlanWatch:
    """Polls plans until they are terminal, noting how long each spent ``planning``.

    ``secs[id]`` runs from the first poll that saw it planning to the first
    that saw it terminal (±0.5 s, the poll period); ``running(id)`` is how long
    it has been planning so far.
    """

    def __init__(self, api: Api) -> None:
        self.api = api
        self.started: dict[str, float] = {}
        self.done: dict[str, dict[str, Any]] = {}
        self.secs: dict[str, float] = {}

    def running(self, pid: str) -> float:
        t = self.started.get(pid)
        return 0.0 if t is None else time.monotonic() - t

    def poll(self, ids: list[str]) -> None:
        pending = [p for p in ids if p not in self.done]
        if not pending:
            return
        listed = {p["id"]: p for p in self.api.get("/plans", params={"limit": 500})}
        for pid in pending:
            plan = listed.get(pid) or self.api.get(f"/plans/{pid}")
            now = time.monotonic()
            if plan["state"] == "planning":
                self.started.setdefault(pid, now)
            elif plan["state"] in TERMINAL_PLAN_STATES:
                self.done[pid] = plan
                self.secs[pid] = round(now - self.started.get(pid, now), 1)

    def wait(self, ids: list[str], timeout: float, until: Callable[[], bool] | None = None) -> None:
        """Until every plan in ``ids`` is terminal (or ``until()`` holds)."""
        deadline = time.monotonic() + timeout
        while True:
            self.poll(ids)
            if all(p in self.done for p in ids) or (until is not None and until()):
                return
            if time.monotonic() > deadline:
                left = [p for p in ids if p not in self.done]
                raise BenchError(f"{len(left)} plan(s) still planning after {timeout:.0f} s")
            time.sleep(0.5)


def all_executions(api: Api, page: int = 500) -> list[dict[str, Any]]:
    """Every execution, page by page (``GET /executions`` answers at most 500)."""
    out: list[dict[str, Any]] = []
    while True:
        got = api.get("/executions", params={"limit": page, "offset": len(out)})
        out += got
        if len(got) < page:
            return out


def robot_state(api: Api, robot: str) -> dict[str, Any]:
    return dict(api.get(f"/robots/{robot}/state"))


def wait_ready(api: Api, robot: str, timeout: float = 60.0) -> None:
    last: dict[str, Any] = {}

    def ready() -> bool:
        last.update(robot_state(api, robot))
        # The robot's own report must say idle too: right after clear-estop the host
        # is clear while the robot may still report its latch or its last run, and a
        # run dispatched in that instant faults at once ("E-stop is latched",
        # "robot_busy: robot is executing run ...").
        rep = last.get("report") or {}
        return (
            bool(last.get("connected"))
            and not last.get("estop_latched")
            and rep.get("mode") == MODE_IDLE
            and rep.get("executing", -1) < 0
        )

    try:
        wait_for(f"robot {robot} connected with no E-stop latched", ready, timeout, 0.05)
    except BenchError as exc:
        keys = ("state", "reason", "connected", "estop_latched", "faults", "execution")
        seen = {k: last.get(k) for k in keys}
        seen["mode"] = (last.get("report") or {}).get("mode")
        raise BenchError(f"{exc}; last state: {seen}") from None


def clear_all(api: Api, robots: list[str]) -> None:
    for r in robots:
        api.post(f"/robots/{r}/clear-estop")
    for r in robots:
        wait_ready(api, r)


# ------------------------------------------------------------------ set-up
@dataclass
class Prepared:
    robots: list[str]
    dispatchable: dict[str, str]  # kind -> robot
    not_dispatchable: dict[str, str]  # kind -> why
    template_ids: dict[str, str]
    plan_s: dict[str, float]  # kind -> seconds its default plan spent planning
    dispatch_jobs: list[tuple[str, str, str]]  # (kind, robot, approved plan id)
    estop_plans: list[str]


def estop_route_params(length_m: float) -> dict[str, Any]:
    """A straight demo route of ``length_m``: long enough to be moving when the E-stop lands."""
    half = length_m / 2
    return {
        "nodes": {"s": [0.0, 0.0, 0.0], "m": [half, 0.0, 0.0], "e": [length_m, 0.0, 0.0]},
        "edges": [["s", "m"], ["m", "e"]],
        "start": "s",
        "end": "e",
        "max_length_m": length_m + 1.0,
    }


def why_not_dispatchable(plan: dict[str, Any], robot: str, robots: list[str]) -> str | None:
    failed = [c["name"] for c in plan.get("checks") or [] if not c.get("passed")]
    if plan["state"] != "planned":
        return f"plan {plan['id']} ended {plan['state']}: {plan.get('error')}"
    if failed:
        return f"plan {plan['id']} failed checks {failed}"
    if not plan.get("program_length"):
        return f"plan {plan['id']} has an empty program"
    if robot not in robots:
        return f"its robot {robot!r} is not among {robots}"
    return None


def spread_extras(secs: dict[str, float], n: int, budget_s: float) -> list[str]:
    """``n`` kinds for the extra dispatches: round robin, cheapest first, within a budget.

    Each round takes every kind in order of its planning time while the summed
    planning time stays within ``budget_s``; once no kind fits, the rest go to the
    cheapest kind, so the set-up is bounded and still spread over every kind it can.
    """
    order = sorted(secs, key=secs.__getitem__)
    out: list[str] = []
    spent = 0.0
    while order and len(out) < n:
        took = False
        for k in order:
            if len(out) < n and spent + secs[k] <= budget_s:
                out.append(k)
                spent += secs[k]
                took = True
        if not took:
            out += [order[0]] * (n - len(out))
    return out


def prepare(
    api: Api,
    n_dispatches: int,
    n_estop: int,
    extra_max_s: float,
    extra_budget_s: float,
    route_m: float,
) -> Prepared:
    """Plan and approve every plan the run dispatches, before anything is measured.

    Each dispatchable kind's default plan is its first dispatch; the other
    ``n_dispatches - kinds`` dispatches are fresh revisions spread over the
    kinds whose default plan planned within ``extra_max_s`` by
    :func:`spread_extras` (summed planning time within ``extra_budget_s``),
    submitted as soon as that set is known (every default plan done or planning
    longer than ``extra_max_s``), so set-up stays within minutes on two cores.
    The E-stop plans are straight ``route_m`` demo routes.
    """
    robots = [r["name"] for r in api.get("/robots")]
    kinds = api.get("/kinds")
    compiling = {k["name"]: k["robot"] for k in kinds if k.get("compiles")}
    if "demo.route" not in compiling:
        raise BenchError("the E-stop trials need the demo.route kind, which is not registered")
    log(f"planning the default plan of each kind that compiles: {sorted(compiling)}")
    submitted = {
        kind: api.post("/plans", {"kind": kind, "params": {}}, expect=(202,))["id"]
        for kind in sorted(compiling)
    }
    route = {"kind": "demo.route", "params": estop_route_params(route_m)}
    estop_ids = [api.post("/plans", route, expect=(202,))["id"] for _ in range(n_estop)]
    watch = PlanWatch(api)
    tids = list(submitted.values())
    watch.wait(
        tids,
        1800,
        until=lambda: all(p in watch.done or watch.running(p) > extra_max_s for p in tids),
    )
    cheap = sorted(
        (
            k
            for k, pid in submitted.items()
            if pid in watch.done
            and watch.secs[pid] <= extra_max_s
            and why_not_dispatchable(watch.done[pid], compiling[k], robots) is None
        ),
        key=lambda k: watch.secs[submitted[k]],
    )
    n_extra = max(0, n_dispatches - len(compiling))
    extra_kinds = spread_extras(
        {k: watch.secs[submitted[k]] for k in cheap}, n_extra, extra_budget_s
    )
    log(
        f"{len(extra_kinds)} more dispatch plans: "
        + ", ".join(f"{k} ×{extra_kinds.count(k)}" for k in sorted(set(extra_kinds)))
    )
    revised = [
        (k, api.post(f"/plans/{submitted[k]}/revise", {"params": {}}, expect=(202,))["id"])
        for k in extra_kinds
    ]
    watch.wait(tids + [p for _, p in revised] + estop_ids, 1800)
    plan_s = {k: watch.secs[pid] for k, pid in submitted.items()}
    dispatchable, why_not = {}, {}
    for kind, pid in submitted.items():
        why = why_not_dispatchable(watch.done[pid], compiling[kind], robots)
        if why is None:
            dispatchable[kind] = compiling[kind]
        else:
            why_not[kind] = why
    log(f"dispatchable: {sorted(dispatchable)}; default plans' planning s: {plan_s}")
    for pid in estop_ids:
        why = why_not_dispatchable(watch.done[pid], ESTOP_ROBOT, robots)
        if why is not None:
            raise BenchError(f"the E-stop route {route['params']} is not dispatchable: {why}")
    jobs = [(k, submitted[k]) for k in sorted(dispatchable)] + revised
    jobs = jobs[:n_dispatches]
    for k, pid in jobs:
        why = why_not_dispatchable(watch.done[pid], compiling[k], robots)
        if why is not None:
            raise BenchError(f"a {k} dispatch plan is not dispatchable: {why}")
    for pid in [p for _, p in jobs] + estop_ids:
        api.post(f"/plans/{pid}/approve", {"comment": "bench_busy"})
    # Interleave kinds so each robot's queue mixes them and every robot starts at once.
    order = {k: i for i, k in enumerate(sorted(dispatchable))}
    seen: dict[str, int] = {}
    ranked = []
    for k, pid in jobs:
        seen[k] = seen.get(k, 0) + 1
        ranked.append((seen[k], order[k], k, pid))
    return Prepared(
        robots=robots,
        dispatchable=dispatchable,
        not_dispatchable=why_not,
        template_ids=submitted,
        plan_s=plan_s,
        dispatch_jobs=[(k, dispatchable[k], pid) for _, _, k, pid in sorted(ranked)],
        estop_plans=estop_ids,
    )


# ------------------------------------------------------------------- E-stop
class LogTail:
    """Reads the complete JSON lines appended to a file since the last call."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.offset = 0
        self.buf = b""

    def new(self) -> list[dict[str, Any]]:
        try:
            with self.path.open("rb") as fh:
                fh.seek(self.offset)
                chunk = fh.read()
        except FileNotFoundError:
            return []
        self.offset += len(chunk)
        self.buf += chunk
        *lines, self.buf = self.buf.split(b"\n")
        out = []
        for line in lines:
            if line.strip():
                with contextlib.suppress(ValueError):
                    out.append(json.loads(line))
        return out


def estop_stop_record(records: list[dict[str, Any]]) -> dict[str, Any] | None:
    """The first emulator ``stop`` record caused by an E-stop, if any."""
    return next(
        (r for r in records if r.get("record") == "stop" and r.get("reason") == "estop"), None
    )


@dataclass
class Trial:
    latency_ms: float
    http_ms: float
    moving: bool
    upload_in_flight: bool
    plans_in_flight: int
    execution: str
    #: The server's own account of its time (the answer's ``timings_ms``), if given.
    server_ms: dict[str, float] = field(default_factory=dict)


@dataclass
class EstopRun:
    trials: list[Trial] = field(default_factory=list)
    method: str = "emulator log"
    probed: bool = False  # the first trial of a run tells whether stop records exist
    skipped: int = 0  # routes that finished before the host saw them execute
    cut_short: int | None = None  # trials done when the time budget ran out
    #: E-stop routes a lost link interrupted before the E-stop (the robot's
    #: watchdog saw the host fall silent): each one resumed and counted.
    link_lost: list[str] = field(default_factory=list)


MAX_SKIPS = 5
MAX_LINK_LOSSES = 5


class RouteFinished(Exception):
    """The E-stop route completed before the host saw it execute (the host is that slow)."""


def dispatch_when_free(api: Api, pid: str, robot: str, timeout: float = 30.0) -> dict[str, Any]:
    """``POST /plans/{pid}/dispatch``, retrying while the robot still winds up its last run."""
    deadline = time.monotonic() + timeout
    while True:
        r = api.c.post(f"/plans/{pid}/dispatch", json={"robot": robot})
        if r.status_code == 201:
            return dict(r.json())
        if r.status_code != 409 or time.monotonic() > deadline:
            raise BenchError(f"dispatch {pid} to {robot}: HTTP {r.status_code}: {r.text[:400]}")
        time.sleep(0.05)


def estop_trials(
    api: Api,
    plans: list[str],
    n: int,
    tail: LogTail,
    run: EstopRun,
    rng: random.Random,
    upload_flag: Any,
    plans_flag: Any,
    label: str,
    budget_s: float = math.inf,
) -> None:
    """Append ``n`` E-stop trials to ``run`` (see the module docstring for one trial).

    Stops early once ``budget_s`` is spent (noted in ``run.cut_short``), so a
    host too slow to answer its own control requests still ends the run.
    """
    target = len(run.trials) + n
    i = 0
    t_end = time.monotonic() + budget_s
    while len(run.trials) < target:
        if time.monotonic() > t_end:
            run.cut_short = n - (target - len(run.trials))
            log(f"{label}: trial budget of {budget_s:.0f} s spent after {run.cut_short} trials")
            break
        i += 1
        if not plans:
            raise BenchError("ran out of prepared E-stop plans")
        pid = plans.pop()
        wait_ready(api, ESTOP_ROBOT)
        ex = dispatch_when_free(api, pid, ESTOP_ROBOT)

        def executing(ex: dict[str, Any] = ex) -> bool:
            rep = robot_state(api, ESTOP_ROBOT).get("report") or {}
            ours = rep.get("run_id") == ex.get("run_id") or not ex.get("run_id")
            if rep.get("executing", -1) >= 0 and ours:
                return True
            # Only a report of this run, idle, can mean it already finished: ask then.
            if ours and rep.get("mode") != MODE_MOVING:
                cur = api.get(f"/executions/{ex['id']}")
                if cur["state"] == "completed":
                    raise RouteFinished(ex["id"])
                if cur["state"] == "interrupted" and len(run.link_lost) < MAX_LINK_LOSSES:
                    # A target missed, not a reason to stop measuring: count it,
                    # clear the robot's latched fault and go on with this trial.
                    run.link_lost.append(f"{cur['id']}: {cur.get('fault') or cur.get('error')}")
                    log(f"{label}: link lost before the E-stop: {run.link_lost[-1]}")
                    wait_for(
                        "the ARA link back",
                        lambda: bool(robot_state(api, ESTOP_ROBOT).get("connected")),
                        60,
                        0.05,
                    )
                    api.post(f"/executions/{cur['id']}/resume", {"clear_faults": True})
                    return False
                if cur["state"] in TERMINAL_EXEC_STATES:
                    raise BenchError(
                        f"E-stop route {ex['id']} ended {cur['state']} before it was stopped: "
                        f"fault={cur.get('fault')!r} error={cur.get('error')!r}"
                    )
            return False

        try:
            wait_for("the ARA to execute a command", executing, 60, 0.01)
        except RouteFinished:
            run.skipped += 1
            log(f"{label}: execution {ex['id']} finished before it was seen executing")
            if run.skipped > max(MAX_SKIPS, n // 5):
                raise BenchError(
                    f"{run.skipped} E-stop routes finished before the host saw them execute: "
                    "lengthen --estop-route-m or lower --time-scale"
                ) from None
            continue
        time.sleep(rng.uniform(0.0, 0.05))
        tail.new()  # everything before the E-stop is not its evidence
        upload, planning = bool(upload_flag.value), int(plans_flag.value)
        t0 = time.monotonic()
        answer = api.post("/estop", {"reason": f"bench_busy {label} trial {i}"})
        http_ms = (time.monotonic() - t0) * 1e3
        server_ms = dict((answer or {}).get("timings_ms") or {})
        rec: dict[str, Any] | None = None
        if run.method == "emulator log":
            probe = not run.probed
            deadline = time.monotonic() + (3.0 if probe else 30.0)
            seen: list[dict[str, Any]] = []
            while rec is None and time.monotonic() < deadline:
                seen += tail.new()
                rec = estop_stop_record(seen)
                if rec is None:
                    time.sleep(0.002)
            run.probed = True
            if rec is None and probe and not any(r.get("record") for r in seen):
                # The probe found no stop records: this trial measured nothing, drop it.
                run.method = "host sees ESTOP (fallback: the emulator log has no stop records)"
                log(f"no 'record: stop' line in {tail.path}: falling back to {run.method}")
                api.post(f"/robots/{ESTOP_ROBOT}/clear-estop")
                continue
            if rec is None:
                raise BenchError(f"no E-stop stop record in {tail.path} within 30 s")
        if rec is not None:
            latency = (float(rec["t"]) - t0) * 1e3
            moving = bool(rec.get("moving", True))
        else:

            def host_sees() -> float | None:
                rep = robot_state(api, ESTOP_ROBOT).get("report") or {}
                return time.monotonic() if rep.get("mode") == MODE_ESTOP else None

            latency = (wait_for("mode ESTOP in the state report", host_sees, 30, 0.0) - t0) * 1e3
            moving = True
        run.trials.append(Trial(latency, http_ms, moving, upload, planning, ex["id"], server_ms))
        # Clear only once the robot reported its E-stop and the execution stopped:
        # the link service finishes an E-stop's bookkeeping after it has answered, and
        # that bookkeeping latches the link again (Streamer.estop), undoing a clear
        # that overtook it.
        wait_for(
            "the ARA to report ESTOP",
            lambda: (robot_state(api, ESTOP_ROBOT).get("report") or {}).get("mode") == MODE_ESTOP,
            60,
            0.02,
        )
        ex_id = str(ex["id"])

        def ended(ex_id: str = ex_id) -> bool:
            return api.get(f"/executions/{ex_id}")["state"] in TERMINAL_EXEC_STATES

        wait_for(f"E-stopped execution {ex_id} to end", ended, 60, 0.02)
        # An E-stop interrupts the run (resumable); end it, so the next trial's
        # dispatch finds the robot free.
        if api.get(f"/executions/{ex_id}")["state"] == "interrupted":
            api.post(f"/executions/{ex_id}/abort")
        api.post(f"/robots/{ESTOP_ROBOT}/clear-estop")
    log(f"{label}: {n} E-stop trials done" + (f", {run.skipped} skipped" if run.skipped else ""))


# --------------------------------------------------------------- dispatches
def run_dispatches(
    url: str, token: str, jobs: list[tuple[str, str, str]], timeout_s: float
) -> list[dict[str, Any]]:
    """Dispatch each job; one thread per robot runs that robot's jobs one after another."""
    by_robot: dict[str, list[tuple[str, str, str]]] = {}
    for job in jobs:
        by_robot.setdefault(job[1], []).append(job)
    results: list[dict[str, Any]] = []
    lock = threading.Lock()

    def worker(robot: str, mine: list[tuple[str, str, str]]) -> None:
        api = Api(url, token)
        try:
            for kind, _, pid in mine:
                rec: dict[str, Any] = {"kind": kind, "robot": robot, "plan": pid}
                t0 = time.monotonic()
                try:
                    wait_ready(api, robot)
                    ex = api.post(f"/plans/{pid}/dispatch", {"robot": robot}, expect=(201,))
                    rec["execution"] = ex["id"]
                    deadline = time.monotonic() + timeout_s
                    while True:
                        cur = api.get(f"/executions/{ex['id']}")
                        if cur["state"] in TERMINAL_EXEC_STATES:
                            break
                        if time.monotonic() > deadline:
                            cur["state"] = f"still {cur['state']} after {timeout_s:.0f} s"
                            break
                        time.sleep(0.25)
                    rec.update(
                        state=cur["state"],
                        fault=cur.get("fault"),
                        error=cur.get("error"),
                        acked=f"{cur.get('acked')}/{cur.get('total')}",
                    )
                    if cur["state"] not in ("completed", "aborted"):
                        # An unfinished execution (interrupted, faulted, still running)
                        # blocks its robot: end it so the rest can run.
                        with contextlib.suppress(BenchError, httpx.HTTPError):
                            api.post(f"/executions/{ex['id']}/abort")
                except (BenchError, httpx.HTTPError) as exc:
                    rec.update(state="refused", error=str(exc))
                rec["s"] = round(time.monotonic() - t0, 1)
                with lock:
                    results.append(rec)
                log(f"dispatch {kind} on {robot}: {rec['state']} ({rec['s']} s)")
        finally:
            api.close()

    threads = [threading.Thread(target=worker, args=item) for item in by_robot.items()]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return results


# -------------------------------------------------------------------- load
@dataclass
class LoadProc:
    name: str
    proc: Any
    out: Path

    def result(self) -> dict[str, Any]:
        try:
            return dict(json.loads(self.out.read_text()))
        except (OSError, ValueError):
            return {}


@contextlib.contextmanager
def load_processes(
    ctx: Any, specs: list[tuple[str, Callable[..., None], tuple[Any, ...]]], tmp: Path
) -> Iterator[tuple[Any, list[LoadProc]]]:
    """Start one process per spec with a shared stop event; stop and join them on exit."""
    stop = ctx.Event()
    procs = []
    try:
        for name, target, args in specs:
            out = tmp / f"load-{name}-{time.monotonic_ns()}.json"
            p = ctx.Process(target=target, args=(*args, stop, str(out)), name=f"bench-{name}")
            p.start()
            procs.append(LoadProc(name, p, out))
        yield stop, procs
    finally:
        stop.set()
        for lp in procs:
            # The upload may be mid-file: give it the time to finish or be cut off.
            lp.proc.join(120 if lp.name == "upload" else 30)
            if lp.proc.is_alive():
                log(f"load process {lp.name} did not stop: terminating it")
                lp.proc.terminate()
                lp.proc.join(10)
                if lp.proc.is_alive():
                    lp.proc.kill()
                    lp.proc.join(5)


def read_stats(samples: list[list[Any]], t_from: float, t_to: float) -> dict[str, Any]:
    window = [s for s in samples if t_from <= s[0] <= t_to]
    lat = [s[2] for s in window]
    by_label: dict[str, list[float]] = {}
    for s in window:
        by_label.setdefault(s[1], []).append(s[2])
    return {
        "n": len(lat),
        "failed": sum(1 for s in window if s[3] != 200),
        "codes": sorted({s[3] for s in window if s[3] != 200}),
        "p50": percentile(lat, 50),
        "p95": percentile(lat, 95),
        "p99": percentile(lat, 99),
        "max": max(lat, default=math.nan),
        "p95_by": {k: percentile(v, 95) for k, v in sorted(by_label.items())},
    }


# ------------------------------------------------------------------ report
def fmt(v: float) -> str:
    return "—" if v is None or (isinstance(v, float) and math.isnan(v)) else f"{v:.1f}"


def ratio(a: float, b: float) -> str:
    if any(math.isnan(x) for x in (a, b)) or b <= 0:
        return "—"
    return f"{a / b:.1f}×"


def lat_stats(values: list[float]) -> dict[str, float]:
    return {
        "p50": percentile(values, 50),
        "p95": percentile(values, 95),
        "p99": percentile(values, 99),
        "max": max(values, default=math.nan),
    }


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--clients", type=int, default=50, help="concurrent API clients (loaded)")
    ap.add_argument("--upload-mb", type=float, default=250.0, help="size of the cloud upload")
    ap.add_argument("--trials", type=int, default=60, help="E-stop trials under load")
    ap.add_argument("--quiet-trials", type=int, default=None, help="quiet trials (trials/2)")
    ap.add_argument("--dispatches", type=int, default=20, help="dispatches under load")
    ap.add_argument("--planning", type=int, default=4, help="planning jobs kept in flight")
    ap.add_argument("--poll-interval", type=float, default=0.5, help="s between a client's reads")
    ap.add_argument("--quiet-read-s", type=float, default=10.0, help="quiet read phase length")
    ap.add_argument("--time-scale", type=float, default=10.0, help="emulator time scale")
    ap.add_argument(
        "--emulator-nice",
        type=int,
        default=0,
        help="STEELPATH_EMULATOR_NICE: the emulators' priority (0: level with the server)",
    )
    ap.add_argument("--job-workers", type=int, default=2, help="STEELPATH_JOB_WORKERS")
    ap.add_argument("--log-level", default="info", help="server log level")
    ap.add_argument(
        "--extra-plan-max-s",
        type=float,
        default=60.0,
        help="dispatches beyond one per kind go to kinds that plan within this many seconds",
    )
    ap.add_argument(
        "--extra-plan-budget-s",
        type=float,
        default=150.0,
        help="summed planning seconds the extra dispatch plans may take (cheapest kinds first)",
    )
    ap.add_argument(
        "--estop-route-m", type=float, default=30.0, help="length of the E-stop trials' route"
    )
    ap.add_argument(
        "--trial-budget-s", type=float, default=420.0, help="most seconds for the loaded trials"
    )
    ap.add_argument("--dispatch-timeout", type=float, default=300.0, help="s per dispatch")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--json", default=None, help="also write every figure to this JSON file")
    ap.add_argument("--keep", action="store_true", help="keep the temporary directory")
    args = ap.parse_args()
    for name in ("clients", "trials", "dispatches", "planning"):
        if getattr(args, name) < 1:
            ap.error(f"--{name} must be at least 1")
    if args.upload_mb <= 0 or args.poll_interval < 0:
        ap.error("--upload-mb must be positive and --poll-interval non-negative")
    quiet_trials = args.quiet_trials if args.quiet_trials is not None else max(5, args.trials // 2)

    tmp = Path(tempfile.mkdtemp(prefix="bench_busy-"))
    servers: list[Server] = []  # run() puts the server here at once, so finally can stop it
    try:
        return run(args, quiet_trials, tmp, servers)
    except BenchError as exc:
        log(f"benchmark failed: {exc}")
        for srv in servers:
            log(f"server log tail:\n{srv.log_tail()}")
        return 2
    finally:
        for srv in servers:
            stop_server(srv)
        if args.keep:
            log(f"kept {tmp}")
        else:
            shutil.rmtree(tmp, ignore_errors=True)


def run(args: argparse.Namespace, quiet_trials: int, tmp: Path, servers: list[Server]) -> int:
    """Set up, measure quiet, measure loaded, print the report; returns the exit status."""
    rng = random.Random(args.seed)
    ctx = mp.get_context("spawn")
    upload_flag, plans_flag = ctx.Value("i", 0), ctx.Value("i", 0)

    # The cloud is written while the server plans the set-up (neither is measured).
    cloud = tmp / "busy.xyz"
    writer = ctx.Process(
        target=write_xyz, args=(cloud, args.upload_mb), kwargs={"seed": args.seed}, daemon=True
    )
    writer.start()
    try:
        log("starting steelpath serve")
        srv = start_server(tmp, args, servers)
        admin = Api(srv.url, srv.admin_token)
        operator = admin.post("/tokens", {"name": "bench operator", "role": "operator"}, (201,))
        viewer = admin.post("/tokens", {"name": "bench viewer", "role": "viewer"}, (201,))
        admin.close()
        api = Api(srv.url, operator["token"])
        for r in [r["name"] for r in api.get("/robots")]:
            wait_ready(api, r, 120)
        # Spares: the probe trial may be dropped, and a few routes may end unseen.
        n_estop = quiet_trials + args.trials + 1 + MAX_SKIPS
        prep = prepare(
            api,
            args.dispatches,
            n_estop,
            args.extra_plan_max_s,
            args.extra_plan_budget_s,
            args.estop_route_m,
        )
        writer.join(600)
    finally:
        if writer.is_alive():
            writer.terminate()
            writer.join(10)
    if writer.exitcode != 0 or not cloud.exists():
        raise BenchError(f"writing the {args.upload_mb} MiB cloud failed (exit {writer.exitcode})")
    log(f"set-up done; the upload is {cloud.stat().st_size / 2**20:.0f} MiB")
    mix = read_paths(list(prep.template_ids.values()))
    heavy = [k for k in HEAVY_KINDS if k in prep.template_ids] or sorted(prep.template_ids)
    tail = LogTail(srv.data / "emulators" / f"{ESTOP_ROBOT}.log.jsonl")
    tail.new()

    # ---- quiet
    log("quiet: API reads by one client")
    with load_processes(
        ctx, [("reads", read_clients, (srv.url, viewer["token"], 1, mix, 0.05, 0))], tmp
    ) as (_, procs):
        time.sleep(args.quiet_read_s)
    q_reads = procs[0].result().get("samples", [])
    quiet_reads = read_stats(q_reads, -math.inf, math.inf)
    log(f"quiet: {quiet_trials} E-stop trials")
    quiet_run = EstopRun()
    estop_trials(
        api, prep.estop_plans, quiet_trials, tail, quiet_run, rng, upload_flag, plans_flag, "quiet"
    )
    clear_all(api, prep.robots)

    # ---- loaded
    log(
        f"loaded: {args.clients} clients, {args.planning} planning jobs of {heavy}, "
        f"{args.upload_mb:.0f} MiB upload loop"
    )
    sampler = RssSampler(srv.proc.pid, upload_flag)
    sampler.start()
    specs: list[tuple[str, Callable[..., None], tuple[Any, ...]]] = [
        ("upload", upload_load, (srv.url, operator["token"], str(cloud), upload_flag)),
        (
            "planning",
            planning_load,
            (srv.url, operator["token"], heavy, args.planning, plans_flag),
        ),
    ]
    # The clients are spread over processes of at most CLIENTS_PER_PROCESS each:
    # 50 pollers on one httpx event loop measured that loop, not the server
    # (a separate probe saw /robots p95 31 ms while the single loader reported
    # 937 ms, with the server at 27 % of a core).
    for k, first in enumerate(range(0, args.clients, CLIENTS_PER_PROCESS)):
        n = min(CLIENTS_PER_PROCESS, args.clients - first)
        specs.append(
            (
                f"reads-{k}",
                read_clients,
                (srv.url, viewer["token"], n, mix, args.poll_interval, first),
            )
        )
    loaded_run = EstopRun(method=quiet_run.method, probed=True)
    with load_processes(ctx, specs, tmp) as (_, procs):
        wait_for(
            "the upload and the planning jobs to be in flight",
            lambda: upload_flag.value and plans_flag.value >= args.planning,
            180,
            0.1,
        )
        time.sleep(3.0)  # let the upload's body start flowing and the clients settle
        t_loaded = time.monotonic()
        log(f"loaded: {args.trials} E-stop trials")
        estop_trials(
            api,
            prep.estop_plans,
            args.trials,
            tail,
            loaded_run,
            rng,
            upload_flag,
            plans_flag,
            "loaded",
            args.trial_budget_s,
        )
        clear_all(api, prep.robots)
        log(f"loaded: {len(prep.dispatch_jobs)} dispatches")
        t_dispatch = time.monotonic()
        dispatches = run_dispatches(
            srv.url, operator["token"], prep.dispatch_jobs, args.dispatch_timeout
        )
        t_end = time.monotonic()
        hwm = vm_hwm_mb(srv.proc.pid)
    sampler.halt.set()
    sampler.join(5)
    results = {lp.name: lp.result() for lp in procs}
    ex_state = {e["id"]: e["state"] for e in all_executions(api)}
    trial_states: dict[str, int] = {}
    for t in quiet_run.trials + loaded_run.trials:
        st = ex_state.get(t.execution, "missing")
        trial_states[st] = trial_states.get(st, 0) + 1
    results["estop_executions"] = trial_states
    read_samples = [
        s for name, r in results.items() if name.startswith("reads-") for s in r.get("samples", [])
    ]
    loaded_reads = read_stats(read_samples, t_loaded, t_end)
    loaded_reads["by_phase"] = {
        "E-stop trials": read_stats(read_samples, t_loaded, t_dispatch),
        "dispatches": read_stats(read_samples, t_dispatch, t_end),
    }
    loaded_reads["errors"] = [
        e for name, r in results.items() if name.startswith("reads-") for e in r.get("errors", [])
    ]
    api.close()

    return report(
        args,
        prep,
        quiet_run,
        loaded_run,
        quiet_reads,
        loaded_reads,
        dispatches,
        results,
        sampler,
        hwm,
        cloud.stat().st_size,
        t_end - t_loaded,
    )


def report(
    args: argparse.Namespace,
    prep: Prepared,
    quiet_run: EstopRun,
    loaded_run: EstopRun,
    quiet_reads: dict[str, Any],
    loaded_reads: dict[str, Any],
    dispatches: list[dict[str, Any]],
    results: dict[str, dict[str, Any]],
    sampler: RssSampler,
    hwm_mb: float,
    cloud_bytes: int,
    loaded_s: float,
) -> int:
    q = lat_stats([t.latency_ms for t in quiet_run.trials])
    lo = lat_stats([t.latency_ms for t in loaded_run.trials])
    qh = lat_stats([t.http_ms for t in quiet_run.trials])
    lh = lat_stats([t.http_ms for t in loaded_run.trials])
    uploads = results.get("upload", {}).get("uploads", [])
    planning = results.get("planning", {})
    n_up = sum(1 for t in loaded_run.trials if t.upload_in_flight)
    n_pl = sum(1 for t in loaded_run.trials if t.plans_in_flight >= args.planning)
    not_moving = sum(1 for t in quiet_run.trials + loaded_run.trials if not t.moving)

    print()
    print(
        f"bench_busy — loaded: {args.clients} clients (a read each {args.poll_interval} s), "
        f"{args.planning} planning jobs ({args.job_workers} workers), "
        f"{cloud_bytes / 2**20:.0f} MiB XYZ upload loop; emulator time scale {args.time_scale}, "
        f"nice {args.emulator_nice}"
    )
    print(f"E-stop measured as: {loaded_run.method}")
    if loaded_run.cut_short is not None:
        print(
            f"NOTE: only {loaded_run.cut_short} of {args.trials} loaded E-stop trials fit in "
            f"--trial-budget-s {args.trial_budget_s:.0f}"
        )
    print()
    print(f"{'ms':38} {'p50':>8} {'p95':>8} {'p99':>8} {'max':>8}")
    rows = [
        (f"E-stop → motion stop, quiet (n={len(quiet_run.trials)})", q),
        (f"E-stop → motion stop, loaded (n={len(loaded_run.trials)})", lo),
        ("  ratio loaded/quiet", None),
        ("POST /estop response, quiet", qh),
        ("POST /estop response, loaded", lh),
        (f"API reads, quiet (1 client, n={quiet_reads['n']})", quiet_reads),
        (f"API reads, loaded (n={loaded_reads['n']})", loaded_reads),
        ("  ratio loaded/quiet", None),
    ]
    prev: list[dict[str, Any]] = []
    for name, st in rows:
        if st is None:
            a, b = prev[-1], prev[-2]
            cells = [ratio(a[k], b[k]) for k in ("p50", "p95", "p99", "max")]
        else:
            prev.append(st)
            cells = [fmt(st[k]) for k in ("p50", "p95", "p99", "max")]
        print(f"{name:38} {cells[0]:>8} {cells[1]:>8} {cells[2]:>8} {cells[3]:>8}")
    for name, reads in (("quiet", quiet_reads), ("loaded", loaded_reads)):
        print(
            f"{name} read p95 by route (ms): "
            + ", ".join(f"{k} {fmt(v)}" for k, v in reads["p95_by"].items())
        )
    print(
        "loaded read p50/p95 by phase (ms): "
        + ", ".join(
            f"{k} {fmt(v['p50'])}/{fmt(v['p95'])} (n={v['n']})"
            for k, v in loaded_reads.get("by_phase", {}).items()
        )
    )
    print(
        f"loaded E-stop trials with the upload in flight: {n_up}/{len(loaded_run.trials)}, "
        f"with {args.planning} plans in flight: {n_pl}/{len(loaded_run.trials)}"
        + (f"; trials where the robot was not moving: {not_moving}" if not_moving else "")
    )
    print(
        "E-stop trial executions: "
        + ", ".join(f"{v} {k}" for k, v in sorted(results["estop_executions"].items()))
        + (
            f"; routes skipped (done before seen moving): {quiet_run.skipped + loaded_run.skipped}"
            if quiet_run.skipped + loaded_run.skipped
            else ""
        )
    )
    states: dict[str, int] = {}
    for d in dispatches:
        states[d["state"]] = states.get(d["state"], 0) + 1
    per_kind: dict[str, list[str]] = {}
    for d in dispatches:
        per_kind.setdefault(d["kind"], []).append(d["state"])
    print(
        f"dispatches under load: {len(dispatches)} over {sorted(per_kind)} — "
        + ", ".join(f"{v} {k}" for k, v in sorted(states.items()))
    )
    for d in dispatches:
        if d["state"] != "completed":
            print(
                f"  {d['kind']} on {d['robot']}: {d['state']} acked {d.get('acked')} "
                f"fault={d.get('fault')!r} error={d.get('error')!r}"
            )
    print(
        "dispatches per kind (default plan's planning s): "
        + ", ".join(f"{k} {len(v)} ({prep.plan_s[k]})" for k, v in sorted(per_kind.items()))
    )
    if prep.not_dispatchable:
        print(f"kinds not dispatched: {prep.not_dispatchable}")
    up_ok = [u for u in uploads if u.get("status") in (200, 201)]
    up_bad = [u for u in uploads if u.get("status") not in (200, 201)]
    up_s = [u["s"] for u in up_ok]
    print(
        f"uploads: {len(up_ok)} stored"
        + (f" (median {statistics.median(up_s):.0f} s each)" if up_s else "")
        + (f", {len(up_bad)} failed: {up_bad[:2]}" if up_bad else "")
        + f"; plans finished by the planning load: {len(planning.get('finished', []))}"
        + (f", errors: {planning['errors'][:2]}" if planning.get("errors") else "")
        + f"; loaded phase {loaded_s:.0f} s"
    )
    mem_bound = 2 * cloud_bytes / 2**20 + 200
    print(
        f"server memory: main process VmHWM {fmt(hwm_mb)} MiB; largest single process while "
        f"uploading {fmt(sampler.peak_single_upload[0])} MiB ({sampler.peak_single_upload[1]}); "
        f"process-tree peak {fmt(sampler.peak_tree_mb)} MiB "
        f"(info: issue bound for the upload 2×file+200 = {mem_bound:.0f} MiB)"
    )

    lost = quiet_run.link_lost + loaded_run.link_lost
    if lost:
        print(f"E-stop routes interrupted by a lost link before their E-stop: {len(lost)}")
        for why in lost:
            print(f"  {why}")
    targets = [
        ("no link lost during the E-stop trials", not lost),
        (f"E-stop p95 < {ESTOP_P95_MS:.0f} ms", lo["p95"] < ESTOP_P95_MS),
        (f"E-stop p99 < {ESTOP_P99_MS:.0f} ms", lo["p99"] < ESTOP_P99_MS),
        (f"API reads p95 < {READ_P95_MS:.0f} ms", loaded_reads["p95"] < READ_P95_MS),
        (
            "no failed API read",
            loaded_reads["failed"] == 0,
        ),
        (
            f"{len(dispatches)}/{len(prep.dispatch_jobs)} dispatches completed, 0 interrupted",
            len(dispatches) == len(prep.dispatch_jobs)
            and all(d["state"] == "completed" for d in dispatches),
        ),
    ]
    load_ok = bool(up_ok) and not up_bad and n_up > 0
    if args.json:
        Path(args.json).write_text(
            json.dumps(
                {
                    "estop_ms": {"quiet": q, "loaded": lo, "method": loaded_run.method},
                    "estop_http_ms": {"quiet": qh, "loaded": lh},
                    "reads_ms": {"quiet": quiet_reads, "loaded": loaded_reads},
                    "dispatches": dispatches,
                    "uploads": uploads,
                    "planning_finished": planning.get("finished", []),
                    "memory_mb": {
                        "main_vmhwm": hwm_mb,
                        "largest_while_uploading": sampler.peak_single_upload[0],
                        "tree_peak": sampler.peak_tree_mb,
                    },
                    "targets": {name: ok for name, ok in targets},
                    "load_applied": load_ok,
                },
                indent=1,
                default=str,
            ),
            encoding="utf-8",
        )
    print()
    for name, ok in targets:
        print(f"  {'met   ' if ok else 'MISSED'}  {name}")
    if loaded_reads["failed"]:
        print(f"          failed reads: {loaded_reads['failed']} (codes {loaded_reads['codes']})")
        for err in loaded_reads.get("errors", [])[:5]:
            print(f"            {err}")
    if not load_ok:
        print("  MISSED  the load was not applied as asked (see uploads above)")
    return 0 if all(ok for _, ok in targets) and load_ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
