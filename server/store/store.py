"""The service's persistent state: plans, clouds, executions, audit, tokens, robots.

Rows live in SQLite (:class:`server.store.database.Database`) or, with a
``postgresql://`` database URL, in PostgreSQL
(:class:`server.store.postgres.PostgresDatabase`); large arrays in ``.npy``
files under the data directory (:class:`server.store.arrays.ArrayStore`),
which several servers sharing one PostgreSQL must therefore share too.  Arrays are written
*before* the row that references them is committed, so a crash at any point
leaves the previously committed state readable (an orphan file at worst).
Every state change and its audit event commit in one transaction.
"""

from __future__ import annotations

import json
import secrets
import threading
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from server.lifecycle import (
    ACTIVE_EXECUTION,
    DELETABLE,
    IllegalTransitionError,
    PlanState,
    allowed_actions,
    next_execution_state,
    next_state,
)
from server.store.arrays import ArrayStore
from server.store.database import StoreDatabase, ensure_private_dir, open_database, utcnow
from server.store.records import (
    AuditEvent,
    CloudRecord,
    ExecutionRecord,
    PlanRecord,
    TokenRecord,
)


class NotFoundError(KeyError):
    """No row with that id; the message names the resource and the id."""

    def __str__(self) -> str:  # KeyError quotes its message; we want it plain
        return str(self.args[0]) if self.args else "not found"


def new_id(prefix: str) -> str:
    return f"{prefix}_{secrets.token_hex(6)}"


def _json(value: Any) -> str:
    return json.dumps(value, allow_nan=False, separators=(",", ":"))


#: A plan row without its (possibly megabytes of) ``result`` and ``program``;
#: ``program_length_hint`` counts the program's commands in SQL.
_PLAN_SUMMARY_COLUMNS = (
    "id, kind, state, params, parent_id, progress, stage, NULL AS result, metrics, "
    "checks, arrays, error, created_at, updated_at, created_by, approved_by, "
    "approved_at, NULL AS program, "
    "CASE WHEN program IS NULL THEN NULL ELSE json_array_length(program) END "
    "AS program_length_hint"
)
#: The same on PostgreSQL, whose ``json_array_length`` takes ``json``, not text.
_PLAN_SUMMARY_COLUMNS_PG = _PLAN_SUMMARY_COLUMNS.replace(
    "json_array_length(program)", "json_array_length(program::json)"
)

#: One command of a plan's program as JSON text, picked in SQL, per dialect.
_PLAN_COMMAND = {
    "sqlite": "SELECT json_extract(program, '$[' || ? || ']') AS cmd FROM plans WHERE id = ?",
    "postgresql": "SELECT (program::json -> ?::int)::text AS cmd FROM plans WHERE id = ?",
}


def _checks_verdict(checks: list[dict[str, Any]]) -> tuple[str, str]:
    """A finished plan's action (``finish``, or ``reject`` if a check failed) and its reason."""
    failed = [c for c in checks if not c.get("passed")]
    if failed:
        return "reject", "checks failed: " + "; ".join(
            f"{c['name']}: {c.get('message', '')}" for c in failed
        )
    return "finish", f"{len(checks)} checks passed"


def worker_name(run: str | None) -> str:
    """The worker part of a plan's ``worker`` column (``name@address#run``): ``name``."""
    if not run:
        return "?"
    return run.rsplit("#", 1)[0].split("@", 1)[0]


def worker_address(run: str | None) -> str | None:
    """The Dask address in a plan's ``worker`` column (``name@address#run``)."""
    if not run or "@" not in run:
        return None
    return run.rsplit("#", 1)[0].split("@", 1)[1]


#: Portable SQL (SQLite ≥ 3.24 and PostgreSQL): a repeated ack changes nothing,
#: and ``acked`` only grows (SQLite's two-argument ``MAX`` is ``GREATEST`` there).
_INSERT_ACK = (
    "INSERT INTO execution_acks (execution_id, idx, ts) VALUES (?,?,?) ON CONFLICT DO NOTHING"
)
_RAISE_ACKED = (
    "UPDATE executions SET acked = CASE WHEN acked < ? THEN ? ELSE acked END, updated_at = ? "
    "WHERE id = ?"
)

_INSERT_CLOUD = (
    "INSERT INTO clouds (id, name, source, n_points, bounds, dropped, array_file, created_at,"
    " created_by, survey, crs_wkt, attributes) VALUES (?,?,?,?,?,?,?,?,?,?,?,?)"
)


def cloud_attribute_relname(cloud_id: str, name: str) -> str:
    """Where an upload's per-point attribute ``name`` is stored (beside its points)."""
    return f"clouds/{cloud_id}.{name}.npy"


class Store:
    """All persistent state: rows in SQLite under ``data_dir`` or, given a
    ``postgresql://`` ``database_url``, in PostgreSQL; arrays under ``data_dir``
    either way (a directory every server sharing the database must share)."""

    def __init__(
        self,
        data_dir: Path,
        *,
        database_url: str | None = None,
        migrate_to: int | None = None,
    ) -> None:
        self.data_dir = Path(data_dir)
        ensure_private_dir(self.data_dir)
        self.db: StoreDatabase = open_database(self.data_dir, database_url, migrate_to=migrate_to)
        self._summary_columns = (
            _PLAN_SUMMARY_COLUMNS_PG if self.db.dialect == "postgresql" else _PLAN_SUMMARY_COLUMNS
        )
        # Bumped by every revocation in this process: long-lived connections
        # (event streams, scene sockets) poll it and re-check their token.
        self._token_epoch = 0
        self._epoch_lock = threading.Lock()
        self.arrays = ArrayStore(self.data_dir / "arrays")

    def close(self) -> None:
        self.db.close()

    # ------------------------------------------------------------------ audit
    def _audit(
        self,
        conn: Any,
        actor: str,
        entity: str,
        entity_id: str,
        action: str,
        from_state: str | None = None,
        to_state: str | None = None,
        reason: str = "",
        ts: str | None = None,
    ) -> None:
        conn.execute(
            "INSERT INTO audit_events (ts, actor, entity, entity_id, action, from_state, "
            "to_state, reason) VALUES (?,?,?,?,?,?,?,?)",
            (ts or utcnow(), actor, entity, entity_id, action, from_state, to_state, reason),
        )

    def audit(
        self,
        actor: str,
        entity: str,
        entity_id: str,
        action: str,
        reason: str = "",
        *,
        ts: str | None = None,
    ) -> None:
        """Record an event that is not a state transition (E-stop, token use…);
        ``ts``: when it happened, if earlier than now (a record written late)."""
        with self.db.transaction() as conn:
            self._audit(conn, actor, entity, entity_id, action, reason=reason, ts=ts)

    def list_audit(
        self, entity: str | None = None, entity_id: str | None = None, limit: int = 200
    ) -> list[AuditEvent]:
        sql = "SELECT * FROM audit_events WHERE 1=1"
        args: list[Any] = []
        if entity:
            sql += " AND entity = ?"
            args.append(entity)
        if entity_id:
            sql += " AND entity_id = ?"
            args.append(entity_id)
        sql += " ORDER BY id DESC LIMIT ?"
        args.append(limit)
        return [AuditEvent.from_row(r) for r in self.db.query(sql, args)]

    # ----------------------------------------------------------------- clouds
    def add_cloud(
        self,
        name: str,
        source: str,
        points: np.ndarray,
        dropped: int,
        actor: str,
        survey: dict[str, Any] | None = None,
    ) -> CloudRecord:
        cid = new_id("cl")
        relname = self.arrays.save(f"clouds/{cid}.npy", np.ascontiguousarray(points, np.float64))
        lo, hi = points.min(axis=0), points.max(axis=0)
        bounds = {"min": [float(v) for v in lo], "max": [float(v) for v in hi]}
        with self.db.transaction() as conn:
            conn.execute(
                _INSERT_CLOUD,
                (cid, name, source, len(points), _json(bounds), dropped, relname, utcnow(), actor)
                + (_json(survey or {}), None, "{}"),
            )
            self._audit(
                conn, actor, "cloud", cid, "upload", reason=f"{name} ({len(points)} points)"
            )
        return self.get_cloud(cid)

    def register_cloud(
        self,
        cloud_id: str,
        name: str,
        source: str,
        n_points: int,
        bounds: dict[str, list[float]],
        dropped: int,
        actor: str,
        survey: dict[str, Any] | None = None,
        *,
        crs_wkt: str | None = None,
        attributes: list[str] | tuple[str, ...] = (),
    ) -> CloudRecord:
        """Record a cloud whose array a parser already wrote at ``clouds/{cloud_id}.npy``,
        with the per-point ``attributes`` it wrote beside it
        (``clouds/{cloud_id}.<name>.npy``) and the CRS the file named (WKT)."""
        relname = f"clouds/{cloud_id}.npy"
        if not self.arrays.path(relname).is_file():
            raise FileNotFoundError(f"cloud array {relname} was not written")
        files = {a: cloud_attribute_relname(cloud_id, a) for a in attributes}
        for rel in files.values():
            if not self.arrays.path(rel).is_file():
                raise FileNotFoundError(f"cloud attribute array {rel} was not written")
        with self.db.transaction() as conn:
            conn.execute(
                _INSERT_CLOUD,
                (cloud_id, name, source, n_points, _json(bounds), dropped, relname, utcnow(), actor)
                + (_json(survey or {}), crs_wkt, _json(files)),
            )
            self._audit(
                conn, actor, "cloud", cloud_id, "upload", reason=f"{name} ({n_points} points)"
            )
        return self.get_cloud(cloud_id)

    def get_cloud(self, cloud_id: str) -> CloudRecord:
        row = self.db.query_one("SELECT * FROM clouds WHERE id = ?", (cloud_id,))
        if row is None:
            raise NotFoundError(f"no cloud with id {cloud_id!r}")
        return CloudRecord.from_row(row)

    def list_clouds(self, limit: int = 100, offset: int = 0) -> list[CloudRecord]:
        rows = self.db.query(
            "SELECT * FROM clouds ORDER BY created_at DESC, id LIMIT ? OFFSET ?", (limit, offset)
        )
        return [CloudRecord.from_row(r) for r in rows]

    def cloud_points(self, cloud_id: str) -> np.ndarray:
        return self.arrays.load(self.get_cloud(cloud_id).array_file)

    def cloud_path(self, cloud_id: str) -> Path:
        return self.arrays.path(self.get_cloud(cloud_id).array_file)

    def cloud_attribute_path(self, cloud_id: str, name: str) -> Path:
        """The ``.npy`` of a cloud's per-point attribute ``name``; raises
        :class:`NotFoundError` when the cloud has no such attribute (or its file
        is gone: a cloud imported from an archive carries its points only)."""
        rec = self.get_cloud(cloud_id)
        if name not in rec.attributes:
            have = ", ".join(rec.attributes) or "none"
            raise NotFoundError(f"cloud {cloud_id!r} has no attribute {name!r} (it has: {have})")
        path = self.arrays.path(rec.attributes[name])
        if not path.is_file():
            raise NotFoundError(f"the {name} array of cloud {cloud_id!r} is not stored here")
        return path

    def cloud_attribute(self, cloud_id: str, name: str, mmap: bool = True) -> np.ndarray:
        """A cloud's per-point attribute (rows match :meth:`cloud_points`)."""
        return np.load(
            self.cloud_attribute_path(cloud_id, name),
            mmap_mode="r" if mmap else None,
            allow_pickle=False,
        )

    def delete_cloud(self, cloud_id: str, actor: str) -> None:
        rec = self.get_cloud(cloud_id)
        with self.db.transaction() as conn:
            conn.execute("DELETE FROM clouds WHERE id = ?", (cloud_id,))
            self._audit(conn, actor, "cloud", cloud_id, "delete")
        self.arrays.delete(rec.array_file)
        for rel in rec.attributes.values():
            self.arrays.delete(rel)

    # ------------------------------------------------------------------ plans
    def create_plan(
        self,
        kind: str,
        params: Mapping[str, Any],
        actor: str,
        parent_id: str | None = None,
        reason: str = "",
    ) -> PlanRecord:
        pid = new_id("pl")
        now = utcnow()
        with self.db.transaction() as conn:
            if parent_id is not None:
                self.get_plan(parent_id)
            conn.execute(
                "INSERT INTO plans (id, kind, state, params, parent_id, created_at, updated_at, "
                "created_by) VALUES (?,?,?,?,?,?,?,?)",
                (pid, kind, PlanState.QUEUED, _json(dict(params)), parent_id, now, now, actor),
            )
            why = reason or (f"revision of {parent_id}" if parent_id else "submitted")
            self._audit(conn, actor, "plan", pid, "submit", None, PlanState.QUEUED, why)
        return self.get_plan(pid)

    def get_plan(self, plan_id: str, *, result: bool = True, program: bool = True) -> PlanRecord:
        """One plan; ``result=False``/``program=False`` leave those unread and
        undecoded (``{}``/``None``): a multi-megabyte ``json.loads`` holds the
        GIL for its whole length, which the robot-link service cannot afford."""
        cols = "*"
        if not (result and program):
            cols = self._summary_columns
            if result:
                cols = cols.replace("NULL AS result", "result")
            if program:
                cols = cols.replace("NULL AS program", "program")
        row = self.db.query_one(f"SELECT {cols} FROM plans WHERE id = ?", (plan_id,))
        if row is None:
            raise NotFoundError(f"no plan with id {plan_id!r}")
        return PlanRecord.from_row(row, loader=self.arrays.load)

    def get_plan_json(self, plan_id: str) -> tuple[PlanRecord, str, str]:
        """A plan without ``result``/``program`` decoded, and those two as their
        stored JSON text (``null`` when unset).

        For answers that only pass them on: decoding and re-encoding a
        multi-megabyte result was most of a busy server's CPU on ``GET
        /plans/{id}``.
        """
        row = self.db.query_one(
            f"SELECT {self._summary_columns}, result AS result_json, program AS program_json "
            "FROM plans WHERE id = ?",
            (plan_id,),
        )
        if row is None:
            raise NotFoundError(f"no plan with id {plan_id!r}")
        d = dict(row)
        result_json, program_json = d.pop("result_json"), d.pop("program_json")
        rec = PlanRecord.from_mapping(d, loader=self.arrays.load)
        return rec, result_json or "{}", program_json or "null"

    def plan_command(self, plan_id: str, index: int) -> dict[str, Any] | None:
        """Command ``index`` of a plan's program (``None`` past its end or without
        one), picked in SQL: the program is not decoded."""
        if index < 0:
            self.get_plan_json(plan_id)  # NotFoundError for an unknown plan
            return None
        row = self.db.query_one(_PLAN_COMMAND[self.db.dialect], (int(index), plan_id))
        if row is None:
            raise NotFoundError(f"no plan with id {plan_id!r}")
        return None if row["cmd"] is None else json.loads(row["cmd"])

    def list_plans_json(
        self,
        *,
        kind: str | None = None,
        state: str | None = None,
        parent_id: str | None = None,
        limit: int = 50,
        offset: int = 0,
    ) -> str:
        """``list_plans(summary=True)`` as the JSON text of its public form."""
        sql, args = self._plans_query(self._summary_columns, kind, state, parent_id, limit, offset)
        return "[" + ",".join(PlanRecord.summary_json(r) for r in self.db.query(sql, args)) + "]"

    def _plans_query(
        self,
        cols: str,
        kind: str | None,
        state: str | None,
        parent_id: str | None,
        limit: int,
        offset: int,
    ) -> tuple[str, list[Any]]:
        sql = f"SELECT {cols} FROM plans WHERE 1=1"
        args: list[Any] = []
        for col, val in (("kind", kind), ("state", state), ("parent_id", parent_id)):
            if val is not None:
                sql += f" AND {col} = ?"
                args.append(val)
        sql += " ORDER BY created_at DESC, id DESC LIMIT ? OFFSET ?"
        args += [limit, offset]
        return sql, args

    def list_plans(
        self,
        *,
        kind: str | None = None,
        state: str | None = None,
        parent_id: str | None = None,
        limit: int = 50,
        offset: int = 0,
        summary: bool = False,
    ) -> list[PlanRecord]:
        """Plans, newest first.  ``summary`` leaves out ``result`` and ``program``
        (``program_length`` is kept): a listing then costs no JSON decoding of
        results, which can be megabytes per plan."""
        cols = self._summary_columns if summary else "*"
        sql, args = self._plans_query(cols, kind, state, parent_id, limit, offset)
        return [PlanRecord.from_row(r, loader=self.arrays.load) for r in self.db.query(sql, args)]

    def transition_plan(
        self,
        plan_id: str,
        action: str,
        actor: str,
        reason: str = "",
        *,
        expect: str | None = None,
        **fields: Any,
    ) -> PlanRecord:
        """Apply ``action`` atomically with its audit event.

        ``fields`` are extra columns to set (JSON-encoded when not scalars).
        ``expect`` guards against a race: the transition only applies if the
        plan is still in that state.
        """
        with self.db.transaction() as conn:
            plan = self.get_plan(plan_id)
            if expect is not None and plan.state != expect:
                raise IllegalTransitionError(
                    "plan", plan_id, plan.state, action, allowed_actions(plan.state)
                )
            new = next_state(plan_id, plan.state, action)
            sets = {"state": str(new), "updated_at": utcnow()}
            for k, v in fields.items():
                sets[k] = _json(v) if isinstance(v, dict | list) else v
            cols = ", ".join(f"{k} = ?" for k in sets)
            conn.execute(f"UPDATE plans SET {cols} WHERE id = ?", (*sets.values(), plan_id))
            self._audit(conn, actor, "plan", plan_id, action, plan.state, str(new), reason)
        return self.get_plan(plan_id)

    def set_progress(self, plan_id: str, progress: float, stage: str) -> None:
        with self.db.transaction() as conn:
            conn.execute(
                "UPDATE plans SET progress = ?, stage = ?, updated_at = ? WHERE id = ? "
                "AND state = ?",
                (float(progress), stage, utcnow(), plan_id, PlanState.PLANNING),
            )

    def store_plan_result(
        self,
        plan_id: str,
        *,
        result: dict[str, Any],
        arrays: Mapping[str, np.ndarray],
        checks: list[dict[str, Any]],
        metrics: dict[str, float],
        program: list[dict[str, Any]] | None = None,
        actor: str = "planner",
    ) -> PlanRecord:
        """Persist a finished plan: ``planned`` if every check passed, else ``rejected``."""
        refs = {
            name: self.arrays.save(f"plans/{plan_id}/{name}.npy", arr)
            for name, arr in arrays.items()
        }
        action, reason = _checks_verdict(checks)
        extra = {"program": _json(program)} if program is not None else {}
        return self.transition_plan(
            plan_id,
            action,
            actor,
            reason,
            expect=PlanState.PLANNING,
            result=result,
            arrays=refs,
            checks=checks,
            metrics=metrics,
            progress=1.0,
            stage="done",
            **extra,
        )

    def delete_plan(self, plan_id: str, actor: str) -> None:
        plan = self.get_plan(plan_id)
        if plan.state not in DELETABLE:
            raise IllegalTransitionError(
                "plan", plan_id, plan.state, "delete", allowed_actions(plan.state)
            )
        executions = [
            str(r["id"])
            for r in self.db.query("SELECT id FROM executions WHERE plan_id = ?", (plan_id,))
        ]
        with self.db.transaction() as conn:
            conn.execute("UPDATE plans SET parent_id = NULL WHERE parent_id = ?", (plan_id,))
            conn.execute(
                "DELETE FROM execution_acks WHERE execution_id IN "
                "(SELECT id FROM executions WHERE plan_id = ?)",
                (plan_id,),
            )
            conn.execute("DELETE FROM executions WHERE plan_id = ?", (plan_id,))
            conn.execute("DELETE FROM plans WHERE id = ?", (plan_id,))
            self._audit(conn, actor, "plan", plan_id, "delete", plan.state, None)
        self.arrays.delete_tree(f"plans/{plan_id}")
        for eid in executions:  # what their robots' cameras saw (server.captures)
            ArrayStore(self.data_dir / "captures").delete_tree(eid)

    def plans_in_states(self, states: set[str] | frozenset[str]) -> list[PlanRecord]:
        marks = ",".join("?" * len(states))
        rows = self.db.query(
            f"SELECT * FROM plans WHERE state IN ({marks}) ORDER BY created_at", list(states)
        )
        return [PlanRecord.from_row(r, loader=self.arrays.load) for r in rows]

    # ----------------------------------------- plan runs on a Dask cluster (#17 §2)
    # A planning worker on another machine writes its plan's start, progress and
    # end here itself; the server only reads them.  Each start of a plan on a
    # worker is a *run*, named in ``worker`` as ``name@address#token`` (the token
    # is new per start).  Every write of a run is a conditional UPDATE on
    # ``state`` and ``worker``: a run that has been replaced (its worker died and
    # the task was re-run elsewhere) or a plan already out of ``planning``
    # changes nothing, so no plan is finished twice and no cancel is overwritten.
    # Plain SQL with ``?`` placeholders only (the PostgreSQL store runs it too).

    def start_plan_run(
        self, plan_id: str, run: str, *, max_starts: int = 2
    ) -> tuple[str, PlanRecord | None]:
        """Record that ``run`` starts planning ``plan_id``; returns what to do.

        ``("run", plan)``: plan it.  A plan still ``planning`` when a run starts
        lost its previous run (Dask re-runs the task of a worker that died):
        that start is a re-run, audited as ``rerun``; the start after
        ``max_starts`` fails the plan instead.  ``("cancelled", …)``: a cancel
        was asked before it started; ``("gone", …)``: it is no longer queued or
        planning; ``("failed", …)``: too many starts; ``("raced", …)``: another
        start changed it first.
        """
        now = utcnow()
        with self.db.transaction() as conn:
            plan = self.get_plan(plan_id)
            if plan.state not in (PlanState.QUEUED, PlanState.PLANNING):
                return "gone", plan
            if plan.cancel_requested:
                why = "cancelled before it started"
                done = self._run_update(
                    conn, plan_id, plan.state, plan.worker, "cancel", "operator", why, {}
                )
                return ("cancelled" if done else "raced"), None
            starts = plan.attempts + 1
            if plan.state == PlanState.QUEUED:
                done = self._run_update(
                    conn,
                    plan_id,
                    PlanState.QUEUED,
                    plan.worker,
                    "start",
                    "planner",
                    f"worker {worker_name(run)} picked it up",
                    {"attempts": starts, "worker": run, "progress": 0.0, "stage": "start"},
                )
                return ("run" if done else "raced"), plan
            lost = worker_name(plan.worker)
            if starts > max_starts:
                msg = (
                    f"planning was started {starts} times: the worker running it died or was "
                    f"restarted each time (last: {lost}); it is not re-run again"
                )
                done = self._run_update(
                    conn,
                    plan_id,
                    PlanState.PLANNING,
                    plan.worker,
                    "fail",
                    "planner",
                    msg,
                    {"attempts": starts, "worker": run, "error": msg},
                )
                return ("failed" if done else "raced"), None
            why = f"re-run after worker {lost} died"
            cur = conn.execute(
                "UPDATE plans SET attempts = ?, worker = ?, progress = ?, stage = ?, "
                "updated_at = ? WHERE id = ? AND state = ? AND attempts = ?",
                (starts, run, 0.0, why, now, plan_id, PlanState.PLANNING, plan.attempts),
            )
            if cur.rowcount != 1:
                return "raced", None
            self._audit(
                conn,
                "planner",
                "plan",
                plan_id,
                "rerun",
                PlanState.PLANNING,
                PlanState.PLANNING,
                f"{why}; run {starts} of {max_starts} on {worker_name(run)}",
            )
        return "run", plan

    def plan_run_status(self, plan_id: str, run: str) -> tuple[bool, bool]:
        """``(cancel asked, still this run's)`` for a worker's progress call."""
        row = self.db.query_one(
            "SELECT state, cancel_requested, worker FROM plans WHERE id = ?", (plan_id,)
        )
        if row is None:
            return True, False
        mine = row["state"] == PlanState.PLANNING and row["worker"] == run
        return bool(row["cancel_requested"]), mine

    def set_run_progress(self, plan_id: str, run: str, progress: float, stage: str) -> bool:
        """Store a run's progress; ``False`` when the plan is no longer this run's."""
        with self.db.transaction() as conn:
            cur = conn.execute(
                "UPDATE plans SET progress = ?, stage = ?, updated_at = ? "
                "WHERE id = ? AND state = ? AND worker = ?",
                (float(progress), stage, utcnow(), plan_id, PlanState.PLANNING, run),
            )
            return bool(cur.rowcount == 1)

    def end_plan_run(
        self, plan_id: str, run: str, action: str, actor: str, reason: str, **fields: Any
    ) -> bool:
        """``action`` (``fail``, ``cancel``…) out of ``planning``, only if ``run`` still owns it."""
        with self.db.transaction() as conn:
            return self._run_update(
                conn, plan_id, PlanState.PLANNING, run, action, actor, reason, fields
            )

    def finish_plan_run(
        self,
        plan_id: str,
        run: str,
        *,
        result: dict[str, Any],
        arrays: Mapping[str, np.ndarray],
        checks: list[dict[str, Any]],
        metrics: dict[str, float],
        program: list[dict[str, Any]] | None = None,
    ) -> bool:
        """:meth:`store_plan_result` for a run: once, and only by the run that owns the plan.

        Arrays go to files named after the run, so a run that lost the plan
        (between its check here and its UPDATE) never overwrites the arrays of
        the one that finished it; its files are removed again.
        """
        if not self.plan_run_status(plan_id, run)[1]:
            return False  # not this run's any more: write no arrays at all
        token = run.rsplit("#", 1)[-1]
        refs = {
            name: self.arrays.save(f"plans/{plan_id}/{name}.{token}.npy", arr)
            for name, arr in arrays.items()
        }
        action, reason = _checks_verdict(checks)
        fields: dict[str, Any] = {
            "result": result,
            "arrays": refs,
            "checks": checks,
            "metrics": metrics,
            "progress": 1.0,
            "stage": "done",
        }
        if program is not None:
            fields["program"] = _json(program)
        done = False
        try:
            done = self.end_plan_run(plan_id, run, action, "planner", reason, **fields)
        finally:
            if not done:
                for ref in refs.values():
                    self.arrays.delete(ref)
        return done

    def request_plan_cancel(self, plan_id: str) -> None:
        """Ask the plan's run (wherever it is) to stop at its next progress call."""
        with self.db.transaction() as conn:
            conn.execute(
                "UPDATE plans SET cancel_requested = 1 WHERE id = ? AND state IN (?, ?)",
                (plan_id, PlanState.QUEUED, PlanState.PLANNING),
            )

    def cancel_queued_plan(self, plan_id: str, actor: str, reason: str) -> bool:
        """Cancel a plan no run has started; ``False`` if one started first."""
        with self.db.transaction() as conn:
            row = conn.execute("SELECT worker FROM plans WHERE id = ?", (plan_id,)).fetchone()
            if row is None:
                return False
            return self._run_update(
                conn, plan_id, PlanState.QUEUED, row["worker"], "cancel", actor, reason, {}
            )

    def plan_run_rows(self, plan_ids: Iterable[str]) -> list[dict[str, Any]]:
        """What the server's poller follows of plans in flight (one query)."""
        ids = list(plan_ids)
        if not ids:
            return []
        marks = ",".join("?" * len(ids))
        rows = self.db.query(
            "SELECT id, kind, state, progress, stage, error, updated_at, attempts, worker "
            f"FROM plans WHERE id IN ({marks})",
            ids,
        )
        return [dict(r) for r in rows]

    def _run_update(
        self,
        conn: Any,
        plan_id: str,
        state: str,
        run: str | None,
        action: str,
        actor: str,
        reason: str,
        fields: Mapping[str, Any],
    ) -> bool:
        """Apply ``action`` to a plan in ``state`` whose ``worker`` is ``run``, with its
        audit event; ``False`` (nothing written) if the plan is not that any more."""
        new = next_state(plan_id, state, action)
        sets: dict[str, Any] = {"state": str(new), "updated_at": utcnow()}
        for k, v in fields.items():
            sets[k] = _json(v) if isinstance(v, dict | list) else v
        cols = ", ".join(f"{k} = ?" for k in sets)
        args: tuple[str, ...] = ()
        where = "worker IS NULL"
        if run is not None:
            where, args = "worker = ?", (run,)
        cur = conn.execute(
            f"UPDATE plans SET {cols} WHERE id = ? AND state = ? AND {where}",
            (*sets.values(), plan_id, state, *args),
        )
        if cur.rowcount != 1:
            return False
        self._audit(conn, actor, "plan", plan_id, action, state, str(new), reason)
        return True

    # ------------------------------------------------- end of Dask plan runs (#17 §2)

    # ------------------------------------------------------------- executions
    def create_execution(
        self, plan_id: str, robot: str, total: int, actor: str, run_id: int = 0
    ) -> ExecutionRecord:
        """Create an execution and move its plan to ``executing`` atomically."""
        eid = new_id("ex")
        now = utcnow()
        with self.db.transaction() as conn:
            self.transition_plan(plan_id, "dispatch", actor, f"to robot {robot} as {eid}")
            conn.execute(
                "INSERT INTO executions (id, plan_id, robot, state, acked, total, error, "
                "created_at, updated_at, created_by, run_id) VALUES (?,?,?,?,?,?,?,?,?,?,?)",
                (eid, plan_id, robot, "pending", 0, total, None, now, now, actor, run_id),
            )
            self._audit(conn, actor, "execution", eid, "create", None, "pending", f"plan {plan_id}")
        return self.get_execution(eid)

    def get_execution(self, execution_id: str) -> ExecutionRecord:
        row = self.db.query_one("SELECT * FROM executions WHERE id = ?", (execution_id,))
        if row is None:
            raise NotFoundError(f"no execution with id {execution_id!r}")
        return ExecutionRecord.from_row(row)

    def list_executions(
        self,
        plan_id: str | None = None,
        state: str | None = None,
        limit: int = 100,
        offset: int = 0,
    ) -> list[ExecutionRecord]:
        """Executions, newest first (``limit`` rows after skipping ``offset``)."""
        sql = "SELECT * FROM executions WHERE 1=1"
        args: list[Any] = []
        if plan_id:
            sql += " AND plan_id = ?"
            args.append(plan_id)
        if state:
            sql += " AND state = ?"
            args.append(state)
        sql += " ORDER BY created_at DESC LIMIT ? OFFSET ?"
        args += [limit, offset]
        return [ExecutionRecord.from_row(r) for r in self.db.query(sql, args)]

    def newest_execution_of(self, robot: str, states: Iterable[str]) -> str | None:
        """Id of ``robot``'s newest execution in one of ``states``, or ``None``.

        One SQL query, not a record decoded per row in Python:
        the link service asks this for every robot on every ``GET /robots``.
        """
        wanted = [str(s) for s in states]
        if not wanted:
            return None
        marks = ",".join("?" * len(wanted))
        # An archived (imported) plan's executions are another server's
        # history: never this robot's run, whatever state they ended in.
        row = self.db.query_one(
            f"SELECT id FROM executions WHERE robot = ? AND state IN ({marks}) "
            "AND plan_id NOT IN (SELECT id FROM plans WHERE state = ?) "
            "ORDER BY created_at DESC LIMIT 1",
            [robot, *wanted, str(PlanState.ARCHIVED)],
        )
        return str(row["id"]) if row is not None else None

    def transition_execution(
        self,
        execution_id: str,
        action: str,
        actor: str,
        reason: str = "",
        *,
        plan_action: str | None = None,
        **fields: Any,
    ) -> ExecutionRecord:
        """Move an execution (and, with ``plan_action``, its plan) in one transaction."""
        with self.db.transaction() as conn:
            ex = self.get_execution(execution_id)
            new = next_execution_state(execution_id, ex.state, action)
            sets = {"state": str(new), "updated_at": utcnow(), **fields}
            cols = ", ".join(f"{k} = ?" for k in sets)
            conn.execute(
                f"UPDATE executions SET {cols} WHERE id = ?", (*sets.values(), execution_id)
            )
            self._audit(conn, actor, "execution", execution_id, action, ex.state, str(new), reason)
            if plan_action is not None:
                self.transition_plan(ex.plan_id, plan_action, actor, reason)
        return self.get_execution(execution_id)

    def record_ack(self, execution_id: str, index: int) -> None:
        """Command ``index`` finished on the robot: log it and advance ``acked``.

        Idempotent (a repeated ack changes nothing) and durable before it
        returns, so the streamer may advance only after this call.
        """
        with self.db.transaction() as conn:
            conn.execute(_INSERT_ACK, (execution_id, int(index), utcnow()))
            conn.execute(_RAISE_ACKED, (int(index) + 1, int(index) + 1, utcnow(), execution_id))

    def record_acks(self, execution_id: str, first: int, last: int) -> None:
        """Commands ``first`` … ``last`` finished: :meth:`record_ack` for each, in one
        transaction (one durable commit)."""
        if last < first:
            raise ValueError(f"record_acks({first}, {last}): last < first")
        now = utcnow()
        with self.db.transaction() as conn:
            conn.executemany(
                _INSERT_ACK, [(execution_id, i, now) for i in range(int(first), int(last) + 1)]
            )
            conn.execute(_RAISE_ACKED, (int(last) + 1, int(last) + 1, now, execution_id))

    def list_acks(self, execution_id: str) -> list[int]:
        rows = self.db.query(
            "SELECT idx FROM execution_acks WHERE execution_id = ? ORDER BY idx", (execution_id,)
        )
        return [int(r["idx"]) for r in rows]

    def record_execution_state(self, execution_id: str, t: float, state: dict[str, Any]) -> None:
        """A state report of the robot running ``execution_id`` at Unix time ``t``."""
        with self.db.transaction() as conn:
            conn.execute(
                "INSERT INTO execution_states (execution_id, t, state) VALUES (?,?,?)",
                (execution_id, t, _json(state)),
            )

    def execution_states(self, execution_id: str) -> list[tuple[float, dict[str, Any]]]:
        rows = self.db.query(
            "SELECT t, state FROM execution_states WHERE execution_id = ? ORDER BY t, rowid",
            (execution_id,),
        )
        return [(float(r["t"]), json.loads(r["state"])) for r in rows]

    def ack_times(self, execution_id: str) -> list[tuple[int, str]]:
        """(command index, ISO time acknowledged) in index order."""
        rows = self.db.query(
            "SELECT idx, ts FROM execution_acks WHERE execution_id = ? ORDER BY idx",
            (execution_id,),
        )
        return [(int(r["idx"]), str(r["ts"])) for r in rows]

    def save_robot_state(self, name: str, state: dict[str, Any]) -> None:
        with self.db.transaction() as conn:
            conn.execute(
                "INSERT INTO robot_states (name, state, updated_at) VALUES (?,?,?) "
                "ON CONFLICT(name) DO UPDATE SET "
                "state = excluded.state, updated_at = excluded.updated_at",
                (name, _json(state), utcnow()),
            )

    def robot_state(self, name: str) -> tuple[dict[str, Any], str] | None:
        row = self.db.query_one(
            "SELECT state, updated_at FROM robot_states WHERE name = ?", (name,)
        )
        return None if row is None else (json.loads(row["state"]), row["updated_at"])

    def set_execution_acked(self, execution_id: str, acked: int) -> None:
        with self.db.transaction() as conn:
            conn.execute(
                "UPDATE executions SET acked = ?, updated_at = ? WHERE id = ?",
                (int(acked), utcnow(), execution_id),
            )

    def active_executions(self) -> list[ExecutionRecord]:
        rows = self.db.query(
            "SELECT e.* FROM executions e JOIN plans p ON p.id = e.plan_id WHERE p.state IN "
            f"({','.join('?' * len(ACTIVE_EXECUTION))})",
            [str(s) for s in ACTIVE_EXECUTION],
        )
        return [ExecutionRecord.from_row(r) for r in rows]

    # ----------------------------------------------------------------- tokens
    def add_token(
        self,
        name: str,
        role: str,
        token_hash: str,
        actor: str,
        *,
        expires_at: str | None = None,
    ) -> TokenRecord:
        """Store a token's hash; ``expires_at`` is ISO-8601 UTC or ``None`` (never)."""
        tid = new_id("tk")
        reason = f"{name} ({role})" + (f", expires {expires_at}" if expires_at else "")
        with self.db.transaction() as conn:
            conn.execute(
                "INSERT INTO tokens (id, name, role, hash, created_at, revoked_at, expires_at) "
                "VALUES (?,?,?,?,?,?,?)",
                (tid, name, role, token_hash, utcnow(), None, expires_at),
            )
            self._audit(conn, actor, "token", tid, "create", reason=reason)
        return self.get_token(tid)

    def add_first_token(
        self, name: str, role: str, token_hash: str, actor: str
    ) -> TokenRecord | None:
        """Store a token only if no active token exists, in one write transaction:
        servers starting together on one empty store create one
        first-start token between them, not one each. ``None``: one existed."""
        tid = new_id("tk")
        with self.db.transaction() as conn:
            row = conn.execute(
                "SELECT COUNT(*) FROM tokens WHERE revoked_at IS NULL "
                "AND (expires_at IS NULL OR expires_at > ?)",
                (utcnow(),),
            ).fetchone()
            if row is not None and int(row[0]) > 0:
                return None
            conn.execute(
                "INSERT INTO tokens (id, name, role, hash, created_at, revoked_at, expires_at) "
                "VALUES (?,?,?,?,?,?,?)",
                (tid, name, role, token_hash, utcnow(), None, None),
            )
            self._audit(conn, actor, "token", tid, "create", reason=f"{name} ({role})")
        return self.get_token(tid)

    def get_token(self, token_id: str) -> TokenRecord:
        row = self.db.query_one("SELECT * FROM tokens WHERE id = ?", (token_id,))
        if row is None:
            raise NotFoundError(f"no token with id {token_id!r}")
        return TokenRecord.from_row(row)

    def lookup_token(self, token_hash: str) -> TokenRecord | None:
        """The token with this hash, revoked or expired included (to say which)."""
        row = self.db.query_one("SELECT * FROM tokens WHERE hash = ?", (token_hash,))
        return None if row is None else TokenRecord.from_row(row)

    def find_token(self, token_hash: str) -> TokenRecord | None:
        """The *usable* token with this hash: not revoked, not expired."""
        row = self.db.query_one(
            "SELECT * FROM tokens WHERE hash = ? AND revoked_at IS NULL "
            "AND (expires_at IS NULL OR expires_at > ?)",
            (token_hash, utcnow()),
        )
        return None if row is None else TokenRecord.from_row(row)

    def list_tokens(self) -> list[TokenRecord]:
        return [
            TokenRecord.from_row(r)
            for r in self.db.query("SELECT * FROM tokens ORDER BY created_at")
        ]

    def count_active_tokens(self) -> int:
        row = self.db.query_one(
            "SELECT COUNT(*) FROM tokens WHERE revoked_at IS NULL "
            "AND (expires_at IS NULL OR expires_at > ?)",
            (utcnow(),),
        )
        return int(row[0]) if row else 0

    def revoke_token(self, token_id: str, actor: str) -> TokenRecord:
        self.get_token(token_id)
        with self.db.transaction() as conn:
            conn.execute("UPDATE tokens SET revoked_at = ? WHERE id = ?", (utcnow(), token_id))
            self._audit(conn, actor, "token", token_id, "revoke")
        with self._epoch_lock:
            self._token_epoch += 1
        return self.get_token(token_id)

    @property
    def token_epoch(self) -> int:
        """Count of revocations made through this store object (cheap to poll)."""
        return self._token_epoch

    # ----------------------------------------------------------------- robots
    def set_robot_url(self, name: str, url: str, actor: str) -> None:
        with self.db.transaction() as conn:
            conn.execute(
                "INSERT INTO robots (name, url, updated_at, updated_by) VALUES (?,?,?,?) "
                "ON CONFLICT(name) DO UPDATE SET "
                "url = excluded.url, updated_at = excluded.updated_at, "
                "updated_by = excluded.updated_by",
                (name, url, utcnow(), actor),
            )
            self._audit(conn, actor, "robot", name, "connect", reason=url)

    def robot_urls(self) -> dict[str, str]:
        return {r["name"]: r["url"] for r in self.db.query("SELECT name, url FROM robots")}
