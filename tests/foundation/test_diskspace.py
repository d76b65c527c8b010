"""Telling a full disk from other failures, and the gauge's states against the reserve."""

from __future__ import annotations

import errno
import sqlite3
from collections import namedtuple
from pathlib import Path

import psycopg
import pytest

from server import diskspace
from server.diskspace import LOW_BYTES, DiskGauge, is_disk_full

Usage = namedtuple("Usage", "total used free")


def test_a_full_disk_is_recognised_in_every_form_and_through_wrapping() -> None:
    assert is_disk_full(sqlite3.OperationalError("database or disk is full"))
    assert is_disk_full(OSError(errno.ENOSPC, "No space left on device"))
    assert is_disk_full(OSError(errno.EDQUOT, "Disk quota exceeded"))
    assert is_disk_full(psycopg.errors.DiskFull("could not extend file"))
    try:
        try:
            raise OSError(errno.ENOSPC, "No space left on device")
        except OSError as inner:
            raise RuntimeError("storing the result failed") from inner
    except RuntimeError as outer:
        assert is_disk_full(outer)


def test_other_failures_are_not_a_full_disk() -> None:
    assert not is_disk_full(sqlite3.OperationalError("database is locked"))
    assert not is_disk_full(OSError(errno.EACCES, "Permission denied"))
    assert not is_disk_full(psycopg.errors.UniqueViolation("duplicate key"))
    assert not is_disk_full(ValueError("bad"))
    assert not is_disk_full(None)


@pytest.mark.parametrize(
    "free, state",
    [
        (10 << 20, "full"),
        (32 << 20, "full"),
        ((32 << 20) + 1, "low"),
        ((32 << 20) + LOW_BYTES + 1, "ok"),
    ],
)
def test_the_gauge_states_against_the_reserve(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, free: int, state: str
) -> None:
    monkeypatch.setattr(diskspace.shutil, "disk_usage", lambda _: Usage(1 << 40, 0, free))
    gauge = DiskGauge(tmp_path / "not-made-yet", reserve_bytes=32 << 20)
    assert gauge.read().state == state
    assert gauge.room_for(0) == (state != "full")
    assert not gauge.room_for(free)  # a body as big as what is free never fits


def test_the_gauge_is_read_again_after_refresh(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    free = [1 << 30]
    monkeypatch.setattr(diskspace.shutil, "disk_usage", lambda _: Usage(1 << 40, 0, free[0]))
    gauge = DiskGauge(tmp_path, reserve_bytes=1 << 20, period_s=3600)
    assert gauge.read().state == "ok"
    free[0] = 0
    assert gauge.read().state == "ok"  # cached within the period
    gauge.refresh()
    assert gauge.read().state == "full"
