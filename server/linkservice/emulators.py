"""Built-in robot emulators as processes of their own, like real robots.

A real robot does not die with the server that commands it, and it still
knows its pose, odometry, joints and last completed command when the server
comes back.  So ``steelpath serve`` runs each built-in emulator as a separate
process (``python -m robots.emulator``, its own session so a terminal's
Ctrl-C or a ``kill -9`` of the server does not reach it) with:

- ``--state-file``: where it keeps its state at rest (survives its own restart);
- ``--port-file``: where it says which port it listens on, so a restarted
  server finds and reuses a running emulator instead of starting a second;
- ``--secret-file``: the per-robot link secret (the same file the link service
  reads), so only this server can command it;
- ``--log-jsonl``: its execution log, the evidence tests read;
- ``--exit-when-orphaned``: an emulator left behind by a killed server exits
  after that long without a controller;
- ``--world`` (ARA's, once its emulator takes the option): the scan its
  simulated camera sees, ``<robot>.world.npz``, which the dispatch engine
  rewrites from each plan it dispatches to the emulator
  (:mod:`server.captures.world`) and the emulator reloads when it changes.

All of it lives under ``<data>/emulators/``.
"""

from __future__ import annotations

import contextlib
import json
import logging
import os
import signal
import socket
import subprocess
import sys
import time
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Any

import numpy as np

from robots.emulator.persist import pid_alive
from server.captures.world import WORLD_ROBOTS, world_path, write_world
from server.linkservice.service import robot_key_path

log = logging.getLogger(__name__)

ORPHAN_EXIT_S = 600.0


@dataclass
class EmulatorProcess:
    """One emulator process: where it listens and where its evidence is."""

    robot: str
    url: str
    pid: int
    log_path: Path
    state_path: Path
    started_here: bool

    def alive(self) -> bool:
        return pid_alive(self.pid)

    def execution_log(self) -> list[Any]:
        """The emulator's own execution log (``robots.emulator.robot.ExecutionRecord``s)."""
        from robots.emulator.robot import ExecutionRecord

        out: list[ExecutionRecord] = []
        if not self.log_path.exists():
            return out
        fields = set(ExecutionRecord.__dataclass_fields__)
        for line in self.log_path.read_text(encoding="utf-8").splitlines():
            if not line.strip():
                continue
            rec = json.loads(line)
            if rec.get("record", "command") != "command":
                continue
            out.append(ExecutionRecord(**{k: v for k, v in rec.items() if k in fields}))
        return out

    def stop_events(self) -> list[dict[str, Any]]:
        """Every time the robot stopped (``t`` is its ``time.monotonic()``), oldest first."""
        return [r for r in self.log_lines() if r.get("record") == "stop"]

    def log_lines(self) -> list[dict[str, Any]]:
        if not self.log_path.exists():
            return []
        return [
            json.loads(line)
            for line in self.log_path.read_text(encoding="utf-8").splitlines()
            if line.strip()
        ]

    def state(self) -> dict[str, Any] | None:
        """The state the emulator last saved at rest (pose, odometry, joints…)."""
        try:
            return dict(json.loads(self.state_path.read_text(encoding="utf-8")))
        except (OSError, ValueError):
            return None


@lru_cache(maxsize=1)
def emulator_takes_world() -> bool:
    """Whether ``python -m robots.emulator`` accepts ``--world`` (an emulator
    without it would refuse to start when given one)."""
    try:
        from robots.emulator.cli import build_parser

        return "--world" in build_parser()._option_string_actions
    except Exception:
        return False


def _answers(url: str) -> bool:
    host, _, port = url.removeprefix("socket://").rpartition(":")
    try:
        with socket.create_connection((host, int(port)), timeout=0.5):
            return True
    except (OSError, ValueError):
        return False


class EmulatorSupervisor:
    """Finds or starts one emulator process per robot under ``<data>/emulators``."""

    def __init__(
        self, data: Path, robots: list[str], *, time_scale: float = 1.0, nice: int = 0
    ) -> None:
        self.dir = Path(data) / "emulators"
        self.robots = list(robots)
        self.time_scale = time_scale
        self.nice = nice
        self.procs: dict[str, EmulatorProcess] = {}
        self._popen: dict[str, subprocess.Popen[bytes]] = {}

    def urls(self) -> dict[str, str]:
        return {name: p.url for name, p in self.procs.items()}

    def __getitem__(self, robot: str) -> EmulatorProcess:
        return self.procs[robot]

    def start(self, timeout: float = 30.0) -> EmulatorSupervisor:
        self.dir.mkdir(parents=True, exist_ok=True)
        os.chmod(self.dir, 0o700)
        starting: list[str] = []
        for name in self.robots:
            found = self._reuse(name)
            if found is not None:
                log.info("reusing emulator %s (pid %d) at %s", name, found.pid, found.url)
                self.procs[name] = found
            else:
                self._spawn(name)
                starting.append(name)
        deadline = time.monotonic() + timeout
        for name in starting:
            self.procs[name] = self._wait_port_file(name, deadline)
        return self

    def _paths(self, name: str) -> dict[str, Path]:
        return {
            "port": self.dir / f"{name}.port.json",
            "state": self.dir / f"{name}.state.json",
            "log": self.dir / f"{name}.log.jsonl",
            "world": world_path(self.dir.parent, name),
        }

    def _reuse(self, name: str) -> EmulatorProcess | None:
        paths = self._paths(name)
        try:
            info = json.loads(paths["port"].read_text(encoding="utf-8"))
        except (OSError, ValueError):
            return None
        pid, url = int(info.get("pid", 0)), str(info.get("url", ""))
        if pid <= 0 or not pid_alive(pid) or not _answers(url):
            with contextlib.suppress(OSError):
                paths["port"].unlink()
            return None
        return EmulatorProcess(name, url, pid, paths["log"], paths["state"], started_here=False)

    def _spawn(self, name: str) -> None:
        paths = self._paths(name)
        with contextlib.suppress(OSError):
            paths["port"].unlink()
        key = robot_key_path(self.dir.parent, name)
        from robots.protocol.auth import load_or_create_secret

        load_or_create_secret(key)  # the emulator and the link service read the same file
        cmd = [
            sys.executable,
            "-m",
            "robots.emulator",
            "--robot",
            name,
            "--listen",
            "tcp://127.0.0.1:0",
            "--time-scale",
            repr(self.time_scale),
            "--nice",
            str(self.nice),
            "--secret-file",
            str(key),
            "--state-file",
            str(paths["state"]),
            "--port-file",
            str(paths["port"]),
            "--log-jsonl",
            str(paths["log"]),
            "--exit-when-orphaned",
            repr(ORPHAN_EXIT_S),
        ]
        if name in WORLD_ROBOTS and emulator_takes_world():
            if not paths["world"].exists():  # no plan dispatched yet: nothing to see
                write_world(paths["world"], np.zeros((0, 3), np.float32))
            cmd += ["--world", str(paths["world"])]
        root = str(Path(__file__).resolve().parents[2])
        env = {
            **os.environ,
            "PYTHONPATH": os.pathsep.join(filter(None, [root, os.environ.get("PYTHONPATH")])),
        }
        errlog = open(self.dir / f"{name}.stderr.log", "ab")  # noqa: SIM115 - child keeps it
        self._popen[name] = subprocess.Popen(
            cmd,
            stdin=subprocess.DEVNULL,
            stdout=subprocess.DEVNULL,
            stderr=errlog,
            env=env,
            start_new_session=True,
            close_fds=True,
        )
        errlog.close()

    def _wait_port_file(self, name: str, deadline: float) -> EmulatorProcess:
        paths = self._paths(name)
        proc = self._popen[name]
        while True:
            with contextlib.suppress(OSError, ValueError):
                info = json.loads(paths["port"].read_text(encoding="utf-8"))
                if int(info.get("pid", 0)) == proc.pid:
                    return EmulatorProcess(
                        name, str(info["url"]), proc.pid, paths["log"], paths["state"], True
                    )
            if proc.poll() is not None:
                err = (self.dir / f"{name}.stderr.log").read_text(errors="replace")[-2000:]
                raise RuntimeError(f"emulator {name} exited with {proc.returncode}: {err}")
            if time.monotonic() > deadline:
                proc.kill()
                raise RuntimeError(f"emulator {name} did not report its port in time")
            time.sleep(0.05)

    def stop(self, timeout: float = 5.0) -> None:
        """Stop the emulators (they save their state at rest first)."""
        for p in self.procs.values():
            with contextlib.suppress(ProcessLookupError):
                os.kill(p.pid, signal.SIGTERM)
        deadline = time.monotonic() + timeout
        for name, p in self.procs.items():
            popen = self._popen.get(name)
            while pid_alive(p.pid) and time.monotonic() < deadline:
                if popen is not None and popen.poll() is not None:
                    break
                time.sleep(0.05)
            if pid_alive(p.pid):
                with contextlib.suppress(ProcessLookupError):
                    os.kill(p.pid, signal.SIGKILL)
            if popen is not None:
                with contextlib.suppress(Exception):
                    popen.wait(timeout=1)
