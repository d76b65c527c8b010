"""Output of real-time threads never blocks them (robots/background_io.py)."""

from __future__ import annotations

import logging
import os
import threading

from robots.background_io import LineWriter, log_through_a_queue


def test_line_writer_returns_while_the_file_cannot_take_more(tmp_path) -> None:
    fifo = tmp_path / "pipe"
    os.mkfifo(fifo)
    reader = os.open(fifo, os.O_RDONLY | os.O_NONBLOCK)
    try:
        w = LineWriter(fifo)
        lines = [f"{i:06d} " + "x" * 200 for i in range(2000)]  # ~400 KiB: 6× a pipe's buffer
        done = threading.Event()

        def produce() -> None:
            for line in lines:
                w.write(line)
            done.set()

        threading.Thread(target=produce, daemon=True).start()
        # Nobody reads the pipe yet, so its writer is blocked in write(); the
        # producer (a link or emulator loop) must still get through.
        assert done.wait(10), "LineWriter.write blocked on a full pipe"
        got = b""
        os.set_blocking(reader, True)
        closer = threading.Thread(target=w.close, kwargs={"timeout": 30}, daemon=True)
        closer.start()
        while True:
            chunk = os.read(reader, 65536)
            if not chunk:
                break
            got += chunk
        closer.join(30)
        assert got.decode().splitlines() == lines
    finally:
        os.close(reader)


def test_line_writer_close_writes_everything_in_order(tmp_path) -> None:
    path = tmp_path / "log.jsonl"
    path.write_text("old\n")
    w = LineWriter(path)
    for i in range(500):
        w.write(str(i))
    w.close()
    w.write("after close")  # dropped, not an error
    assert path.read_text().splitlines() == ["old", *map(str, range(500))]


def test_log_records_go_through_a_queue_to_the_same_handlers(tmp_path) -> None:
    root = logging.getLogger()
    saved = list(root.handlers)
    target = logging.FileHandler(tmp_path / "out.log")
    for h in saved:
        root.removeHandler(h)
    root.addHandler(target)
    try:
        listener = log_through_a_queue()
        assert [type(h).__name__ for h in root.handlers] == ["QueueHandler"]
        logging.getLogger("steelpath.test").warning("through the queue %d", 7)
        listener.stop()  # drains the queue
        assert "through the queue 7" in (tmp_path / "out.log").read_text()
    finally:
        for h in list(root.handlers):
            root.removeHandler(h)
        target.close()
        for h in saved:
            root.addHandler(h)
