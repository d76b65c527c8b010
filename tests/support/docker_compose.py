"""Driving ``docker/compose.yml`` on a real daemon from a test, and the API it serves.

:class:`Compose` runs one compose project of its own (a unique project name,
free host ports, the test's image tag), and :meth:`Compose.down` removes its
containers, networks and volumes.  ``docker compose`` (v2) is used where the
client has it, else ``docker-compose`` (v1.28+, Debian bookworm's).  :class:`Api`
is a small HTTP client of the REST API with the admin token.
"""

from __future__ import annotations

import shutil
import subprocess
import time
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import httpx

from tests.support.docker_standins import docker_env
from tests.support.waiting import wait_for

ROOT = Path(__file__).resolve().parents[2]
COMPOSE_FILE = ROOT / "docker" / "compose.yml"


def compose_command() -> list[str]:
    r = subprocess.run(["docker", "compose", "version"], capture_output=True, timeout=30)
    if r.returncode == 0:
        return ["docker", "compose"]
    v1 = shutil.which("docker-compose")
    if v1 is None:
        raise RuntimeError("neither 'docker compose' nor 'docker-compose' is installed")
    return [v1]


@dataclass
class Compose:
    """One compose project: ``compose(args…)`` runs a compose command in it."""

    project: str
    env: dict[str, str]
    profile: str | None = None
    cmd: list[str] = field(default_factory=compose_command)

    def __call__(
        self, *args: str, timeout: float = 600, check: bool = True
    ) -> subprocess.CompletedProcess[str]:
        argv = [*self.cmd, "-p", self.project, "-f", str(COMPOSE_FILE)]
        if self.profile:
            argv += ["--profile", self.profile]
        r = subprocess.run(
            [*argv, *args],
            capture_output=True,
            text=True,
            timeout=timeout,
            env={**docker_env(), **self.env},
            cwd=ROOT,
        )
        if check and r.returncode != 0:
            raise AssertionError(
                f"compose {' '.join(args)} exited {r.returncode}:\n{r.stdout[-3000:]}\n"
                f"{r.stderr[-3000:]}\n--- logs\n{self.logs()}"
            )
        return r

    def container(self, service: str) -> str:
        cid = self("ps", "-q", service).stdout.strip()
        assert cid, f"no container for {service}"
        return cid.splitlines()[0]

    def inspect(self, service: str, fmt: str) -> str:
        r = subprocess.run(
            ["docker", "inspect", "--format", fmt, self.container(service)],
            capture_output=True,
            text=True,
            timeout=60,
        )
        return r.stdout.strip()

    def health(self, service: str) -> str:
        return self.inspect(
            service, "{{if .State.Health}}{{.State.Health.Status}}{{else}}{{.State.Status}}{{end}}"
        )

    def wait_healthy(self, services: Iterable[str], timeout: float = 240) -> float:
        """Seconds until every service's health check passes; fails on one that exits."""
        t0 = time.monotonic()
        pending = list(services)
        while pending:
            states = {s: self.health(s) for s in pending}
            bad = {s: h for s, h in states.items() if h in ("exited", "dead", "unhealthy")}
            assert not bad, f"services not healthy: {bad}\n{self.logs()}"
            pending = [s for s, h in states.items() if h != "healthy"]
            if pending and time.monotonic() - t0 > timeout:
                raise AssertionError(f"not healthy after {timeout} s: {states}\n{self.logs()}")
            if pending:
                time.sleep(0.5)
        return time.monotonic() - t0

    def read(self, service: str, path: str) -> str:
        return self("exec", "-T", service, "cat", path).stdout

    def logs(self, tail: int = 40) -> str:
        try:
            argv = [*self.cmd, "-p", self.project, "-f", str(COMPOSE_FILE)]
            if self.profile:
                argv += ["--profile", self.profile]
            r = subprocess.run(
                [*argv, "logs", "--no-color", "--tail", str(tail)],
                capture_output=True,
                text=True,
                timeout=60,
                env={**docker_env(), **self.env},
            )
            return r.stdout[-8000:]
        except Exception as e:  # the logs are a diagnosis; their failure must not hide the cause
            return f"(logs unavailable: {e})"

    def down(self) -> None:
        self("down", "-v", "--remove-orphans", "--timeout", "10", check=False, timeout=300)


class Api:
    """The REST API at ``url`` with a bearer token."""

    def __init__(self, url: str, token: str) -> None:
        self.url = url
        self.http = httpx.Client(
            base_url=url + "/api/v1", headers={"Authorization": f"Bearer {token}"}, timeout=30
        )

    def get(self, path: str) -> Any:
        r = self.http.get(path)
        assert r.status_code == 200, f"GET {path}: {r.status_code} {r.text[:500]}"
        return r.json()

    def post(self, path: str, body: dict[str, Any] | None = None, status: int = 200) -> Any:
        r = self.http.post(path, json=body or {})
        assert r.status_code == status, f"POST {path}: {r.status_code} {r.text[:500]}"
        return r.json()

    def planned(self, kind: str, timeout: float = 180) -> dict[str, Any]:
        """Submit a plan with its default params, wait until planned, approve it."""
        plan = self.post("/plans", {"kind": kind, "params": {}}, status=202)
        plan = wait_for(
            lambda: (
                (p := self.get(f"/plans/{plan['id']}"))["state"] not in ("queued", "planning") and p
            ),
            timeout,
            f"{kind} planned",
            poll_s=0.5,
        )
        assert plan["state"] == "planned", plan.get("error")
        self.post(f"/plans/{plan['id']}/approve")
        return plan

    def finished(self, execution_id: str, timeout: float = 300) -> dict[str, Any]:
        return wait_for(
            lambda: (
                (e := self.get(f"/executions/{execution_id}"))["state"]
                in ("completed", "aborted", "faulted", "interrupted")
                and e
            ),
            timeout,
            f"execution {execution_id} to finish",
            poll_s=0.5,
        )

    def close(self) -> None:
        self.http.close()
