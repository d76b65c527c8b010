"""SQLite + npy storage: WAL, migrations, atomic writes, restart persistence."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import numpy as np
import pytest

from server.lifecycle import IllegalTransitionError
from server.store import NotFoundError, Store
from server.store.migrations import SCHEMA_VERSION, SchemaTooNewError


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


def test_restart_finds_everything(tmp_path: Path) -> None:
    store = Store(tmp_path)
    cloud = store.add_cloud(
        "scan", "upload:scan.ply", np.random.default_rng(0).random((50, 3)), 2, "bob"
    )
    pid = _planned(store)
    store.transition_plan(pid, "approve", "carol", approved_by="carol")
    ex = store.create_execution(pid, "ara", 10, "carol")
    store.set_execution_acked(ex.id, 4)
    audit_before = [(e.id, e.action) for e in store.list_audit()]
    store.close()

    again = Store(tmp_path)
    assert again.get_cloud(cloud.id).n_points == 50
    assert np.array_equal(again.cloud_points(cloud.id), store.arrays.load(cloud.array_file))
    plan = again.get_plan(pid)
    assert plan.state == "executing" and plan.approved_by == "carol"
    assert np.array_equal(plan.array("traj"), np.arange(12.0).reshape(4, 3))
    assert again.get_execution(ex.id).acked == 4
    assert [(e.id, e.action) for e in again.list_audit()] == audit_before
    again.close()


def test_crash_mid_array_write_keeps_previous_state(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    store = Store(tmp_path)
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


def test_failed_transaction_rolls_back(tmp_path: Path) -> None:
    store = Store(tmp_path)
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


def test_rejected_when_a_check_fails(tmp_path: Path) -> None:
    store = Store(tmp_path)
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


def test_not_found_and_delete_rules(tmp_path: Path) -> None:
    store = Store(tmp_path)
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


def test_newest_execution_of_agrees_with_a_scan_of_every_record(tmp_path: Path) -> None:
    import random

    store = Store(tmp_path / "var")
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


def test_json_reads_agree_with_decoding_every_row(tmp_path: Path) -> None:
    """The undecoded JSON paths (listing, plan detail, one program command)
    give exactly what decoding the rows and building ``public()`` gives."""
    import json

    store = Store(tmp_path)
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


def test_get_plan_can_leave_result_and_program_unread(tmp_path: Path) -> None:
    store = Store(tmp_path)
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


def test_record_acks_is_record_ack_for_a_range_and_survives_a_restart(tmp_path: Path) -> None:
    store = Store(tmp_path)
    pid = _planned(store)
    store.transition_plan(pid, "approve", "carol", approved_by="carol")
    one = store.create_execution(pid, "ara", 10, "carol")
    for i in range(0, 6):
        store.record_ack(one.id, i)
    store.close()
    store = Store(tmp_path)
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
