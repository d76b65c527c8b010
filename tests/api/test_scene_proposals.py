"""Scene interactions are proposals: the viser port cannot create a plan.

A direct client of the viser port is refused at the handshake (no proxy
ticket); one that gets in (with a ticket, as the proxy does) can only record
rate-limited proposals, which an operator accepts or dismisses over REST.
"""

from __future__ import annotations

import socket
import time
import types
from collections.abc import Iterator
from contextlib import contextmanager
from typing import Any

import msgspec
import pytest
import viser
import websockets.sync.client as wsclient
from websockets.exceptions import InvalidStatus

from server.scene.proposals import ProposalBook, ProposalDecidedError
from server.scene.wsguard import TICKET_HEADER, TicketDesk
from server.store import NotFoundError

PROTO = f"viser-v{viser.__version__}"


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def sapi(make_api):
    return make_api(scene_port=free_port())


def shown_demo_plan(sapi) -> dict[str, Any]:
    parent = sapi.wait(sapi.submit("demo.route")["id"])
    assert sapi.post("/api/v1/scene/show", json={"plan_id": parent["id"]}).status_code == 200
    return parent


def click(handle: Any, index: int, client_id: int) -> None:
    """A vertex click through the scene's own callback path, as viser delivers it."""
    event = types.SimpleNamespace(instance_index=index, client_id=client_id)
    for entry in handle._impl.click_cb:
        entry.callback(event)


def click_message(name: str, index: int) -> bytes:
    """The bytes viser's browser client sends for a click on a batched mesh instance."""
    return msgspec.msgpack.encode(
        {
            "type": "SceneNodeClickMessage",
            "name": name,
            "instance_index": index,
            "ray_origin": [0.0, 0.0, 5.0],
            "ray_direction": [0.0, 0.0, -1.0],
            "screen_pos": [0.5, 0.5],
            "modifier": None,
            "owner": "",
        }
    )


def camera_message() -> bytes:
    """viser counts a client as connected after its first camera report."""
    return msgspec.msgpack.encode(
        {
            "type": "ViewerCameraMessage",
            "wxyz": [1.0, 0.0, 0.0, 0.0],
            "position": [0.0, 0.0, 5.0],
            "fov": 1.0,
            "near": 0.01,
            "far": 100.0,
            "image_height": 480,
            "image_width": 640,
            "look_at": [0.0, 0.0, 0.0],
            "up_direction": [0.0, 0.0, 1.0],
        }
    )


@contextmanager
def raw_viser(port: int, ticket: str | None = None) -> Iterator[Any]:
    headers = {TICKET_HEADER: ticket} if ticket else None
    ws = wsclient.connect(
        f"ws://127.0.0.1:{port}/",
        subprotocols=[PROTO],  # type: ignore[list-item]
        additional_headers=headers,
        open_timeout=10,
        max_size=None,
    )
    try:
        yield ws
    finally:
        ws.close()


def children(sapi, parent_id: str) -> list[dict[str, Any]]:
    return sapi.get(f"/api/v1/plans?parent_id={parent_id}").json()


def wait_for(pred, timeout: float = 10.0) -> Any:
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        value = pred()
        if value:
            return value
        time.sleep(0.05)
    return pred()


# ----------------------------------------------------------- the viser port
def test_raw_websocket_to_viser_port_without_ticket_is_refused(sapi) -> None:
    scene = sapi.services.scene
    for ticket in (None, "forged-ticket"):
        with pytest.raises(InvalidStatus) as ei, raw_viser(scene.port, ticket):
            pass
        assert ei.value.response.status_code == 403
    # A spelling variant of the upgrade header is refused too.
    with socket.create_connection(("127.0.0.1", scene.port), timeout=5) as s:
        s.sendall(
            b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\nUpgrade: WebSocket\r\nConnection: Upgrade\r\n"
            b"Sec-WebSocket-Key: dGhlIHNhbXBsZSBub25jZQ==\r\nSec-WebSocket-Version: 13\r\n\r\n"
        )
        assert s.recv(64).startswith(b"HTTP/1.1 403")
    assert scene.tickets.refused >= 3
    # The static client page itself is public code and still served.
    with socket.create_connection(("127.0.0.1", scene.port), timeout=5) as s:
        s.sendall(b"GET / HTTP/1.1\r\nHost: 127.0.0.1\r\n\r\n")
        assert s.recv(64).startswith(b"HTTP/1.1 200")


def test_tickets_are_one_time() -> None:
    desk = TicketDesk(ttl_s=30.0)
    t = desk.issue()
    assert desk.redeem(t) is True
    assert desk.redeem(t) is False
    assert desk.redeem(None) is False and desk.redeem("") is False
    expired = TicketDesk(ttl_s=0.0)
    assert expired.redeem(expired.issue()) is False


def test_a_ticketed_ticket_is_single_use_on_the_viser_port(sapi) -> None:
    scene = sapi.services.scene
    ticket = scene.issue_ticket()
    with raw_viser(scene.port, ticket) as ws:
        assert ws.subprotocol == PROTO
        assert len(ws.recv(timeout=10)) > 0
    with pytest.raises(InvalidStatus), raw_viser(scene.port, ticket):
        pass


def test_clicks_over_a_viser_websocket_never_create_a_plan(sapi) -> None:
    """Even a client inside viser (ticket in hand) only makes a rate-limited proposal."""
    parent = shown_demo_plan(sapi)
    names = list(parent["result"]["nodes"])
    scene = sapi.services.scene
    with raw_viser(scene.port, scene.issue_ticket()) as ws:
        ws.recv(timeout=10)
        ws.send(camera_message())
        # Ten plans' worth of start/end clicks in ~2 s (the issue's attack).
        for k in range(10):
            for name in ("b1", "c0") if k % 2 == 0 else ("a0", "c2"):
                ws.send(click_message("/plan/vertices", names.index(name)))
            time.sleep(0.2)
        got = wait_for(lambda: sapi.get("/api/v1/scene/proposals", "viewer").json(), 10)
        time.sleep(0.5)  # let any late callbacks land before counting
    proposals = sapi.get("/api/v1/scene/proposals", "viewer").json()
    assert got and proposals
    assert children(sapi, parent["id"]) == []  # no plan was created
    # One client, one proposal per second at most: 2 s of clicks → ≤ 3.
    assert 1 <= len(proposals) <= 3, proposals
    p = proposals[-1]
    assert p["plan_id"] == parent["id"] and p["state"] == "pending"
    assert p["patch"] in ({"start": "b1", "end": "c0"}, {"start": "a0", "end": "c2"})
    assert p["source"].startswith("scene client")
    assert sapi.services.scene.proposals.dropped >= 1


# --------------------------------------------------------------- REST flow
def test_operator_accepts_a_proposal_through_rest(sapi) -> None:
    parent = shown_demo_plan(sapi)
    handle = sapi.services.scene.server.scene.get_handle_by_name("/plan/vertices")
    names = list(parent["result"]["nodes"])
    events_before = sapi.services.events.recent(500)
    for name in ("b1", "c0"):
        click(handle, names.index(name), client_id=7)
    assert children(sapi, parent["id"]) == []
    listed = sapi.get("/api/v1/scene/proposals", "viewer").json()
    assert len(listed) == 1
    prop = listed[0]
    assert prop["patch"] == {"start": "b1", "end": "c0"}
    assert prop["source"] == "scene client 7" and prop["kind"] == "demo.route"
    assert {"id", "plan_id", "patch", "created_at", "source"} <= set(prop)
    published = [e for e in sapi.services.events.recent(500) if e not in events_before]
    assert any(e.type == "proposal" and e.data["id"] == prop["id"] for e in published)
    assert sapi.get("/api/v1/scene", "viewer").json()["proposals"][0]["id"] == prop["id"]

    # A viewer can look but not decide.
    r = sapi.post(f"/api/v1/scene/proposals/{prop['id']}/accept", "viewer")
    assert r.status_code == 403
    r = sapi.post(f"/api/v1/scene/proposals/{prop['id']}/accept", "operator")
    assert r.status_code == 202, r.text
    plan = r.json()
    assert plan["parent_id"] == parent["id"]
    assert plan["created_by"].startswith("test-operator")
    assert r.headers["location"] == f"/api/v1/plans/{plan['id']}"
    done = sapi.wait(plan["id"])
    assert (done["params"]["start"], done["params"]["end"]) == ("b1", "c0")
    assert done["state"] == "planned"
    again = sapi.post(f"/api/v1/scene/proposals/{prop['id']}/accept", "operator")
    assert again.status_code == 409 and "accepted" in again.json()["detail"]
    decided = sapi.get(f"/api/v1/scene/proposals/{prop['id']}", "viewer").json()
    assert decided["state"] == "accepted" and decided["result_plan_id"] == plan["id"]
    audit = sapi.get(f"/api/v1/audit?entity=plan&entity_id={plan['id']}", "viewer").json()
    assert any(a["action"] == "accept_proposal" and prop["id"] in a["reason"] for a in audit)
    # The scene follows the accepted plan once it is planned.
    assert wait_for(lambda: sapi.services.scene.current.get("plan_id") == plan["id"])


def test_dismiss_and_unknown_proposals(sapi) -> None:
    parent = shown_demo_plan(sapi)
    handle = sapi.services.scene.server.scene.get_handle_by_name("/plan/vertices")
    names = list(parent["result"]["nodes"])
    for name in ("a0", "b1"):
        click(handle, names.index(name), client_id=1)
    (prop,) = sapi.get("/api/v1/scene/proposals?state=pending", "viewer").json()
    assert sapi.post(f"/api/v1/scene/proposals/{prop['id']}/dismiss", "viewer").status_code == 403
    r = sapi.post(f"/api/v1/scene/proposals/{prop['id']}/dismiss")
    assert r.status_code == 200 and r.json()["state"] == "dismissed"
    assert r.json()["decided_by"].startswith("test-operator")
    assert sapi.get("/api/v1/scene/proposals?state=pending", "viewer").json() == []
    assert sapi.post(f"/api/v1/scene/proposals/{prop['id']}/accept").status_code == 409
    assert children(sapi, parent["id"]) == []
    assert sapi.post("/api/v1/scene/proposals/pr_nope/accept").status_code == 404
    assert sapi.get("/api/v1/scene/proposals?state=bogus", "viewer").status_code == 422


def test_accept_with_invalid_params_stays_pending(sapi) -> None:
    parent = shown_demo_plan(sapi)
    book = sapi.services.scene.proposals
    p = book.propose(parent["id"], "demo.route", {"start": 12.5}, client=1, source="test")
    assert p is not None
    r = sapi.post(f"/api/v1/scene/proposals/{p.id}/accept")
    assert r.status_code == 422
    assert book.get(p.id).state == "pending"
    assert children(sapi, parent["id"]) == []


def test_no_scene_no_proposals(api) -> None:
    assert api.get("/api/v1/scene/proposals", "viewer").json() == []
    assert api.post("/api/v1/scene/proposals/pr_x/accept").status_code == 404


# --------------------------------------------------------- the book's limits
class FakeClock:
    def __init__(self) -> None:
        self.t = 1000.0

    def __call__(self) -> float:
        return self.t


def test_book_rate_limits_per_client_and_overall() -> None:
    clock = FakeClock()
    book = ProposalBook(min_interval_s=1.0, global_interval_s=0.2, max_pending=3, clock=clock)
    assert book.propose("pl_a", "demo.route", {"start": "a"}, client=1, source="c1")
    assert book.propose("pl_a", "demo.route", {"start": "b"}, client=1, source="c1") is None
    clock.t += 0.1
    # Another client, but too soon after the last proposal from anyone.
    assert book.propose("pl_a", "demo.route", {"start": "c"}, client=2, source="c2") is None
    clock.t += 0.2
    assert book.propose("pl_a", "demo.route", {"start": "c"}, client=2, source="c2")
    clock.t += 1.0
    assert book.propose("pl_a", "demo.route", {"start": "d"}, client=1, source="c1")
    clock.t += 1.0
    # Three pending: the cap drops the fourth whoever sends it.
    assert book.propose("pl_a", "demo.route", {"start": "e"}, client=3, source="c3") is None
    assert book.dropped == 3
    assert [p.patch["start"] for p in book.list("pending")] == ["d", "c", "a"]


def test_book_decisions_expiry_and_pruning() -> None:
    clock = FakeClock()
    book = ProposalBook(
        min_interval_s=0, global_interval_s=0, max_pending=50, max_kept=5, ttl_s=60, clock=clock
    )
    first = book.propose("pl_a", "k", {"x": 1}, client=1, source="s")
    assert first is not None
    taken = book.begin_accept(first.id)
    with pytest.raises(ProposalDecidedError):  # a second accept while the first submits
        book.begin_accept(first.id)
    book.abort_accept(first.id)
    assert book.get(first.id).state == "pending"
    book.dismiss(taken.id, "op")
    with pytest.raises(ProposalDecidedError):
        book.dismiss(first.id, "op")
    with pytest.raises(NotFoundError):
        book.get("pr_missing")
    stale = book.propose("pl_a", "k", {"x": 2}, client=1, source="s")
    assert stale is not None
    clock.t += 61
    assert book.get(stale.id).state == "lapsed"
    for i in range(10):
        assert book.propose("pl_a", "k", {"x": 10 + i}, client=i, source="s")
    kept = book.list()
    assert len(kept) == 10 and all(p.state == "pending" for p in kept)
    # Decided ones go first; pending ones are never forgotten by pruning.
    assert first.id not in {p.id for p in kept} and stale.id not in {p.id for p in kept}
