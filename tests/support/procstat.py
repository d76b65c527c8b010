"""``/proc/PID/stat`` fields the process tests check (Linux)."""

from __future__ import annotations

from pathlib import Path
from typing import NamedTuple


class ProcStat(NamedTuple):
    state: str  # R, S, D, Z, …
    ppid: int
    nice: int


def proc_stat(pid: int) -> ProcStat | None:
    """State, parent pid and nice of ``pid``, or ``None`` once it is gone."""
    try:
        raw = Path(f"/proc/{pid}/stat").read_text()
    except OSError:
        return None
    fields = raw[raw.rindex(")") + 2 :].split()  # after "pid (comm) ": comm may hold spaces
    return ProcStat(fields[0], int(fields[1]), int(fields[16]))


def loaded_modules(prefixes: tuple[str, ...]) -> list[str]:
    """The modules under ``prefixes`` this (worker) process has imported."""
    import sys

    return sorted(m for m in sys.modules if m.startswith(prefixes))
