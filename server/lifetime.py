"""Child processes that do not outlive the server that started them.

Planning workers, upload parsers and the robot-link service must end when the
web server dies (a ``kill -9`` leaves no one to stop them otherwise): Linux
``prctl(PR_SET_PDEATHSIG)`` asks the kernel for a signal when the parent
*thread* that started us exits (so callers start children from long-lived
threads), and a daemon thread watching ``getppid()`` covers everything else.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import threading
import time
from collections.abc import Callable

PR_SET_PDEATHSIG = 1


def die_with_parent(
    parent_pid: int,
    *,
    sig: int = signal.SIGKILL,
    on_orphaned: Callable[[], None] | None = None,
    poll_s: float = 1.0,
) -> None:
    """Make this process end when ``parent_pid`` dies.

    ``sig`` is what the kernel sends (SIGKILL: nothing to clean up; SIGTERM for
    a process with a handler that must close things first).  The watcher calls
    ``on_orphaned`` (default: ``os._exit(1)``) when the parent pid changes.
    Checked once right away, for a parent that died before the prctl took hold.
    """
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(PR_SET_PDEATHSIG, int(sig), 0, 0, 0)
    orphaned = on_orphaned or (lambda: os._exit(1))
    if os.getppid() != parent_pid:
        orphaned()
        return

    def watch() -> None:
        while True:
            time.sleep(poll_s)
            if os.getppid() != parent_pid:
                orphaned()
                return

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


def leave_interrupts_to_parent() -> None:
    """Ignore SIGINT in a helper process the server starts and stops itself.

    Ctrl-C in a terminal signals the whole foreground process group: each
    planning worker then died in the middle of waiting for work and printed a
    ``KeyboardInterrupt`` traceback, while the server was already shutting the
    pool down in order.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)


def exit_without_teardown(code: int = 0) -> None:
    """Flush the logs and standard streams and end the process now.

    OMPL's nanobind bindings report every type and function they registered
    as "leaked" when the interpreter tears its modules down (some 1,600
    lines at each exit of a process that planned); nothing leaks while the
    process runs.  A process whose own shutdown has finished (the server
    after uvicorn returned, a planning worker leaving the pool) skips that
    teardown.
    """
    import logging

    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        with contextlib.suppress(Exception):
            stream.flush()
    os._exit(code)
