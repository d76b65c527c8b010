"""Plans of several servers on one store: each plan's job belongs
to the server that submitted it (``plans.planner``).

Two real ``steelpath serve`` processes share one data directory.  A server
starting beside another leaves the other's plan alone (no re-queue, one start,
one finish, planned by its own server); a server killed mid-plan has its plan
adopted by the other once its heartbeat is older than ``orphan_plan_s``, which
plans it again: re-queued once, finished once, by the adopting server.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from server.store import Store
from server.store.ownership import OwnershipStore
from tests.support.serve import ServeProcess, stop_emulators
from tests.support.waiting import wait_for

pytestmark = pytest.mark.slow

ORPHAN_S = 6.0  # well above a loaded machine's late heartbeats (renewed every 1 s)


def _server(data: Path, name: str, token: str | None = None) -> ServeProcess:
    return ServeProcess(
        data,
        name,
        token=token,
        emulators="false",
        extra_kinds="tests.support.kinds",
        orphan_plan_s=str(ORPHAN_S),
    )


@pytest.fixture
def data(tmp_path: Path) -> Iterator[Path]:
    d = tmp_path / "var"
    yield d
    stop_emulators(d)


def _ticking(server: ServeProcess, seconds: float) -> str:
    pid = server.post("/plans", {"kind": "test.job", "params": {"seconds": seconds}}, status=202)[
        "id"
    ]
    wait_for(
        lambda: (server.get(f"/plans/{pid}")["stage"] or "").startswith("tick"), 30, "planning"
    )
    return str(pid)


def _actions(store: Store, pid: str) -> list[str]:
    return [e.action for e in reversed(store.list_audit("plan", pid))]


def test_a_starting_server_leaves_a_live_servers_plan_and_adopts_a_dead_ones(
    data: Path,
) -> None:
    a = _server(data, "a")
    b = None
    try:
        first = _ticking(a, 6.0)
        store = Store(data)
        a_id = store.get_plan(first).planner
        assert a_id is not None and a_id.startswith("srv_")
        # B starts while A plans: B's start and its sweeps leave the plan to A.
        b = _server(data, "b", token=a.token)
        time.sleep(ORPHAN_S + 2.5)
        assert store.get_plan(first).planner == a_id
        done = wait_for(
            lambda: (p := store.get_plan(first)).state not in ("queued", "planning") and p,
            60,
            "A to finish its plan",
        )
        assert done.state == "planned" and done.planner == a_id, done
        acts = _actions(store, first)
        assert acts.count("start") == 1 and acts.count("finish") == 1, acts
        assert "requeue" not in acts, acts

        # A dies mid-plan: B adopts the plan once A is silent, and plans it again.
        second = _ticking(a, 6.0)
        a.kill9()
        killed = time.monotonic()
        adopted = wait_for(
            lambda: (p := store.get_plan(second)).planner not in (None, a_id) and p,
            ORPHAN_S + 15,
            "B to adopt A's plan",
        )
        # Not before A's last heartbeat was ORPHAN_S old (the rule; how long
        # after the kill depends on how late A's last beat was on a busy machine).
        seen_at = time.time()
        beats = {r.id: r.heartbeat_at for r in OwnershipStore(store.db).servers()}
        if a_id in beats:
            assert seen_at - beats[a_id] >= ORPHAN_S, (seen_at, beats[a_id])
        assert time.monotonic() - killed < ORPHAN_S + 15
        ended = wait_for(
            lambda: (p := store.get_plan(second)).state not in ("queued", "planning") and p,
            60,
            "B to finish the adopted plan",
        )
        assert ended.state == "planned" and ended.planner == adopted.planner, ended
        assert b.get(f"/plans/{second}")["state"] == "planned"
        acts = _actions(store, second)
        # Started by A, re-queued and started again by B, finished once.
        assert acts.count("requeue") == 1 and acts.count("start") == 2, acts
        assert acts.count("finish") == 1, acts
        requeue = next(e for e in store.list_audit("plan", second) if e.action == "requeue")
        assert a_id in requeue.reason and str(adopted.planner) in requeue.reason, requeue
        store.close()
    finally:
        a.stop()
        if b is not None:
            b.stop()
