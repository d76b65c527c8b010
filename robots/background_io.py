"""File output that never blocks a real-time thread.

A ``write()`` to a file or a pipe can block: the kernel throttles a writer
while dirty pages are flushed (a 250 MiB upload being written does that for
hundreds of milliseconds), and a pipe blocks when its reader is slow.  The
threads that keep robot links alive (heartbeats, the emulator's loop with its
watchdog) must not wait on that, so what they log or record goes into an
in-memory queue that one writer thread drains:

- :func:`log_through_a_queue` makes every ``logging`` record of the process
  go through a :class:`logging.handlers.QueueHandler` (the stdlib's
  answer to exactly this);
- :class:`LineWriter` appends text lines to a file from a thread of its own.
"""

from __future__ import annotations

import atexit
import logging
import logging.handlers
import os
import queue
import threading
from typing import IO


def log_through_a_queue() -> logging.handlers.QueueListener:
    """Move the root logger's handlers behind a queue served by one thread.

    Call after ``logging.basicConfig``; returns the started listener (stopped,
    and so flushed, at interpreter exit or by the caller).
    """
    root = logging.getLogger()
    handlers = list(root.handlers)
    q: queue.SimpleQueue[logging.LogRecord] = queue.SimpleQueue()
    for h in handlers:
        root.removeHandler(h)
    root.addHandler(logging.handlers.QueueHandler(q))
    listener = logging.handlers.QueueListener(q, *handlers, respect_handler_level=True)
    listener.start()

    def stop_once() -> None:
        if listener._thread is not None:  # stop() twice raises
            listener.stop()

    atexit.register(stop_once)
    return listener


class LineWriter:
    """Append lines to ``path`` from a writer thread; :meth:`write` never blocks.

    Lines are written in the order given and flushed as soon as the writer
    gets to them (readers poll the file); :meth:`close` writes every line
    given before it, then closes the file.
    """

    def __init__(self, path: str | os.PathLike[str]) -> None:
        self._fh: IO[str] = open(path, "a", encoding="utf-8")  # noqa: SIM115 - closed by close()
        self._q: queue.SimpleQueue[str | None] = queue.SimpleQueue()
        self._closed = False
        self._lock = threading.Lock()
        self._thread = threading.Thread(target=self._drain, name="line-writer", daemon=True)
        self._thread.start()

    def write(self, line: str) -> None:
        if not self._closed:
            self._q.put(line if line.endswith("\n") else line + "\n")

    def _drain(self) -> None:
        while True:
            line = self._q.get()
            batch = []
            while line is not None:
                batch.append(line)
                try:
                    line = self._q.get_nowait()
                except queue.Empty:
                    break
            if batch:
                self._fh.write("".join(batch))
                self._fh.flush()
            if line is None:
                return

    def close(self, timeout: float = 5.0) -> None:
        with self._lock:
            if self._closed:
                return
            self._closed = True
        self._q.put(None)
        self._thread.join(timeout)
        self._fh.close()
