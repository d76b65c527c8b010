"""A full disk: the E-stop still stops and answers, clearing it is refused until it
can be recorded, every other write answers 507 with a message, and nothing is lost.

The data directory is on a small tmpfs the test mounts (root only; CI runs as
root), filled to the last byte with a file the test removes to "free space".
SQLite's write-ahead log is truncated first (``wal_checkpoint(TRUNCATE)``), so
the first write after the disk filled needs new space, as on a server whose
log was just checkpointed.
"""

from __future__ import annotations

import contextlib
import os
import subprocess
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from server.kinds import registry
from tests.support.waiting import wait_for

pytestmark = pytest.mark.slow

TMPFS_MB = 64


@pytest.fixture
def small_disk(tmp_path: Path) -> Iterator[Path]:
    if os.geteuid() != 0:
        pytest.skip("mounting a tmpfs needs root (CI runs these as root)")
    mnt = tmp_path / "disk"
    mnt.mkdir()
    subprocess.run(
        ["mount", "-t", "tmpfs", "-o", f"size={TMPFS_MB}m", "tmpfs", str(mnt)], check=True
    )
    try:
        yield mnt
    finally:
        subprocess.run(["umount", "-l", str(mnt)], check=False)


def fill(disk: Path) -> Path:
    """Write zeros until the file system refuses (1 MiB, then 4 KiB writes); the filler."""
    filler = disk / "filler"
    fd = os.open(filler, os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o600)
    try:
        for size in (1 << 20, 4096):
            block = b"\0" * size
            with contextlib.suppress(OSError):
                while True:
                    os.write(fd, block)
    finally:
        os.close(fd)
    return filler


def truncate_wal(api: Any) -> None:
    api.services.store.db.query("PRAGMA wal_checkpoint(TRUNCATE)")


def audit_actions(api: Any, entity_id: str) -> list[dict[str, Any]]:
    r = api.get(f"/api/v1/audit?entity=robot&entity_id={entity_id}&limit=50")
    assert r.status_code == 200, r.text
    return list(r.json())


@pytest.fixture
def full_api(small_disk: Path, make_api: Any) -> Iterator[tuple[Any, Path]]:
    api = make_api(
        data=small_disk / "var",
        emulators=True,
        emulator_time_scale=40.0,
        disk_reserve_mb=4,
    )
    eng = api.services.dispatch
    for name in eng.robot_names():
        assert eng.wait_connected(name, 20), name
    yield api, small_disk


def test_estop_on_a_full_disk_stops_answers_and_is_audited_when_space_returns(
    full_api: tuple[Any, Path],
) -> None:
    api, disk = full_api
    truncate_wal(api)
    filler = fill(disk)

    r = api.post("/api/v1/estop", json={"reason": "full-disk drill"})
    assert r.status_code == 200, r.text
    body = r.json()
    assert body["audit"].startswith("failed: disk full"), body
    assert body["errors"] == [] and set(body["local"]) == set(api.services.dispatch.robot_names())
    for robot in api.get("/api/v1/robots").json():
        assert robot["estop_latched"], robot
    assert not any(e["action"] == "estop" for e in audit_actions(api, "all"))
    health = api.client.get("/api/v1/health").json()
    assert health["disk"]["state"] == "full" and health["disk"]["audit_pending"] == 1, health

    # Nothing moves unrecorded: the latch stays while the clear cannot be recorded.
    r = api.post("/api/v1/robots/ara/clear-estop")
    assert r.status_code == 409, r.text
    assert "stays E-stopped" in r.json()["detail"] and "disk full" in r.json()["detail"]
    assert api.get("/api/v1/robots/ara/state").json()["estop_latched"]

    # Any other write: 507 with a message, before anything is stored; reads work.
    r = api.post("/api/v1/plans", json={"kind": "demo.route", "params": {}})
    assert r.status_code == 507, r.text
    assert "disk is full" in r.json()["detail"] and "/" not in r.json()["detail"].split("(")[0]
    assert api.get("/api/v1/plans").status_code == 200

    filler.unlink()
    wait_for(
        lambda: api.client.get("/api/v1/health").json()["disk"]["audit_pending"] == 0,
        15,
        "the kept E-stop record written",
    )
    estops = [e for e in audit_actions(api, "all") if e["action"] == "estop"]
    assert len(estops) == 1 and estops[0]["reason"] == "full-disk drill", estops
    r = api.post("/api/v1/robots/ara/clear-estop")
    assert r.status_code == 200, r.text
    assert not api.get("/api/v1/robots/ara/state").json()["estop_latched"]
    assert [e["action"] for e in audit_actions(api, "ara")][:1] == ["clear-estop"]
    assert api.client.get("/api/v1/health").json()["disk"]["state"] in ("ok", "low")


def test_a_write_that_fails_for_space_is_a_507_and_a_plan_is_planned_again(
    small_disk: Path, make_api: Any, monkeypatch: pytest.MonkeyPatch
) -> None:
    """No reserve: the request gets past the check and SQLite itself refuses it."""
    monkeypatch.setenv("STEELPATH_EXTRA_KINDS", "tests.support.kinds")
    registry.cache_clear()
    api = make_api(data=small_disk / "var", disk_reserve_mb=0)
    plan = api.submit("test.job", {"mode": "hang", "seconds": 1.5})
    truncate_wal(api)
    filler = fill(small_disk)
    r = api.post("/api/v1/plans", json={"kind": "demo.route", "params": {}})
    assert r.status_code == 507, r.text
    assert "disk is full" in r.json()["detail"]
    # The running plan's result is refused: it waits, not failed and not lost.
    wait_for(lambda: api.services.jobs.disk_waiting() == [plan["id"]], 20, "the plan waiting")
    assert api.get(f"/api/v1/plans/{plan['id']}").json()["state"] == "planning"
    filler.unlink()
    done = api.wait(plan["id"], timeout=30)
    assert done["state"] == "planned", done
    audit = api.get(f"/api/v1/audit?entity=plan&entity_id={plan['id']}").json()
    assert any("planned again" in str(e["reason"]) for e in audit), audit
    registry.cache_clear()
