"""``steelpath emulate`` entry point (``robots.emulator.main``)."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

from robots.adapters import LinkConfig, RobotLink
from robots.emulator import main
from robots.protocol import JointMove, generate_secret, load_or_create_secret
from tests.support.procstat import proc_stat


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
        "--secret-file",
        "--nice",
    ):
        assert flag in out
    assert main(["--listen", "udp://x"]) == 2
    assert "expected tcp://HOST:PORT" in capsys.readouterr().err
    assert main(["--corrupt-rate", "2"]) == 2


def test_runs_until_sigterm_and_serves_tcp_and_pty(tmp_path: Path) -> None:
    log = tmp_path / "exec.jsonl"
    key = tmp_path / "keys" / "denso_vm6083.key"  # created by the emulator, mode 0600
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
            "--secret-file",
            str(key),
            "--nice",
            "3",
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
        assert key.stat().st_mode & 0o777 == 0o600
        # --nice lowers its priority relative to its parent's (field 19 of /proc/PID/stat).
        st = proc_stat(proc.pid)
        assert st is not None and st.nice == min(19, os.nice(0) + 3)
        assert key.parent.stat().st_mode & 0o777 == 0o700
        cfg = LinkConfig(secret=load_or_create_secret(key))
        # Without the key file's secret nobody gets a session.
        stranger = LinkConfig(secret=generate_secret(), backoff_max_s=0.2)
        with RobotLink(url, stranger) as link:
            assert link.wait_for(lambda lk: "failed authentication" in lk.status().reason, 10)
            assert not link.connected
        for target in (url, pty_path):
            with RobotLink(target, cfg) as link:
                assert link.wait_connected(10)
                assert link.robot_info.name == "denso_vm6083"
        with RobotLink(url, cfg) as link:
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


def test_secret_file_errors_and_warning(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    loose = tmp_path / "loose.key"
    loose.write_text(generate_secret().hex())
    loose.chmod(0o644)
    assert main(["--secret-file", str(loose)]) == 2
    assert "lets others read it" in capsys.readouterr().err
    bad = tmp_path / "bad.key"
    bad.write_text("not hex")
    bad.chmod(0o600)
    assert main(["--secret-file", str(bad)]) == 2
    assert "64 hex characters" in capsys.readouterr().err
    # No --secret-file: a warning (the emulator runs with a secret nobody has).
    from robots.emulator.cli import _secret

    assert _secret(None) is None
    assert "no host can control this emulator" in capsys.readouterr().err
