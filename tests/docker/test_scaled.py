"""The scaled deployment on a real Docker daemon: ``--profile scaled up -d proxy``.

PostgreSQL, a Dask scheduler and two workers, one emulator container per
robot, two API servers and Caddy, each container healthy.  Through the proxy:
plans run on the Dask workers, a run completes on the emulator container with
every command once, the E-stop latches every robot, and when the API server
that drives the robot is killed (``docker kill``) mid-run, the other takes the
robot over and the run resumes to completion with every command once — the
promises of ``docs/scaling.md``, measured in containers.  Without a database
password the stack does not start, and says why.
"""

from __future__ import annotations

import secrets
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from robots import ROBOT_NAMES
from robots.emulator.robot import check_exactly_once
from server.linkservice.emulators import EmulatorProcess
from tests.docker.conftest import Image
from tests.support.docker_compose import Api, Compose
from tests.support.live import free_port
from tests.support.waiting import wait_for

# The first test's set-up builds the image (on a fresh machine: bases, ~3 min).
pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]

SERVICES = [
    "postgres",
    "dask-scheduler",
    "dask-worker-1",
    "dask-worker-2",
    "robot-ara",
    "robot-cmbot",
    "robot-denso",
    "robot-sbg",
    "api-1",
    "api-2",
    "proxy",
]
LEASE_S = 3.0  # the default robot_lease_s


class Scaled:
    def __init__(self, compose: Compose, api: Api, healthy_s: float) -> None:
        self.compose = compose
        self.api = api
        self.healthy_s = healthy_s

    def sql(self, query: str) -> list[list[str]]:
        out = self.compose(
            "exec", "-T", "postgres", "psql", "-U", "steelpath", "-d", "steelpath", "-At",
            "-F", "\t", "-c", query,
        ).stdout  # fmt: skip
        return [line.split("\t") for line in out.splitlines() if line]

    def server_urls(self) -> dict[str, str]:
        return {sid: url for sid, url in self.sql("SELECT id, url FROM servers")}

    def emulator(self, service: str, robot: str, tmp: Path) -> EmulatorProcess:
        log = tmp / f"{robot}.log.jsonl"
        log.write_text(self.compose.read(service, f"/data/robots/{robot}.log.jsonl"))
        return EmulatorProcess(robot, "", 0, log, tmp / "none.json", False)


@pytest.fixture(scope="module")
def scaled(docker_image: Image) -> Iterator[Scaled]:
    port = free_port()
    compose = Compose(
        f"spscaled{secrets.token_hex(4)}",
        {
            "STEELPATH_IMAGE": docker_image.tag,
            "STEELPATH_PROXY_PORT": str(port),
            "POSTGRES_PASSWORD": secrets.token_hex(16),
            "STEELPATH_EMULATOR_TIME_SCALE": "4",
        },
        profile="scaled",
    )
    try:
        t0 = time.monotonic()
        compose("up", "-d", "proxy")
        healthy_s = (time.monotonic() - t0) + compose.wait_healthy(SERVICES, timeout=240)
        print(f"\nscaled: up -> all {len(SERVICES)} healthy in {healthy_s:.1f} s")
        token = compose.read("api-1", "/data/admin.token").strip()
        api = Api(f"http://127.0.0.1:{port}", token)
        try:
            yield Scaled(compose, api, healthy_s)
        finally:
            api.close()
    finally:
        compose.down()


def test_no_database_password_no_start(docker_image: Image) -> None:
    compose = Compose(
        f"spnopw{secrets.token_hex(4)}",
        {"STEELPATH_IMAGE": docker_image.tag, "POSTGRES_PASSWORD": ""},
        profile="scaled",
    )
    try:
        compose("up", "-d", "postgres")
        # It exits at once, and its restart policy brings it back to exit again.
        wait_for(
            lambda: compose.inspect("postgres", "{{.RestartCount}}") not in ("", "0"),
            60,
            "postgres to refuse to start",
            poll_s=0.5,
        )
        assert compose.inspect("postgres", "{{.State.ExitCode}}") != "0"
        assert compose.health("postgres") != "healthy"
        logs = compose("logs", "--no-color", "postgres").stdout
        assert "POSTGRES_PASSWORD" in logs, logs
    finally:
        compose.down()


def test_every_service_is_healthy_and_api_1_drives_the_robots(scaled: Scaled) -> None:
    for service in SERVICES:
        assert scaled.compose.health(service) == "healthy", service
    assert scaled.api.get("/health")["jobs"]["mode"] == "dask"
    urls = scaled.server_urls()
    assert sorted(urls.values()) == ["http://api-1:8000", "http://api-2:8000"], urls
    robots = wait_for(
        lambda: (
            (rs := {r["name"]: r for r in scaled.api.get("/robots")})
            and all(r["owner"] for r in rs.values())
            and rs
        ),
        60,
        "every robot owned",
        poll_s=0.5,
    )
    assert set(robots) == set(ROBOT_NAMES)
    assert {urls[r["owner"]] for r in robots.values()} == {"http://api-1:8000"}
    # The robot keys on the shared volume: the service's user's alone.
    for robot in ROBOT_NAMES:
        stat = scaled.compose(
            "exec", "-T", "api-1", "stat", "-c", "%a %u", f"/data/robots/{robot}.key"
        )
        assert stat.stdout.split() == ["600", "10001"], (robot, stat.stdout)


def _worker_addresses(compose: Compose) -> set[str]:
    ips = set()
    for w in ("dask-worker-1", "dask-worker-2"):
        ips |= set(
            compose.inspect(w, "{{range .NetworkSettings.Networks}}{{.IPAddress}} {{end}}").split()
        )
    return ips


def _picked_by(api: Api, plan_id: str) -> str:
    audit = api.get(f"/audit?entity=plan&entity_id={plan_id}&limit=50")
    picked = [e["reason"] for e in audit if "picked it up" in str(e.get("reason"))]
    assert picked, audit
    return picked[0]


def test_plans_run_on_the_dask_workers_and_a_run_completes(scaled: Scaled, tmp_path: Path) -> None:
    api = scaled.api
    workers = _worker_addresses(scaled.compose)
    route = api.planned("demo.route")
    blast = api.planned("blast")
    assert blast["program_length"] > 100, blast["program_length"]
    for plan in (route, blast):
        picked = _picked_by(api, plan["id"])
        assert any(f"tcp://{ip}:" in picked for ip in workers), (picked, workers)
    # Both at once: the ARA's route on robot-ara, the blast job on robot-denso.
    runs = {
        ("robot-ara", "ara"): api.post(f"/plans/{route['id']}/dispatch", {"robot": "ara"}, 201),
        ("robot-denso", "denso_vm6083"): api.post(
            f"/plans/{blast['id']}/dispatch", {"robot": "denso_vm6083"}, 201
        ),
    }
    for (service, robot), ex in runs.items():
        done = api.finished(ex["id"], timeout=600)
        assert done["state"] == "completed", done
        assert (
            done["acked"] == done["total"] == (blast if robot != "ara" else route)["program_length"]
        )
        emu = scaled.emulator(service, robot, tmp_path)
        assert check_exactly_once(emu.execution_log(), done["run_id"], done["total"]) == []


def test_estop_through_the_proxy_latches_every_robot(scaled: Scaled) -> None:
    api = scaled.api
    t0 = time.monotonic()
    body = api.post("/estop", {"reason": "docker scaled-profile test"})
    ms = (time.monotonic() - t0) * 1e3
    print(f"\nscaled: E-stop through the proxy answered in {ms:.0f} ms")
    assert set(body["robots"]) == set(ROBOT_NAMES) and body["unreached"] == [], body
    # The answer comes once every robot was sent its stop; the robots' states
    # reach this server's list from the link service a moment later.
    every = dict.fromkeys(ROBOT_NAMES, True)
    latched = wait_for(
        lambda: (
            (got := {r["name"]: r["estop_latched"] for r in api.get("/robots")}) == every and got
        ),
        10,
        "every robot's latch in /robots",
        poll_s=0.1,
    )
    assert latched == every, latched
    for robot in ROBOT_NAMES:
        api.post(f"/robots/{robot}/clear-estop")
    wait_for(lambda: not any(r["estop_latched"] for r in api.get("/robots")), 20, "latches cleared")


def _state(api: Api, robot: str) -> dict[str, Any]:
    return api.get(f"/robots/{robot}/state")


def test_killed_api_server_the_other_takes_the_robot_and_the_run_completes_once(
    scaled: Scaled, tmp_path: Path
) -> None:
    api, compose = scaled.api, scaled.compose
    urls = scaled.server_urls()
    owner = _state(api, "ara")["owner"]
    assert urls[owner] == "http://api-1:8000"
    plan = api.planned("demo.route")
    ex = api.post(f"/plans/{plan['id']}/dispatch", {"robot": "ara"}, status=201)
    wait_for(lambda: api.get(f"/executions/{ex['id']}")["acked"] >= 1, 60, "a command done")
    killed_at = time.monotonic()
    subprocess.run(
        ["docker", "kill", compose.container("api-1")], check=True, timeout=60, capture_output=True
    )
    # Through the proxy, api-2 answers; it takes ara over once api-1's lease lapsed.
    took = wait_for(
        lambda: (s := _state(api, "ara"))["owner"] != owner and s["owned_here"] and s,
        LEASE_S + 30,
        "api-2 to take ara over",
        poll_s=0.5,
    )
    took_s = time.monotonic() - killed_at
    print(f"\nscaled: api-2 took ara over {took_s:.1f} s after api-1 was killed")
    assert urls[took["owner"]] == "http://api-2:8000"
    got = wait_for(
        lambda: (e := api.get(f"/executions/{ex['id']}"))["state"] == "interrupted" and e,
        30,
        "the run marked interrupted",
        poll_s=0.5,
    )
    wait_for(lambda: _state(api, "ara")["state"] in ("ready", "fault"), 30, "api-2 connected")
    if _state(api, "ara")["estop_latched"]:
        api.post("/robots/ara/clear-estop")
    api.post(f"/executions/{ex['id']}/resume")
    done = api.finished(ex["id"], timeout=180)
    assert done["state"] == "completed", done
    assert done["acked"] == done["total"] > got["acked"], (done, got)
    emu = scaled.emulator("robot-ara", "ara", tmp_path)
    assert check_exactly_once(emu.execution_log(), done["run_id"], done["total"]) == []
    # Every robot is api-2's now.
    wait_for(
        lambda: {urls.get(r["owner"]) for r in api.get("/robots")} == {"http://api-2:8000"},
        30,
        "api-2 to drive every robot",
        poll_s=0.5,
    )
