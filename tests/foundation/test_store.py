"""The store on SQLite and PostgreSQL: migrations, atomic writes, restart persistence.

The tests taking ``open_store`` run once per backend (``[sqlite]`` and
``[postgresql]``); the PostgreSQL server is a real one started for the session
(:mod:`tests.support.postgres`), each test on a database of its own.
"""

from __future__ import annotations

import sqlite3
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest

from server.lifecycle import IllegalTransitionError
from server.store import NotFoundError, Store
from server.store.migrations import SCHEMA_VERSION, SchemaTooNewError
from tests.support.postgres import pg_url, postgres_server  # noqa: F401

#: ``open_store(data_dir=tmp_path, **kw)`` → a :class:`Store` on this test's backend
#: (the same database on every call, as a restarted server finds it).
OpenStore = Callable[..., Store]


#: A PostgreSQL server is a server: its tests are ``integration`` (tests/conftest.py).
POSTGRES = pytest.param("postgresql", marks=pytest.mark.integration)


@pytest.fixture(params=["sqlite", POSTGRES])
def open_store(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[OpenStore]:
    url = request.getfixturevalue("pg_url") if request.param == "postgresql" else None
    opened: list[Store] = []

    def factory(data_dir: Path | None = None, **kw: Any) -> Store:
        store = Store(data_dir or tmp_path, database_url=url, **kw)
        opened.append(store)
        return store

    yield factory
    for store in opened:
        store.close()


def _planned(store: Store) -> str:
    p = store.create_plan("demo.route", {"start": "a0"}, "alice")
    store.transition_plan(p.id, "start", "planner")
    store.store_plan_result(
        p.id,
        result={"path": ["a0", "b0"]},
        arrays={"traj": np.arange(12.0).reshape(4, 3)},
        checks=[{"name": "ok", "passed": True, "message": ""}],
        metrics={"route_length_m": 1.0},
    )
    return p.id


def test_wal_and_schema_version(tmp_path: Path) -> None:
    store = Store(tmp_path)
    assert store.db.journal_mode == "wal"
    conn = sqlite3.connect(tmp_path / "steelpath.sqlite3")
    assert conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION
    conn.close()
    store.close()


def test_forward_migration_keeps_data(tmp_path: Path) -> None:
    old = Store(tmp_path, migrate_to=1)
    pid = _planned(old)
    old.close()
    conn = sqlite3.connect(tmp_path / "steelpath.sqlite3")
    assert conn.execute("PRAGMA user_version").fetchone()[0] == 1
    conn.close()
    new = Store(tmp_path)
    plan = new.get_plan(pid)
    assert plan.state == "planned" and plan.metrics == {"route_length_m": 1.0}
    idx = {r[0] for r in new.db.query("SELECT name FROM sqlite_master WHERE type='index'")}
    assert "plans_state" in idx
    new.close()


def test_newer_schema_is_refused(tmp_path: Path) -> None:
    Store(tmp_path).close()
    conn = sqlite3.connect(tmp_path / "steelpath.sqlite3")
    conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 5}")
    conn.commit()
    conn.close()
    with pytest.raises(SchemaTooNewError, match="newer"):
        Store(tmp_path)


def test_restart_finds_everything(open_store: OpenStore, tmp_path: Path) -> None:
    store = open_store()
    cloud = store.add_cloud(
        "scan", "upload:scan.ply", np.random.default_rng(0).random((50, 3)), 2, "bob"
    )
    pid = _planned(store)
    store.transition_plan(pid, "approve", "carol", approved_by="carol")
    ex = store.create_execution(pid, "ara", 10, "carol")
    store.set_execution_acked(ex.id, 4)
    audit_before = [(e.id, e.action) for e in store.list_audit()]
    store.close()

    again = open_store()
    assert again.get_cloud(cloud.id).n_points == 50
    assert np.array_equal(again.cloud_points(cloud.id), store.arrays.load(cloud.array_file))
    plan = again.get_plan(pid)
    assert plan.state == "executing" and plan.approved_by == "carol"
    assert np.array_equal(plan.array("traj"), np.arange(12.0).reshape(4, 3))
    assert again.get_execution(ex.id).acked == 4
    assert [(e.id, e.action) for e in again.list_audit()] == audit_before
    again.close()


def test_crash_mid_array_write_keeps_previous_state(
    open_store: OpenStore, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = open_store()
    pts = np.ones((10, 3))
    cloud = store.add_cloud("a", "upload", pts, 0, "x")

    real_save = np.save

    def dying_save(fh, arr, allow_pickle=False):
        real_save(fh, arr[: len(arr) // 2], allow_pickle=allow_pickle)  # a partial write…
        raise OSError("disk pulled mid-write")  # …then the crash

    monkeypatch.setattr(np, "save", dying_save)
    # Overwrite the same file name: the previous content must survive.
    with pytest.raises(OSError):
        store.arrays.save(cloud.array_file, np.zeros((1000, 3)))
    with pytest.raises(OSError):
        store.add_cloud("b", "upload", np.zeros((7, 3)), 0, "x")
    monkeypatch.undo()
    assert np.array_equal(store.cloud_points(cloud.id), pts)
    assert [c.id for c in store.list_clouds()] == [cloud.id]
    assert not list((tmp_path / "arrays" / "clouds").glob(".tmp-*"))
    store.close()


def test_failed_transaction_rolls_back(open_store: OpenStore, tmp_path: Path) -> None:
    store = open_store()
    p = store.create_plan("demo.route", {}, "x")
    n_audit = len(store.list_audit())
    with pytest.raises(IllegalTransitionError):
        store.transition_plan(p.id, "approve", "x")
    assert store.get_plan(p.id).state == "queued"
    assert len(store.list_audit()) == n_audit
    # A result that cannot be serialised (NaN) leaves the plan untouched.
    store.transition_plan(p.id, "start", "x")
    with pytest.raises(ValueError):
        store.store_plan_result(p.id, result={"x": float("nan")}, arrays={}, checks=[], metrics={})
    assert store.get_plan(p.id).state == "planning"
    store.close()


def test_rejected_when_a_check_fails(open_store: OpenStore, tmp_path: Path) -> None:
    store = open_store()
    p = store.create_plan("demo.route", {}, "x")
    store.transition_plan(p.id, "start", "x")
    rec = store.store_plan_result(
        p.id,
        result={},
        arrays={},
        checks=[{"name": "clearance", "passed": False, "message": "0.01 m < 0.02 m"}],
        metrics={},
    )
    assert rec.state == "rejected"
    assert "clearance" in store.list_audit("plan", p.id)[0].reason


def test_not_found_and_delete_rules(open_store: OpenStore, tmp_path: Path) -> None:
    store = open_store()
    with pytest.raises(NotFoundError, match="no plan"):
        store.get_plan("pl_nope")
    pid = _planned(store)
    child = store.create_plan("demo.route", {}, "x", parent_id=pid)
    store.transition_plan(pid, "approve", "x")
    store.create_execution(pid, "ara", 3, "x")
    with pytest.raises(IllegalTransitionError, match="executing"):
        store.delete_plan(pid, "x")
    store.transition_plan(pid, "abort", "x")
    store.delete_plan(pid, "x")
    assert store.get_plan(child.id).parent_id is None
    assert not (tmp_path / "arrays" / "plans" / pid).exists()
    assert store.list_audit("plan", pid)[0].action == "delete"


def test_newest_execution_of_agrees_with_a_scan_of_every_record(
    open_store: OpenStore, tmp_path: Path
) -> None:
    import random

    store = open_store(tmp_path / "var")
    plan = store.create_plan("demo.route", {}, "t")
    rng = random.Random(7)
    states = ["pending", "running", "paused", "interrupted", "completed", "aborted", "faulted"]
    robots = ["ara", "cmbot", "denso_vm6083"]
    with store.db.transaction() as conn:
        for i in range(300):
            conn.execute(
                "INSERT INTO executions (id, plan_id, robot, state, created_at, updated_at,"
                " created_by) VALUES (?, ?, ?, ?, ?, ?, 't')",
                (
                    f"ex_{i:04d}",
                    plan.id,
                    rng.choice(robots),
                    rng.choice(states),
                    f"2026-01-01T00:{i // 60:02d}:{i % 60:02d}.000+00:00",
                    "x",
                ),
            )
    every = store.list_executions(limit=10_000)
    assert [e.created_at for e in every] == sorted((e.created_at for e in every), reverse=True)
    pages = [store.list_executions(limit=70, offset=k) for k in range(0, 300, 70)]
    assert [len(pg) for pg in pages] == [70, 70, 70, 70, 20]
    assert [e.id for pg in pages for e in pg] == [e.id for e in every]  # pages tile it
    for robot in [*robots, "sbg_climber"]:
        for wanted in ({"pending", "running"}, {"paused", "interrupted", "running"}, set()):
            brute = next((e.id for e in every if e.robot == robot and e.state in wanted), None)
            assert store.newest_execution_of(robot, wanted) == brute, (robot, wanted)
    store.close()


def test_json_reads_agree_with_decoding_every_row(open_store: OpenStore, tmp_path: Path) -> None:
    """The undecoded JSON paths (listing, plan detail, one program command)
    give exactly what decoding the rows and building ``public()`` gives."""
    import json

    store = open_store()
    store.create_plan("demo.route", {"start": "a0"}, "bob")  # queued: no result yet
    done = _planned(store)
    p = store.create_plan("blast", {"surface": {"w": 1.5}}, "alice")
    store.transition_plan(p.id, "start", "planner")
    program = [{"op": "joints", "q_rad": [0.1 * i, -0.2], "duration_s": 0.5} for i in range(7)]
    store.store_plan_result(
        p.id,
        result={"cost": 2.5, "nested": {"a": [1, None, "x"]}},
        arrays={},
        checks=[{"name": "reach", "passed": False, "message": "too far ü"}],
        metrics={"n": 3.0},
        program=program,
    )
    failed = store.create_plan("demo.route", {"start": "zz"}, "carol").id
    store.transition_plan(failed, "start", "planner")
    store.transition_plan(failed, "fail", "planner", error="no such vertex")
    for kw in ({}, {"kind": "demo.route"}, {"limit": 2, "offset": 1}, {"parent_id": done}):
        want = [r.public(include_result=False) for r in store.list_plans(summary=True, **kw)]
        assert json.loads(store.list_plans_json(**kw)) == want
    assert len(json.loads(store.list_plans_json())) == 4
    for pid in (done, p.id, failed):
        rec, result_json, program_json = store.get_plan_json(pid)
        full = store.get_plan(pid)
        assert rec.public(include_result=False) == full.public(include_result=False)
        assert json.loads(result_json) == full.result
        assert json.loads(program_json) == full.program
    assert [store.plan_command(p.id, i) for i in range(-1, 9)] == [None, *program, None, None]
    assert store.plan_command(done, 0) is None  # no program
    with pytest.raises(NotFoundError):
        store.plan_command("pl_missing", 0)
    with pytest.raises(NotFoundError):
        store.get_plan_json("pl_missing")


def test_get_plan_can_leave_result_and_program_unread(
    open_store: OpenStore, tmp_path: Path
) -> None:
    store = open_store()
    pid = _planned(store)
    program = [{"op": "stop"}]
    with store.db.transaction() as conn:
        conn.execute("UPDATE plans SET program = ? WHERE id = ?", ('[{"op": "stop"}]', pid))
    full = store.get_plan(pid)
    assert full.result == {"path": ["a0", "b0"]} and full.program == program
    lean = store.get_plan(pid, result=False)
    assert lean.result == {} and lean.program == program
    bare = store.get_plan(pid, result=False, program=False)
    assert bare.result == {} and bare.program is None
    assert bare.public(include_result=False) == full.public(include_result=False)
    assert store.get_plan(pid, program=False).result == full.result


def test_record_acks_is_record_ack_for_a_range_and_survives_a_restart(
    open_store: OpenStore, tmp_path: Path
) -> None:
    store = open_store()
    pid = _planned(store)
    store.transition_plan(pid, "approve", "carol", approved_by="carol")
    one = store.create_execution(pid, "ara", 10, "carol")
    for i in range(0, 6):
        store.record_ack(one.id, i)
    store.close()
    store = open_store()
    pid2 = _planned(store)
    store.transition_plan(pid2, "approve", "carol", approved_by="carol")
    ranged = store.create_execution(pid2, "ara", 10, "carol")
    store.record_acks(ranged.id, 0, 2)
    store.record_acks(ranged.id, 1, 5)  # overlaps: nothing twice, acked only grows
    store.record_acks(ranged.id, 3, 3)
    assert store.list_acks(ranged.id) == store.list_acks(one.id) == list(range(6))
    assert store.get_execution(ranged.id).acked == store.get_execution(one.id).acked == 6
    with pytest.raises(ValueError, match="last < first"):
        store.record_acks(ranged.id, 4, 3)
    assert store.list_acks(ranged.id) == list(range(6))
    store.close()


def test_a_violated_constraint_raises_the_store_integrity_error(open_store: OpenStore) -> None:
    """One exception for both backends (an archive import catches it), and the
    transaction is rolled back whole."""
    from server.store.database import IntegrityError

    store = open_store()
    with pytest.raises(IntegrityError, match=r"(?i)unique"), store.db.transaction() as conn:
        conn.execute(
            "INSERT INTO tokens (id, name, role, hash, created_at) VALUES (?,?,?,?,?)",
            ("tk_1", "a", "admin", "h", "now"),
        )
        conn.execute(
            "INSERT INTO tokens (id, name, role, hash, created_at) VALUES (?,?,?,?,?)",
            ("tk_2", "b", "admin", "h", "now"),  # the same hash: UNIQUE
        )
    assert store.list_tokens() == []
    with pytest.raises(IntegrityError):  # a foreign key: no such plan
        store.db.query(
            "INSERT INTO executions (id, plan_id, robot, state, created_at, updated_at, "
            "created_by) VALUES ('ex_1', 'pl_none', 'ara', 'pending', 't', 't', 't')"
        )


# ------------------------------------------------------------- PostgreSQL only
# (integration: each starts on the session's PostgreSQL server)


def _pg_version(url: str) -> int:
    import psycopg

    with psycopg.connect(url) as conn:
        row = conn.execute("SELECT version FROM schema_version").fetchone()
        assert row is not None
        return int(row[0])


@pytest.mark.integration
def test_postgres_schema_version_and_forward_migration(pg_url: str, tmp_path: Path) -> None:  # noqa: F811
    old = Store(tmp_path, database_url=pg_url, migrate_to=1)
    assert _pg_version(pg_url) == 1
    pid = _planned(old)
    old.close()
    new = Store(tmp_path, database_url=pg_url)
    assert _pg_version(pg_url) == SCHEMA_VERSION
    plan = new.get_plan(pid)
    assert plan.state == "planned" and plan.metrics == {"route_length_m": 1.0}
    idx = {r[0] for r in new.db.query("SELECT indexname FROM pg_indexes")}
    assert {"plans_state", "audit_entity", "findings_by_plan"} <= idx
    types = {
        (r[0], r[1]): r[2]
        for r in new.db.query(
            "SELECT table_name, column_name, data_type FROM information_schema.columns "
            "WHERE table_schema = current_schema()"
        )
    }
    # SQLite's REAL is a double and its INTEGER 64-bit: the translation keeps both.
    assert types[("plans", "progress")] == "double precision"
    assert types[("execution_states", "t")] == "double precision"
    assert types[("executions", "acked")] == "bigint"
    assert types[("audit_events", "id")] == "bigint"
    new.close()


@pytest.mark.integration
def test_postgres_newer_schema_is_refused(pg_url: str, tmp_path: Path) -> None:  # noqa: F811
    import psycopg

    Store(tmp_path, database_url=pg_url).close()
    with psycopg.connect(pg_url, autocommit=True) as conn:
        conn.execute("UPDATE schema_version SET version = %s", (SCHEMA_VERSION + 5,))
    with pytest.raises(SchemaTooNewError, match="newer"):
        Store(tmp_path, database_url=pg_url)


@pytest.mark.integration
def test_postgres_servers_starting_at_once_migrate_once(pg_url: str, tmp_path: Path) -> None:  # noqa: F811
    """Six stores opened at the same moment on an empty database: each migration
    runs once (a second run would fail on CREATE TABLE), every store works."""
    import threading

    barrier = threading.Barrier(6)
    stores: list[Store] = []
    errors: list[BaseException] = []

    def open_one(i: int) -> None:
        barrier.wait()
        try:
            stores.append(Store(tmp_path / str(i), database_url=pg_url))
        except BaseException as exc:
            errors.append(exc)

    threads = [threading.Thread(target=open_one, args=(i,)) for i in range(6)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(60)
    assert errors == [] and len(stores) == 6
    assert _pg_version(pg_url) == SCHEMA_VERSION
    pid = stores[0].create_plan("demo.route", {}, "x").id
    assert all(s.get_plan(pid).state == "queued" for s in stores)
    for s in stores:
        s.close()


@pytest.mark.integration
def test_postgres_rows_read_like_sqlite_rows(pg_url: str, tmp_path: Path) -> None:  # noqa: F811
    store = Store(tmp_path, database_url=pg_url)
    pid = _planned(store)
    row = store.db.query_one("SELECT * FROM plans WHERE id = ?", (pid,))
    assert row is not None and row["id"] == row[0] == pid
    # The stand-in for SQLite's rowid stays hidden, as rowid is from SELECT * there.
    assert row.keys() == store.db.columns("plans") and "rowid" not in dict(row)
    assert dict(row)["state"] == "planned" and len(row) == len(row.keys())
    # A literal '?' and '%' stay literal; placeholders still bind.
    lit = store.db.query_one("SELECT '?' AS q, '100%' AS p, ? AS v", ("x",))
    assert (lit["q"], lit["p"], lit["v"]) == ("?", "100%", "x")
    # A bool is stored as 0/1 in an INTEGER column, as SQLite stores it.
    with store.db.transaction() as conn:
        conn.execute("UPDATE plans SET cancel_requested = ? WHERE id = ?", (True, pid))
    assert store.get_plan(pid).cancel_requested == 1
    assert tuple(store.db.query_one("SELECT ? + 0, ?", (True, False))) == (1, 0)
    store.close()


@pytest.mark.integration
def test_postgres_writers_on_two_stores_take_turns(pg_url: str, tmp_path: Path) -> None:  # noqa: F811
    """Read-check-write is atomic across servers, as on SQLite: of 8 threads on
    two stores approving one plan, exactly one succeeds."""
    import threading

    a = Store(tmp_path / "a", database_url=pg_url)
    b = Store(tmp_path / "b", database_url=pg_url)
    pid = _planned(a)
    barrier = threading.Barrier(8)
    outcomes: list[str] = []

    def approve(store: Store) -> None:
        barrier.wait()
        try:
            store.transition_plan(pid, "approve", "x", expect="planned")
            outcomes.append("ok")
        except IllegalTransitionError:
            outcomes.append("409")

    threads = [threading.Thread(target=approve, args=((a, b)[i % 2],)) for i in range(8)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(60)
    assert sorted(outcomes) == ["409"] * 7 + ["ok"]
    assert [e.action for e in b.list_audit("plan", pid)].count("approve") == 1
    a.close()
    b.close()


@pytest.mark.integration
def test_postgres_reads_see_the_last_commit_and_a_writer_its_own_rows(
    pg_url: str,  # noqa: F811
    tmp_path: Path,
) -> None:
    """As on SQLite (tests/api/test_database_readers.py): a read does not wait for
    another thread's open transaction and sees the last commit; inside its own
    transaction a thread reads what it has written."""
    import threading

    store = Store(tmp_path, database_url=pg_url)
    pid = store.create_plan("demo.route", {}, "x").id
    inside, release = threading.Event(), threading.Event()

    def writer() -> None:
        with store.db.transaction() as conn:
            conn.execute("UPDATE plans SET stage = 'pending' WHERE id = ?", (pid,))
            assert store.get_plan(pid).stage == "pending"  # its own, uncommitted
            inside.set()
            release.wait(30)

    th = threading.Thread(target=writer)
    th.start()
    try:
        assert inside.wait(30)
        assert store.get_plan(pid).stage == ""  # the last commit, without waiting
    finally:
        release.set()
        th.join(30)
    assert store.get_plan(pid).stage == "pending"
    store.close()


def test_servers_starting_together_make_one_first_start_token(
    open_store: OpenStore, tmp_path: Path
) -> None:
    """Several servers starting on one empty store: the check for an
    active token and the insert are one transaction, so exactly one of them
    creates (and prints) the first-start admin token."""
    import threading

    from server.auth import bootstrap_admin

    stores = [open_store(tmp_path / "shared") for _ in range(2)]
    barrier = threading.Barrier(6)
    secrets: list[str | None] = []

    def start(store: Store) -> None:
        barrier.wait()
        secrets.append(bootstrap_admin(store, None))

    threads = [threading.Thread(target=start, args=(stores[i % 2],)) for i in range(6)]
    for th in threads:
        th.start()
    for th in threads:
        th.join(60)
    made = [s for s in secrets if s is not None]
    assert len(secrets) == 6 and len(made) == 1, secrets
    assert stores[1].count_active_tokens() == 1
    assert bootstrap_admin(stores[0], None) is None  # a later start makes none
