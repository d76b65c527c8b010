"""``steelpath emulate`` entry point (``robots.emulator.main``)."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from robots.adapters import RobotLink
from robots.emulator import main
from robots.protocol import JointMove


def test_help_and_bad_arguments(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as exc:
        main(["--help"])
    assert exc.value.code == 0
    out = capsys.readouterr().out
    for flag in (
        "--robot",
        "--listen",
        "--pty",
        "--drop-after",
        "--corrupt-rate",
        "--delay",
        "--nak-index",
        "--fault-at-index",
    ):
        assert flag in out
    assert main(["--listen", "udp://x"]) == 2
    assert "expected tcp://HOST:PORT" in capsys.readouterr().err
    assert main(["--corrupt-rate", "2"]) == 2


def test_runs_until_sigterm_and_serves_tcp_and_pty(tmp_path: Path) -> None:
    log = tmp_path / "exec.jsonl"
    proc = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "robots.emulator",
            "--robot",
            "denso_vm6083",
            "--pty",
            "--listen",
            "tcp://127.0.0.1:0",
            "--log-jsonl",
            str(log),
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.DEVNULL,
        text=True,
    )
    try:
        assert proc.stdout is not None
        lines = [proc.stdout.readline() for _ in range(3)]
        assert lines[0].startswith("robot denso_vm6083: 6 joints")
        url = lines[1].split()[-1]
        pty_path = lines[2].split()[-1]
        assert url.startswith("socket://127.0.0.1:") and pty_path.startswith("/dev/pts/")
        for target in (url, pty_path):
            with RobotLink(target) as link:
                assert link.wait_connected(10)
                assert link.robot_info.name == "denso_vm6083"
        with RobotLink(url) as link:
            assert link.wait_connected(10)
            link.send_command(JointMove((0.1,) * 6, 0.0), run_id=3, index=0)
            assert link.wait_for(lambda lk: lk.last_report.last_done == 0, 10)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(10) == 0
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if proc.stdout is not None:
            proc.stdout.close()
    records = [json.loads(line) for line in log.read_text().splitlines()]
    assert [(r["run_id"], r["index"], r["outcome"]) for r in records] == [(3, 0, "done")]
