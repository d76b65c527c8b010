"""Robot emulators that run elsewhere (``STEELPATH_EMULATOR_URLS``): the scaled
Docker set-up runs one emulator container per robot, which every API server
reaches, instead of emulators on one server's loopback.

A standalone ``python -m robots.emulator`` process stands for the container:
the server drives it at the configured URL (shown as emulated), a plan runs
on it to completion exactly once, and bad values are refused saying why.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from collections.abc import Iterator
from pathlib import Path

import pytest
from pydantic import ValidationError

from robots.emulator.robot import check_exactly_once
from server.app import create_app
from server.linkservice.emulators import EmulatorProcess
from server.settings import Settings
from tests.api.test_dispatch import approved_demo, wait_execution
from tests.conftest import make_settings
from tests.support.serve import ROOT
from tests.support.waiting import wait_for


@pytest.fixture
def ara_emulator(tmp_path: Path) -> Iterator[tuple[str, EmulatorProcess]]:
    """An emulator of ``ara`` as its own process, with the data directory's link secret."""
    data, run = tmp_path / "var", tmp_path / "emu"
    run.mkdir()
    port_file, log = run / "ara.port.json", run / "ara.log.jsonl"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "robots.emulator",
            "--robot",
            "ara",
            "--listen",
            "tcp://127.0.0.1:0",
            "--time-scale",
            "40",
            "--secret-file",
            str(data / "robots" / "ara.key"),
            "--port-file",
            str(port_file),
            "--log-jsonl",
            str(log),
        ],
        cwd=ROOT,
    )
    try:
        info = wait_for(
            lambda: port_file.exists() and json.loads(port_file.read_text()), 30, "the port file"
        )
        url = str(info["url"])
        yield url, EmulatorProcess("ara", url, proc.pid, log, run / "none.json", False)
    finally:
        proc.send_signal(signal.SIGTERM)
        proc.wait(timeout=10)


def test_a_configured_emulator_is_driven_at_its_url(make_api, ara_emulator, tmp_path) -> None:
    url, emulator = ara_emulator
    api = make_api(tmp_path / "var", emulator_urls={"ara": url})
    assert api.services.dispatch.wait_connected("ara", 20)
    robot = api.get("/api/v1/robots/ara/state", "viewer").json()
    assert robot["url"] == url and robot["emulated"] and robot["connected"], robot
    plan = approved_demo(api, end="b1")
    r = api.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code == 201, r.text
    ex = wait_execution(api, r.json()["id"], ("completed", "faulted", "aborted"))
    assert ex["state"] == "completed", ex
    assert check_exactly_once(emulator.execution_log(), ex["run_id"], ex["total"]) == []


def test_bad_emulator_urls_are_refused_saying_why(tmp_path) -> None:
    with pytest.raises(ValidationError, match="expected socket://host:port"):
        Settings(emulator_urls={"ara": "http://robot-ara:9100"})
    settings = make_settings(tmp_path / "var", emulator_urls={"nobot": "socket://h:1"})
    from fastapi.testclient import TestClient

    with pytest.raises(ValueError, match="names no robot: nobot"), TestClient(create_app(settings)):
        pass
