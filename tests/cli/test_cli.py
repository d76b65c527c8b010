"""The ``steelpath`` command line."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from server.auth import hash_token
from server.store import Store
from tests.conftest import make_settings
from tests.support.live import free_port, live_server


def steelpath(
    *args: str, env: dict[str, str] | None = None, cwd: Path | None = None
) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "server.cli", *args],
        capture_output=True,
        text=True,
        timeout=120,
        env={**os.environ, **(env or {})},
        cwd=cwd,
    )


@pytest.mark.parametrize(
    "args",
    [
        [],
        ["serve"],
        ["token"],
        ["token", "create"],
        ["plan"],
        ["plan", "submit"],
        ["plan", "show"],
        ["plan", "params"],
        ["plan", "approve"],
        ["plan", "dispatch"],
        ["plan", "watch"],
        ["estop"],
        ["estop", "clear"],
    ],
)
def test_help_everywhere(args: list[str]) -> None:
    r = steelpath(*args, "--help")
    assert r.returncode == 0, r.stderr
    assert "usage: steelpath" in r.stdout


def test_emulate_help_and_bad_flags() -> None:
    r = steelpath("emulate", "--help")
    assert r.returncode == 0 and "--listen" in r.stdout and "--robot" in r.stdout
    assert steelpath("emulate", "--listen", "nonsense://x").returncode != 0


def test_console_script_installed() -> None:
    exe = Path(sys.executable).parent / "steelpath"
    assert exe.exists()
    assert subprocess.run([str(exe), "--help"], capture_output=True, timeout=60).returncode == 0


def test_token_create_refuses_a_data_directory_no_server_used(tmp_path: Path) -> None:
    """A token written where no server looks would be refused by the server."""
    r = steelpath("token", "create", "--data", str(tmp_path / "nowhere"))
    assert r.returncode == 2 and "no SteelPath database in" in r.stderr, r.stderr
    assert "--new-data" in r.stderr and not (tmp_path / "nowhere").exists()
    assert steelpath("token", "list", "--data", str(tmp_path / "nowhere")).returncode == 2
    r = steelpath("token", "create", "--new-data", "--data", str(tmp_path / "new"))
    assert r.returncode == 0 and r.stdout.strip().splitlines()[-1].startswith("sp_"), r.stderr
    assert "no server runs on" in r.stderr  # and it says that no server uses it yet


def test_token_create_says_whether_a_server_runs_on_its_data(tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "var", port=free_port())
    with live_server(settings):
        r = steelpath("token", "create", "--data", str(tmp_path / "var"))
        assert r.returncode == 0, r.stderr
        assert "no server runs" not in r.stderr


def test_token_create_prints_token_last(tmp_path: Path) -> None:
    Store(tmp_path).close()  # a data directory a server has used
    r = steelpath("token", "create", "--role", "viewer", "--name", "dash", "--data", str(tmp_path))
    assert r.returncode == 0, r.stderr
    token = r.stdout.strip().splitlines()[-1]
    assert token.startswith("sp_") and " " not in token
    store = Store(tmp_path)
    rec = store.find_token(hash_token(token))
    assert rec is not None and rec.role == "viewer" and rec.name == "dash"
    listed = steelpath("token", "list", "--data", str(tmp_path)).stdout
    assert rec.id in listed and token not in listed
    assert steelpath("token", "revoke", rec.id, "--data", str(tmp_path)).returncode == 0
    assert store.find_token(hash_token(token)) is None
    assert steelpath("token", "create", "--role", "root", "--data", str(tmp_path)).returncode == 2


def test_token_create_with_expiry(tmp_path: Path) -> None:
    Store(tmp_path).close()
    r = steelpath(
        "token", "create", "--role", "operator", "--expires-in", "30d", "--data", str(tmp_path)
    )
    assert r.returncode == 0, r.stderr
    token = r.stdout.strip().splitlines()[-1]
    store = Store(tmp_path)
    rec = store.find_token(hash_token(token))
    assert rec is not None and rec.expires_ts is not None
    assert abs(rec.expires_ts - (time.time() + 30 * 86400)) < 120
    assert "expires" in r.stdout
    listed = steelpath("token", "list", "--data", str(tmp_path)).stdout
    line = next(ln for ln in listed.splitlines() if rec.id in ln)
    assert f"expires {rec.expires_at}" in line and "active" in line
    for bad in ("30", "30x", "0d", "soon"):
        r = steelpath("token", "create", "--expires-in", bad, "--data", str(tmp_path))
        assert r.returncode == 2, bad
        assert "--expires-in" in r.stderr
        assert "s, m, h or d" in r.stderr or "lifetime" in r.stderr
    assert len(store.list_tokens()) == 1  # the refused ones made nothing


def test_plan_submit_and_show_against_a_running_server(tmp_path: Path) -> None:
    settings = make_settings(tmp_path / "var", port=free_port())
    with live_server(settings) as (url, tokens, _):
        params = tmp_path / "p.json"
        params.write_text(json.dumps({"end": "b2", "step_delay_s": 0.2}))
        env = {"STEELPATH_TOKEN": tokens["operator"]}
        r = steelpath("plan", "submit", "demo.route", str(params), "--server", url, env=env)
        assert r.returncode == 0, r.stderr
        assert "state planned" in r.stdout
        assert "route_length_m" in r.stdout and "[PASS] route_found" in r.stdout
        assert "%" in r.stderr and "step" in r.stderr  # the progress bar
        pid = r.stdout.split()[1]
        shown = steelpath("plan", "show", pid, "--server", url, env=env)
        assert shown.returncode == 0 and pid in shown.stdout and "allowed actions" in shown.stdout
        assert pid in steelpath("plan", "list", "--server", url, env=env).stdout
        bad = steelpath("plan", "submit", "demo.route", "-", "--server", url, env=env)
        assert bad.returncode == 0  # empty stdin → defaults
        r = steelpath("plan", "show", "pl_missing", "--server", url, env=env)
        assert r.returncode != 0 and "HTTP 404" in r.stderr
        r = steelpath("plan", "show", pid, "--server", url, env={"STEELPATH_TOKEN": "sp_bogus"})
        assert r.returncode != 0 and "HTTP 401" in r.stderr
        bad_json = tmp_path / "bad.json"
        bad_json.write_text("{nope")
        r = steelpath("plan", "submit", "demo.route", str(bad_json), "--server", url, env=env)
        assert r.returncode != 0 and "not valid JSON" in r.stderr


def test_plan_params_prints_a_kinds_defaults() -> None:
    """``plan params KIND`` prints the params model's defaults as JSON (no
    server); that JSON is a valid params file for the kind."""
    from server.kinds import registry

    r = steelpath("plan", "params", "ara.switch")
    assert r.returncode == 0, r.stderr
    defaults = json.loads(r.stdout)
    assert defaults["sample"] == "perpendicular" and defaults["clearance_margin_m"] == 0.01
    model = registry()["ara.switch"].params_model
    assert model.model_validate(defaults) == model()
    bad = steelpath("plan", "params", "ara.swich")
    assert bad.returncode == 2 and "unknown kind 'ara.swich'" in bad.stderr
    assert "ara.switch" in bad.stderr  # the kinds are listed


def test_approve_dispatch_watch_estop_and_clear(tmp_path: Path) -> None:
    """A whole CLI session against a server with its emulators: submit,
    approve, dispatch with --watch to completion; E-stop every robot, then
    clear them all.  Bad input gets a clear error and a non-zero exit."""
    settings = make_settings(
        tmp_path / "var", port=free_port(), emulators=True, emulator_time_scale=40.0
    )
    with live_server(settings) as (url, tokens, app):
        eng = app.state.services.dispatch
        for name in eng.robot_names():
            assert eng.wait_connected(name, 30), name
        env = {"STEELPATH_TOKEN": tokens["operator"], "STEELPATH_URL": url}
        r = steelpath("plan", "submit", "demo.route", "--no-wait", env=env)
        pid = r.stdout.strip().splitlines()[-1]
        deadline = time.monotonic() + 60
        while "state planned" not in steelpath("plan", "show", pid, env=env).stdout:
            assert time.monotonic() < deadline, "plan did not finish"
            time.sleep(0.2)
        r = steelpath("plan", "dispatch", pid, "--robot", "ara", env=env)
        assert r.returncode != 0 and "HTTP 409" in r.stderr  # not approved yet
        r = steelpath("plan", "approve", pid, "--comment", "CLI test", env=env)
        assert r.returncode == 0 and "approved" in r.stdout, r.stderr
        r = steelpath(
            "plan", "dispatch", pid, "--robot", "ara", "--watch", "--interval", "0.1", env=env
        )
        assert r.returncode == 0, r.stdout + r.stderr
        lines = r.stdout.splitlines()
        assert lines[-1].split(": ", 1)[1].startswith("completed")
        ex_id = lines[0].split()[1]
        done = app.state.services.store.get_execution(ex_id)
        assert done.state == "completed" and done.acked == done.total > 0
        assert f"{done.total}/{done.total} commands" in lines[-1]
        again = steelpath("plan", "watch", pid, env=env)  # a plan id: its newest execution
        assert again.returncode == 0 and ex_id in again.stdout and "completed" in again.stdout

        viewer = {**env, "STEELPATH_TOKEN": tokens["viewer"]}
        assert "HTTP 403" in steelpath("plan", "approve", pid, env=viewer).stderr
        r = steelpath("estop", "--reason", "CLI test", env=env)
        assert r.returncode == 0 and "E-STOP sent to every robot" in r.stdout, r.stderr
        audit = app.state.services.store.list_audit(limit=20)
        assert any(a.action == "estop" and a.reason == "CLI test" for a in audit)
        r = steelpath("estop", "clear", env=env)
        assert r.returncode != 0 and "--all" in r.stderr
        r = steelpath("estop", "clear", "--all", env=env)
        assert r.returncode == 0, r.stderr
        said = dict(ln.split(": ", 1) for ln in r.stdout.splitlines())
        assert sorted(said) == sorted(eng.robot_names()), r.stdout
        assert all(v.startswith("E-stop cleared") for v in said.values()), said
        # Per robot what it did: one latched, the others had nothing to clear.
        assert steelpath("estop", "--robot", "ara", env=env).returncode == 0
        r = steelpath("estop", "clear", "--all", env=env)
        said = dict(ln.split(": ", 1) for ln in r.stdout.splitlines())
        assert said.pop("ara").startswith("E-stop cleared"), r.stdout
        assert all(v == "not E-stopped, nothing to clear" for v in said.values()), said
        r = steelpath("estop", "clear", "nobody", env=env)
        assert r.returncode == 2 and "no robot 'nobody'" in r.stderr
