"""Webhooks: admin-registered receivers get signed JSON POSTs of execution
results and E-stops, retried with back-off.  Receivers are
real HTTP servers on loopback, including one that is down and comes back, so
the webhooks here are registered with ``allow_private_network`` (what the
address policy refuses without it: tests/api/test_webhook_ssrf.py).
"""

from __future__ import annotations

import json
import socket
import threading
import time
from collections.abc import Iterator
from contextlib import contextmanager
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from typing import Any

import pytest

from server.webhooks import sign, verify
from tests.support.waiting import wait_for


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Receiver:
    """An HTTP receiver on loopback: records each POST (headers, body) and
    answers with the next status of ``statuses`` (then 200)."""

    def __init__(self, port: int, statuses: list[int] | None = None) -> None:
        self.port = port
        self.got: list[tuple[dict[str, str], bytes, int]] = []
        self.statuses = list(statuses or [])
        rec = self

        class Handler(BaseHTTPRequestHandler):
            def do_POST(self) -> None:
                body = self.rfile.read(int(self.headers.get("Content-Length", 0)))
                status = rec.statuses.pop(0) if rec.statuses else 200
                rec.got.append((dict(self.headers), body, status))
                self.send_response(status)
                self.end_headers()

            def log_message(self, *args: Any) -> None:
                pass

        self.server = ThreadingHTTPServer(("127.0.0.1", port), Handler)
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)

    @property
    def url(self) -> str:
        return f"http://127.0.0.1:{self.port}/hook"

    def __enter__(self) -> Receiver:
        self.thread.start()
        return self

    def __exit__(self, *exc: object) -> None:
        self.server.shutdown()
        self.server.server_close()


@contextmanager
def receiver(port: int | None = None, statuses: list[int] | None = None) -> Iterator[Receiver]:
    with Receiver(port or free_port(), statuses) as r:
        yield r


def register(
    api, url: str, events: list[str] | None = None, *, allow_private: bool = True
) -> dict[str, Any]:
    """Register ``url``; loopback receivers need ``allow_private`` (the default here)."""
    body: dict[str, Any] = {"url": url, "allow_private_network": allow_private}
    if events is not None:
        body["events"] = events
    r = api.post("/api/v1/webhooks", "admin", json=body)
    assert r.status_code == 201, r.text
    return r.json()


def deliveries(api, hook_id: str) -> list[dict[str, Any]]:
    r = api.get(f"/api/v1/webhooks/{hook_id}/deliveries", "admin")
    assert r.status_code == 200, r.text
    return r.json()


def first_in(ds: list[dict[str, Any]], state: str) -> dict[str, Any] | None:
    """The newest delivery when it is in ``state`` (none yet: None)."""
    return ds[0] if ds and ds[0]["state"] == state else None


@pytest.fixture
def wapi(make_api):
    return make_api(webhook_backoff_s=0.2)


# ------------------------------------------------------------------ signing
def test_signature_is_hmac_sha256_of_timestamp_and_body() -> None:
    import hashlib
    import hmac

    body = b'{"event":"estop"}'
    want = hmac.new(b"s3cret", b"1700000000." + body, hashlib.sha256).hexdigest()
    assert sign("s3cret", 1700000000, body) == "sha256=" + want
    assert verify("s3cret", "1700000000", body, "sha256=" + want, now=1700000100)
    assert not verify("s3cret", "1700000000", body + b" ", "sha256=" + want, now=1700000100)
    assert not verify("other", "1700000000", body, "sha256=" + want, now=1700000100)
    # An old delivery replayed later is refused by its timestamp.
    assert not verify("s3cret", "1700000000", body, "sha256=" + want, now=1700001000)
    assert not verify("s3cret", "soon", body, "sha256=" + want)


# ------------------------------------------------------------------ REST
def test_only_an_admin_registers_and_bad_requests_are_named(wapi) -> None:
    url = "http://127.0.0.1:9/hook"
    assert wapi.post("/api/v1/webhooks", "operator", json={"url": url}).status_code == 403
    assert wapi.get("/api/v1/webhooks", "viewer").status_code == 403
    for body, words in (
        ({"url": "ftp://example.org/x"}, "https?://"),
        ({"url": "not a url"}, "https?://"),
        ({"url": url, "events": ["estop", "plan.done"]}, "plan.done"),
        ({"url": url, "events": []}, "at least 1"),
        ({"url": url, "secret": "mine"}, "secret"),
    ):
        r = wapi.post("/api/v1/webhooks", "admin", json=body)
        assert r.status_code == 422 and words in r.text, (body, r.text)
    hook = register(wapi, url, ["estop"])
    assert hook["secret"].startswith("whsec_") and hook["events"] == ["estop"]
    assert hook["allow_private_network"] is True
    listed = wapi.get("/api/v1/webhooks", "admin").json()
    assert [h["id"] for h in listed] == [hook["id"]]
    assert (
        "secret" not in listed[0]
        and "secret" not in wapi.get(f"/api/v1/webhooks/{hook['id']}", "admin").json()
    )
    assert wapi.get("/api/v1/webhooks/wh_nope", "admin").status_code == 404
    audit = wapi.get("/api/v1/audit?entity=webhook", "admin").json()
    assert any(a["entity_id"] == hook["id"] and a["action"] == "create" for a in audit)


def test_an_estop_is_delivered_signed_and_listed(wapi) -> None:
    with receiver() as rx:
        hook = register(wapi, rx.url)
        other = register(wapi, rx.url, ["execution.completed"])  # not for E-stops
        r = wapi.post("/api/v1/estop", "operator", json={"reason": "webhook test"})
        assert r.status_code == 200, r.text
        wait_for(lambda: rx.got, what="the delivery")
        time.sleep(0.5)  # nothing more arrives
    assert len(rx.got) == 1
    headers, body, _ = rx.got[0]
    h = {k.lower(): v for k, v in headers.items()}
    assert h["x-steelpath-event"] == "estop"
    assert verify(hook["secret"], h["x-steelpath-timestamp"], body, h["x-steelpath-signature"])
    assert not verify(other["secret"], h["x-steelpath-timestamp"], body, h["x-steelpath-signature"])
    msg = json.loads(body)
    assert msg["event"] == "estop" and msg["id"] == h["x-steelpath-delivery"]
    assert msg["data"]["reason"] == "webhook test" and msg["data"]["by"]
    (d,) = deliveries(wapi, hook["id"])
    assert (d["state"], d["attempts"], d["last_status"], d["id"]) == (
        "delivered",
        1,
        200,
        msg["id"],
    )
    assert deliveries(wapi, other["id"]) == []


def test_execution_results_are_sent_once_per_state_change(wapi) -> None:
    """The execution events the link service publishes: progress (acks in
    the same state) is not sent, each result once."""
    with receiver() as rx:
        hook = register(wapi, rx.url, ["execution.completed", "execution.faulted"])
        bus = wapi.services.events
        for state, acked in (("running", 0), ("running", 1), ("running", 2), ("completed", 3)):
            bus.publish(
                "execution",
                {"id": "ex_1", "plan_id": "pl_1", "state": state, "acked": acked, "total": 3},
            )
        bus.publish("execution", {"id": "ex_1", "plan_id": "pl_1", "state": "completed"})
        bus.publish("execution", {"id": "ex_2", "plan_id": "pl_2", "state": "interrupted"})
        bus.publish("execution", {"id": "ex_3", "plan_id": "pl_3", "state": "faulted"})
        wait_for(lambda: len(rx.got) >= 2, what="two deliveries")
        time.sleep(0.5)
    events = sorted(json.loads(b)["event"] for _, b, _ in rx.got)
    assert events == ["execution.completed", "execution.faulted"]  # not interrupted: not asked
    got = {json.loads(b)["data"]["id"]: json.loads(b)["data"] for _, b, _ in rx.got}
    assert got["ex_1"]["state"] == "completed" and got["ex_3"]["state"] == "faulted"
    assert {d["state"] for d in deliveries(wapi, hook["id"])} == {"delivered"}


def test_a_receiver_that_is_down_then_comes_back_gets_it_after_retries(wapi) -> None:
    port = free_port()
    hook = register(wapi, f"http://127.0.0.1:{port}/hook", ["estop"])
    wapi.post("/api/v1/estop", "operator", json={"reason": "down"})
    # Nothing listens: attempts pile up as "unreachable" (no more detail: the
    # list must not tell a closed port from an open one), backing off.
    d = wait_for(
        lambda: (ds := deliveries(wapi, hook["id"])) and ds[0]["attempts"] >= 2 and ds[0],
        what="two failed attempts",
    )
    assert d["state"] == "pending" and d["last_status"] is None
    assert d["last_error"] == "unreachable"
    with receiver(port, statuses=[503]) as rx:  # back, but busy once
        d = wait_for(
            lambda: first_in(deliveries(wapi, hook["id"]), "delivered"),
            timeout=30,
            what="the delivery after the receiver came back",
        )
    assert [s for _, _, s in rx.got] == [503, 200]
    assert d["attempts"] >= 4 and d["last_status"] == 200 and d["last_error"] is None


def test_attempts_run_out_and_a_removed_webhook_gets_nothing(make_api) -> None:
    api = make_api(webhook_backoff_s=0.1, webhook_max_attempts=2)
    with receiver(statuses=[500, 500, 500]) as rx:
        hook = register(api, rx.url, ["estop"])
        api.post("/api/v1/estop", "operator", json={})
        d = wait_for(
            lambda: first_in(deliveries(api, hook["id"]), "failed"),
            what="the delivery to fail",
        )
        assert d["attempts"] == 2 and d["last_status"] == 500 and d["last_error"] == "HTTP 500"
        assert len(rx.got) == 2
        assert api.delete(f"/api/v1/webhooks/{hook['id']}", "admin").status_code == 204
        api.post("/api/v1/estop", "operator", json={})
        time.sleep(0.8)
        assert len(rx.got) == 2  # removed: nothing more
    assert api.get("/api/v1/webhooks", "admin").json() == []
    (kept,) = api.get("/api/v1/webhooks?include_removed=true", "admin").json()
    assert kept["removed_at"] and kept["removed_by"]
    assert len(deliveries(api, hook["id"])) == 1  # its history stays


def test_a_pending_delivery_survives_a_restart(make_api, tmp_path) -> None:
    data = tmp_path / "var"
    port = free_port()
    first = make_api(data=data, webhook_backoff_s=0.2)
    hook = register(first, f"http://127.0.0.1:{port}/hook", ["estop"])
    first.post("/api/v1/estop", "operator", json={"reason": "before restart"})
    wait_for(
        lambda: (ds := deliveries(first, hook["id"])) and ds[0]["attempts"] >= 1,
        what="a failed attempt",
    )
    first.client.__exit__(None, None, None)
    with receiver(port) as rx:
        second = make_api(data=data, webhook_backoff_s=0.2)
        wait_for(lambda: rx.got, timeout=30, what="the delivery after the restart")
        d = wait_for(
            lambda: first_in(deliveries(second, hook["id"]), "delivered"),
            what="delivered",
        )
    assert json.loads(rx.got[0][1])["data"]["reason"] == "before restart"
    assert d["attempts"] >= 2
