"""Reads do not queue behind a write transaction; a writer sees its own rows.

Ordering assertions (events), not timings: a thread holds a write
transaction open on purpose while another thread reads.
"""

from __future__ import annotations

import gc
import threading
from collections.abc import Iterator
from pathlib import Path

import pytest

from server.store.database import Database


@pytest.fixture
def db(tmp_path: Path) -> Iterator[Database]:
    d = Database(tmp_path / "x.sqlite3")
    d.query("CREATE TABLE IF NOT EXISTS t (k TEXT PRIMARY KEY, v INTEGER)")
    d.query("INSERT INTO t VALUES ('a', 1)")
    yield d
    d.close()


def test_a_read_completes_while_another_thread_holds_a_write_transaction(db: Database) -> None:
    inside, release, done = threading.Event(), threading.Event(), threading.Event()

    def writer() -> None:
        with db.transaction() as conn:
            conn.execute("UPDATE t SET v = 2 WHERE k = 'a'")
            conn.execute("INSERT INTO t VALUES ('b', 3)")
            inside.set()
            release.wait(30)
        done.set()

    th = threading.Thread(target=writer)
    th.start()
    try:
        assert inside.wait(30)
        # With one shared connection this read waited for the writer's lock.
        rows = db.query("SELECT k, v FROM t ORDER BY k")
        assert not done.is_set()  # the writer is still inside its transaction
        assert [tuple(r) for r in rows] == [("a", 1)]  # the last commit, not the pending one
        assert db.query_one("SELECT v FROM t WHERE k = 'a'")["v"] == 1
    finally:
        release.set()
        th.join(30)
    assert [tuple(r) for r in db.query("SELECT k, v FROM t ORDER BY k")] == [("a", 2), ("b", 3)]


def test_a_thread_in_a_transaction_reads_its_own_rows(db: Database) -> None:
    with db.transaction() as conn:
        conn.execute("INSERT INTO t VALUES ('c', 9)")
        assert db.query_one("SELECT v FROM t WHERE k = 'c'")["v"] == 9
        assert len(db.query("SELECT * FROM t")) == 2


def test_writes_through_query_still_work_and_readers_are_read_only(db: Database) -> None:
    db.query("UPDATE t SET v = 5 WHERE k = 'a'")  # not a SELECT: the writer runs it
    assert db.query_one("SELECT v FROM t WHERE k = 'a'")["v"] == 5
    reader = db._reader()
    assert reader is not None
    with pytest.raises(Exception, match="readonly"):
        reader.execute("UPDATE t SET v = 6 WHERE k = 'a'")


def test_a_finished_threads_reader_is_released(db: Database) -> None:
    def read() -> None:
        db.query("SELECT 1")

    for _ in range(20):
        th = threading.Thread(target=read)
        th.start()
        th.join()
    gc.collect()
    assert len(db._readers) == 0
    db.query("SELECT 1")
    assert len(db._readers) == 1  # this thread's, until close()
