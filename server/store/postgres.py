"""The PostgreSQL store (``STEELPATH_DATABASE_URL=postgresql://…``): psycopg 3 with a pool.

Same interface as the SQLite :class:`server.store.database.Database`, so
:class:`server.store.store.Store` and the stores built on ``store.db`` run
unchanged on both:

* ``?`` placeholders are rewritten to psycopg's ``%s`` (a ``?`` inside a quoted
  literal is left alone; a ``%`` is doubled so psycopg reads it literally);
* rows behave like :class:`sqlite3.Row` (by column name, by index, ``dict(row)``),
  without the ``rowid`` column the migrations add to stand in for SQLite's
  implicit one (:data:`server.store.migrations.ROWID_COLUMN`);
* a Python ``bool`` is sent as an integer, as SQLite stores it;
* a violated constraint raises :class:`server.store.database.IntegrityError`.

Writes keep SQLite's semantics: one writer at a time.  Every transaction takes
a transaction-scoped advisory lock first, so read-check-write sequences such as
:meth:`Store.transition_plan` stay atomic across every server sharing the
database, exactly as ``BEGIN IMMEDIATE`` makes them on SQLite; within one
process a lock keeps waiting writers from holding pooled connections.  Reads
outside a transaction go to any pooled connection and see the last commit; a
thread inside a transaction reads through its own connection and sees its
uncommitted rows.
"""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable, Iterator, Sequence
from contextlib import contextmanager
from functools import lru_cache
from typing import Any, Literal

import psycopg
from psycopg.adapt import Dumper
from psycopg.rows import RowMaker
from psycopg_pool import ConnectionPool

from server.store.database import IntegrityError
from server.store.migrations import migrate_postgres

log = logging.getLogger(__name__)

#: ``pg_advisory_xact_lock`` key every write transaction holds ("SteelWrt").
WRITE_LOCK = 0x537465656C577274

#: Pooled connections per :class:`PostgresDatabase` (reads run in parallel on
#: these; several servers each hold up to this many, within PostgreSQL's
#: default ``max_connections`` of 100).
POOL_MAX = 12

HIDDEN = "rowid"


class Row:
    """A result row read like :class:`sqlite3.Row`: ``row["col"]``, ``row[0]``,
    ``row.keys()``, ``dict(row)``, ``tuple(row)``."""

    __slots__ = ("_index", "_keys", "_values")

    def __init__(self, keys: tuple[str, ...], index: dict[str, int], values: tuple[Any, ...]):
        self._keys = keys
        self._index = index
        self._values = values

    def __getitem__(self, key: str | int) -> Any:
        if isinstance(key, str):
            try:
                return self._values[self._index[key]]
            except KeyError:
                raise IndexError(f"no column named {key!r}") from None
        return self._values[key]

    def keys(self) -> list[str]:
        return list(self._keys)

    def __iter__(self) -> Iterator[Any]:
        return iter(self._values)

    def __len__(self) -> int:
        return len(self._values)

    def __eq__(self, other: object) -> bool:
        if isinstance(other, Row):
            return self._keys == other._keys and self._values == other._values
        return NotImplemented

    def __hash__(self) -> int:
        return hash((self._keys, self._values))

    def __repr__(self) -> str:
        return f"Row({dict(zip(self._keys, self._values, strict=True))!r})"


def row_factory(cursor: psycopg.Cursor[Any]) -> RowMaker[Row]:
    """psycopg row factory making :class:`Row`\\ s, leaving out the hidden ``rowid``."""
    desc = cursor.description or []
    names = [d.name for d in desc]
    shown = [i for i, n in enumerate(names) if n != HIDDEN]
    keys = tuple(names[i] for i in shown)
    index = {k: i for i, k in enumerate(keys)}
    if len(shown) == len(names):
        return lambda values: Row(keys, index, tuple(values))
    return lambda values: Row(keys, index, tuple(values[i] for i in shown))


class _BoolAsInt(Dumper):
    """``True``/``False`` as ``1``/``0``: the schema's flags are INTEGER columns."""

    oid = psycopg.postgres.types["int8"].oid

    def dump(self, obj: Any) -> bytes:
        return b"1" if obj else b"0"


@lru_cache(maxsize=1024)
def to_pg(sql: str) -> str:
    """SQLite-style ``?`` placeholders → ``%s``; literal ``%`` → ``%%``.

    A ``?`` inside a single-quoted literal or a double-quoted identifier is kept.
    """
    out: list[str] = []
    quote: str | None = None
    for ch in sql:
        if ch == "%":
            out.append("%%")
            continue
        if quote is not None:
            if ch == quote:
                quote = None
        elif ch in ("'", '"'):
            quote = ch
        elif ch == "?":
            out.append("%s")
            continue
        out.append(ch)
    return "".join(out)


def _params(args: Sequence[Any] | None) -> Sequence[Any]:
    return () if args is None else args


class PgConnection:
    """What ``transaction()`` yields: ``execute``/``executemany`` with ``?`` placeholders."""

    def __init__(self, raw: psycopg.Connection[Row]) -> None:
        self.raw = raw

    def execute(self, sql: str, args: Sequence[Any] | None = ()) -> psycopg.Cursor[Row]:
        try:
            return self.raw.execute(to_pg(sql), _params(args))
        except psycopg.errors.IntegrityError as exc:
            raise IntegrityError(str(exc)) from exc

    def executemany(self, sql: str, seq: Sequence[Sequence[Any]]) -> psycopg.Cursor[Row]:
        cur = self.raw.cursor()
        try:
            cur.executemany(to_pg(sql), seq)
        except psycopg.errors.IntegrityError as exc:
            raise IntegrityError(str(exc)) from exc
        return cur


def _configure(conn: psycopg.Connection[Any]) -> None:
    conn.adapters.register_dumper(bool, _BoolAsInt)


def redact(url: str) -> str:
    """``url`` without its password, for logs and errors."""
    try:
        info = psycopg.conninfo.conninfo_to_dict(url)
    except psycopg.ProgrammingError:
        return "<unparsable database URL>"
    host = info.get("host", "localhost")
    return f"postgresql://{info.get('user', '')}@{host}:{info.get('port', 5432)}/{info.get('dbname', '')}"


class PostgresDatabase:
    """A pool of PostgreSQL connections behind the store's database interface."""

    dialect: Literal["sqlite", "postgresql"] = "postgresql"

    def __init__(
        self, url: str, *, migrate_to: int | None = None, max_size: int = POOL_MAX
    ) -> None:
        self.url = url
        self._pool: ConnectionPool[psycopg.Connection[Row]] = ConnectionPool(
            url,
            min_size=1,
            max_size=max_size,
            kwargs={"autocommit": True, "row_factory": row_factory},
            configure=_configure,
            name="steelpath-store",
            open=False,
        )
        self._pool.open(wait=True, timeout=30.0)
        try:
            with self._pool.connection() as conn:
                if migrate_to is None:
                    migrate_postgres(conn)
                else:
                    migrate_postgres(conn, migrate_to)
        except BaseException:
            self._pool.close()
            raise
        self._local = threading.local()
        self._write_lock = threading.Lock()
        log.info("store: PostgreSQL at %s", redact(url))

    def _tx(self) -> PgConnection | None:
        tx: PgConnection | None = getattr(self._local, "tx", None)
        return tx

    @contextmanager
    def transaction(self) -> Iterator[PgConnection]:
        """``BEGIN`` + the write lock … ``COMMIT``; rolls back on any exception.
        Nested use joins the outer transaction, as on SQLite."""
        current = self._tx()
        if current is not None:
            yield current
            return
        with self._write_lock, self._pool.connection() as raw:
            try:
                with raw.transaction():
                    raw.execute("SELECT pg_advisory_xact_lock(%s)", (WRITE_LOCK,))
                    tx = PgConnection(raw)
                    self._local.tx = tx
                    try:
                        yield tx
                    finally:
                        self._local.tx = None
            except psycopg.errors.IntegrityError as exc:  # e.g. raised by COMMIT
                raise IntegrityError(str(exc)) from exc

    def _run(
        self, sql: str, args: Sequence[Any], fetch: Callable[[psycopg.Cursor[Row]], Any]
    ) -> Any:
        tx = self._tx()
        if tx is not None:
            return fetch(tx.execute(sql, args))
        if not _is_read(sql):
            with self.transaction() as conn:
                return fetch(conn.execute(sql, args))
        with self._pool.connection() as raw:
            return fetch(raw.execute(to_pg(sql), args))

    def query(self, sql: str, args: tuple[Any, ...] | list[Any] = ()) -> list[Row]:
        rows: list[Row] = self._run(
            sql, args, lambda cur: cur.fetchall() if cur.description is not None else []
        )
        return rows

    def query_one(self, sql: str, args: tuple[Any, ...] | list[Any] = ()) -> Row | None:
        row: Row | None = self._run(
            sql, args, lambda cur: cur.fetchone() if cur.description is not None else None
        )
        return row

    def columns(self, table: str) -> list[str]:
        """``table``'s column names in schema order (without the hidden ``rowid``)."""
        rows = self.query(
            "SELECT column_name FROM information_schema.columns "
            "WHERE table_schema = current_schema() AND table_name = ? AND column_name <> ? "
            "ORDER BY ordinal_position",
            (table, HIDDEN),
        )
        return [str(r[0]) for r in rows]

    def close(self) -> None:
        self._pool.close()


def _is_read(sql: str) -> bool:
    """A plain ``SELECT`` (anything else runs as a write transaction)."""
    return sql.lstrip()[:6].upper() == "SELECT"
