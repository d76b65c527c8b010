"""Forward-only schema migrations, tracked by SQLite's ``PRAGMA user_version``.

Append a new script to :data:`MIGRATIONS` to change the schema; never edit a
released one.  Each script runs in its own transaction with the version bump,
so a crash mid-migration leaves the previous version intact.
"""

from __future__ import annotations

import sqlite3

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
    # 10: beyond one machine (issue #17): planning attempts and cancel requests that any
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
]

SCHEMA_VERSION = len(MIGRATIONS)


class SchemaTooNewError(RuntimeError):
    """The database was written by a newer SteelPath than this one."""


def current_version(conn: sqlite3.Connection) -> int:
    return int(conn.execute("PRAGMA user_version").fetchone()[0])


def migrate(conn: sqlite3.Connection, target: int = SCHEMA_VERSION) -> int:
    """Apply migrations up to ``target``; return the version reached."""
    version = current_version(conn)
    if version > SCHEMA_VERSION:
        raise SchemaTooNewError(
            f"database schema version {version} is newer than this SteelPath "
            f"understands ({SCHEMA_VERSION}); upgrade SteelPath or use another data directory"
        )
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
