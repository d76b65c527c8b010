"""Forward-only schema migrations, one set for SQLite and PostgreSQL.

Append a new script to :data:`MIGRATIONS` to change the schema; never edit a
released one.  Each script runs in its own transaction with the version bump,
so a crash mid-migration leaves the previous version intact.

The scripts are written in SQLite's dialect.  SQLite tracks the version in
``PRAGMA user_version``; PostgreSQL in a one-row ``schema_version`` table, and
gets each script translated mechanically by :func:`postgres_statements` (type
names, ``AUTOINCREMENT``, and a ``rowid`` column standing in for SQLite's
implicit one), never rewritten by hand, so both schemas mean the same.  Servers
that start at once against one PostgreSQL take turns on a transaction-scoped
advisory lock: one migrates, the others find the work done.
"""

from __future__ import annotations

import re
import sqlite3
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:
    import psycopg

MIGRATIONS: list[str] = [
    # 1: core tables
    """
    CREATE TABLE clouds (
        id TEXT PRIMARY KEY,
        name TEXT NOT NULL,
        source TEXT NOT NULL,
        n_points INTEGER NOT NULL,
        bounds TEXT NOT NULL,
        dropped INTEGER NOT NULL DEFAULT 0,
        array_file TEXT NOT NULL,
        created_at TEXT NOT NULL,
        created_by TEXT NOT NULL
    );
    CREATE TABLE plans (
        id TEXT PRIMARY KEY,
        kind TEXT NOT NULL,
        state TEXT NOT NULL,
        params TEXT NOT NULL,
        parent_id TEXT REFERENCES plans(id) ON DELETE SET NULL,
        progress REAL NOT NULL DEFAULT 0,
        stage TEXT NOT NULL DEFAULT '',
        result TEXT,
        metrics TEXT,
        checks TEXT,
        arrays TEXT,
        error TEXT,
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL,
        created_by TEXT NOT NULL,
        approved_by TEXT,
        approved_at TEXT
    );
    CREATE TABLE executions (
        id TEXT PRIMARY KEY,
        plan_id TEXT NOT NULL REFERENCES plans(id),
        robot TEXT NOT NULL,
        state TEXT NOT NULL,
        acked INTEGER NOT NULL DEFAULT 0,
        total INTEGER NOT NULL DEFAULT 0,
        error TEXT,
        created_at TEXT NOT NULL,
        updated_at TEXT NOT NULL,
        created_by TEXT NOT NULL
    );
    CREATE TABLE audit_events (
        id INTEGER PRIMARY KEY AUTOINCREMENT,
        ts TEXT NOT NULL,
        actor TEXT NOT NULL,
        entity TEXT NOT NULL,
        entity_id TEXT NOT NULL,
        action TEXT NOT NULL,
        from_state TEXT,
        to_state TEXT,
        reason TEXT NOT NULL DEFAULT ''
    );
    CREATE TABLE tokens (
        id TEXT PRIMARY KEY,
        name TEXT NOT NULL,
        role TEXT NOT NULL,
        hash TEXT NOT NULL UNIQUE,
        created_at TEXT NOT NULL,
        revoked_at TEXT
    );
    CREATE TABLE robots (
        name TEXT PRIMARY KEY,
        url TEXT NOT NULL,
        updated_at TEXT NOT NULL,
        updated_by TEXT NOT NULL
    );
    """,
    # 2: indexes for the list filters and the audit trail
    """
    CREATE INDEX plans_state ON plans(state);
    CREATE INDEX plans_kind ON plans(kind);
    CREATE INDEX plans_parent ON plans(parent_id);
    CREATE INDEX audit_entity ON audit_events(entity, entity_id);
    CREATE INDEX executions_plan ON executions(plan_id);
    """,
    # 3: dispatch: compiled programs, resumable executions, ack log, robot state mirror
    """
    ALTER TABLE plans ADD COLUMN program TEXT;
    ALTER TABLE executions ADD COLUMN run_id INTEGER NOT NULL DEFAULT 0;
    ALTER TABLE executions ADD COLUMN fault TEXT;
    CREATE TABLE execution_acks (
        execution_id TEXT NOT NULL REFERENCES executions(id) ON DELETE CASCADE,
        idx INTEGER NOT NULL,
        ts TEXT NOT NULL,
        PRIMARY KEY (execution_id, idx)
    );
    CREATE TABLE robot_states (
        name TEXT PRIMARY KEY,
        state TEXT NOT NULL,
        updated_at TEXT NOT NULL
    );
    """,
    # 4: token lifetime: optional expiry (ISO-8601 UTC; NULL = never expires)
    """
    ALTER TABLE tokens ADD COLUMN expires_at TEXT;
    """,
    # 5: clouds: how an upload was read (format, units and how they were decided,
    # scale applied, measured spacing), JSON
    """
    ALTER TABLE clouds ADD COLUMN survey TEXT NOT NULL DEFAULT '{}';
    """,
    # 6: webhooks (admin-configured receivers) and their deliveries (retried,
    # listed); a removed webhook keeps its row and deliveries (removed_at)
    """
    CREATE TABLE webhooks (
        id TEXT PRIMARY KEY,
        url TEXT NOT NULL,
        events TEXT NOT NULL,
        secret TEXT NOT NULL,
        created_by TEXT NOT NULL,
        created_at TEXT NOT NULL,
        removed_at TEXT,
        removed_by TEXT
    );
    CREATE TABLE webhook_deliveries (
        id TEXT PRIMARY KEY,
        webhook_id TEXT NOT NULL REFERENCES webhooks(id),
        event TEXT NOT NULL,
        payload TEXT NOT NULL,
        state TEXT NOT NULL,
        attempts INTEGER NOT NULL DEFAULT 0,
        next_at REAL,
        last_status INTEGER,
        last_error TEXT,
        created_at TEXT NOT NULL,
        delivered_at TEXT
    );
    CREATE INDEX webhook_deliveries_due ON webhook_deliveries (state, next_at);
    """,
    # 7: recorded runs: the robot's state reports while an execution is active
    """
    CREATE TABLE execution_states (
        execution_id TEXT NOT NULL REFERENCES executions(id) ON DELETE CASCADE,
        t REAL NOT NULL,
        state TEXT NOT NULL
    );
    CREATE INDEX execution_states_by_execution ON execution_states (execution_id, t);
    """,
    # 8: findings on the structure, and their photos (files under photos/)
    """
    CREATE TABLE findings (
        id TEXT PRIMARY KEY,
        plan_id TEXT NOT NULL,
        member_id INTEGER,
        face_id INTEGER,
        cluster_id INTEGER,
        point_m TEXT,
        region_m TEXT,
        type TEXT NOT NULL,
        condition_state INTEGER NOT NULL,
        notes TEXT NOT NULL DEFAULT '',
        created_by TEXT NOT NULL,
        created_at TEXT NOT NULL,
        updated_by TEXT,
        updated_at TEXT,
        deleted_by TEXT,
        deleted_at TEXT,
        deleted_reason TEXT
    );
    CREATE INDEX findings_by_plan ON findings (plan_id, member_id);
    CREATE TABLE finding_photos (
        id TEXT PRIMARY KEY,
        finding_id TEXT NOT NULL REFERENCES findings(id),
        filename TEXT NOT NULL,
        content_type TEXT NOT NULL,
        size INTEGER NOT NULL,
        created_by TEXT NOT NULL,
        created_at TEXT NOT NULL
    );
    """,
    # 9: maintenance plans made from a finding, and what their runs achieved
    """
    CREATE TABLE finding_plans (
        plan_id TEXT PRIMARY KEY,
        finding_id TEXT NOT NULL REFERENCES findings(id),
        kind TEXT NOT NULL,
        created_by TEXT NOT NULL,
        created_at TEXT NOT NULL,
        execution_id TEXT,
        outcome TEXT,
        coverage_pct REAL,
        spots_done INTEGER,
        spots_planned INTEGER,
        review_requested_at TEXT,
        reviewed_at TEXT
    );
    CREATE INDEX finding_plans_by_finding ON finding_plans (finding_id);
    """,
    # 10: beyond one machine: planning attempts and cancel requests that any
    # server's or Dask worker's job reads from the store; the servers sharing this store
    # and which of them owns each robot link (a lease renewed with the heartbeat)
    """
    ALTER TABLE plans ADD COLUMN attempts INTEGER NOT NULL DEFAULT 0;
    ALTER TABLE plans ADD COLUMN cancel_requested INTEGER NOT NULL DEFAULT 0;
    ALTER TABLE plans ADD COLUMN worker TEXT;
    CREATE TABLE servers (
        id TEXT PRIMARY KEY,
        url TEXT NOT NULL,
        started_at TEXT NOT NULL,
        heartbeat_at REAL NOT NULL
    );
    CREATE TABLE robot_leases (
        name TEXT PRIMARY KEY,
        server_id TEXT NOT NULL,
        expires_at REAL NOT NULL,
        taken_at TEXT NOT NULL
    );
    """,
    # 11: which server runs each plan's planning job, so that servers sharing the
    # store adopt only the plans of a server that died (server/store/plan_owners.py);
    # E-stops that reached no server, latched by the robot's next owner
    """
    ALTER TABLE plans ADD COLUMN planner TEXT;
    CREATE TABLE estop_pending (
        robot TEXT PRIMARY KEY,
        at TEXT NOT NULL,
        actor TEXT NOT NULL,
        reason TEXT NOT NULL
    );
    """,
    # 12: webhooks an admin lets deliver to loopback and private networks (lab
    # receivers on the LAN; server/netpolicy.py); 0 = public addresses only
    """
    ALTER TABLE webhooks ADD COLUMN allow_private_network INTEGER NOT NULL DEFAULT 0;
    """,
    # 13: what the robot's camera saw (server/captures): one row per sensor frame a
    # ``capture`` command brought back; its points are .npy files under captures/
    """
    CREATE TABLE execution_captures (
        execution_id TEXT NOT NULL REFERENCES executions(id) ON DELETE CASCADE,
        capture_id INTEGER NOT NULL,
        run_id INTEGER NOT NULL,
        command_index INTEGER NOT NULL,
        t_robot_s REAL NOT NULL,
        received_at REAL NOT NULL,
        position_m TEXT NOT NULL,
        rotation TEXT NOT NULL,
        n_points INTEGER NOT NULL,
        complete INTEGER NOT NULL DEFAULT 1,
        points_file TEXT NOT NULL,
        intensity_file TEXT,
        meta TEXT NOT NULL DEFAULT '{}',
        created_at TEXT NOT NULL,
        PRIMARY KEY (execution_id, capture_id)
    );
    CREATE INDEX execution_captures_by_time ON execution_captures (execution_id, received_at);
    """,
    # 14: clouds: the coordinate reference system the upload named (WKT; NULL: none),
    # kept for exports, and its per-point attributes (JSON: name → array file beside the
    # points, e.g. {"intensity": "clouds/<id>.intensity.npy"})
    """
    ALTER TABLE clouds ADD COLUMN crs_wkt TEXT;
    ALTER TABLE clouds ADD COLUMN attributes TEXT NOT NULL DEFAULT '{}';
    """,
]

SCHEMA_VERSION = len(MIGRATIONS)


class SchemaTooNewError(RuntimeError):
    """The database was written by a newer SteelPath than this one."""


def _too_new(version: int) -> SchemaTooNewError:
    return SchemaTooNewError(
        f"database schema version {version} is newer than this SteelPath "
        f"understands ({SCHEMA_VERSION}); upgrade SteelPath or use another database"
    )


def current_version(conn: sqlite3.Connection) -> int:
    return int(conn.execute("PRAGMA user_version").fetchone()[0])


def migrate(conn: sqlite3.Connection, target: int = SCHEMA_VERSION) -> int:
    """Apply migrations up to ``target``; return the version reached."""
    version = current_version(conn)
    if version > SCHEMA_VERSION:
        raise _too_new(version)
    while version < target:
        script = MIGRATIONS[version]
        statements = [s.strip() for s in script.split(";") if s.strip()]
        conn.execute("BEGIN IMMEDIATE")
        try:
            for stmt in statements:
                conn.execute(stmt)
            conn.execute(f"PRAGMA user_version = {version + 1}")
            conn.execute("COMMIT")
        except BaseException:
            conn.execute("ROLLBACK")
            raise
        version += 1
    return version


# ------------------------------------------------------------------ PostgreSQL

#: ``pg_advisory_xact_lock`` key held while checking and applying migrations
#: (any fixed 64-bit number no other code uses; this is "SteelPth" in ASCII).
MIGRATION_LOCK = 0x537465656C507468 & 0x7FFFFFFFFFFFFFFF

#: The hidden column that stands in for SQLite's implicit ``rowid`` (insertion
#: order, used by ``ORDER BY rowid``); PostgreSQL rows leave it out of ``SELECT *``
#: results (:mod:`server.store.postgres`) as SQLite does.
ROWID_COLUMN = "rowid BIGINT GENERATED ALWAYS AS IDENTITY"

_CREATE_TABLE = re.compile(r"^\s*CREATE\s+TABLE\s", re.IGNORECASE)
_TYPES = (
    (
        re.compile(r"\bINTEGER\s+PRIMARY\s+KEY\s+AUTOINCREMENT\b", re.IGNORECASE),
        "BIGINT GENERATED BY DEFAULT AS IDENTITY PRIMARY KEY",
    ),
    # SQLite integers are 64-bit; PostgreSQL's INTEGER is 32.
    (re.compile(r"\bINTEGER\b", re.IGNORECASE), "BIGINT"),
    # SQLite REAL is an 8-byte float; PostgreSQL's REAL is 4 bytes.
    (re.compile(r"\bREAL\b", re.IGNORECASE), "DOUBLE PRECISION"),
)


def postgres_statements(script: str) -> list[str]:
    """``script`` (SQLite dialect) as PostgreSQL statements: type names mapped,
    and every ``CREATE TABLE`` given a trailing :data:`ROWID_COLUMN`."""
    out: list[str] = []
    for stmt in (s.strip() for s in script.split(";")):
        if not stmt:
            continue
        for pattern, replacement in _TYPES:
            stmt = pattern.sub(replacement, stmt)
        if _CREATE_TABLE.match(stmt):
            body = stmt.rstrip()
            if not body.endswith(")"):
                raise ValueError(f"cannot translate CREATE TABLE without a closing ')': {stmt}")
            stmt = f"{body[:-1].rstrip()},\n    {ROWID_COLUMN}\n)"
        out.append(stmt)
    return out


def current_version_postgres(conn: psycopg.Connection[Any]) -> int:
    """The version in ``schema_version`` (0 for a database SteelPath never wrote)."""
    exists = conn.execute("SELECT to_regclass('schema_version') IS NOT NULL").fetchone()
    if not exists or not exists[0]:
        return 0
    row = conn.execute("SELECT version FROM schema_version").fetchone()
    return 0 if row is None else int(row[0])


def migrate_postgres(conn: psycopg.Connection[Any], target: int = SCHEMA_VERSION) -> int:
    """Apply migrations up to ``target`` on an autocommit PostgreSQL connection;
    return the version reached.  One transaction per migration, each under
    :data:`MIGRATION_LOCK`, re-reading the version once it holds the lock."""
    with conn.transaction():
        conn.execute("SELECT pg_advisory_xact_lock(%s)", (MIGRATION_LOCK,))
        conn.execute("CREATE TABLE IF NOT EXISTS schema_version (version BIGINT NOT NULL)")
        count = conn.execute("SELECT count(*) FROM schema_version").fetchone()
        if count is None or count[0] == 0:
            conn.execute("INSERT INTO schema_version (version) VALUES (0)")
        version = current_version_postgres(conn)
    if version > SCHEMA_VERSION:
        raise _too_new(version)
    while version < target:
        with conn.transaction():
            conn.execute("SELECT pg_advisory_xact_lock(%s)", (MIGRATION_LOCK,))
            version = current_version_postgres(conn)  # another server may have moved it on
            if version > SCHEMA_VERSION:
                raise _too_new(version)
            if version >= target:
                break
            for stmt in postgres_statements(MIGRATIONS[version]):
                conn.execute(stmt)  # no parameters: a "%" in it is not a placeholder
            conn.execute("UPDATE schema_version SET version = %s", (version + 1,))
        version += 1
    return version
