"""The SQLite connection: WAL mode, migrations, serialised transactions.

This is the embedded default store; :func:`open_database` picks it, or the
PostgreSQL one (:mod:`server.store.postgres`) when a ``postgresql://`` URL is
configured.  Both offer the same interface (``transaction``, ``query``,
``query_one``, ``columns``, ``close``, ``dialect``) and raise
:class:`IntegrityError` for a violated constraint.

The database holds token hashes and the audit trail, so it is private to the
service's user: the data directory is 0700 and the database with its WAL and
shared-memory files 0600, enforced on every open (a directory or file left
looser by an older version or a careless copy is tightened, and logged).
"""

from __future__ import annotations

import logging
import os
import sqlite3
import stat
import threading
import weakref
from collections.abc import Iterator
from contextlib import AbstractContextManager, contextmanager
from datetime import UTC, datetime
from pathlib import Path
from typing import Any, Literal, Protocol

from server.store.migrations import migrate

log = logging.getLogger(__name__)

DIR_MODE = 0o700
FILE_MODE = 0o600


class IntegrityError(sqlite3.IntegrityError):
    """A unique, foreign-key or not-null constraint was violated, on either backend.

    A subclass of :class:`sqlite3.IntegrityError` so code written against the
    SQLite store keeps catching it; the PostgreSQL store raises it too.
    """


class RowLike(Protocol):
    """A result row of either backend (:class:`sqlite3.Row` or
    :class:`server.store.postgres.Row`): by column name or index, or ``dict(row)``."""

    def keys(self) -> list[str]: ...

    def __getitem__(self, key: str | int, /) -> Any: ...


class StoreDatabase(Protocol):
    """What the stores need of a database; SQLite's :class:`Database` and
    :class:`~server.store.postgres.PostgresDatabase` both provide it.

    SQL is written with ``?`` placeholders in the dialect both accept; where
    they differ, code branches on ``dialect``.  Rows are read by column name
    or index, or turned into a dict.
    """

    @property
    def dialect(self) -> Literal["sqlite", "postgresql"]: ...

    def transaction(self) -> AbstractContextManager[Any]: ...

    def query(self, sql: str, args: tuple[Any, ...] | list[Any] = ()) -> list[Any]: ...

    def query_one(self, sql: str, args: tuple[Any, ...] | list[Any] = ()) -> Any: ...

    def columns(self, table: str) -> list[str]: ...

    def close(self) -> None: ...


def open_database(
    data_dir: Path, database_url: str | None = None, *, migrate_to: int | None = None
) -> StoreDatabase:
    """The store's database: PostgreSQL for a ``postgresql://`` URL, else SQLite
    under ``data_dir`` (psycopg is only imported when PostgreSQL is asked for)."""
    if database_url:
        if not database_url.startswith(("postgresql://", "postgres://")):
            raise ValueError(
                f"database_url {database_url.split('@')[-1]!r} is not a postgresql:// URL "
                "(unset it to keep SQLite under the data directory)"
            )
        from server.store.postgres import PostgresDatabase

        return PostgresDatabase(database_url, migrate_to=migrate_to)
    return Database(Path(data_dir) / "steelpath.sqlite3", migrate_to=migrate_to)


def utcnow() -> str:
    return datetime.now(UTC).isoformat(timespec="milliseconds")


def _tighten(path: Path, mode: int) -> None:
    """chmod ``path`` to ``mode`` if its permission bits differ; log the change."""
    try:
        current = stat.S_IMODE(path.stat().st_mode)
    except FileNotFoundError:
        return
    if current == mode:
        return
    try:
        os.chmod(path, mode)
    except OSError as exc:  # not our file (e.g. a mounted volume): say so, keep going
        log.warning("cannot set %s to %o (it is %o): %s", path, mode, current, exc)
        return
    log.warning("tightened permissions of %s from %o to %o", path, current, mode)


def ensure_private_dir(path: Path) -> None:
    """Create ``path`` (and parents) with the leaf at mode 0700; fix an existing one."""
    path = Path(path)
    path.mkdir(parents=True, exist_ok=True, mode=DIR_MODE)
    _tighten(path, DIR_MODE)


def secure_database_files(path: Path) -> None:
    """Mode 0600 for the database file and its ``-wal``/``-shm`` companions."""
    for p in (path, Path(f"{path}-wal"), Path(f"{path}-shm")):
        _tighten(p, FILE_MODE)


class Database:
    """One SQLite writer connection shared by the service's threads, a reader per thread.

    SQLite serialises writers anyway; one writer connection behind a
    re-entrant lock keeps transactions simple and avoids ``database is
    locked`` between our own threads, and ``synchronous=FULL`` makes every
    commit durable.  Reads (``SELECT``) go to a read-only connection of the
    calling thread, so under WAL they see the last commit without waiting for
    a writer: with one shared connection every API read queued behind each
    plan result, upload row and robot-state write, which is what made reads
    take seconds on a busy server.  A thread inside a transaction reads
    through the writer, so it sees its own uncommitted rows.
    """

    dialect: Literal["sqlite", "postgresql"] = "sqlite"

    def __init__(self, path: Path, *, migrate_to: int | None = None) -> None:
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True, mode=DIR_MODE)
        if not self.path.exists():
            # Created 0600 before SQLite opens it: SQLite gives the WAL and
            # shm files the database file's mode, so they start private too.
            os.close(os.open(self.path, os.O_WRONLY | os.O_CREAT, FILE_MODE))
        self._lock = threading.RLock()
        self._conn = sqlite3.connect(
            self.path, check_same_thread=False, isolation_level=None, timeout=30.0
        )
        self._conn.row_factory = sqlite3.Row
        self._conn.execute("PRAGMA journal_mode=WAL")
        self._conn.execute("PRAGMA synchronous=FULL")
        self._conn.execute("PRAGMA foreign_keys=ON")
        with self._lock:
            if migrate_to is None:
                migrate(self._conn)
            else:
                migrate(self._conn, migrate_to)
        secure_database_files(self.path)  # the -wal/-shm exist once WAL has written
        self._local = threading.local()
        # Weak: a reader is freed (and closed) with its thread's locals, e.g.
        # when an idle worker thread ends; close() closes those still alive.
        self._readers: weakref.WeakSet[_Reader] = weakref.WeakSet()
        self._readers_lock = threading.Lock()
        self._writer_thread: int | None = None
        self._closed = False

    def _reader(self) -> sqlite3.Connection | None:
        """This thread's read-only connection; ``None`` when the writer must serve the read."""
        if self._writer_thread == threading.get_ident() or self._closed:
            return None
        reader: _Reader | None = getattr(self._local, "reader", None)
        if reader is None:
            conn = sqlite3.connect(
                self.path, check_same_thread=False, isolation_level=None, timeout=30.0
            )
            conn.row_factory = sqlite3.Row
            conn.execute("PRAGMA query_only=1")
            conn.execute("PRAGMA cache_size=-1024")  # 1 MiB a thread, not the 2 MiB default
            reader = _Reader(conn)
            # Closed when its thread's locals drop it: a connection sits in a
            # reference cycle (its statement cache), so left to the garbage
            # collector its file descriptors would outlive the thread, for
            # good once gc.freeze() (server.app) has made the cycle permanent.
            weakref.finalize(reader, conn.close)
            with self._readers_lock:
                if self._closed:
                    conn.close()
                    return None
                self._readers.add(reader)
            self._local.reader = reader
        return reader.conn

    @property
    def journal_mode(self) -> str:
        return str(self._conn.execute("PRAGMA journal_mode").fetchone()[0])

    @contextmanager
    def transaction(self) -> Iterator[sqlite3.Connection]:
        """``BEGIN IMMEDIATE`` … ``COMMIT``; rolls back on any exception."""
        with self._lock:
            if self._conn.in_transaction:
                # Nested use joins the outer transaction.
                yield self._conn
                return
            self._conn.execute("BEGIN IMMEDIATE")
            self._writer_thread = threading.get_ident()
            try:
                yield self._conn
            except sqlite3.IntegrityError as exc:
                self._conn.execute("ROLLBACK")
                if isinstance(exc, IntegrityError):
                    raise
                raise IntegrityError(*exc.args) from exc
            except BaseException:
                self._conn.execute("ROLLBACK")
                raise
            else:
                self._conn.execute("COMMIT")
            finally:
                self._writer_thread = None

    def query(self, sql: str, args: tuple[Any, ...] | list[Any] = ()) -> list[sqlite3.Row]:
        reader = self._reader() if _is_read(sql) else None
        if reader is not None:
            return list(reader.execute(sql, args).fetchall())
        with self._lock:
            try:
                return list(self._conn.execute(sql, args).fetchall())
            except sqlite3.IntegrityError as exc:
                if isinstance(exc, IntegrityError):
                    raise
                raise IntegrityError(*exc.args) from exc

    def query_one(self, sql: str, args: tuple[Any, ...] | list[Any] = ()) -> sqlite3.Row | None:
        reader = self._reader() if _is_read(sql) else None
        if reader is not None:
            row: sqlite3.Row | None = reader.execute(sql, args).fetchone()
            return row
        with self._lock:
            return self._conn.execute(sql, args).fetchone()

    def columns(self, table: str) -> list[str]:
        """``table``'s column names in schema order."""
        return [str(r["name"]) for r in self.query(f"PRAGMA table_info({table})")]

    def close(self) -> None:
        with self._readers_lock:
            self._closed = True
            readers = list(self._readers)
        for reader in readers:
            reader.conn.close()
        with self._lock:
            self._conn.close()


class _Reader:
    """A thread's read-only connection (a holder, as connections take no weak references)."""

    __slots__ = ("__weakref__", "conn")

    def __init__(self, conn: sqlite3.Connection) -> None:
        self.conn = conn


def _is_read(sql: str) -> bool:
    """A plain ``SELECT`` (anything else, a write or a PRAGMA, goes to the writer)."""
    return sql.lstrip()[:6].upper() == "SELECT"
