"""Live Foxglove server ("Live"): off by default, bound to
127.0.0.1, reached through the authenticated proxy ``/foxglove``, publishing
the recording's channels while a robot runs.  The client speaks the Foxglove
WebSocket protocol (foxglove.websocket.v1): ``advertise`` → ``subscribe`` →
binary message data (opcode 0x01, subscription id, timestamp, payload)."""

from __future__ import annotations

import json
import queue
import socket
import struct
import threading
import time
from pathlib import Path
from typing import Any

import pytest
from starlette.testclient import WebSocketDenialResponse
from starlette.websockets import WebSocketDisconnect

from server.recording.messages import CHANNELS
from server.settings import Settings
from tests.api.test_dispatch import approved_demo, wait_execution

PROTO = "foxglove.websocket.v1"
SDK_PROTO = "foxglove.sdk.v1"  # the same protocol, as foxglove-sdk 0.30 names it


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def listening_on(port: int) -> set[str]:
    """Local addresses (hex, as /proc/net/tcp{,6} write them) listening on ``port``."""
    found = set()
    for name in ("/proc/net/tcp", "/proc/net/tcp6"):
        path = Path(name)
        if not path.exists():
            continue
        for line in path.read_text().splitlines()[1:]:
            cols = line.split()
            addr, hexport = cols[1].rsplit(":", 1)
            if int(hexport, 16) == port and cols[3] == "0A":  # 0A: LISTEN
                found.add(addr)
    return found


def refused(client: Any, url: str, **kw: Any) -> WebSocketDenialResponse:
    """The HTTP refusal of a handshake (the test fails if it is accepted)."""
    kw.setdefault("subprotocols", [PROTO])
    with pytest.raises(WebSocketDenialResponse) as exc, client.websocket_connect(url, **kw):
        pass
    return exc.value


@pytest.fixture
def fapi(make_api):
    return make_api(emulators=True, emulator_time_scale=10.0, foxglove_port=free_port())


def test_off_by_default_and_the_proxy_says_so(api) -> None:
    assert Settings.model_fields["foxglove_port"].default == 0
    assert api.services.settings.foxglove_port == 0
    assert api.services.foxglove is None  # nothing started, no port listening
    token = api.tokens["viewer"]
    r = refused(api.client, f"/foxglove?token={token}")
    assert r.status_code == 503
    assert "STEELPATH_FOXGLOVE_PORT" in r.json()["detail"]


def test_the_server_listens_on_loopback_only_and_the_proxy_needs_a_token(fapi) -> None:
    live = fapi.services.foxglove
    assert live.running and live.port == fapi.services.settings.foxglove_port
    if Path("/proc/net/tcp").exists():
        # 0100007F: 127.0.0.1 (little-endian hex); no 0.0.0.0 or :: listener.
        assert listening_on(live.port) == {"0100007F"}
    c = fapi.client
    for url, kw in [
        ("/foxglove", {}),
        ("/foxglove?token=sp_not-a-token", {}),
        ("/foxglove", {"headers": {"authorization": "Bearer nope"}}),
    ]:
        assert refused(c, url, **kw).status_code == 401, url
    # The session cookie is ambient: refused from another origin ...
    c.cookies.set("steelpath_token", fapi.tokens["viewer"])
    try:
        r = refused(c, "/foxglove", headers={"origin": "http://evil.example"})
        assert r.status_code == 401 and "cross-origin" in r.json()["detail"]
        # ... and accepted from the same origin.
        with c.websocket_connect(
            "/foxglove", subprotocols=[SDK_PROTO, PROTO], headers={"origin": "http://testserver"}
        ) as ws:
            assert ws.accepted_subprotocol == SDK_PROTO  # the SDK's name for the protocol
            assert json.loads(ws.receive_text())["op"] == "serverInfo"
    finally:
        c.cookies.clear()
    # A client offering neither subprotocol is told which to offer.
    r = refused(c, f"/foxglove?token={fapi.tokens['viewer']}", subprotocols=["x"])
    assert r.status_code == 400 and PROTO in r.json()["detail"]


class FoxgloveClient:
    """A Foxglove WebSocket protocol client over a TestClient websocket."""

    def __init__(self, ws: Any) -> None:
        self.ws = ws
        self.q: queue.Queue[dict[str, Any] | bytes | None] = queue.Queue()
        self.channels: dict[int, dict[str, Any]] = {}
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        try:
            while True:
                msg = self.ws.receive()
                if msg.get("bytes") is not None:
                    self.q.put(msg["bytes"])
                elif msg.get("text") is not None:
                    self.q.put(json.loads(msg["text"]))
                else:
                    break
        except (WebSocketDisconnect, Exception):
            pass
        self.q.put(None)

    def next(self, timeout: float) -> dict[str, Any] | bytes | None:
        return self.q.get(timeout=timeout)

    def advertised(self, topics: set[str], timeout: float = 10.0) -> None:
        deadline = time.monotonic() + timeout
        while {c["topic"] for c in self.channels.values()} < topics:
            m = self.next(max(0.1, deadline - time.monotonic()))
            if isinstance(m, dict) and m.get("op") == "advertise":
                self.channels.update({c["id"]: c for c in m["channels"]})

    def subscribe_all(self) -> dict[int, str]:
        subs = {i + 1: c for i, c in enumerate(self.channels.values())}
        self.ws.send_text(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": sid, "channelId": c["id"]} for sid, c in subs.items()]}))  # fmt: skip
        return {sid: c["topic"] for sid, c in subs.items()}


def test_a_run_is_published_live_through_the_proxy(fapi) -> None:
    assert fapi.services.dispatch.wait_connected("ara", 20)
    plan = approved_demo(fapi, end="c2")
    token = fapi.tokens["viewer"]
    with fapi.client.websocket_connect(f"/foxglove?token={token}", subprotocols=[PROTO]) as ws:
        assert ws.accepted_subprotocol == PROTO
        fc = FoxgloveClient(ws)
        fc.advertised(set(CHANNELS))
        by_topic = {c["topic"]: c for c in fc.channels.values()}
        assert by_topic["/tf"]["schemaName"] == "foxglove.FrameTransforms"
        assert by_topic["/robot/state"]["schemaEncoding"] == "jsonschema"
        assert by_topic["/robot/state"]["encoding"] == "json"
        subs = fc.subscribe_all()
        time.sleep(0.3)  # the subscription reaches the server before the run starts
        r = fapi.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"})
        assert r.status_code in (200, 201, 202), r.text
        eid = r.json()["id"]
        got: dict[str, list[tuple[int, dict[str, Any]]]] = {}
        deadline = time.monotonic() + 120
        while time.monotonic() < deadline:
            try:
                m = fc.next(1.0)
            except queue.Empty:
                continue
            assert m is not None, "the proxy closed the connection"
            if not isinstance(m, bytes):
                continue
            assert m[0] == 0x01  # message data
            sid, ts = struct.unpack_from("<IQ", m, 1)
            got.setdefault(subs[sid], []).append((ts, json.loads(m[13:])))
            if any("→ completed" in msg["message"] for _, msg in got.get("/operator", [])):
                break
    ex = wait_execution(fapi, eid, ("completed",), timeout=30)

    lines = [msg["message"] for _, msg in got["/operator"]]
    assert any(f"execution {eid}" in s and "→ running" in s for s in lines), lines
    assert any(f"{ex['total']}/{ex['total']} commands" in s for s in lines if "completed" in s)
    acked = [msg["index"] for _, msg in got["/commands/acknowledged"]]
    assert acked == list(range(ex["total"]))
    assert len(got["/plan/program"]) == ex["total"]
    assert len(got["/plan/path"]) == 1 and got["/plan/path"][0][1]["frame_id"] == "world"
    assert "/plan/cloud" not in got  # demo.route names no stored cloud

    states = got["/robot/state"]
    assert len(states) >= 2, states
    assert all(msg["robot"] == "ara" for _, msg in states)
    stored = {tuple(s["q_rad"]) for _, s in fapi.services.store.execution_states(eid)}
    # The dispatch engine stores a report, then publishes it: every live one
    # is a stored one (the last may race the completion and not be stored).
    live = [tuple(msg["q_rad"]) for _, msg in states]
    assert all(q in stored for q in live[:-1]), (live, stored)
    assert len(got["/tf"]) == len(states)
    tf = got["/tf"][0][1]["transforms"]
    assert tf and {"parent_frame_id", "child_frame_id", "translation", "rotation"} <= set(tf[0])
    assert len(got["/robot/tool_pose"]) == len(states)
    now = time.time_ns()
    assert all(now - 300e9 < ts <= now for ts, _ in states)


def test_a_late_subscriber_gets_the_running_plan(fapi) -> None:
    """/plan/program, /plan/path are latched: a client that subscribes while a run
    is under way (here: paused) gets the running plan's messages then."""
    assert fapi.services.dispatch.wait_connected("ara", 20)
    plan = approved_demo(fapi)  # the whole route: long enough to pause in
    r = fapi.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code in (200, 201, 202), r.text
    eid = r.json()["id"]
    wait_execution(fapi, eid, ("running",), timeout=30)
    r = fapi.post(f"/api/v1/executions/{eid}/pause")
    assert r.status_code == 200, r.text
    ex = wait_execution(fapi, eid, ("paused",), timeout=30)
    live = fapi.services.foxglove
    token = fapi.tokens["viewer"]
    with fapi.client.websocket_connect(f"/foxglove?token={token}", subprotocols=[PROTO]) as ws:
        fc = FoxgloveClient(ws)
        fc.advertised(set(CHANNELS))
        subs = fc.subscribe_all()
        got: dict[str, list[dict[str, Any]]] = {}
        deadline = time.monotonic() + 20
        while time.monotonic() < deadline and (
            len(got.get("/plan/program", [])) < ex["total"] or "/plan/path" not in got
        ):
            try:
                m = fc.next(0.5)
            except queue.Empty:
                continue
            assert m is not None, "the proxy closed the connection"
            if isinstance(m, bytes) and m[0] == 0x01:
                sid = struct.unpack_from("<I", m, 1)[0]
                got.setdefault(subs[sid], []).append(json.loads(m[13:]))
    assert [msg["index"] for msg in got["/plan/program"]] == list(range(ex["total"]))
    assert len(got["/plan/path"]) == 1 and got["/plan/path"][0]["frame_id"] == "world"
    assert live.resent >= ex["total"] + 1
    r = fapi.post(f"/api/v1/executions/{eid}/abort")
    assert r.status_code == 200, r.text
    wait_execution(fapi, eid, ("aborted",), timeout=30)
    assert live._latched == {}, "a finished run leaves nothing latched"
