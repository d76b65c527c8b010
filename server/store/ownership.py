"""Which server owns which robot link: ``servers`` and ``robot_leases``.

Several ``steelpath serve`` processes may share one store.  Each registers a
row in ``servers`` (its id, the URL other servers reach it at, a heartbeat),
and each robot link is owned by at most one server at a time through a lease
row in ``robot_leases`` that its owner renews with the heartbeat.

A lease is taken with one conditional upsert: the row is written only if it
is absent, expired, or already this server's — so two servers racing for a
robot cannot both win, on SQLite (``BEGIN IMMEDIATE`` serialises writers) or
PostgreSQL (the row's primary key and ``ON CONFLICT … DO UPDATE … WHERE``).
Times are Unix seconds (``time.time()``) written by the servers themselves:
servers on several hosts need synchronised clocks (NTP), and the lease must be
longer than their worst skew.

Plain portable SQL only (``?`` placeholders, ``INSERT … ON CONFLICT … DO
UPDATE``, no SQLite functions): the PostgreSQL store runs it unchanged.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from typing import Any

from server.store.database import utcnow

#: ``robots.updated_by`` of a URL that ``steelpath serve`` recorded for one of its
#: embedded emulators (so a server without emulators can reach them); an
#: operator's URL (``PUT /robots/{name}/connection``) is never overwritten by it.
EMULATOR_ACTOR_PREFIX = "emulators@"


@dataclass(frozen=True)
class ServerRow:
    """One registered server."""

    id: str
    url: str
    started_at: str
    heartbeat_at: float


@dataclass(frozen=True)
class LeaseRow:
    """One robot's lease; ``url`` is its owner's (``None`` if the owner is unregistered)."""

    name: str
    server_id: str
    expires_at: float
    taken_at: str
    url: str | None


class OwnershipStore:
    """The ``servers`` / ``robot_leases`` rows, on any database with the store's interface."""

    def __init__(self, db: Any) -> None:
        self.db = db

    # ---------------------------------------------------------------- servers
    def heartbeat(self, server_id: str, url: str, now: float) -> None:
        """Register this server, or refresh its heartbeat (and URL)."""
        with self.db.transaction() as conn:
            self._heartbeat(conn, server_id, url, now)

    @staticmethod
    def _heartbeat(conn: Any, server_id: str, url: str, now: float) -> None:
        conn.execute(
            "INSERT INTO servers (id, url, started_at, heartbeat_at) VALUES (?,?,?,?) "
            "ON CONFLICT (id) DO UPDATE SET url = excluded.url, "
            "heartbeat_at = excluded.heartbeat_at",
            (server_id, url, utcnow(), now),
        )

    def servers(self) -> list[ServerRow]:
        rows = self.db.query("SELECT id, url, started_at, heartbeat_at FROM servers ORDER BY id")
        return [
            ServerRow(r["id"], r["url"], r["started_at"], float(r["heartbeat_at"])) for r in rows
        ]

    def unregister(self, server_id: str) -> None:
        """A clean shutdown: this server's leases and its row go (others may take over now)."""
        with self.db.transaction() as conn:
            conn.execute("DELETE FROM robot_leases WHERE server_id = ?", (server_id,))
            conn.execute("DELETE FROM servers WHERE id = ?", (server_id,))

    def forget_dead_servers(self, older_than: float) -> int:
        """Drop rows of servers silent since ``older_than`` that hold no lease (a killed
        server leaves one behind); the table stays the list of live servers."""
        with self.db.transaction() as conn:
            cur = conn.execute(
                "DELETE FROM servers WHERE heartbeat_at < ? AND id NOT IN "
                "(SELECT server_id FROM robot_leases)",
                (older_than,),
            )
            return int(cur.rowcount or 0)

    # ----------------------------------------------------------------- leases
    def claim(
        self, server_id: str, url: str, names: Iterable[str], lease_s: float, now: float
    ) -> dict[str, LeaseRow]:
        """Heartbeat, then take or renew the lease of each robot in ``names``.

        One transaction.  Each upsert writes only where the lease is absent,
        expired (``expires_at < now``) or already ``server_id``'s; ``taken_at``
        changes only when the owner changes.  Returns every lease row after it
        (the caller compares ``server_id`` with its own).
        """
        taken = utcnow()
        with self.db.transaction() as conn:
            self._heartbeat(conn, server_id, url, now)
            for name in names:
                conn.execute(
                    "INSERT INTO robot_leases (name, server_id, expires_at, taken_at) "
                    "VALUES (?,?,?,?) ON CONFLICT (name) DO UPDATE SET "
                    "server_id = excluded.server_id, expires_at = excluded.expires_at, "
                    "taken_at = CASE WHEN robot_leases.server_id = excluded.server_id "
                    "THEN robot_leases.taken_at ELSE excluded.taken_at END "
                    "WHERE robot_leases.server_id = excluded.server_id "
                    "OR robot_leases.expires_at < ?",
                    (name, server_id, now + lease_s, taken, now),
                )
            rows = conn.execute(
                "SELECT l.name, l.server_id, l.expires_at, l.taken_at, s.url "
                "FROM robot_leases l LEFT JOIN servers s ON s.id = l.server_id"
            ).fetchall()
        return {r["name"]: _lease(r) for r in rows}

    def release(self, server_id: str, names: Iterable[str]) -> None:
        """Give up leases of this server (never another server's)."""
        with self.db.transaction() as conn:
            for name in names:
                conn.execute(
                    "DELETE FROM robot_leases WHERE name = ? AND server_id = ?",
                    (name, server_id),
                )

    def leases(self) -> dict[str, LeaseRow]:
        rows = self.db.query(
            "SELECT l.name, l.server_id, l.expires_at, l.taken_at, s.url "
            "FROM robot_leases l LEFT JOIN servers s ON s.id = l.server_id"
        )
        return {r["name"]: _lease(r) for r in rows}

    # ------------------------------------------------- E-stops that reached nobody
    # An E-stop for a robot that no live server answered for (its owner died and
    # its lease has not lapsed yet, or no server drives it) is kept here; the
    # server that next drives the robot latches it first (LeaseKeeper).

    def hold_estops(self, names: Iterable[str], actor: str, reason: str) -> None:
        """Keep an E-stop for each robot in ``names`` until a server drives it."""
        at = utcnow()
        with self.db.transaction() as conn:
            for name in names:
                conn.execute(
                    "INSERT INTO estop_pending (robot, at, actor, reason) VALUES (?,?,?,?) "
                    "ON CONFLICT (robot) DO UPDATE SET at = excluded.at, "
                    "actor = excluded.actor, reason = excluded.reason",
                    (name, at, actor, reason),
                )

    def take_estops(self, names: Iterable[str]) -> dict[str, dict[str, str]]:
        """Remove and return the held E-stops of ``names`` (for their new driver)."""
        wanted = list(names)
        if not wanted:
            return {}
        marks = ",".join("?" * len(wanted))
        with self.db.transaction() as conn:
            rows = conn.execute(
                f"SELECT robot, at, actor, reason FROM estop_pending WHERE robot IN ({marks})",
                wanted,
            ).fetchall()
            for r in rows:
                conn.execute("DELETE FROM estop_pending WHERE robot = ?", (r["robot"],))
        return {r["robot"]: {k: r[k] for k in ("at", "actor", "reason")} for r in rows}

    def held_estops(self) -> dict[str, dict[str, str]]:
        rows = self.db.query("SELECT robot, at, actor, reason FROM estop_pending")
        return {r["robot"]: {k: r[k] for k in ("at", "actor", "reason")} for r in rows}

    # ------------------------------------------------------- robot URLs (shared)
    def record_emulator_urls(self, urls: Mapping[str, str], server_id: str) -> None:
        """Publish this server's embedded emulators' URLs in the shared ``robots`` table.

        A server started without emulators connects to the robots it comes to
        own at the URLs in the store; without this it would know none of them.
        A row an operator set (``PUT /robots/{name}/connection``) is kept.
        """
        by = f"{EMULATOR_ACTOR_PREFIX}{server_id}"
        with self.db.transaction() as conn:
            for name, url in urls.items():
                conn.execute(
                    "INSERT INTO robots (name, url, updated_at, updated_by) VALUES (?,?,?,?) "
                    "ON CONFLICT (name) DO UPDATE SET url = excluded.url, "
                    "updated_at = excluded.updated_at, updated_by = excluded.updated_by "
                    "WHERE robots.updated_by LIKE ? AND robots.url <> excluded.url",
                    (name, url, utcnow(), by, EMULATOR_ACTOR_PREFIX + "%"),
                )

    def emulator_urls(self) -> dict[str, str]:
        """Robot URLs that a server recorded for its embedded emulators."""
        rows = self.db.query(
            "SELECT name, url FROM robots WHERE updated_by LIKE ?", (EMULATOR_ACTOR_PREFIX + "%",)
        )
        return {r["name"]: r["url"] for r in rows}


def _lease(r: Any) -> LeaseRow:
    return LeaseRow(r["name"], r["server_id"], float(r["expires_at"]), r["taken_at"], r["url"])
