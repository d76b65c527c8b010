"""Whole rows in and out of the store's database for a plan's export and import.

Rows are read with ``SELECT *`` and written back by column name, so a column
added to ``findings`` (or any table listed in :data:`TABLES`) by a later
migration travels in an archive without this module changing.  An import
writes every row in one transaction (:meth:`ArchiveStore.write`); a row that
carries a non-null value for a column this server's schema lacks is refused
(:class:`UnknownColumnsError`) rather than silently dropped.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

from server.store.database import StoreDatabase

#: Tables whose rows an archive carries, with the column that keys each lookup.
TABLES: dict[str, tuple[str, ...]] = {
    "plans": ("id",),
    "clouds": ("id",),
    "executions": ("id", "plan_id"),
    "execution_acks": ("execution_id",),
    "execution_states": ("execution_id",),
    "findings": ("id", "plan_id"),
    "finding_photos": ("id", "finding_id"),
    "finding_plans": ("finding_id", "plan_id"),
    "audit_events": ("entity",),
}


class UnknownColumnsError(ValueError):
    """A row has values for columns this server's schema does not have."""


class IdConflictError(ValueError):
    """A row with that id already exists here; ``table`` and ``ids`` say which."""

    def __init__(self, table: str, ids: Sequence[str]) -> None:
        self.table = table
        self.ids = list(ids)
        super().__init__(f"{table} already has {', '.join(self.ids)}")


def _check(table: str, column: str) -> None:
    if column not in TABLES.get(table, ()):
        raise ValueError(f"no archive lookup of {table}.{column}")


class ArchiveStore:
    """Generic row reads and the all-or-nothing write of an import."""

    def __init__(self, db: StoreDatabase) -> None:
        self.db = db

    def columns(self, table: str) -> list[str]:
        """The table's columns in this server's schema."""
        if table not in TABLES:
            raise ValueError(f"table {table!r} is not archived")
        return self.db.columns(table)

    def rows(self, table: str, column: str, values: Iterable[str]) -> list[dict[str, Any]]:
        """Every row of ``table`` whose ``column`` is one of ``values``, as dicts
        (``rowid`` order: the order they were written)."""
        _check(table, column)
        vals = list(values)
        if not vals:
            return []
        marks = ",".join("?" * len(vals))
        sql = f"SELECT * FROM {table} WHERE {column} IN ({marks}) ORDER BY rowid"
        return [dict(r) for r in self.db.query(sql, vals)]

    def existing(self, table: str, ids: Iterable[str]) -> list[str]:
        """Which of ``ids`` are already rows of ``table``."""
        _check(table, "id")
        vals = list(ids)
        if not vals:
            return []
        marks = ",".join("?" * len(vals))
        rows = self.db.query(f"SELECT id FROM {table} WHERE id IN ({marks})", vals)
        return sorted(str(r["id"]) for r in rows)

    def write(
        self,
        rows: Mapping[str, Sequence[Mapping[str, Any]]],
        *,
        must_be_new: Mapping[str, Sequence[str]],
        before_commit: Callable[[], None] | None = None,
    ) -> None:
        """Insert ``rows`` (table → rows, in the mapping's order) in one transaction.

        ``must_be_new`` (table → ids) is checked inside the transaction first:
        any id already present raises :class:`IdConflictError` and nothing is
        written.  ``before_commit`` runs after the inserts, before the commit
        (an import moves its files into place there); if it or anything else
        raises, the transaction rolls back.
        """
        with self.db.transaction() as conn:
            for table, ids in must_be_new.items():
                taken = self._existing(conn, table, ids)
                if taken:
                    raise IdConflictError(table, taken)
            for table, table_rows in rows.items():
                known = set(self.columns(table))
                for row in table_rows:
                    self._insert(conn, table, known, row)
            if before_commit is not None:
                before_commit()

    @staticmethod
    def _existing(conn: Any, table: str, ids: Sequence[str]) -> list[str]:
        _check(table, "id")
        if not ids:
            return []
        marks = ",".join("?" * len(ids))
        found = conn.execute(f"SELECT id FROM {table} WHERE id IN ({marks})", list(ids))
        return sorted(str(r[0]) for r in found.fetchall())

    @staticmethod
    def _insert(conn: Any, table: str, known: set[str], row: Mapping[str, Any]) -> None:
        unknown = sorted(k for k, v in row.items() if k not in known and v is not None)
        if unknown:
            raise UnknownColumnsError(
                f"{table} rows in the archive have columns this server does not know: "
                f"{', '.join(unknown)} (exported by a newer SteelPath; upgrade this one)"
            )
        cols = [k for k in row if k in known]
        marks = ",".join("?" * len(cols))
        conn.execute(
            f"INSERT INTO {table} ({', '.join(cols)}) VALUES ({marks})", [row[k] for k in cols]
        )
