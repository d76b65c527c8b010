"""What can be validated of the Docker set-up without starting a container."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _tool(name: str) -> str:
    path = shutil.which(name) or str(Path(sys.executable).parent / name)
    if not Path(path).exists():
        pytest.fail(f"{name} is not installed; 'make test' installs it")
    return path


def test_compose_file_validates() -> None:
    r = subprocess.run(
        [_tool("docker-compose"), "-f", str(ROOT / "docker" / "compose.yml"), "config"],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    assert "steelpath-data" in r.stdout and "8000" in r.stdout and "/data" in r.stdout


def test_dockerfile_passes_hadolint() -> None:
    r = subprocess.run(
        [_tool("hadolint"), str(ROOT / "docker" / "Dockerfile")],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stdout + r.stderr


def test_dockerfile_installs_like_the_readme() -> None:
    dockerfile = (ROOT / "docker" / "Dockerfile").read_text()
    makefile = (ROOT / "Makefile").read_text()
    # The README's first command is `make serve` → the `install` target.
    block = re.search(
        r"^\$\(BIN\)/python:\n((?:\t.*\n)+)\ninstall: .*\n((?:\t.*\n)+)", makefile, re.M
    )
    assert block, "Makefile install recipe not found"
    for line in (block.group(1) + block.group(2)).splitlines():
        cmd = line.strip().replace("$(PYTHON)", "python3").replace("$(VENV)", "/app/.venv")
        cmd = cmd.replace("$(BIN)", "/app/.venv/bin")
        assert cmd in dockerfile, f"Dockerfile lacks README install step {cmd!r}"
    readme = (ROOT / "README.md").read_text()
    assert "make serve" in readme
    assert re.search(r"^USER 10001", dockerfile, re.M), "image must not run as root"
    assert "/api/v1/health" in dockerfile


def test_no_password_is_written_in_the_compose_file() -> None:
    """The database password comes from the operator's docker/.env, never a default."""
    import yaml

    compose = yaml.safe_load((ROOT / "docker" / "compose.yml").read_text())
    services = compose["services"]
    assert services["postgres"]["environment"]["POSTGRES_PASSWORD"] == "${POSTGRES_PASSWORD:-}"
    for name, svc in services.items():
        url = (svc.get("environment") or {}).get("STEELPATH_DATABASE_URL")
        if url:
            assert url.startswith("postgresql://steelpath:${POSTGRES_PASSWORD:-}@"), name
    ignored = (ROOT / ".dockerignore").read_text().split()
    assert "docker/.env" in ignored and "docker/.env" in (ROOT / ".gitignore").read_text()


def test_scaled_profile_validates() -> None:
    """The scaled set-up: PostgreSQL, a Dask scheduler and two workers,
    two API servers on one shared volume behind a reverse proxy."""
    import yaml

    r = subprocess.run(
        [
            _tool("docker-compose"),
            "-f",
            str(ROOT / "docker" / "compose.yml"),
            "--profile",
            "scaled",
            "config",
        ],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    services = yaml.safe_load(r.stdout)["services"]
    scaled = {name for name, s in services.items() if "scaled" in s.get("profiles", [])}
    assert scaled == {
        "postgres",
        "dask-scheduler",
        "dask-worker-1",
        "dask-worker-2",
        "api-1",
        "api-2",
        "proxy",
        "robot-ara",
        "robot-cmbot",
        "robot-denso",
        "robot-sbg",
    }
    assert "profiles" not in services["steelpath"], "the lab default must start without a profile"
    apis = [services["api-1"], services["api-2"]]
    for api in apis:
        env = api["environment"]
        assert env["STEELPATH_DATABASE_URL"].startswith("postgresql://")
        assert env["STEELPATH_DASK_SCHEDULER"] == "tcp://dask-scheduler:8786"
        assert api["volumes"][0].startswith("steelpath-shared:/data")
    # No server runs embedded emulators (they would be on its loopback only): both
    # reach one emulator container per robot, on the port it listens on, with the
    # link secret from the shared volume; each server advertises its own URL.
    assert len({a["environment"]["STEELPATH_SERVER_URL"] for a in apis}) == 2
    from robots import ROBOT_NAMES
    from server.settings import Settings

    for api in apis:
        env = api["environment"]
        assert env["STEELPATH_EMULATORS"] == "false"
        urls = Settings(emulator_urls=json.loads(env["STEELPATH_EMULATOR_URLS"])).emulator_urls
        assert set(urls) == set(ROBOT_NAMES)
        for robot, url in urls.items():
            host, port = url.removeprefix("socket://").split(":")
            emu = services[host]
            cmd = emu["command"]
            assert cmd[cmd.index("--robot") + 1] == robot
            assert cmd[cmd.index("--listen") + 1] == f"tcp://0.0.0.0:{port}"
            assert cmd[cmd.index("--secret-file") + 1] == f"/data/robots/{robot}.key"
            assert emu["volumes"][0].startswith("steelpath-shared:/data")
            assert host in api["depends_on"]
    for worker in ("dask-worker-1", "dask-worker-2"):
        w = services[worker]
        assert "tcp://dask-scheduler:8786" in w["command"]
        assert w["environment"]["DASK_CONFIG"] == "/app/docker/dask"
        assert (ROOT / "docker" / "dask" / "steelpath.yaml").is_file()
        assert (
            w["environment"]["STEELPATH_DATABASE_URL"]
            == apis[0]["environment"]["STEELPATH_DATABASE_URL"]
        )
    caddyfile = (ROOT / "docker" / "Caddyfile").read_text()
    assert "api-1:8000" in caddyfile and "api-2:8000" in caddyfile
    assert services["proxy"]["ports"]
