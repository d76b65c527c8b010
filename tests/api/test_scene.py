"""The in-process viser scene: drawing, clicks → proposals, and the authenticated proxy
(more on proposals and the guarded viser port in ``test_scene_proposals.py``)."""

from __future__ import annotations

import socket
import time
import types

import pytest
from starlette.websockets import WebSocketDisconnect


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@pytest.fixture
def sapi(make_api):
    return make_api(scene_port=free_port())


def non_loopback_ip() -> str | None:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        try:
            s.connect(("10.255.255.255", 1))
            ip = s.getsockname()[0]
        except OSError:
            return None
    return None if ip.startswith("127.") else ip


def test_scene_runs_on_loopback_and_reports_its_port(sapi) -> None:
    scene = sapi.services.scene
    assert scene.running and scene.port > 0
    assert scene.server.get_host() == "127.0.0.1"
    health = sapi.client.get("/api/v1/health").json()
    assert health["scene"]["running"] is True
    ip = non_loopback_ip()
    if ip is not None:  # the raw viser port must not answer on a public address
        with socket.socket() as s:
            s.settimeout(1)
            assert s.connect_ex((ip, scene.port)) != 0


def test_show_plan_draws_from_store(sapi) -> None:
    pid = sapi.wait(sapi.submit("demo.route")["id"])["id"]
    r = sapi.post("/api/v1/scene/show", json={"plan_id": pid})
    assert r.status_code == 200 and r.json()["shown"] == pid
    scene = sapi.services.scene.server.scene
    for name in ("/plan/edges", "/plan/vertices", "/plan/route", "/plan/robot", "/plan/labels/a0"):
        assert scene.get_handle_by_name(name) is not None, name
    assert sapi.get("/api/v1/scene", "viewer").json()["current"]["plan_id"] == pid
    # The robot marker animates along the stored route.
    robot = scene.get_handle_by_name("/plan/robot")
    p0 = tuple(robot.position)
    time.sleep(0.4)
    assert tuple(robot.position) != p0
    cid = sapi.post("/api/v1/clouds", json={"sample": "demo_plane"}).json()["id"]
    r = sapi.post("/api/v1/scene/show", json={"cloud_id": cid})
    assert r.json()["points_drawn"] == 5000
    assert scene.get_handle_by_name("/cloud") is not None
    assert scene.get_handle_by_name("/plan/route") is None
    assert sapi.post("/api/v1/scene/show", json={}).status_code == 422
    assert sapi.post("/api/v1/scene/show", json={"plan_id": "pl_x"}).status_code == 404


def test_vertex_clicks_make_a_proposal_not_a_plan(sapi) -> None:
    parent = sapi.wait(sapi.submit("demo.route")["id"])
    sapi.post("/api/v1/scene/show", json={"plan_id": parent["id"]})
    handle = sapi.services.scene.server.scene.get_handle_by_name("/plan/vertices")
    names = list(parent["result"]["nodes"])
    for name in ("b1", "c0"):
        event = types.SimpleNamespace(instance_index=names.index(name))
        for entry in handle._impl.click_cb:
            entry.callback(event)
    assert sapi.get(f"/api/v1/plans?parent_id={parent['id']}").json() == []
    (proposal,) = sapi.get("/api/v1/scene", "viewer").json()["proposals"]
    assert proposal["plan_id"] == parent["id"]
    assert proposal["patch"] == {"start": "b1", "end": "c0"}
    # Accepting it (REST, as the operator) plans it; the scene then follows it.
    r = sapi.post(f"/api/v1/scene/proposals/{proposal['id']}/accept")
    assert r.status_code == 202, r.text
    plan = sapi.wait(r.json()["id"])
    assert (plan["params"]["start"], plan["params"]["end"]) == ("b1", "c0")
    assert plan["created_by"] != "scene" and plan["parent_id"] == parent["id"]
    deadline = time.monotonic() + 10
    while sapi.services.scene.current.get("plan_id") != plan["id"] and time.monotonic() < deadline:
        time.sleep(0.05)
    assert sapi.services.scene.current["plan_id"] == plan["id"]


def test_proxy_requires_a_token_and_a_viewer_sees_the_scene(sapi) -> None:
    c = sapi.client
    assert c.get("/scene/").status_code == 401
    for role in ("viewer", "operator"):
        page = sapi.get("/scene/", role)
        assert page.status_code == 200 and "<html" in page.text.lower()
    with (
        pytest.raises(WebSocketDisconnect) as ei,
        c.websocket_connect("/scene", subprotocols=["viser-v1"]),
    ):
        pass
    assert ei.value.code == 1008
    import viser

    c.cookies.set("steelpath_token", sapi.tokens["viewer"])
    with c.websocket_connect("/scene", subprotocols=[f"viser-v{viser.__version__}"]) as ws:
        assert len(ws.receive_bytes()) > 0  # the scene reaches a viewer


def test_a_viewers_scene_is_read_only(sapi) -> None:
    """Through the proxy a viewer's camera reaches viser, its clicks do not:
    the same vertex clicks that propose a plan for an operator propose
    nothing for a viewer."""
    import viser

    from tests.api.test_scene_proposals import camera_message, click_message

    parent = sapi.wait(sapi.submit("demo.route")["id"])
    assert sapi.post("/api/v1/scene/show", json={"plan_id": parent["id"]}).status_code == 200
    scene = sapi.services.scene
    proto = f"viser-v{viser.__version__}"
    c = sapi.client

    def clicks(role: str) -> int:
        before = len(scene.server.get_clients())
        c.cookies.set("steelpath_token", sapi.tokens[role])
        with c.websocket_connect("/scene", subprotocols=[proto]) as ws:
            ws.receive_bytes()
            ws.send_bytes(camera_message())
            deadline = time.monotonic() + 10  # counted connected after its camera report
            while len(scene.server.get_clients()) <= before:
                assert time.monotonic() < deadline, f"the {role}'s camera never reached viser"
                time.sleep(0.05)
            for index in (3, 7):  # two vertices: an operator's pair proposes a route
                ws.send_bytes(click_message("/plan/vertices", index))
            time.sleep(1.0)
        return len(sapi.get("/api/v1/scene/proposals").json())

    assert clicks("viewer") == 0
    assert clicks("operator") >= 1  # the same frames, from an operator, act


def test_proxy_refuses_cross_origin_websockets(sapi) -> None:
    import viser

    c = sapi.client
    c.cookies.set("steelpath_token", sapi.tokens["operator"])
    proto = f"viser-v{viser.__version__}"
    for origin in ("http://evil.example", "http://testserver:9999", "null"):
        with (
            pytest.raises(WebSocketDisconnect) as ei,
            c.websocket_connect("/scene", subprotocols=[proto], headers={"origin": origin}),
        ):
            pass
        assert ei.value.code == 1008, origin
    # The console's own origin is fine.
    with c.websocket_connect(
        "/scene", subprotocols=[proto], headers={"origin": "http://testserver"}
    ) as ws:
        assert len(ws.receive_bytes()) > 0


def test_proxy_websocket_carries_the_scene(sapi) -> None:
    c = sapi.client
    c.post("/api/v1/session", json={"token": sapi.tokens["operator"]})
    import viser

    proto = f"viser-v{viser.__version__}"
    with c.websocket_connect("/scene", subprotocols=[proto]) as ws:
        assert ws.accepted_subprotocol == proto
        first = ws.receive_bytes()
        assert len(first) > 0


def test_live_robot_state_beside_the_plan(make_api) -> None:
    api = make_api(scene_port=free_port(), emulators=True, emulator_time_scale=2.0)
    assert api.services.dispatch.wait_connected("ara", 20)
    plan = api.wait(api.submit("demo.route")["id"])
    api.post(f"/api/v1/plans/{plan['id']}/approve")
    api.post("/api/v1/scene/show", json={"plan_id": plan["id"]})
    scene = api.services.scene.server.scene
    assert scene.get_handle_by_name("/plan/live_ara") is None
    r = api.post(f"/api/v1/plans/{plan['id']}/dispatch", json={"robot": "ara"})
    assert r.status_code == 201
    deadline = time.monotonic() + 20
    while scene.get_handle_by_name("/plan/live_ara") is None and time.monotonic() < deadline:
        time.sleep(0.05)
    assert scene.get_handle_by_name("/plan/live_ara") is not None
    stored = api.get("/api/v1/robots/ara/state").json()["stored_report"]
    assert stored is not None and len(stored["q_rad"]) == 6
