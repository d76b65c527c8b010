"""Free space on the data directory, and telling a full disk from other failures.

A full disk shows up as ``sqlite3.OperationalError("database or disk is full")``,
``OSError(ENOSPC)`` (arrays, photos, uploads), or PostgreSQL's ``DiskFull``
(SQLSTATE 53100), often wrapped in another exception; :func:`is_disk_full` looks
through the chain.  :class:`DiskGauge` reads ``statvfs`` at most every
``period_s``, cheap enough for a check on every write request.
"""

from __future__ import annotations

import errno
import shutil
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

DiskState = Literal["ok", "low", "full"]

#: Below this much free space (and above the reserve) /health says "low".
LOW_BYTES = 512 * 1024 * 1024

_FULL_ERRNOS = {errno.ENOSPC, errno.EDQUOT}
_FULL_TEXT = ("database or disk is full", "no space left on device", "disk quota exceeded")


def is_disk_full(exc: BaseException | None) -> bool:
    """Whether ``exc`` (or an exception it was raised from) is a full disk or quota."""
    seen: set[int] = set()
    while exc is not None and id(exc) not in seen:
        seen.add(id(exc))
        if isinstance(exc, OSError) and exc.errno in _FULL_ERRNOS:
            return True
        if getattr(exc, "sqlstate", None) == "53100":  # psycopg: disk_full
            return True
        text = str(exc).lower()
        if any(t in text for t in _FULL_TEXT):
            return True
        exc = exc.__cause__ or exc.__context__
    return False


def describe(exc: BaseException) -> str:
    """A short reason for people: "disk full", or the exception's type and text."""
    return "disk full" if is_disk_full(exc) else f"{type(exc).__name__}: {exc}"


@dataclass(frozen=True)
class DiskReading:
    free_bytes: int
    total_bytes: int
    state: DiskState


def _existing(path: Path) -> Path:
    """``path`` or its nearest existing ancestor (the data directory is made at start)."""
    path = path.absolute()
    while not path.exists() and path != path.parent:
        path = path.parent
    return path


class DiskGauge:
    """The data directory's free space against the reserve, cached for ``period_s``."""

    def __init__(self, path: Path, reserve_bytes: int, period_s: float = 0.5) -> None:
        self.path = path
        self.reserve_bytes = reserve_bytes
        self.period_s = period_s
        self._lock = threading.Lock()
        self._at = -1e9
        self._last = DiskReading(2**62, 2**62, "ok")  # until the first reading

    def read(self) -> DiskReading:
        now = time.monotonic()
        with self._lock:
            if now - self._at < self.period_s:
                return self._last
            try:
                usage = shutil.disk_usage(_existing(self.path))
            except OSError:  # unreadable: nothing to say about space
                return self._last
            free = int(usage.free)
            state: DiskState = (
                "full"
                if free <= self.reserve_bytes
                else "low"
                if free <= self.reserve_bytes + LOW_BYTES
                else "ok"
            )
            self._last = DiskReading(free, int(usage.total), state)
            self._at = now
            return self._last

    def room_for(self, nbytes: int) -> bool:
        """Whether ``nbytes`` more still leave the reserve free."""
        return self.read().free_bytes - max(nbytes, 0) > self.reserve_bytes

    def refresh(self) -> None:
        """Forget the cached reading (after a write failed for space, or space was freed)."""
        with self._lock:
            self._at = -1e9
