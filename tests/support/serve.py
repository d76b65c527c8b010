"""A real ``steelpath serve`` process (``python -m server.cli serve``) for tests and
benchmarks that need several servers, or a server to kill."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import httpx

from server.linkservice.emulators import EmulatorProcess
from tests.support.live import free_port
from tests.support.waiting import wait_for

ROOT = Path(__file__).resolve().parents[2]


class ServeProcess:
    """One server on ``data``; ``env`` adds ``STEELPATH_*`` settings."""

    def __init__(self, data: Path, name: str, token: str | None = None, **env: str) -> None:
        self.data = data
        self.name = name
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        token_file = data.parent / "admin.token"
        full_env = {
            **os.environ,
            "STEELPATH_DATA": str(data),
            "STEELPATH_PORT": str(self.port),
            "STEELPATH_SCENE_PORT": "0",
            "STEELPATH_TOKEN_FILE": str(token_file),
            "STEELPATH_LOG_LEVEL": "warning",
            "STEELPATH_JOB_MODE": "thread",
            "PYTHONPATH": str(ROOT),
            **{f"STEELPATH_{k.upper()}": v for k, v in env.items()},
        }
        self.log = open(data.parent / f"server-{name}.log", "wb")  # noqa: SIM115
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "server.cli", "serve"],
            env=full_env,
            stdout=self.log,
            stderr=subprocess.STDOUT,
            cwd=str(data.parent),
        )
        deadline = time.monotonic() + 90
        while True:
            with contextlib.suppress(httpx.HTTPError):
                if httpx.get(f"{self.url}/api/v1/health", timeout=2).status_code == 200:
                    break
            if self.proc.poll() is not None or time.monotonic() > deadline:
                raise AssertionError(f"server {name} did not start: {self.tail()}")
            time.sleep(0.1)
        self.token = token or token_file.read_text().strip().splitlines()[-1]
        self.http = httpx.Client(
            base_url=f"{self.url}/api/v1",
            headers={"Authorization": f"Bearer {self.token}"},
            timeout=60,
        )

    def tail(self) -> str:
        self.log.flush()
        return Path(self.log.name).read_text(errors="replace")[-3000:]

    def get(self, path: str) -> Any:
        r = self.http.get(path)
        assert r.status_code == 200, (self.name, path, r.status_code, r.text)
        return r.json()

    def post(self, path: str, body: dict[str, Any] | None = None, status: int = 200) -> Any:
        r = self.http.post(path, json=body or {})
        assert r.status_code == status, (self.name, path, r.status_code, r.text)
        return r.json()

    def robots(self) -> dict[str, dict[str, Any]]:
        return {r["name"]: r for r in self.get("/robots")}

    def kill9(self) -> None:
        self.proc.send_signal(signal.SIGKILL)
        self.proc.wait(timeout=10)
        self.http.close()

    def stop(self) -> None:
        if self.proc.poll() is None:
            self.proc.send_signal(signal.SIGTERM)
            try:
                self.proc.wait(timeout=20)
            except subprocess.TimeoutExpired:
                self.proc.kill()
                self.proc.wait()
        self.http.close()
        self.log.close()


def emulator(data: Path, robot: str) -> EmulatorProcess:
    """The evidence (log, state) of an embedded emulator that a server under ``data`` started."""
    d = data / "emulators"
    return EmulatorProcess(robot, "", 0, d / f"{robot}.log.jsonl", d / f"{robot}.state.json", False)


def stop_emulators(data: Path) -> None:
    """Stop emulator processes a test left (they run in sessions of their own)."""
    for port_file in (data / "emulators").glob("*.port.json"):
        with contextlib.suppress(Exception):
            os.kill(int(json.loads(port_file.read_text())["pid"]), signal.SIGTERM)


def planned(
    server: ServeProcess, kind: str, params: dict[str, Any] | None = None
) -> dict[str, Any]:
    """Submit a plan on ``server`` and wait until it is planned and approved."""
    plan = server.post("/plans", {"kind": kind, "params": params or {}}, status=202)
    plan = wait_for(
        lambda: (
            (p := server.get(f"/plans/{plan['id']}"))["state"] not in ("queued", "planning") and p
        ),
        120,
        "planned",
    )
    assert plan["state"] == "planned", plan.get("error")
    server.post(f"/plans/{plan['id']}/approve")
    return plan
