"""Fixtures for emulator/adapter tests: no leaked threads or file descriptors."""

from __future__ import annotations

import os
import threading
import time
from collections.abc import Iterator

import pytest


def _fds() -> dict[int, str]:
    out = {}
    for name in os.listdir("/proc/self/fd"):
        try:
            out[int(name)] = os.readlink(f"/proc/self/fd/{name}")
        except OSError:
            continue
    return out


@pytest.fixture(autouse=True)
def no_leaks() -> Iterator[None]:
    """Every thread started and every socket/pty opened by a test is gone after it."""
    threads_before = set(threading.enumerate())
    fds_before = _fds()
    yield
    deadline = time.monotonic() + 5.0
    while True:
        extra = [t for t in threading.enumerate() if t not in threads_before and t.is_alive()]
        if not extra or time.monotonic() > deadline:
            break
        extra[0].join(0.2)  # a thread that is ending: wait for it, do not sleep
    assert not extra, f"threads leaked: {[t.name for t in extra]}"
    leaked = {
        fd: target
        for fd, target in _fds().items()
        if fds_before.get(fd) != target
        and (target.startswith(("socket:", "/dev/pts", "/dev/ptmx", "pipe:")))
    }
    assert not leaked, f"file descriptors leaked: {leaked}"
