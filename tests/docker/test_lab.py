"""The lab deployment on a real Docker daemon: ``docker compose -f docker/compose.yml up -d``.

One container: API, console, scene and the built-in emulators, its data on the
named volume ``steelpath-data``.  Checked: it becomes healthy (Docker's own
HEALTHCHECK), the admin token is in ``/data/admin.token`` (mode 0600, the
service's user), a plan is driven to completion on the emulator with every
command once, the container stops on SIGTERM well within compose's 10 s with
exit code 0 and SQLite closed (no write-ahead log left), and after a restart the
plans, the token, the robot keys and the emulator's state are all still there.
"""

from __future__ import annotations

import hashlib
import secrets
import subprocess
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from robots.emulator.robot import check_exactly_once
from server.linkservice.emulators import EmulatorProcess
from tests.docker.conftest import Image
from tests.support.docker_compose import Api, Compose
from tests.support.live import free_port
from tests.support.waiting import wait_for

# The first test's set-up builds the image (on a fresh machine: bases, ~3 min).
pytestmark = [pytest.mark.slow, pytest.mark.timeout(900)]


@pytest.fixture(scope="module")
def lab(docker_image: Image) -> Iterator[tuple[Compose, Api, float]]:
    port = free_port()
    compose = Compose(
        f"splab{secrets.token_hex(4)}",
        {
            "STEELPATH_IMAGE": docker_image.tag,
            "STEELPATH_LAB_PORT": str(port),
            "STEELPATH_EMULATOR_TIME_SCALE": "4",
        },
    )
    try:
        t0 = time.monotonic()
        compose("up", "-d")
        healthy_s = (time.monotonic() - t0) + compose.wait_healthy(["steelpath"], timeout=180)
        print(f"\nlab: up -> healthy in {healthy_s:.1f} s")
        token = compose.read("steelpath", "/data/admin.token").strip()
        api = Api(f"http://127.0.0.1:{port}", token)
        try:
            yield compose, api, healthy_s
        finally:
            api.close()
    finally:
        compose.down()


def _emulator_log(compose: Compose, robot: str, tmp: Path) -> EmulatorProcess:
    log = tmp / f"{robot}.log.jsonl"
    log.write_text(compose.read("steelpath", f"/data/emulators/{robot}.log.jsonl"))
    return EmulatorProcess(robot, "", 0, log, tmp / "none.json", False)


def _keys(compose: Compose) -> dict[str, str]:
    names = compose("exec", "-T", "steelpath", "ls", "/data/robots").stdout.split()
    assert sorted(names) == sorted(
        f"{r}.key" for r in ("ara", "cmbot", "denso_vm6083", "sbg_climber")
    ), names
    return {
        n: hashlib.sha256(compose.read("steelpath", f"/data/robots/{n}").encode()).hexdigest()
        for n in names
    }


def test_the_token_is_on_the_volume_for_the_operator_only(lab: tuple[Compose, Api, float]) -> None:
    compose, api, _ = lab
    stat = compose("exec", "-T", "steelpath", "stat", "-c", "%a %u", "/data/admin.token")
    assert stat.stdout.split() == ["600", "10001"], stat.stdout
    assert compose("exec", "-T", "steelpath", "id", "-u").stdout.strip() == "10001"
    assert api.get("/health")["status"] == "ok"
    assert {r["name"] for r in api.get("/robots")} == {
        "ara",
        "cmbot",
        "denso_vm6083",
        "sbg_climber",
    }
    r = api.http.get("/robots", headers={"Authorization": "Bearer sp_not-a-token"})
    assert r.status_code == 401, r.text


def test_a_plan_runs_to_completion_and_survives_a_restart(
    lab: tuple[Compose, Api, float], tmp_path: Path
) -> None:
    compose, api, _ = lab
    wait_for(lambda: api.get("/robots/ara/state")["state"] == "ready", 60, "ara ready", poll_s=0.5)
    plan = api.planned("demo.route")
    ex = api.post(f"/plans/{plan['id']}/dispatch", {"robot": "ara"}, status=201)
    done = api.finished(ex["id"], timeout=180)
    assert done["state"] == "completed", done
    emu = _emulator_log(compose, "ara", tmp_path)
    assert check_exactly_once(emu.execution_log(), done["run_id"], done["total"]) == []
    before = api.get("/robots/ara/state")["report"]
    assert any(abs(x) > 1e-3 for x in before["odometry_m"]), before  # the robot moved
    keys = _keys(compose)
    volume = f"{compose.project}_steelpath-data"

    # Stopped as compose stops it: SIGTERM, 10 s before SIGKILL.
    t0 = time.monotonic()
    compose("stop", "-t", "10", "steelpath")
    stop_s = time.monotonic() - t0
    assert stop_s < 10, stop_s
    assert compose.inspect("steelpath", "{{.State.ExitCode}}") == "0"
    print(f"\nlab: stopped in {stop_s:.1f} s")
    files = subprocess.run(
        ["docker", "run", "--rm", "-v", f"{volume}:/data", "--entrypoint", "ls",
         compose.env["STEELPATH_IMAGE"], "-a", "/data", "/data/emulators"],
        capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert files.returncode == 0, files.stderr
    listing = files.stdout.split()
    assert "steelpath.sqlite3" in listing
    assert "steelpath.sqlite3-wal" not in listing, listing  # closed, checkpointed
    # The emulators were stopped by the server, not killed with the container:
    # each removed its port file on exit.
    assert not [n for n in listing if n.endswith(".port.json")], listing

    compose("start", "steelpath")
    compose.wait_healthy(["steelpath"], timeout=180)
    # The same token (not a new first-start one), the same plan and run, the same
    # keys, and the emulator where the run left it.
    again = api.get(f"/plans/{plan['id']}")
    assert again["id"] == plan["id"] and again["kind"] == "demo.route"
    assert api.get(f"/executions/{ex['id']}")["state"] == "completed"
    assert _keys(compose) == keys
    after = wait_for(
        lambda: (s := api.get("/robots/ara/state"))["state"] == "ready" and s["report"],
        60,
        "ara ready after the restart",
        poll_s=0.5,
    )
    assert after["odometry_m"] == pytest.approx(before["odometry_m"], abs=1e-6)
